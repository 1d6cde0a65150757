"""glradial.evaluation.real_eval (real frames with known lenses -> per-source table) and the CLI hooks
(``glradial estimate --method``, ``glradial evaluate --frames``)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from glradial.estimation.lens_estimate import LensEstimate
from glradial.estimation.net_lines import default_model_path
from glradial.evaluation.real_eval import Sample, centre_16_9, extended_lenses, frames_in, load_calibrated, markdown, self_consistent_items, self_consistent_truth, summarise
from glradial.lens.lens import Lens, lens_to_pixels, pixels_to_lens
from glradial.lens.metrics import manifold_k2, max_displacement_px
from glradial.remapping.remap import distort

ROOT = Path(__file__).resolve().parents[2]
needs_shipped = pytest.mark.skipif(not default_model_path().is_file(), reason="no shipped model in glradial/models")


def test_centre_16_9_and_extended_lenses():
    assert centre_16_9(np.zeros((100, 100, 3), np.uint8)).shape == (56, 100, 3)
    assert centre_16_9(np.zeros((90, 400, 3), np.uint8)).shape == (90, 160, 3)
    lenses = np.array(extended_lenses(200, 0))
    assert lenses[:, 0].min() >= -1.0 and lenses[:, 0].max() <= 0.4
    assert np.all(lenses[:, 1] >= manifold_k2(lenses[:, 0]))  # on or above the manifold
    assert lenses[:, 0].min() < -0.8  # the extended range is really used


def test_summarise_against_hand_computed_figures():
    truth = (-0.3, float(manifold_k2(-0.3)))
    # 'lines' exact; 'net' off in k1 by 0.05 with the manifold k2 of the truth
    samples = [Sample("a", truth, {"net": LensEstimate(-0.25, truth[1], uncertainty_px=16.0, method="net"),
                                   "lines": LensEstimate(*truth, uncertainty_px=1.0, method="lines", chains=5),
                                   "auto": LensEstimate(*truth, uncertainty_px=1.0, method="lines", chains=5)}) for _ in range(3)]
    table = summarise(samples)["a"]
    expected = float(max_displacement_px(np.array([-0.25, truth[1]]), np.array(truth)))
    assert table["net"]["median_px"] == pytest.approx(expected)  # 0.05 * 0.5737**3 * 1920 = 18.1 px
    assert table["net"]["inside_bound"] == 0.0 and table["lines"]["inside_bound"] == 1.0
    assert table["lines"]["median_px"] == 0.0 and table["auto"]["lines_share"] == 1.0
    # the truth's k2 is on the manifold: 'lines' ties method B (not a win), 'net' has k2 off its own manifold
    assert table["lines"]["a_beats_b"] == 0.0
    assert "| a | net | 3 |" in markdown(summarise(samples), "t")
    # frames that carry their own lens are left out of the extra aggregate row
    other = [Sample("b/paper", truth, samples[0].estimates)]
    grouped = summarise(samples + other, own_lens={"a"})
    assert grouped["all real"]["net"]["n"] == 4
    assert grouped["all real without own-lens frames"]["net"]["n"] == 1


def test_bad_inputs_name_what_is_wrong(tmp_path):
    with pytest.raises(ValueError, match="frames folder not found"):
        frames_in(tmp_path / "nope")
    with pytest.raises(ValueError, match="no images"):
        frames_in(tmp_path)
    bad = tmp_path / "cam.json"
    bad.write_text("{\"frames\": []}")
    with pytest.raises(ValueError, match="non-empty 'frames'"):
        load_calibrated(bad)
    cv2.imwrite(str(tmp_path / "f.png"), np.zeros((72, 128, 3), np.uint8))
    bad.write_text(json.dumps({"frames": ["f.png"]}))
    with pytest.raises(ValueError, match="camera_matrix"):
        load_calibrated(bad)


def test_calibrated_camera_from_opencv_numbers(tmp_path):
    cv2.imwrite(str(tmp_path / "f.png"), np.zeros((72, 128, 3), np.uint8))
    spec = {"frames": ["f.png"], "size": [128, 72], "camera_matrix": [[128, 0, 63.5], [0, 128, 35.5], [0, 0, 1]],
            "dist_coeffs": [-0.2, 0.05, 0, 0, 0]}
    (tmp_path / "cam.json").write_text(json.dumps(spec))
    name, frames, lens = load_calibrated(tmp_path / "cam.json")
    assert name == "cam" and len(frames) == 1
    assert (lens.k1, lens.k2) == pytest.approx((-0.2, 0.05))  # f = W: the numbers are ours (docs/DESIGN.md)


def _pitch_png(path: Path) -> None:
    img = np.full((360, 640, 3), (40, 110, 40), np.uint8)
    for y in (40, 120, 200, 280, 340):
        cv2.line(img, (-20, y - 15), (660, y + 15), (230, 230, 230), 2, cv2.LINE_AA)
    for x in (80, 300, 520):
        cv2.line(img, (x - 120, -20), (x + 120, 380), (230, 230, 230), 2, cv2.LINE_AA)
    cv2.imwrite(str(path), img)


@needs_shipped
def test_cli_estimate_prints_method_and_uncertainty(tmp_path):
    _pitch_png(tmp_path / "pitch.png")
    run = [sys.executable, "-m", "glradial", "estimate", str(tmp_path / "pitch.png")]
    out = subprocess.run(run + ["--json", "--method", "lines"], capture_output=True, text=True, cwd=ROOT, check=True)
    row = json.loads(out.stdout)
    assert row["method"] == "lines" and row["chains"] >= 3 and 0 < row["uncertainty_px"] < 16
    assert abs(row["k1"]) < 0.05  # an undistorted drawing
    text = subprocess.run(run + ["--method", "net"], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert "method=net" in text and "uncertainty=" in text
    bad = subprocess.run(run + ["--method", "x"], capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode != 0 and "--method" in bad.stderr


@needs_shipped
def test_cli_evaluate_frames_writes_the_table(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    _pitch_png(frames / "pitch.png")
    out = tmp_path / "out"
    subprocess.run([sys.executable, "-m", "glradial", "evaluate", "--frames", str(frames), "--out", str(out),
                    "--threads", "1"], capture_output=True, text=True, cwd=ROOT, check=True)
    text = (out / "real.md").read_text()
    assert "| pitch/paper | auto | 12 |" in text and "own distortion" in text
    summary = json.loads((out / "real_metrics.json").read_text())["summary"]
    # a clean drawing of straight lines: the lines method reads the applied lenses closely
    assert summary["pitch/paper"]["lines"]["median_px"] < 2.0


def test_agreed_own_lens_needs_both_readings_far_from_no_lens_and_close_to_each_other():
    """A frame's own lens is removed only when the line fit and the CNN agree on it: known answers
    for agreement (the bundled USL frame's readings), disagreement, near-pinhole and no line fit."""
    from glradial.estimation.lens_estimate import LensEstimate
    from glradial.evaluation.real_eval import agreed_own_lens

    lines = LensEstimate(-0.2305, 0.0432, uncertainty_px=7.7, method="lines", chains=2)
    net = LensEstimate(-0.248, 0.051, uncertainty_px=16.0, method="net")
    found = agreed_own_lens({"lines": lines, "net": net})
    assert (found.k1, found.k2) == (lines.k1, lines.k2)
    opposite = LensEstimate(0.2, 0.05, uncertainty_px=16.0, method="net")
    assert agreed_own_lens({"lines": lines, "net": opposite}) is None
    small = LensEstimate(-0.02, 0.0, uncertainty_px=3.0, method="lines", chains=4)  # 3.6 px from no lens
    assert agreed_own_lens({"lines": small, "net": LensEstimate(-0.03, 0.0, uncertainty_px=16.0)}) is None
    fallback = LensEstimate(-0.248, 0.051, uncertainty_px=16.0, method="net")  # 'lines' fell back to the net
    assert agreed_own_lens({"lines": fallback, "net": net}) is None


def test_self_consistent_items_scale_is_the_one_distort_applies():
    """Known answer through the real remap: dots of an ideal frame, moved by the frame's own lens
    (``distort``, fit "same"), then by a known lens as ``self_consistent_items`` applies it (fit
    "crop", scale s); each dot lands where the refitted composite
    (``self_consistent_truth(applied, own, s)``) puts it, ``T(s x)`` for an ideal point ``x``,
    within 0.6 px at 1280 (blob centroids; a scale of 1 instead of s would be off by tens of px)."""
    size, own, applied = (1280, 720), (-0.12, 0.02), (-0.45, 0.17)
    ideal_px = np.array([[640 + dx, 360 + dy] for dx in (-420, -210, 0, 210, 420) for dy in (-220, 0, 220)], np.float64)
    yy, xx = np.mgrid[0:size[1], 0:size[0]]
    ideal = np.zeros(size[::-1], np.float32)
    for x, y in ideal_px:
        ideal += np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 2.5**2))
    frame = distort(np.dstack([ideal] * 3), *own, fit="same", backend="cpu")
    (lens, scale, out), = self_consistent_items(frame, [applied])
    assert lens == applied and scale == pytest.approx(Lens(*applied).fit_scale(size, "crop", "distort"))
    k = np.array(self_consistent_truth(applied, own, scale))
    u = scale * pixels_to_lens(ideal_px, size)
    r2 = np.sum(u**2, axis=1, keepdims=True)
    expected = lens_to_pixels(u * (1 + k[0] * r2 + k[1] * r2**2), size)
    gray = out[..., 0].astype(np.float64)
    for ex, ey in expected:
        x0, y0 = int(round(ex)) - 9, int(round(ey)) - 9
        w = gray[y0:y0 + 19, x0:x0 + 19]
        cy, cx = np.mgrid[y0:y0 + 19, x0:x0 + 19]
        assert np.hypot((w * cx).sum() / w.sum() - ex, (w * cy).sum() / w.sum() - ey) < 0.6
