"""Procedural stadium panoramas: determinism, seed split, geometry against the analytic camera model,
straight lines through the crop synthesis (and curved ones under a lens), anti-aliased thin lines."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import check_existing_out_needs_y

from glradial.lens import lensfuncs
from glradial.synthesis.stadium import StadiumRenderer, project_point, stadium_panorama
from glradial.synthesis.stadium_style import (
    HALF_WIDTH,
    SPLITS,
    sample_style,
    split_seeds,
    stadium_split,
)

# A main-camera stadium (camera on the halfway line, ~120 m from the far touchline), chosen by its
# style so that the test survives changes of the style sampler.
SEED = next(s for s in range(200) if sample_style(s).camera_kind == "main")
# Clutter that is not part of the geometry under test: stripes, players, wear, shadow edges and the
# advertising boards (a few rows above the far touchline).
CLEAN = {"stripe_pattern": "none", "players": (), "wear": 0.0, "lighting": "overcast", "board_height": 0.01}


@pytest.fixture(scope="module")
def renderer(gl_ctx):
    with StadiumRenderer(gl_ctx) as r:
        yield r


def test_split_is_seed_mod_10():
    assert [stadium_split(s) for s in range(10)] == ["train"] * 8 + ["val", "test"]
    assert stadium_split(123459) == "test"
    seeds = {name: split_seeds(name, 30) for name in SPLITS}
    assert all(len(v) == 30 and v == sorted(v) for v in seeds.values())
    assert not set(seeds["train"]) & set(seeds["val"]) and not set(seeds["val"]) & set(seeds["test"])
    assert all(s % 10 == 9 for s in seeds["test"]) and all(s % 10 == 8 for s in seeds["val"])
    with pytest.raises(ValueError, match="split"):
        split_seeds("training", 3)
    with pytest.raises(ValueError, match="-1"):
        stadium_split(-1)
    with pytest.raises(TypeError, match="seed"):
        stadium_split(1.5)


def test_style_validation_names_the_bad_value():
    style = sample_style(3)
    with pytest.raises(TypeError, match="colour_of_sky"):
        style.with_overrides(colour_of_sky=1)
    with pytest.raises(ValueError, match="dusk"):
        style.with_overrides(lighting="dusk")
    with pytest.raises(ValueError, match="size"):
        stadium_panorama(3, (4, 2))


def test_camera_stands_where_broadcast_cameras_stand():
    kinds = set()
    for seed in range(60):
        st = sample_style(seed)
        kinds.add(st.camera_kind)
        x, y, z = st.camera
        lon, lat = project_point(st, (0.0, 0.0, 0.0))
        assert abs(lon) < 1e-9, (seed, lon)  # the pitch centre is at longitude 0
        if st.camera_kind == "main":
            assert abs(x) <= 2.0 and 30.0 <= -y - HALF_WIDTH <= 70.0, (seed, st.camera)
            assert 5.0 < z < 60.0 and -35.0 < lat < -5.0, (seed, st.camera, lat)
        if st.camera_kind == "pitch_side":
            assert z < 3.0, (seed, st.camera)
    assert kinds == {"main", "tribune", "behind_goal", "pitch_side"}


def test_deterministic_per_seed_and_seeds_differ(ctx):
    a = stadium_panorama(4, (256, 128))
    b = stadium_panorama(4, (256, 128))
    c = stadium_panorama(5, (256, 128))
    assert a.shape == (128, 256, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b)
    assert np.abs(a.astype(int) - c.astype(int)).mean() > 10.0
    # not a flat image: sky, stands and pitch all present
    assert a.std() > 20.0


def test_pitch_centre_is_grass_where_the_camera_says_for_every_camera_kind(ctx, renderer):
    """For every camera kind, the panorama pixels at the analytic (lon, lat) of points on the pitch
    (clear of the markings) are grass: green dominant."""
    w, h = 512, 256
    kinds = {}
    for seed in range(40):
        kind = sample_style(seed).camera_kind
        kinds.setdefault(kind, seed)
    assert len(kinds) == 4
    for kind, seed in kinds.items():
        style = sample_style(seed).with_overrides(players=(), lighting="overcast", stripe_pattern="none", wear=0.0)
        pano = renderer.render(style, (w, h)).astype(int)
        # near the corners too: an off-centre camera with a mirrored or shifted view would miss them
        for point in [(6.0, 14.0, 0.0), (20.0, -12.0, 0.0), (-20.0, 12.0, 0.0), (48.0, 29.0, 0.0), (-48.0, -29.0, 0.0),
                      (48.0, -29.0, 0.0), (-48.0, 29.0, 0.0)]:
            lon, lat = project_point(style, point)
            if lat > -2.5:
                continue  # grazing view from a low camera: the pixel (0.7 deg) reaches past the pitch
            x = int(round((0.5 + lon / 360.0) * w - 0.5)) % w
            y = int(round((0.5 - lat / 180.0) * h - 0.5))
            r, g, b = pano[y, x]
            assert g > r + 5 and g > b + 5, (kind, seed, point, (r, g, b))
        if kind == "main":
            assert abs(project_point(style, (0.0, 0.0, 0.0))[0]) < 1e-9


def test_strips_and_row_windows_give_the_same_pixels(ctx, renderer, monkeypatch):
    import glradial.synthesis.stadium as stadium

    style = sample_style(6).with_overrides(supersample=2)
    full = renderer.render(style, (256, 128)).copy()
    monkeypatch.setattr(stadium, "STRIP_PIXELS", 256 * 7)  # 7-row strips, last one shorter
    strips = renderer.render(style, (256, 128))
    assert np.array_equal(full, strips)
    window = renderer.render(style, (256, 128), rows=(40, 90))
    assert np.array_equal(window[40:90], full[40:90])
    assert not window[:40].any() and not window[90:].any()


# --- the far touchline seen through the crop synthesis --------------------------------------------

PANO = (2048, 1024)
CROP = (640, 360)
HFOV = 40.0


def _touchline_band(renderer, style, margin_deg=(7.0, 20.0)):
    """Panorama with only the rows around the far touchline rendered (the crops need no others)."""
    _, lat = project_point(style, (0.0, HALF_WIDTH, 0.0))
    w, h = PANO
    y_line = (0.5 - lat / 180.0) * h - 0.5
    y0 = int(y_line - margin_deg[1] / 180.0 * h)
    y1 = int(y_line + margin_deg[0] / 180.0 * h)
    return renderer.render(style, PANO, rows=(y0, y1)), lat


def _detect_line_rows(gray: np.ndarray, predicted: np.ndarray, cols: np.ndarray, half: int = 4) -> np.ndarray:
    """Sub-pixel row of a thin bright line in each column: brightness-weighted centroid of the excess
    over the grass below it (the boards above are darker) within ``half`` rows of the predicted row."""
    rows = []
    for col, pred in zip(cols, predicted):
        r0 = int(round(pred))
        window = gray[r0 - half:r0 + half + 1, col].astype(float)
        background = np.median(gray[r0 + half + 1:r0 + 2 * half + 2, col].astype(float))
        excess = np.clip(window - background - 1.0, 0.0, None)
        rows.append(np.sum(excess * np.arange(r0 - half, r0 + half + 1)) / max(excess.sum(), 1e-9))
    return np.array(rows)


def _predicted_rows(style, params, cols: np.ndarray, size=CROP) -> np.ndarray:
    """Analytic row (k = 0 pinhole) of the far touchline's centre line in crop columns ``cols``."""
    w, h = size
    rot = params.rotation()
    y_line = HALF_WIDTH - style.line_width / 2.0
    xs = np.linspace(-80.0, 80.0, 4001)
    pts = []
    for x in xs:
        lon, lat = (math.radians(v) for v in project_point(style, (x, y_line, 0.0)))
        world = np.array([math.cos(lat) * math.sin(lon), -math.sin(lat), math.cos(lat) * math.cos(lon)])
        cam = rot.T @ world
        p = cam[:2] / cam[2] * params.focal  # lens units (width = 1)
        pts.append(((p[0] + 0.5) * w - 0.5, (p[1] * w / h + 0.5) * h - 0.5))
    pts = np.array(pts)
    return np.interp(cols, pts[:, 0], pts[:, 1])


def test_touchline_is_where_the_camera_says_straight_at_k0_curved_at_k1(ctx, renderer):
    from glradial.synthesis.crops import CropParams, render_crops

    style = sample_style(SEED).with_overrides(line_width=0.3, **CLEAN)
    assert style.camera_kind == "main"
    pano, lat = _touchline_band(renderer, style)
    straight = CropParams(pan=0.0, tilt=lat + 7.0, roll=0.0, hfov=HFOV, k1=0.0, k2=0.0)
    curved = CropParams(pan=0.0, tilt=lat + 7.0, roll=0.0, hfov=HFOV, k1=-0.4, k2=0.0)
    crops = render_crops(pano, [straight, curved], size=CROP)
    # columns clear of the halfway line and of the frame edges (where barrel distortion brings the
    # boards within a few rows of the line)
    cols = np.array([c for c in range(50, CROP[0] - 50, 4) if abs(c - CROP[0] / 2) > 20])

    gray0 = cv2.cvtColor(crops[0], cv2.COLOR_RGB2GRAY)
    predicted = _predicted_rows(style, straight, cols)
    rows0 = _detect_line_rows(gray0, predicted, cols)
    # where: the rendered touchline sits on the analytic projection of (x, 34 - w/2, 0) through the
    # camera position and the crop's pinhole (0.5 px: panorama pixels are 2.8 crop pixels wide)
    assert np.abs(rows0 - predicted).mean() < 0.5, np.abs(rows0 - predicted).max()
    # straight: a line fit leaves well under a pixel (a straight 3-D line stays straight at k = 0)
    fit = np.polyfit(cols, rows0, 1)
    assert np.sqrt(np.mean((np.polyval(fit, cols) - rows0) ** 2)) < 0.25

    # k1 = -0.4 (barrel): the same line bows measurably ...
    gray1 = cv2.cvtColor(crops[1], cv2.COLOR_RGB2GRAY)
    w, h = CROP
    # predicted distorted curve: the forward model p_d = p_u (1 + k1 r^2) applied to the analytic line
    dense = np.arange(-150.0, w + 150.0, 0.5)
    yu = _predicted_rows(style, straight, dense)
    p_u = np.stack([(dense + 0.5) / w - 0.5, ((yu + 0.5) / h - 0.5) * h / w], axis=-1)
    p_d = lensfuncs.distort_point(p_u, -0.4, 0.0)
    cols1 = cols
    pred_d = np.interp(cols1, (p_d[:, 0] + 0.5) * w - 0.5, (p_d[:, 1] * w / h + 0.5) * h - 0.5)
    rows1 = _detect_line_rows(gray1, pred_d, cols1)
    fit1 = np.polyfit(cols1, rows1, 1)
    assert np.sqrt(np.mean((np.polyval(fit1, cols1) - rows1) ** 2)) > 2.0
    # ... exactly as the lens model says: undistorting the detected points makes them straight again
    pts = np.stack([(cols1 + 0.5) / w - 0.5, ((rows1 + 0.5) / h - 0.5) * h / w], axis=-1)
    und, valid = lensfuncs.undistort_point_exact(pts, -0.4, 0.0)
    assert valid.all()
    ux, uy = (und[:, 0] + 0.5) * w - 0.5, (und[:, 1] * w / h + 0.5) * h - 0.5
    fitu = np.polyfit(ux, uy, 1)
    assert np.sqrt(np.mean((np.polyval(fitu, ux) - uy) ** 2)) < 0.35
    assert np.abs(rows1 - pred_d).mean() < 0.6


def test_thin_lines_are_antialiased_not_aliased(ctx, renderer):
    """A real 12 cm touchline ~115 m away covers under a tenth of a panorama pixel row. The line alone
    (render with the line minus render without it) must leave the same integrated brightness in
    every column; point-sampled it would be all (a full white pixel) or nothing."""
    style = sample_style(SEED).with_overrides(line_width=0.12, supersample=1, **CLEAN)
    with_line, _ = _touchline_band(renderer, style, margin_deg=(3.0, 3.0))
    without, _ = _touchline_band(renderer, style.with_overrides(line_width=0.0), margin_deg=(3.0, 3.0))
    line = with_line.astype(float).mean(axis=2) - without.astype(float).mean(axis=2)
    w, h = PANO
    sums = []
    for x in np.linspace(-40.0, 40.0, 161):
        if abs(x) < 3.0:
            continue  # halfway line
        lon, lat = project_point(style, (x, HALF_WIDTH - 0.06, 0.0))
        col = int(round((0.5 + lon / 360.0) * w - 0.5))
        r0 = int(round((0.5 - lat / 180.0) * h - 0.5))
        assert np.abs(line[r0 - 6:r0 + 7, col]).sum() == pytest.approx(line[r0 - 2:r0 + 3, col].sum(), abs=1e-9)
        sums.append(line[r0 - 2:r0 + 3, col].sum())
    sums = np.array(sums)
    assert sums.mean() > 5.0  # the line is visible (grey levels summed over the column)
    # aliasing would make this ~1 (a whole pixel in some columns, nothing in others); what is left
    # is the sRGB encoding over a grass texture that varies along the line
    assert sums.std() / sums.mean() < 0.15, (sums.mean(), sums.std())


def test_command_writes_the_panorama(ctx, tmp_path):
    from glradial.commands import stadium as command

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    command.add_parser(sub)
    out = tmp_path / "pano.png"
    args = parser.parse_args(["stadium", "--seed", "4", "--size", "256x128", "--out", str(out)])
    assert command.run(args) == 0
    written = cv2.cvtColor(cv2.imread(str(out)), cv2.COLOR_BGR2RGB)
    assert np.array_equal(written, stadium_panorama(4, (256, 128)))


def test_command_replaces_an_existing_out_only_with_y(ctx, tmp_path, capsys, monkeypatch):
    out = tmp_path / "pano.png"
    argv = ["stadium", "--seed", "4", "--size", "64x32", "--out", str(out)]
    check_existing_out_needs_y(argv, out, "glradial.synthesis.stadium.stadium_panorama", monkeypatch, capsys)
    written = cv2.cvtColor(cv2.imread(str(out)), cv2.COLOR_BGR2RGB)
    assert np.array_equal(written, stadium_panorama(4, (64, 32)))


@pytest.mark.parametrize("name", ["s.bmpx", "s.mp4", "s"])
def test_command_names_an_unknown_image_extension(tmp_path, capsys, name):
    from glradial.cli import main

    assert main(["stadium", "--seed", "1", "--size", "64x32", "--out", str(tmp_path / name)]) == 1
    err = capsys.readouterr().err
    suffix = repr(Path(name).suffix or "(none)")
    assert f"unknown image extension {suffix}; use .jpeg, .jpg, .png, .tif, .tiff or .npy" in err, err
    assert "video" not in err and list(tmp_path.iterdir()) == []


def test_command_refuses_exr_before_rendering(tmp_path, capsys, monkeypatch):
    """OpenEXR stores float samples only: an 8-bit panorama named .exr is refused before the
    render (which takes a minute at the default size), naming the formats that keep it."""
    from glradial.cli import main

    def no_render(*args, **kwargs):
        raise AssertionError("rendered although --out cannot store the panorama")

    monkeypatch.setattr("glradial.synthesis.stadium.stadium_panorama", no_render)
    assert main(["stadium", "--seed", "1", "--size", "64x32", "--out", str(tmp_path / "s.exr")]) == 1
    err = capsys.readouterr().err
    assert "'.exr' " not in err and ".exr cannot store the panorama's 8-bit RGB samples" in err, err
    assert "use .jpeg, .jpg, .png, .tif, .tiff or .npy" in err and list(tmp_path.iterdir()) == []


def test_the_panorama_cache_key_follows_the_shader_source(tmp_path, monkeypatch):
    """A changed stadium shader (here an included file) names another cache file, so a panorama
    rendered by the old shader is never served; the same sources name the same file."""
    import shutil

    from glradial.gl import shaderlib
    from glradial.synthesis.stadium import stadium_cache_path

    before = stadium_cache_path(3, (64, 32), tmp_path)
    copy = tmp_path / "shaders"
    shutil.copytree(shaderlib.shader_dir(), copy)
    monkeypatch.setattr(shaderlib, "shader_dir", lambda: copy)
    assert stadium_cache_path(3, (64, 32), tmp_path) == before
    noise = copy / "stadium_noise.glsl"
    noise.write_text(noise.read_text() + "\n// a changed shader\n")
    after = stadium_cache_path(3, (64, 32), tmp_path)
    assert after != before and after.parent == before.parent and after.name.startswith("stadium_3_64x32_")
    assert stadium_cache_path(4, (64, 32), tmp_path) != after and stadium_cache_path(3, (64, 64), tmp_path) != after
