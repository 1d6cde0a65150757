"""glradial demo: runs end to end on the bundled real frame and on a small stadium, and its reference
lines really are painted lines of the frame (projection conventions agree with crops.py, stadium.py
and distort)."""

from __future__ import annotations

import numpy as np

from glradial.cli import main
from glradial.commands import demo, demo_figure
from glradial.lens.lens import corner_radius, lens_to_pixels
from glradial.lens.metrics import max_displacement_px
from glradial.media.image_io import read_image


def test_demo_small_end_to_end(tmp_path, capsys):
    """With a stand-in ONNX model that always answers (-0.30, 0.07) against the true (-0.32, 0.0764):
    the estimate is printed and the error is the closed form of the difference."""
    from test_cli import constant_model

    out = tmp_path / "demo"
    model = constant_model(tmp_path / "const.onnx", -0.30, 0.07)
    assert main(["demo", "--source", "stadium", "--out", str(out), "--size", "320x180", "--panorama-width", "1024",
                 "--model", str(model), "--method", "net"]) == 0
    printed = capsys.readouterr().out
    figure = read_image(out / "demo.png")
    distorted = read_image(out / "distorted.png")
    corrected = read_image(out / "corrected.png")
    assert distorted.shape == corrected.shape == (180, 320, 3)
    assert figure.shape[1] == 1920 and figure.shape[0] > 540
    assert not np.array_equal(distorted, corrected)
    assert "estimated k1=-0.3000 k2=+0.0700" in printed
    error = float(max_displacement_px((demo.DEFAULT_K1, demo.DEFAULT_K2), (-0.30, 0.07), radius=corner_radius((320, 180))))
    assert f"max displacement error: {error:.1f} px" in printed


def test_demo_without_model_says_so(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(demo_figure, "_find_model", lambda explicit: None)
    assert main(["demo", "--source", "stadium", "--out", str(tmp_path), "--size", "320x180", "--panorama-width", "1024"]) == 0
    printed = capsys.readouterr().out
    assert "no model shipped" in printed
    assert (tmp_path / "demo.png").is_file()
    # corrected with the true lens, the pitch lines are exactly straight again (exact inverse)
    assert "px from straight in the distorted frame, 0.0 px after correction" in printed, printed


def test_reference_lines_lie_on_the_rendered_pitch_lines():
    """Render an undistorted 640×360 crop aimed at the penalty area and sample it along the
    projected penalty-box front line: the painted white line is brighter there than 6 px to either
    side (an independent check of the pan/tilt/axes conventions shared with crops and stadium)."""
    import glradial
    from glradial.synthesis.crops import CropParams, render_crops
    from glradial.synthesis.stadium_style import sample_style

    seed, size = demo.DEFAULT_SEED, (640, 360)
    style = sample_style(seed)
    panorama = glradial.stadium_panorama(seed, (2048, 1024))
    pan, tilt = demo.aim(style, (-30.0, 0.0))
    params = CropParams(pan=pan, tilt=tilt, roll=0.0, hfov=30.0, k1=0.0, k2=0.0)
    frame = render_crops(panorama, [params], size=size)[0].astype(float).mean(axis=2)
    # the centre of the frame is the aimed-at point
    centre = demo.project_undistorted(params, style, np.array([[-30.0, 0.0, 0.0]]), size)
    assert np.abs(centre).max() < 1e-9
    x = -(52.5 - 16.5)
    points = np.stack([np.full(60, x), np.linspace(-15, 15, 60), np.zeros(60)], 1)
    px = lens_to_pixels(demo.project_undistorted(params, style, points, size), size)
    inside = (px[:, 0] > 30) & (px[:, 0] < size[0] - 31) & (px[:, 1] > 8) & (px[:, 1] < size[1] - 9)
    assert inside.sum() > 20

    def contrast(shift: int) -> np.ndarray:
        """Brightness at the projected line (shifted by `shift` px) minus 6 px to either side."""
        values = []
        for u, v in px[inside]:
            iu, iv = int(round(u)) + shift, int(round(v))
            values.append(frame[iv, iu] - 0.5 * (frame[iv, iu - 6] + frame[iv, iu + 6]))
        return np.array(values)

    # the hazy procedural stadium paints thin lines ~5 grey levels above the grass at this scale:
    # on the projected line nearly every sample is brighter; 20 px beside it nothing is
    assert np.mean(contrast(0) > 2.0) > 0.8, contrast(0)
    assert np.median(contrast(20)) < 2.0 and np.median(contrast(-20)) < 2.0


# -- the real frame (default source) ----------------------------------------------------------------

def test_bundled_reference_lines_lie_on_painted_lines():
    """The shipped end points trace painted lines of the undistorted frame the demo starts from:
    along each line the frame is brighter than 5 px to both sides nearly everywhere (players
    crossing it are the exceptions), and 12 px beside it almost nowhere: an independent check of
    the measured end points and of the frame's own lens that was removed."""
    from glradial.commands.demo import bundled_frame

    frame, lines, _own = bundled_frame()
    for name, ends in lines.items():
        t = np.linspace(0.0, 1.0, 300)[:, None]
        points = ends[0] + t * (ends[1] - ends[0])
        assert demo.painted_fraction(frame, points) > 0.8, name
        normal = np.array([-(ends[1] - ends[0])[1], (ends[1] - ends[0])[0]]) / np.hypot(*(ends[1] - ends[0]))
        assert demo.painted_fraction(frame, points + 12 * normal) < 0.2, name


def test_distorted_reference_lines_follow_the_distorted_paint():
    """The positions the demo predicts for the lines in the distorted frame (Lens.distort_points of
    the scaled original) lie on the paint that glradial.distort moved there: the image path (the
    GLSL/CPU remap) and the point path (lensfuncs) agree; the chord between the ends does not."""
    from glradial import Lens, distort
    from glradial.commands.demo import bundled_frame, line_positions

    frame, lines, _own = bundled_frame()
    size = (frame.shape[1], frame.shape[0])
    lens = Lens(-0.45, 0.019 * -0.45 + 0.805 * 0.45**2)
    scale = lens.fit_scale(size, "crop", "distort")
    distorted = distort(frame, lens.k1, lens.k2, fit=scale)
    for name, ends in lines.items():
        curved, _ = line_positions(ends, lens, scale, size)
        assert demo.painted_fraction(distorted, curved) > 0.8, name


def test_real_demo_without_model_straightens_exactly(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(demo_figure, "_find_model", lambda explicit: None)
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "no model shipped" in printed and "real broadcast frame" in printed and "own lens" in printed
    bow = float(printed.split("reference lines: up to ")[1].split(" px")[0])
    assert bow > 3.0  # the default lens visibly bends the lines
    assert "px from straight in the distorted frame, 0.0 px after correction" in printed, printed
    for name in ("demo.png", "distorted.png", "corrected.png"):
        assert (tmp_path / name).is_file()
    assert read_image(tmp_path / "corrected.png").shape == (720, 1280, 3)


def test_real_demo_reports_the_estimate_error(tmp_path, capsys):
    """With a stand-in model answering (-0.30, 0.07): method net prints exactly that, method auto
    (the line fit on this frame) prints its own estimate; either way the printed error is the
    metric of the printed difference."""
    from test_cli import constant_model

    from glradial.lens.metrics import max_displacement_px

    model = constant_model(tmp_path / "const.onnx", -0.30, 0.07)
    for method in ("net", "auto"):
        assert main(["demo", "--out", str(tmp_path / method), "--model", str(model), "--method", method]) == 0
        printed = capsys.readouterr().out
        line = next(row for row in printed.splitlines() if row.startswith("estimated k1="))
        k1, k2 = (float(line.split(f"{name}=")[1].split()[0]) for name in ("k1", "k2"))
        if method == "net":
            assert (k1, k2) == (-0.30, 0.07) and "(net, stated uncertainty" in line
        error = float(max_displacement_px((demo.DEFAULT_K1, demo.DEFAULT_K2), (k1, k2)))
        assert abs(float(printed.split("max displacement error: ")[1].split(" px")[0]) - error) <= 0.06


def test_real_demo_recovers_the_applied_lens_with_the_shipped_model(tmp_path, capsys):
    """The shipped model and the line fit on the default demo: the applied lens comes back within
    the line fit's stated uncertainty and the reference lines end up within a pixel of straight."""
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    error = float(printed.split("max displacement error: ")[1].split(" px")[0])
    stated = float(printed.split("stated uncertainty ")[1].split(" px")[0])
    assert error <= stated, printed
    assert float(printed.split("px from straight in the distorted frame, ")[1].split(" px")[0]) < 1.0, printed
