"""Lens: point maps against OpenCV, Drap-Lefevre known answers, every converter (round trip and
each target convention's own formula written out here), validation of the value."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from glradial import Lens

SIZE = (1280, 720)
LENSES = [(-0.3, 0.06), (0.2, 0.05), (-0.7, 0.805 * 0.49 - 0.7 * 0.019), (0.1, -0.05), (0.0, 0.0)]


def camera(size, f=None):
    w, h = size
    f = float(w) if f is None else f
    return np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def pixels():
    rng = np.random.default_rng(0)
    return rng.uniform([0, 0], [SIZE[0] - 1, SIZE[1] - 1], size=(500, 2))


@pytest.mark.parametrize("k", LENSES)
def test_distort_points_match_cv2_project_points(k, pixels):
    """Undistorted pixel -> ray (x - cx)/f -> cv2.projectPoints with dist (k1, k2, 0, 0, 0) and f = W.
    Both float64 closed forms: agreement to 1e-9 px."""
    K = camera(SIZE)
    rays = np.concatenate([(pixels - K[:2, 2]) / K[0, 0], np.ones((len(pixels), 1))], axis=1)
    projected, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, np.array([k[0], k[1], 0, 0, 0.0]))
    np.testing.assert_allclose(Lens(*k).distort_points(pixels, SIZE), projected[:, 0], atol=1e-9)


@pytest.mark.parametrize("k", LENSES[:3])
def test_undistort_points_match_cv2_undistort_points(k, pixels):
    """cv2.undistortPoints run to convergence with explicit criteria (its default 5 iterations are
    not enough for strong lenses). Our exact inverse is 8 bounded Newton steps: 1e-6 px."""
    K = camera(SIZE)
    dist = np.array([k[0], k[1], 0, 0, 0.0])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(pixels[:, None, :], K, dist, R=None, P=K, criteria=criteria)[:, 0]
    ours = Lens(*k).undistort_points(pixels, SIZE)
    np.testing.assert_allclose(ours, ref, atol=1e-6)
    # and the forward map undoes it
    np.testing.assert_allclose(Lens(*k).distort_points(ours, SIZE), pixels, atol=1e-6)


def test_drap_lefevre_known_answers():
    """b1 = -k1, b2 = 3k1² - k2, b3 = -12k1³ + 8k1k2, b4 = 55k1⁴ - 55k1²k2 + 5k2², worked by hand:
    k = (-0.3, 0.06): (0.3, 0.27 - 0.06, 0.324 - 0.144, 0.4455 - 0.297 + 0.018)
    k = (0.1, 0):     (-0.1, 0.03, -0.012, 0.0055)
    k = (0, 0.2):     (0, -0.2, 0, 0.2)"""
    assert Lens(-0.3, 0.06).inverse_coefficients() == pytest.approx((0.3, 0.21, 0.18, 0.1665), abs=1e-15)
    assert Lens(0.1, 0.0).inverse_coefficients() == pytest.approx((-0.1, 0.03, -0.012, 0.0055), abs=1e-15)
    assert Lens(0.0, 0.2).inverse_coefficients() == pytest.approx((0.0, -0.2, 0.0, 0.2), abs=1e-15)
    # it is the series inverse: P(inverse(r)) - r = O(r^11), so halving r shrinks the error ~2^11x
    lens = Lens(-0.3, 0.06)
    err = [abs(lens.forward_radius(lens.inverse_radius(r, "drap")) - r) for r in (0.2, 0.1)]
    assert 1000 < err[0] / err[1] < 4000
    # the paper's claim: undistorted -> forward -> Drap-Lefevre back leaves up to about 0.002 image
    # widths at the ends of k1 in [-0.7, 0.3] (manifold k2), over the 16:9 frame (measured 0.0012)
    r = np.linspace(0, 0.5737, 200)
    worst = 0.0
    for k1 in (-0.7, 0.3):
        lens = Lens(k1, 0.019 * k1 + 0.805 * k1**2)
        worst = max(worst, np.abs(lens.inverse_radius(lens.forward_radius(r), "drap") - r).max())
    assert 5e-4 < worst < 3e-3


@pytest.mark.parametrize("k", LENSES)
def test_converter_round_trips(k):
    lens = Lens(*k)
    for size in (SIZE, (1920, 1080), (720, 1280), (641, 479)):
        for f in (None, 1000.0, 2500.0):
            K, dist = lens.to_opencv(size, focal=f)
            back = Lens.from_opencv(K, dist, size)
            assert back.k1 == pytest.approx(lens.k1, abs=1e-14) and back.k2 == pytest.approx(lens.k2, abs=1e-14)
            back = Lens.from_opencv(K, dist[:4], size)  # 4-term form too
            assert back.k1 == pytest.approx(lens.k1, abs=1e-14)
        pairs = [
            (lens.to_pixel(size), Lens.from_pixel),
            (lens.to_height_normalised(size), Lens.from_height_normalised),
            (lens.to_lensfun_poly5(size), Lens.from_lensfun_poly5),
        ]
        if max(abs(v) for v in k) < 0.5:
            pairs.append((lens.to_ffmpeg(size), Lens.from_ffmpeg))
        for converted, inverse in pairs:
            back = inverse(*converted, size)
            assert back.k1 == pytest.approx(lens.k1, rel=1e-12, abs=1e-15)
            assert back.k2 == pytest.approx(lens.k2, rel=1e-12, abs=1e-15)
        for s in (0.5, 1.7):
            back = lens.rescale(s).rescale(1 / s)
            assert back.k1 == pytest.approx(lens.k1, rel=1e-12, abs=1e-15)
            assert back.k2 == pytest.approx(lens.k2, rel=1e-12, abs=1e-15)


def radial_polynomial(points, centre, norm, k1, k2):
    """A target convention's model: r_d = r_u (1 + k1 (r_u/norm)² + k2 (r_u/norm)⁴) about centre."""
    d = points - centre
    r2 = np.sum(d * d, axis=1, keepdims=True) / norm**2
    return centre + d * (1 + k1 * r2 + k2 * r2 * r2)


@pytest.mark.parametrize("k", LENSES[:4])
@pytest.mark.parametrize("size", [SIZE, (721, 1281)])
def test_converters_mean_the_target_conventions(k, size, pixels):
    """Each converted pair, plugged into its convention's own formula, moves pixels exactly as the
    lens does (1e-9 px): the formulas are written out here from each tool's documentation."""
    lens = Lens(*k)
    w, h = size
    pts = pixels * np.array([w / SIZE[0], h / SIZE[1]])
    expected = lens.distort_points(pts, size)
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    # pixel-unit ("apparent"): radii in pixels
    k1p, k2p = lens.to_pixel(size)
    np.testing.assert_allclose(radial_polynomial(pts, centre, 1.0, k1p, k2p), expected, atol=1e-9)
    assert k1p == pytest.approx(k[0] / w**2) and k2p == pytest.approx(k[1] / w**4)
    # height-normalised: radii divided by the frame height
    np.testing.assert_allclose(radial_polynomial(pts, centre, h, *lens.to_height_normalised(size)), expected, atol=1e-9)
    # lensfun poly5: Rd = Ru (1 + k1 Ru² + k2 Ru⁴), radii in units of half the shorter side
    np.testing.assert_allclose(radial_polynomial(pts, centre, min(w, h) / 2, *lens.to_lensfun_poly5(size)), expected, atol=1e-9)
    # ffmpeg lenscorrection: r_src = r_tgt (1 + k1 (r_tgt/r0)² + k2 (r_tgt/r0)⁴), r0 = half diagonal;
    # the target (output) point is the undistorted one, the source the distorted one
    np.testing.assert_allclose(radial_polynomial(pts, centre, math.hypot(w, h) / 2, *lens.to_ffmpeg(size)), expected, atol=1e-9)
    # OpenCV with any focal length: normalised coordinates (x - cx) / f
    K, dist = lens.to_opencv(size, focal=0.8 * w)
    rays = np.concatenate([(pts - centre) / K[0, 0], np.ones((len(pts), 1))], axis=1)
    projected, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, dist)
    np.testing.assert_allclose(projected[:, 0], expected, atol=1e-9)


def test_rescale_is_a_centred_crop():
    """A centred crop of width W' = W/s out of a W-wide frame sees the same lens as Lens.rescale(s):
    the same physical points move identically (pixel offsets from the centre are shared)."""
    lens, big, small = Lens(-0.3, 0.06), (1280, 720), (640, 360)
    offsets = np.array([[100.0, 50.0], [-200.0, 120.0], [250.0, -150.0]])
    moved_big = lens.distort_points(offsets + [(big[0] - 1) / 2, (big[1] - 1) / 2], big) - [(big[0] - 1) / 2, (big[1] - 1) / 2]
    cropped = lens.rescale(2.0)
    moved_small = cropped.distort_points(offsets + [(small[0] - 1) / 2, (small[1] - 1) / 2], small) - [(small[0] - 1) / 2, (small[1] - 1) / 2]
    np.testing.assert_allclose(moved_small, moved_big, atol=1e-9)


def test_from_opencv_approximate():
    """p1/p2 are refused by default, naming them; approximate=True drops them and keeps the
    principal point and fx != fy, which are exact (the chessboard camera of tests/data/README.md)."""
    K = np.array([[1156.4996, 0, 671.3496], [0, 1151.3055, 389.1760], [0, 0, 1]])
    dist = np.array([-0.2475567, -0.0195370, -0.0006705, 0.0001363, 0])
    with pytest.raises(ValueError, match="p1=-0.0006705, p2=0.0001363"):
        Lens.from_opencv(K, dist, SIZE)
    lens = Lens.from_opencv(K, dist, SIZE, approximate=True)
    assert lens.k1 == pytest.approx(-0.2475567 * (1280 / 1156.4996) ** 2, rel=1e-12)
    assert lens.k2 == pytest.approx(-0.0195370 * (1280 / 1156.4996) ** 4, rel=1e-12)
    assert lens.principal_point(SIZE) == pytest.approx((671.3496, 389.1760), abs=1e-9)
    assert lens.pixel_aspect == pytest.approx(1151.3055 / 1156.4996, rel=1e-12)
    # the p1, p2-free calibration is exact without approximate=True
    assert Lens.from_opencv(K, dist[:2].tolist() + [0, 0], SIZE) == lens


@pytest.mark.parametrize("k", LENSES)
def test_maps_are_cv2_remap_ready(k):
    """Lens.maps('undistort') in float64 (the NumPy path, lensfuncs) equals
    cv2.initUndistortRectifyMap with K(f=W)."""
    size = (160, 90)
    mx, my = Lens(*k).maps(size, dtype=np.float64)
    ox, oy = cv2.initUndistortRectifyMap(camera(size), np.array([k[0], k[1], 0, 0.0]), None, camera(size), size, cv2.CV_32FC1)
    assert mx.dtype == np.float64 and mx.shape == (90, 160)
    np.testing.assert_allclose(mx, ox, atol=2e-3)
    np.testing.assert_allclose(my, oy, atol=2e-3)


@pytest.mark.parametrize("k", LENSES)
@pytest.mark.parametrize("size, fit", [((1920, 1080), "same"), ((1920, 1080), "crop"), ((1280, 720), "full"), ((997, 601), 0.83)])
def test_fast_float32_maps_match_the_float64_reference(k, size, fit):
    """The float32 correction maps (built by OpenCV, for speed) agree with the float64 NumPy maps
    within float32 rounding: 2 ulp at 2048 px = 2.5e-4 px."""
    lens = Lens(*k)
    try:
        reference = lens.maps(size, fit=fit, dtype=np.float64)
    except ValueError:
        pytest.skip(f"fit {fit} undefined for {k}")
    fast = lens.maps(size, fit=fit)
    assert fast[0].dtype == np.float32 and fast[0].shape == (size[1], size[0])
    for a, b in zip(fast, reference):
        assert np.abs(a.astype(np.float64) - b).max() < 2.5e-4


@pytest.mark.parametrize("lens", [Lens(-0.3, 0.05, 0.05, -0.02, 0.98), Lens(0.2, -0.05, -0.1, 0.03, 1.05)])
@pytest.mark.parametrize("fit", ["same", "crop", 1.3])
def test_fast_float32_maps_carry_the_principal_point(lens, fit):
    """Off-centre principal point and non-square pixels: OpenCV's maps (K with fy = a W and the
    centre moved) still equal the float64 NumPy maps within float32 rounding."""
    size = (1280, 720)
    reference = lens.maps(size, fit=fit, dtype=np.float64)
    for a, b in zip(lens.maps(size, fit=fit), reference):
        assert np.abs(a.astype(np.float64) - b).max() < 2.5e-4


def test_lens_value_validation_and_fold_radius():
    lens = Lens(np.float32(-0.25), 0)
    assert isinstance(lens.k1, float) and lens.k2 == 0.0
    with pytest.raises(Exception):
        lens.k1 = 0.0  # frozen
    assert Lens(-1.5, 0.0).fold_radius() == pytest.approx(math.sqrt(1 / 4.5))
    assert Lens(0.2, 0.05).fold_radius() == math.inf
    Lens(-0.3, 0.06).check_frame((1920, 1080))
    with pytest.raises(ValueError, match="folds over"):
        Lens(-1.5, 0.0).check_frame((1920, 1080))


def test_fold_radii_is_fold_radius_for_many_lenses():
    # the vectorised fold radius (used by the exact inverse for many lenses at once, e.g. the line
    # fit's grid) equals the scalar twin of the GLSL function everywhere, unbounded lenses included
    from glradial.lens import lensfuncs

    rng = np.random.default_rng(7)
    k1, k2 = rng.uniform(-1.3, 0.6, 2000), rng.uniform(-0.3, 0.8, 2000)
    k1[:20], k2[:10] = 0.0, 0.0
    expected = np.array([lensfuncs.fold_radius(a, b) for a, b in zip(k1, k2)])
    np.testing.assert_array_equal(lensfuncs.fold_radii(k1, k2), expected)


def test_the_line_fit_uses_the_lens_models_inverse():
    # one exact inverse: the line fit's radii are undistort_radius_exact's, NaN where it is invalid
    from glradial.estimation.line_fit import _undistort_radius
    from glradial.lens import lensfuncs

    r_d = np.linspace(0.0, 0.6, 50)
    k1, k2 = np.array([[-0.9], [-0.3], [0.2]]), np.array([[0.1], [0.05], [0.0]])
    ours = _undistort_radius(r_d, k1, k2)
    for i in range(3):
        r_u, valid = lensfuncs.undistort_radius_exact(r_d, float(k1[i, 0]), float(k2[i, 0]))
        np.testing.assert_array_equal(np.isnan(ours[i]), ~valid)
        np.testing.assert_allclose(ours[i][valid], r_u[valid], rtol=0, atol=1e-12)
        # and it inverts the forward model where valid
        np.testing.assert_allclose(r_u[valid] * lensfuncs.radial_factor(r_u[valid] ** 2, k1[i, 0], k2[i, 0]),
                                   r_d[valid], atol=1e-9)


@pytest.mark.parametrize("hfov", [8.0, 30.0, 72.4, 120.0])
def test_focal_from_hfov_matches_opencv_field_of_view(hfov):
    # oracle: cv2.calibrationMatrixValues reads the field of view back from a pixel camera matrix
    from glradial.lens.lens import focal_from_hfov, hfov_deg

    width, height = 1920, 1080
    focal_px = focal_from_hfov(hfov) * width
    matrix = np.array([[focal_px, 0, (width - 1) / 2], [0, focal_px, (height - 1) / 2], [0, 0, 1]])
    fovx = cv2.calibrationMatrixValues(matrix, (width, height), 1.0, 1.0)[0]
    assert fovx == pytest.approx(hfov, abs=0.05)  # OpenCV measures from the pixel edge: ±0.5 px of 1920
    assert hfov_deg(focal_from_hfov(hfov)) == pytest.approx(hfov, abs=1e-9)
    assert np.allclose(hfov_deg(np.array([focal_from_hfov(hfov)] * 2)), hfov)


@pytest.mark.parametrize("hfov", [0, 180.0, -5.0, float("nan"), "60", True])
def test_focal_from_hfov_names_a_bad_field_of_view(hfov):
    from glradial.lens.lens import focal_from_hfov

    with pytest.raises(ValueError, match="hfov"):
        focal_from_hfov(hfov)
