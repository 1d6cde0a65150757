"""net.error_calibration on real frames (``--real``): the samples are those ``glradial evaluate`` scores,
and the coverage tables are right on hand-computed cases."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from glradial.estimation.net_lines import default_model_path
from glradial.evaluation.real_eval import Evaluator, broadcast_samples, extended_lenses, paper_lenses
from glradial.lens.metrics import max_displacement_px
from net.error_calibration import coverage_report, main, real_errors

ROOT = Path(__file__).resolve().parents[2]
needs_shipped = pytest.mark.skipif(not default_model_path().is_file(), reason="no shipped model in glradial/models")


def _table_rows(text: str) -> dict[str, list[str]]:
    rows = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) > 2 and not cells[0].startswith("---"):
            rows[cells[0] + ("" if len(cells) == 7 else " -> " + cells[2])] = cells
    return rows


def test_coverage_report_known_answers():
    """Scale 10 px everywhere; real_frames errors 1..10 px, broadcast 2..20 px (clip a: 2..10, b: 12..20).
    At q = 0.55 the bound is 5.5 px: 5 of 10 and 2 of 10 covered. Split conformal on real_frames:
    the ceil(11 x 0.9) = 10th smallest ratio, 1.0, covers broadcast errors <= 10 px: 5 of 10."""
    error = np.r_[np.arange(1.0, 11.0), np.arange(2.0, 21.0, 2.0)]
    result = {"error_px": error, "scale_px": np.full(20, 10.0),
              "source": np.array(["real_frames"] * 10 + ["broadcast"] * 10),
              "group": np.array(["f"] * 10 + ["42ba34"] * 5 + ["2e57b9"] * 5)}
    rows = _table_rows(coverage_report(result, 0.55))
    assert rows["real_frames"][1:] == ["10", "5.50", "10.00", "0.91", "50.0%", "5.5"]
    assert rows["broadcast"][5] == "20.0%" and rows["all real"][5] == "35.0%"
    assert rows["broadcast/42ba34"][5] == "40.0%" and rows["broadcast/2e57b9"][5] == "0.0%"
    assert rows["real_frames -> broadcast"][1] == "1.00" and rows["real_frames -> broadcast"][4] == "50.0%"
    # calibrated on broadcast (ratios 0.2..2.0, 10th smallest 2.0): every real_frames error is covered
    assert rows["broadcast -> real_frames"][1] == "2.00" and rows["broadcast -> real_frames"][4] == "100.0%"
    # clip 42ba34's largest ratio (1.0) covers none of 2e57b9 (1.2..2.0)
    assert rows["broadcast/42ba34 -> broadcast/2e57b9"][4] == "0.0%"
    with pytest.raises(ValueError, match="q_val"):
        coverage_report(result, -1.0)


@needs_shipped
def test_real_errors_are_the_samples_glradial_evaluate_scores(tmp_path):
    """One real_football frame (a panorama beside it is left out) and one broadcast frame: the applied
    lenses are evaluate --frames' (same seeds), the broadcast truth and reading are those of
    real_eval.broadcast_samples (the tested path of evaluate --broadcast), errors recomputed."""
    frame = cv2.imread(str(ROOT / "glradial" / "data" / "usl_broadcast_0195.jpg"))
    (tmp_path / "real_football").mkdir()
    (tmp_path / "broadcast_bundesliga").mkdir()
    cv2.imwrite(str(tmp_path / "real_football" / "usl.png"), cv2.resize(frame, (480, 270), interpolation=cv2.INTER_AREA))
    cv2.imwrite(str(tmp_path / "real_football" / "pano.jpg"), np.full((64, 128, 3), 90, np.uint8))
    cv2.imwrite(str(tmp_path / "broadcast_bundesliga" / "abc123_1_1.jpg"), cv2.resize(frame, (320, 320), interpolation=cv2.INTER_AREA))
    result = real_errors(str(default_model_path()), tmp_path, lenses=1, broadcast_lenses=1, progress=lambda _: None)
    assert list(result["source"]) == ["real_frames", "real_frames", "broadcast"]
    assert list(result["group"]) == ["usl", "usl", "abc123"]
    np.testing.assert_allclose(result["truth"][:2], [paper_lenses(1, 0)[0], extended_lenses(1, 500)[0]])
    np.testing.assert_allclose(result["error_px"], max_displacement_px(result["truth"], result["pred"]))
    assert np.all(result["scale_px"] > 0)
    sample = broadcast_samples(Evaluator(), tmp_path / "broadcast_bundesliga", lenses=1)[0]
    np.testing.assert_allclose(result["truth"][2], sample.truths["net"], atol=1e-6)
    np.testing.assert_allclose(result["pred"][2], (sample.estimates["net"].k1, sample.estimates["net"].k2), atol=1e-6)


def test_real_errors_bad_input(tmp_path, capsys):
    with pytest.raises(ValueError, match="lenses must be a positive integer, got 0"):
        real_errors(str(default_model_path()), tmp_path, lenses=0)
    with pytest.raises(ValueError, match="frames folder not found"):
        real_errors(str(default_model_path()), tmp_path / "missing")
    with pytest.raises(SystemExit) as exit_info:
        main(["--model", "m.onnx", "--real", str(tmp_path), "--q", "-2", "--out", str(tmp_path / "x.npz")])
    assert exit_info.value.code == 2 and "--q must be positive" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        main(["--model", str(tmp_path / "none.onnx"), "--real", str(tmp_path), "--out", str(tmp_path / "x.npz")])
    assert exit_info.value.code == 2 and "model file not found" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()
