"""glradial.distort against an independent exact inverse, and the correct/distort round trip.

Oracle: the inverse radius found by plain bisection on ``r (1 + k1 r² + k2 r⁴) = ρ`` (no Newton,
no Drap-Lefevre seed, the fold radius found by scanning the slope), turned into pixel maps here and
applied with ``cv2.remap``. Photos downscaled to 320×180 as in test_correct.py; tolerances in 8-bit
levels inside an interior mask, justified there (OpenCV's 1/32-px position quantisation at the
sharpest edges: mean <= 0.25, p99 <= 2.5, max <= 5).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest

from glradial import Lens, correct, distort, fit_scale

SIZE = (320, 180)
LENSES = {"barrel": (-0.3, 0.06), "pincushion": (0.2, 0.05), "strong": (-0.7, 0.1)}  # folds at r = 0.740, reaches only r_d = 0.478 < corner 0.574


def bisection_inverse(rho: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Undistorted radius for distorted radii ``rho``; NaN where the lens never reaches ``rho``."""
    grid = np.linspace(0.0, 4.0, 400001)
    slope = 1 + 3 * k1 * grid**2 + 5 * k2 * grid**4
    r_top = grid[np.argmax(slope <= 0)] if np.any(slope <= 0) else grid[-1]
    forward = lambda r: r * (1 + k1 * r**2 + k2 * r**4)  # noqa: E731
    lo, hi = np.zeros_like(rho), np.full_like(rho, r_top)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        below = forward(mid) < rho
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return np.where(rho <= forward(r_top), 0.5 * (lo + hi), np.nan)


@functools.lru_cache(maxsize=None)
def oracle_maps(k, size, scale=1.0):
    """(map_x, map_y) float64 of the distortion at ``scale``, NaN where there is no source (cached,
    read-only)."""
    w, h = size
    x, y = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    px, py = (x - (w - 1) / 2) / w, (y - (h - 1) / 2) / w  # distorted lens coordinates of each pixel
    rho = np.hypot(px, py)
    r_u = bisection_inverse(rho, *k)
    ratio = np.where(rho > 0, r_u / np.where(rho > 0, rho, 1), 1.0) / scale
    maps = px * ratio * w + (w - 1) / 2, py * ratio * w + (h - 1) / 2
    for m in maps:
        m.flags.writeable = False
    return maps


def level_errors(a, b, mask):
    diff = np.abs(a.astype(float) - b.astype(float))
    return (diff.max(axis=2) if diff.ndim == 3 else diff)[mask]


@pytest.fixture(scope="module")
def photo(road):
    return cv2.resize(road, SIZE, interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("name", list(LENSES))
@pytest.mark.parametrize("fit", ["same", "crop"])
def test_maps_match_bisection(name, fit):
    """Lens.maps('distort', exact) equals the bisection maps to 1e-4 px; pixels with no inverse
    agree too (NaN in the oracle, NO_SOURCE in ours), except within LENS_INVERSE_TOLERANCE
    (1e-4 lens units = 0.03 px here) outside the lens's largest distorted radius, which the exact
    inverse accepts (clamped to the fold radius, i.e. the edge of the image circle)."""
    k = LENSES[name]
    if name == "strong" and fit == "crop":  # no scale gives every output pixel a source
        with pytest.raises(ValueError, match="never reaches radius 0.5737"):
            fit_scale(k, SIZE, fit, "distort")
        return
    s = fit_scale(k, SIZE, fit, "distort")
    map_x, map_y = Lens(*k).maps(SIZE, "distort", scale=s, dtype=np.float64)
    ox, oy = oracle_maps(k, SIZE, s)
    valid = np.isfinite(ox)
    ours = map_x > -100
    assert not np.any(valid & ~ours)
    extra = ours & ~valid
    if extra.any():
        w, h = SIZE
        x, y = np.meshgrid(np.arange(w), np.arange(h))
        rho = np.hypot((x - (w - 1) / 2) / w, (y - (h - 1) / 2) / w)
        assert rho[extra].max() - rho[valid].max() <= 2e-4
    np.testing.assert_allclose(map_x[valid], ox[valid], atol=1e-4)
    np.testing.assert_allclose(map_y[valid], oy[valid], atol=1e-4)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("name", list(LENSES))
def test_distort_matches_independent_inverse(ctx, photo, name, backend):
    k = LENSES[name]
    ox, oy = oracle_maps(k, SIZE)
    w, h = SIZE
    inside = np.isfinite(ox) & (ox >= 2) & (ox <= w - 3) & (oy >= 2) & (oy <= h - 3)
    reference = cv2.remap(photo, np.nan_to_num(ox, nan=-1e4).astype(np.float32),
                          np.nan_to_num(oy, nan=-1e4).astype(np.float32), cv2.INTER_LINEAR)
    result = distort(photo, *k, fill=(255, 0, 255), backend=backend)
    errors = level_errors(result, reference, inside)
    assert errors.mean() <= 0.25 and np.percentile(errors, 99) <= 2.5 and errors.max() <= 5, (
        errors.mean(), np.percentile(errors, 99), errors.max())
    # pixels the lens never reaches (strong barrel: beyond its largest distorted radius) get the fill
    no_source = ~np.isfinite(ox)
    no_source &= ~cv2.dilate(np.isfinite(ox).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)  # not at the rim
    if name == "strong":
        assert no_source.any()
    assert np.all(result[no_source] == [255, 0, 255])


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_drap_inverse_is_the_papers_polynomial(ctx, photo, backend):
    """inverse='drap' samples at p_d (1 + b1 r² + b2 r⁴ + b3 r⁶ + b4 r⁸); the coefficients of
    k = (-0.3, 0.06) worked by hand: b1 = 0.3, b2 = 3·0.09 - 0.06 = 0.21,
    b3 = -12·(-0.027) + 8·(-0.3)(0.06) = 0.18, b4 = 55·0.0081 - 55·0.09·0.06 + 5·0.0036 = 0.1665."""
    w, h = SIZE
    x, y = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    px, py = (x - (w - 1) / 2) / w, (y - (h - 1) / 2) / w
    r2 = px**2 + py**2
    factor = 1 + 0.3 * r2 + 0.21 * r2**2 + 0.18 * r2**3 + 0.1665 * r2**4
    mx = (px * factor * w + (w - 1) / 2).astype(np.float32)
    my = (py * factor * w + (h - 1) / 2).astype(np.float32)
    inside = (mx >= 2) & (mx <= w - 3) & (my >= 2) & (my <= h - 3)
    reference = cv2.remap(photo, mx, my, cv2.INTER_LINEAR)
    result = distort(photo, -0.3, 0.06, inverse="drap", backend=backend)
    errors = level_errors(result, reference, inside)
    assert errors.mean() <= 0.25 and errors.max() <= 5


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("name", ["barrel", "pincushion"])
@pytest.mark.parametrize("fit", ["same", "crop", "full"])
def test_correct_undoes_distort(ctx, photo, name, fit, backend):
    """correct(distort(x)) ≈ x where the round trip has a source, with the same scale: the
    distortion's "crop" is the correction's "full" and vice versa (also checked with the number).
    Two bilinear resamplings blur: on a photo smoothed with a Gaussian (σ = 1.5 px, small
    gradients) the mean error stays below 1 level and p99 below 5 (measured 0.3-0.4 / 3); the
    wrong direction, or the same fit name on both sides, gives 5-20 levels mean."""
    k = LENSES[name]
    undo = {"same": "same", "crop": "full", "full": "crop"}[fit]
    x = cv2.GaussianBlur(photo, (0, 0), 1.5)
    there = distort(x, *k, fit=fit, backend=backend)
    back = correct(there, *k, fit=undo, backend=backend)
    s = fit_scale(k, SIZE, fit, "distort")
    assert s == pytest.approx(fit_scale(k, SIZE, undo, "undistort"))
    assert np.array_equal(back, correct(there, *k, fit=s, backend=backend))
    # valid: the pixel's round-trip path stays >= 2 px inside both frames
    lens, w, h = Lens(*k), *SIZE
    mx, my = lens.maps(SIZE, "undistort", scale=s, dtype=np.float64)  # where correct reads `there`
    ox, oy = oracle_maps(k, SIZE, s)  # where distort read `x`, per pixel of `there`
    ix = np.clip(np.round(mx).astype(int), 0, w - 1)
    iy = np.clip(np.round(my).astype(int), 0, h - 1)
    src_x, src_y = ox[iy, ix], oy[iy, ix]
    valid = (mx >= 2) & (mx <= w - 3) & (my >= 2) & (my <= h - 3)
    valid &= np.isfinite(src_x) & (src_x >= 2) & (src_x <= w - 3) & (src_y >= 2) & (src_y <= h - 3)
    assert valid.mean() > 0.5
    errors = level_errors(back, x, valid)
    assert errors.mean() <= 1.0 and np.percentile(errors, 99) <= 5.0, (errors.mean(), np.percentile(errors, 99))
    # the check can fail: the wrong direction is far off
    wrong = correct(correct(x, *k, fit=fit, backend=backend), *k, fit=undo, backend=backend)
    assert level_errors(wrong, x, valid).mean() > 3.0


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32], ids=["u8", "u16", "f32"])
@pytest.mark.parametrize("channels", [None, 1, 4], ids=["HxW", "C1", "C4"])
def test_distort_every_dtype_and_layout(ctx, photo, dtype, channels, backend):
    """Same oracle and tolerances as above, on every dtype and channel layout (errors scaled to
    8-bit levels); shape and dtype are kept."""
    from test_correct import FULL_SCALE, as_dtype

    k = LENSES["barrel"]
    image = as_dtype(photo, dtype, channels)
    ox, oy = oracle_maps(k, SIZE)
    w, h = SIZE
    inside = (ox >= 2) & (ox <= w - 3) & (oy >= 2) & (oy <= h - 3)
    reference = cv2.remap(image, ox.astype(np.float32), oy.astype(np.float32), cv2.INTER_LINEAR).reshape(image.shape)
    result = distort(image, *k, backend=backend, alpha="premultiplied")  # channels as they are
    assert result.shape == image.shape and result.dtype == image.dtype
    errors = level_errors(result, reference, inside) * (255.0 / FULL_SCALE[dtype])
    assert errors.mean() <= 0.25 and np.percentile(errors, 99) <= 2.5 and errors.max() <= 5, (
        errors.mean(), np.percentile(errors, 99), errors.max())
