"""net.evaluate's evaluation figures beyond the paper's: the median's bootstrap interval and the
correlation of the k2 deviation from the manifold (known answers; no torch, no GL)."""

from __future__ import annotations

import numpy as np
import pytest

from glradial.crops import manifold_k2
from net.evaluate import deviation_correlation, median_interval, metrics


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
