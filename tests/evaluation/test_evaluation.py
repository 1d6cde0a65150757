"""glradial.evaluation.evaluation's figures beyond the paper's: the median's bootstrap interval and the
correlation of the k2 deviation from the manifold (known answers; no torch), and the `glradial evaluate` command (GL, the bundled model)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from glradial.evaluation.evaluation import deviation_correlation, metrics
from glradial.lens.metrics import manifold_k2, median_interval


def _lenses(k1: np.ndarray, deviation: np.ndarray) -> np.ndarray:
    return np.stack([k1, manifold_k2(k1) + deviation], axis=1)


def test_deviation_correlation_known_answers():
    rng = np.random.default_rng(1)
    k1 = rng.uniform(-0.7, 0.3, 200)
    deviation = rng.normal(0.0, 0.02, 200)
    labels = _lenses(k1, deviation)
    k1_hat = k1 + rng.normal(0.0, 0.03, 200)  # k1 errors do not enter: each deviation is from its own k1
    assert deviation_correlation(_lenses(k1_hat, 2 * deviation + 0.01), labels) == pytest.approx(1.0, abs=1e-12)
    assert deviation_correlation(_lenses(k1_hat, -deviation), labels) == pytest.approx(-1.0, abs=1e-12)
    # On the manifold (method B) the predicted deviation is constant: no correlation is defined.
    assert deviation_correlation(_lenses(k1_hat, np.zeros(200)), labels) is None
    # Independent deviations: near zero (|r| < 3 / sqrt(n) = 0.21 with overwhelming probability).
    assert abs(deviation_correlation(_lenses(k1_hat, rng.normal(0.0, 0.02, 200)), labels)) < 0.21


def test_median_interval_matches_the_asymptotic_spread():
    # The sample median of n values spread uniformly over [0, N) has standard error N * sqrt(0.25 / n)
    # (N = 1000, n = 1000: 15.8), so a 95 % interval spans about 2 * 1.96 * 15.8 = 62 around 499.5.
    # 1000 bootstrap draws of a discrete median estimate that width to within ~25 %.
    values = np.arange(1000.0)
    lo, hi = median_interval(values)
    assert lo < 499.5 < hi
    assert 0.75 * 62 < hi - lo < 1.25 * 62
    assert median_interval(values) == [lo, hi]  # fixed seed: the same numbers on every run
    assert median_interval(np.full(50, 3.0)) == [3.0, 3.0]


def test_metrics_report_the_new_figures():
    rng = np.random.default_rng(2)
    k1 = rng.uniform(-0.7, 0.3, 100)
    labels = _lenses(k1, rng.normal(0.0, 0.02, 100))
    pred = labels + rng.normal(0.0, 0.01, labels.shape)
    result = metrics(pred, labels)
    lo, hi = result["median_max_px_ci95"]
    assert lo <= result["median_max_px"] <= hi
    assert -1.0 <= result["k2_deviation_corr"] <= 1.0
    assert metrics(pred[:1], labels[:1])["k2_deviation_corr"] is None  # one image: undefined, not NaN


def test_evaluate_on_the_validation_split_uses_only_val_stadiums(tmp_path, capsys):
    """``glradial evaluate --split val`` (checkpoint selection) renders the val stadiums, never test
    ones; without --field-panorama the out-of-domain figure is left out and both stderr and the
    report say so."""
    import json

    from glradial.cli import main
    from glradial.synthesis.stadium_style import split_seeds

    out = tmp_path / "eval"
    argv = ["evaluate", "--out", str(out), "--n", "6", "--test-panoramas", "2", "--panorama-size", "512x256",
            "--cache-dir", str(tmp_path / "cache"), "--threads", "1", "--split", "val"]
    assert main(argv) == 0
    result = json.loads((out / "metrics.json").read_text())
    assert result["test_set"]["split"] == "val"
    assert result["test_set"]["stadium_seeds"] == split_seeds("val", 2)
    assert not set(split_seeds("val", 2)) & (set(split_seeds("test", 8)) | set(split_seeds("train", 40)))
    assert result["overall"]["n"] == 6 and np.isfinite(result["overall"]["median_max_px"])
    assert "out_of_domain" not in result
    report = (out / "results.md").read_text()
    assert "--split val" in report and "No out-of-domain figure" in report
    printed = capsys.readouterr()
    assert "no field panorama given" in printed.err  # logged, shown on stderr by the command line
    assert f"wrote {out / 'metrics.json'}, {out / 'results.md'}" in printed.out  # the summary on stdout
    from glradial.synthesis.stadium import stadium_cache_path

    cache = tmp_path / "cache"
    assert {p.name for p in cache.iterdir()} == {stadium_cache_path(s, (512, 256), cache).name for s in split_seeds("val", 2)}


def test_evaluate_out_of_domain_panorama_is_an_argument(tmp_path, capsys):
    """The real panorama comes from --field-panorama (never from a path inside the package); a
    missing file is an error before anything is written."""
    import json

    from glradial.cli import main

    field = Path(__file__).parents[1] / "data" / "panorama_field_2048x1024.jpg"
    out = tmp_path / "eval"
    base = ["evaluate", "--n", "4", "--test-panoramas", "1", "--panorama-size", "256x128",
            "--cache-dir", str(tmp_path / "cache"), "--threads", "1", "--ood-n", "3"]
    assert main(base + ["--out", str(out), "--field-panorama", str(field)]) == 0
    result = json.loads((out / "metrics.json").read_text())
    assert result["out_of_domain"]["panorama"] == field.name and result["out_of_domain"]["crops"] == 3
    assert result["out_of_domain"]["size"] == [2048, 1024]
    assert field.name in (out / "results.md").read_text()
    missing = tmp_path / "nope.jpg"
    assert main(base + ["--out", str(tmp_path / "none"), "--field-panorama", str(missing)]) == 1
    assert str(missing) in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    square = tmp_path / "square.png"
    import cv2

    cv2.imwrite(str(square), np.zeros((64, 64, 3), np.uint8))
    assert main(base + ["--out", str(tmp_path / "none"), "--field-panorama", str(square)]) == 1
    assert "2:1" in capsys.readouterr().err and not (tmp_path / "none").exists()


def test_training_mean_is_the_mean_of_the_paper_distribution():
    # Monte Carlo over the sampler itself: 20 000 draws give the mean k2 to ~3 standard errors of
    # 0.08 / sqrt(20000) = 6e-4 (lenses rejected near fold-over shift it by less than that)
    from glradial.evaluation.evaluation import TRAINING_MEAN
    from glradial.synthesis.crops import sample_crop_params

    k = np.array([(p.k1, p.k2) for p in sample_crop_params(20000, 7)])
    assert k.mean(axis=0) == pytest.approx(TRAINING_MEAN, abs=2e-3)
    # The value derived by hand before: E[k2] = 0.019 E[k1] + 0.805 (E[k1]^2 + (b - a)^2 / 12), k1 ~ U[a, b].
    assert TRAINING_MEAN == pytest.approx((-0.2, 0.019 * -0.2 + 0.805 * (0.04 + 1 / 12)), rel=1e-12)
    assert TRAINING_MEAN == pytest.approx((-0.2, 0.09548333333333334), rel=1e-12)


@pytest.mark.parametrize("k1_range", [(-0.5, -0.1), (-0.3, 0.3), (0.0, 0.2)])
def test_lens_mean_follows_the_sampling_range(k1_range):
    # Same Monte Carlo bound as above (k2's spread is smaller on these narrower ranges).
    from glradial.evaluation.evaluation import lens_mean
    from glradial.synthesis.crops import sample_crop_params

    a, b = k1_range
    k = np.array([(p.k1, p.k2) for p in sample_crop_params(20000, 3, k1=k1_range)])
    assert k.mean(axis=0) == pytest.approx(lens_mean(k1_range), abs=2e-3)
    assert lens_mean(k1_range)[1] == pytest.approx(0.019 * (a + b) / 2 + 0.805 * (((a + b) / 2) ** 2 + (b - a) ** 2 / 12), rel=1e-12)


def test_plots_without_matplotlib_say_so(tmp_path, monkeypatch, capsys, caplog):
    """The library logs a warning (it prints nothing); the command line shows it on stderr."""
    import logging
    import sys

    from glradial.cli import messages_to_stderr
    from glradial.evaluation.evaluation import plots

    labels = np.array([[-0.2, 0.03], [0.1, 0.01]])
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now raises ImportError
    with caplog.at_level(logging.WARNING, logger="glradial"):
        assert plots(tmp_path, labels, labels, None) == []
    assert [(r.name, r.levelno) for r in caplog.records] == [("glradial.evaluation.evaluation", logging.WARNING)]
    assert "matplotlib is not installed" in caplog.records[0].getMessage()
    assert capsys.readouterr().err == ""
    with messages_to_stderr():
        plots(tmp_path, labels, labels, None)
    assert capsys.readouterr().err == "glradial: warning: matplotlib is not installed: no plots (pip install matplotlib)\n"
    assert list(tmp_path.iterdir()) == []
