"""STMap export (glradial stmap / glradial.export.stmap): Nuke's convention, against Lens.maps and against
cv2.undistort as an independent oracle."""

from __future__ import annotations

import shutil
import subprocess

import cv2
import numpy as np
import pytest
from conftest import check_existing_out_needs_y

from glradial import Lens
from glradial.cli import main
from glradial.export.stmap import STMAP_NO_SOURCE, lens_stmap, maps_from_stmap, read_stmap, write_stmap

SIZE = (96, 54)


def apply_stmap(image: np.ndarray, stmap: np.ndarray) -> np.ndarray:
    """What a compositor does with an STMap (Nuke's convention, written independently of
    glradial.export.stmap): sample the source at x = S W - 0.5, y = (1 - T) H - 0.5 (bilinear)."""
    height, width = stmap.shape[:2]
    map_x = (stmap[..., 0].astype(np.float64) * width - 0.5).astype(np.float32)
    map_y = ((1.0 - stmap[..., 1].astype(np.float64)) * height - 0.5).astype(np.float32)
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def test_identity_stmap_is_the_nuke_identity(tmp_path):
    out = tmp_path / "id.tif"
    assert main(["stmap", "--k1", "0", "--k2", "0", "--size", "96x54", "--out", str(out)]) == 0
    raw = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)  # OpenCV gives B, G, R
    assert raw.dtype == np.float32 and raw.shape == (54, 96, 3)
    x = (np.arange(96) + 0.5) / 96
    y = 1.0 - (np.arange(54) + 0.5) / 54
    np.testing.assert_allclose(raw[..., 2], np.broadcast_to(x, (54, 96)), atol=1e-7)  # red = S
    np.testing.assert_allclose(raw[..., 1], np.broadcast_to(y[:, None], (54, 96)), atol=1e-7)  # green = T
    assert np.all(raw[..., 0] == 0)  # blue = 0
    assert raw[0, 0, 1] > 0.98  # top row: T near 1 (origin at the bottom-left)


@pytest.mark.parametrize("direction", ["undistort", "distort"])
@pytest.mark.parametrize("fit", ["same", "crop"])
@pytest.mark.parametrize("ext", [".exr", ".tif", ".npy"])
def test_stmap_file_matches_lens_maps(tmp_path, direction, fit, ext):
    k1, k2 = -0.3, 0.07
    out = tmp_path / f"m{ext}"
    assert main(["stmap", "--k1", str(k1), "--k2", str(k2), "--size", "96x54", "--direction", direction,
                 "--fit", fit, "--out", str(out)]) == 0
    stmap = read_stmap(out)
    map_x, map_y = maps_from_stmap(stmap)
    ref_x, ref_y = Lens(k1, k2).maps(SIZE, direction=direction, fit=fit, dtype=np.float64)
    # float32 S, T in [0, 1] carry ~6e-8 relative error: < 1e-4 px on a 96-px frame
    np.testing.assert_allclose(map_x, ref_x, atol=1e-4)
    np.testing.assert_allclose(map_y, ref_y, atol=1e-4)


def test_undistort_stmap_applied_like_nuke_equals_cv2_undistort(road):
    """Independent oracle: cv2.undistort with K(f = W) and dist = (k1, k2, 0, 0) (docs/DESIGN.md)."""
    k1, k2 = -0.25, 0.04
    image = cv2.resize(road, SIZE, interpolation=cv2.INTER_AREA)
    stmap = lens_stmap(Lens(k1, k2), SIZE)
    width, height = SIZE
    camera = np.array([[width, 0, (width - 1) / 2], [0, width, (height - 1) / 2], [0, 0, 1]], np.float64)
    expected = cv2.undistort(image, camera, np.array([k1, k2, 0, 0], np.float64))
    difference = np.abs(apply_stmap(image, stmap).astype(int) - expected.astype(int))
    # both bilinear with 1/32-px fixed-point weights; coordinates agree to ~1e-4 px, so only the
    # rounding of the weights differs: a few levels at the sharpest edges, ~0 on average
    assert difference.max() <= 3 and difference.mean() < 0.3, (difference.max(), difference.mean())


def test_off_centre_stmap_applied_like_nuke_equals_cv2_undistort(road):
    """The same oracle with a principal point 20 px right of and 6 px above the centre and
    fx != fy: cv2.undistort(image, K, dist, newCameraMatrix=K); bounds as above."""
    width, height = SIZE
    camera = np.array([[80.0, 0, (width - 1) / 2 + 20], [0, 78.5, (height - 1) / 2 - 6], [0, 0, 1]])
    dist = np.array([-0.25, 0.05, 0, 0])
    image = cv2.resize(road, SIZE, interpolation=cv2.INTER_AREA)
    stmap = lens_stmap(Lens.from_opencv(camera, dist, SIZE), SIZE)
    expected = cv2.undistort(image, camera, dist, newCameraMatrix=camera)
    difference = np.abs(apply_stmap(image, stmap).astype(int) - expected.astype(int))
    assert difference.max() <= 3 and difference.mean() < 0.3, (difference.max(), difference.mean())


def test_distort_then_undistort_stmaps_round_trip():
    lens = Lens(-0.3, 0.07)
    distort_map = lens_stmap(lens, SIZE, direction="distort")
    undistort_map = lens_stmap(lens, SIZE, direction="undistort")
    # composing the two maps is the identity wherever the distortion has a source
    s, t = distort_map[..., 0], distort_map[..., 1]
    ok = (s > 0.05) & (s < 0.95) & (t > 0.05) & (t < 0.95)
    map_x, map_y = maps_from_stmap(undistort_map)
    composed_x = cv2.remap(map_x, *maps_from_stmap(distort_map), cv2.INTER_LINEAR)
    x = np.broadcast_to(np.arange(SIZE[0], dtype=np.float32), map_x.shape)
    assert ok.mean() > 0.5
    assert np.abs(composed_x - x)[ok].max() < 0.05  # px: bilinear interpolation of a smooth map


def test_pixels_without_source_are_marked():
    # strong barrel (valid on 16:9: folds at r = 0.745 > corner 0.574) whose largest distorted
    # radius, 0.745 (1 - 0.6 * 0.745^2) = 0.497, is inside the corner: the corners have no source
    lens = Lens(-0.6, 0.0)
    stmap = lens_stmap(lens, (64, 36), direction="distort")
    assert np.all(stmap[0, 0, :2] == STMAP_NO_SOURCE)
    assert np.all(stmap[18, 32, :2] != STMAP_NO_SOURCE)


def test_stmap_bad_input(tmp_path, capsys):
    assert main(["stmap", "--k1", "0.1", "--size", "96x54", "--out", str(tmp_path / "m.png")]) == 1
    assert "unknown STMap extension '.png'" in capsys.readouterr().err
    assert main(["stmap", "--k1", "0.1", "--size", "96by54", "--out", str(tmp_path / "m.tif")]) == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["stmap", "--k1", "-2", "--k2", "0", "--size", "96x54", "--out", str(tmp_path / "m.tif")]) == 1
    assert "folds over" in capsys.readouterr().err
    assert main(["stmap", "--k1", "nan", "--size", "96x54", "--out", str(tmp_path / "m.tif")]) == 2
    assert list(tmp_path.iterdir()) == []


def test_stmap_replaces_an_existing_out_only_with_y(tmp_path, capsys, monkeypatch):
    out = tmp_path / "m.npy"
    argv = ["stmap", "--k1", "-0.1", "--size", "32x18", "--out", str(out)]
    check_existing_out_needs_y(argv, out, "glradial.export.stmap.lens_stmap", monkeypatch, capsys)
    np.testing.assert_array_equal(read_stmap(out), lens_stmap(Lens(-0.1, 0.0), (32, 18)))


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs the ffmpeg command (installed by make's set-up)")
def test_exr_stmap_decodes_in_ffmpeg_as_written(tmp_path):
    """An independent EXR decoder (FFmpeg's) reads the same float32 S, T, B planes: proof that the
    file is a standard float EXR, not just something our own reader round-trips."""
    stmap = lens_stmap(Lens(-0.3, 0.07), (96, 54))
    out = tmp_path / "m.exr"
    write_stmap(out, stmap)
    raw = subprocess.run(
        ["ffmpeg", "-v", "error", "-i", str(out), "-f", "rawvideo", "-pix_fmt", "gbrpf32le", "-"],
        check=True, capture_output=True,
    ).stdout
    planes = np.frombuffer(raw, dtype="<f4").reshape(3, 54, 96)  # planar G, B, R
    decoded = np.stack([planes[2], planes[0], planes[1]], axis=-1)
    np.testing.assert_array_equal(decoded, stmap)  # float32 in, float32 out: lossless, bit-exact


def test_exr_stmap_is_compressed(tmp_path):
    """ZIP compression: the smooth S, T ramps of a 1080p map take far less than the 24.9 MB of raw
    float32 RGB (the TIFF writer stores them uncompressed)."""
    stmap = lens_stmap(Lens(-0.25, 0.05), (1920, 1080))
    exr = write_stmap(tmp_path / "m.exr", stmap)
    tif = write_stmap(tmp_path / "m.tif", stmap)
    assert exr.stat().st_size < 0.6 * tif.stat().st_size
    np.testing.assert_array_equal(read_stmap(exr), stmap)


def test_read_stmap_rejects_a_broken_exr(tmp_path):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr file at all")
    with pytest.raises(ValueError, match="bad.exr"):
        read_stmap(bad)
