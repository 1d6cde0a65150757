"""The per-lens Chebyshev series of the exact inverse (glradial.lens.inverse_series) and its use in crops.

Oracle: the forward model ``P(r) = r (1 + k1 r^2 + k2 r^4)`` (docs/DESIGN.md), evaluated in float64: a
series value ``r_u`` is right when ``P(r_u)`` gives back ``r_d``. The check grid here (2 001 radii) is
denser than the one the fit is accepted on (129), so it also tests between those points.
"""

from __future__ import annotations

import numpy as np
import pytest

from glradial.lens import lensfuncs
from glradial.lens.inverse_series import SERIES_TOLERANCE, fit_inverse_series, series_radius
from glradial.lens.lens import corner_radius
from glradial.lens.metrics import manifold_k2
from glradial.synthesis.crops import CropParams, CropRenderer, sample_crop_params

CORNER = corner_radius((1280, 720))


def forward(r: np.ndarray, k1: float, k2: float) -> np.ndarray:
    return r * (1.0 + k1 * r**2 + k2 * r**4)


def test_accepted_series_invert_the_forward_model() -> None:
    params = sample_crop_params(300, seed=5)
    k1 = np.array([p.k1 for p in params])
    k2 = np.array([p.k2 for p in params])
    coefficients, accepted = fit_inverse_series(k1, k2, CORNER)
    # Measured: 95 % of the paper's lenses (the rest are barrels near fold-over at the corners).
    assert accepted.mean() > 0.9, accepted.mean()
    r_d = np.linspace(0.0, CORNER, 2001)
    for i in np.flatnonzero(accepted):
        r_u = series_radius(r_d, coefficients[i], CORNER)
        # |r_u - exact| <= tolerance (checked on 129 radii) and |P'| <= ~3 over the frame for these
        # lenses: the forward residual stays below 4 x tolerance on the dense grid.
        assert np.abs(forward(r_u, k1[i], k2[i]) - r_d).max() < 4 * SERIES_TOLERANCE, (k1[i], k2[i])


def test_lenses_without_a_smooth_inverse_are_rejected() -> None:
    # (k1, k2): covers the frame / folds over inside it / leaves the corners unreachable.
    k1 = np.array([0.3, -0.2, -1.6, -0.95])
    k2 = np.array([manifold_k2(0.3), manifold_k2(-0.2), 0.0, 0.0])
    _, accepted = fit_inverse_series(k1, k2, CORNER)
    assert accepted.tolist() == [True, True, False, False]
    for a, b in zip(k1[2:], k2[2:]):  # both rejected lenses really have no inverse at the corner
        _, valid = lensfuncs.undistort_radius_exact(np.array([CORNER]), a, b)
        assert not valid.all()
    with pytest.raises(ValueError, match="corner"):
        fit_inverse_series(k1, k2, float("nan"))


def test_exact_inverse_broadcasts_over_lenses() -> None:
    k1 = np.array([-0.6, -0.1, 0.25])
    k2 = np.array([manifold_k2(-0.6), 0.01, 0.05])
    r_d = np.linspace(0.0, 0.6, 50)
    r_u, valid = lensfuncs.undistort_radius_exact(r_d, k1[:, None], k2[:, None])
    assert r_u.shape == valid.shape == (3, 50)
    for i in range(3):
        one, one_valid = lensfuncs.undistort_radius_exact(r_d, k1[i], k2[i])
        assert np.array_equal(r_u[i], one) and np.array_equal(valid[i], one_valid)


def test_series_and_newton_crops_agree(ctx, field_panorama) -> None:
    """The shader's series path renders the same crops as the per-pixel Newton path."""
    params = sample_crop_params(12, seed=8) + [CropParams(5.0, -8.0, 1.0, 40.0, -0.69, manifold_k2(-0.69))]
    _, accepted = fit_inverse_series([p.k1 for p in params], [p.k2 for p in params], corner_radius((320, 180)))
    assert accepted.any() and not accepted.all()  # both paths are exercised in one batch
    with CropRenderer(field_panorama, size=(320, 180), ctx=ctx) as fast:
        series = fast.render(params).astype(int)
    with CropRenderer(field_panorama, size=(320, 180), series_inverse=False, ctx=ctx) as slow:
        newton = slow.render(params).astype(int)
    # Positions differ by < 2e-6 lens units (float32 on both sides): 0.0006 px here, so at most a
    # rounding step of the 8-bit output.
    diff = np.abs(series - newton)
    assert diff.max() <= 1 and diff.mean() < 0.01, (diff.max(), diff.mean())
