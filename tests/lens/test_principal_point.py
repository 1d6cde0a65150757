"""Lenses with an off-centre principal point and non-square pixels (Lens.cx, cy, pixel_aspect)
against OpenCV, which models both natively: points (cv2.projectPoints / undistortPoints), maps
(cv2.initUndistortRectifyMap), whole frames (cv2.undistort with newCameraMatrix = K), the fits'
closed form against brute force, the fold-over check, and every converter.

The camera: a 1280×720 frame with fx = 1100, fy = 1078 (pixel aspect 0.98) and its principal point
200 px right of and 60 px above the centre, (k1, k2)_cv = (-0.28, 0.08) (a broadcast wide end,
barrel; the pitch cameras of issue 20 sit 15 and 200 px off centre).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

import glradial
from glradial import Lens, correct, distort

SIZE = (1280, 720)
K_OFF = np.array([[1100.0, 0.0, 639.5 + 200.0], [0.0, 1078.0, 359.5 - 60.0], [0.0, 0.0, 1.0]])
DIST = np.array([-0.28, 0.08, 0.0, 0.0, 0.0])
#: the same camera centred, for converters that must keep working
K_CENTRED = np.array([[1100.0, 0.0, 639.5], [0.0, 1100.0, 359.5], [0.0, 0.0, 1.0]])


def scaled_camera(camera: np.ndarray, factor: float) -> np.ndarray:
    """The camera matrix of the same camera on a frame resized by ``factor`` (pixel centres at
    integers: c' = (c + 0.5) factor - 0.5)."""
    out = camera.copy()
    out[:2, :2] *= factor
    out[:2, 2] = (camera[:2, 2] + 0.5) * factor - 0.5
    return out


@pytest.fixture(scope="module")
def lens() -> Lens:
    return Lens.from_opencv(K_OFF, DIST, SIZE)


@pytest.fixture(scope="module")
def pixels():
    rng = np.random.default_rng(3)
    return rng.uniform([0, 0], [SIZE[0] - 1, SIZE[1] - 1], size=(400, 2))


def test_from_opencv_is_exact_off_centre(lens, pixels):
    """Known answers of the conversion, then the lens's point maps against OpenCV's model: forward
    by cv2.projectPoints (both float64 closed forms: 1e-9 px), inverse by cv2.undistortPoints run to
    convergence (our 8 bounded Newton steps: 1e-6 px, as for the centred lens in test_lens.py)."""
    assert lens.k1 == pytest.approx(-0.28 * (1280 / 1100) ** 2, rel=1e-14)
    assert lens.k2 == pytest.approx(0.08 * (1280 / 1100) ** 4, rel=1e-14)
    assert (lens.cx, lens.cy) == pytest.approx((200 / 1280, -60 / 1280), abs=1e-15)
    assert lens.pixel_aspect == pytest.approx(0.98, rel=1e-14)
    assert lens.principal_point(SIZE) == pytest.approx((839.5, 299.5), abs=1e-12)
    rays = np.concatenate(
        [(pixels - K_OFF[:2, 2]) / [K_OFF[0, 0], K_OFF[1, 1]], np.ones((len(pixels), 1))], axis=1
    )
    projected, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K_OFF, DIST)
    np.testing.assert_allclose(lens.distort_points(pixels, SIZE), projected[:, 0], atol=1e-9)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(pixels[:, None, :], K_OFF, DIST, R=None, P=K_OFF, criteria=criteria)[:, 0]
    np.testing.assert_allclose(lens.undistort_points(pixels, SIZE), ref, atol=1e-6)


def test_resolution_independent(lens, pixels):
    """The five numbers do not change when the frame is resized: the same camera on a half-size
    frame (its K scaled) gives the same Lens."""
    half = Lens.from_opencv(scaled_camera(K_OFF, 0.5), DIST, (640, 360))
    for name in ("k1", "k2", "cx", "cy", "pixel_aspect"):
        assert getattr(half, name) == pytest.approx(getattr(lens, name), rel=1e-12, abs=1e-15), name


@pytest.mark.parametrize("focal", [None, 1100.0, 2400.0])
def test_to_opencv_round_trips(lens, focal):
    camera, dist = lens.to_opencv(SIZE, focal=focal)
    back = Lens.from_opencv(camera, dist, SIZE)
    for name in ("k1", "k2", "cx", "cy", "pixel_aspect"):
        assert getattr(back, name) == pytest.approx(getattr(lens, name), rel=1e-12, abs=1e-15), name
    if focal == 1100.0:  # the calibration itself comes back
        np.testing.assert_allclose(camera, K_OFF, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(dist, DIST, rtol=1e-12, atol=1e-15)


def test_maps_match_init_undistort_rectify_map(lens):
    """Lens.maps('undistort') = cv2.initUndistortRectifyMap(K, dist, None, K) (float32 maps,
    2e-3 px: OpenCV computes them in float32 too)."""
    size = (320, 180)
    camera = scaled_camera(K_OFF, 0.25)
    ours = Lens.from_opencv(camera, DIST, size).maps(size)
    ref = cv2.initUndistortRectifyMap(camera, DIST, None, camera, size, cv2.CV_32FC1)
    np.testing.assert_allclose(ours[0], ref[0], atol=2e-3)
    np.testing.assert_allclose(ours[1], ref[1], atol=2e-3)


def interior(camera, size, margin=2.0):
    """Output pixels whose OpenCV source lies >= margin px inside the input (border rules differ)."""
    map_x, map_y = cv2.initUndistortRectifyMap(camera, DIST, None, camera, size, cv2.CV_32FC1)
    w, h = size
    return (map_x >= margin) & (map_x <= w - 1 - margin) & (map_y >= margin) & (map_y <= h - 1 - margin)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("name", ["road", "chessboard"])
def test_correct_matches_cv2_undistort_off_centre(ctx, request, name, lens, backend):
    """The issue's target on the full 1280×720 photos: mean |diff| <= 0.3 levels against
    cv2.undistort(frame, K, dist, newCameraMatrix=K) inside the interior mask. The bounds are the
    centred case's (test_correct.py: OpenCV quantises positions to 1/32 px, the shader does not;
    the CPU path uses OpenCV's quantisation, so it must be near identical)."""
    photo = request.getfixturevalue(name)
    mask = interior(K_OFF, SIZE)
    assert mask.mean() > 0.7
    result = correct(photo, lens, backend=backend)
    reference = cv2.undistort(photo, K_OFF, DIST, newCameraMatrix=K_OFF)
    diff = np.abs(result.astype(np.float64) - reference).max(axis=2)[mask]
    assert diff.mean() <= (0.3 if backend == "gl" else 0.01), diff.mean()
    assert diff.max() <= 5.0, diff.max()
    # the principal point matters: the centred lens with the same (k1, k2) is far off
    centred = correct(photo, lens.k1, lens.k2, backend=backend)
    assert np.abs(centred.astype(np.float64) - reference).max(axis=2)[mask].mean() > 10 * max(diff.mean(), 0.1)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_distort_matches_an_opencv_inverse_off_centre(ctx, road, backend):
    """distort() samples the undistorted input at the exact inverse: the oracle is cv2.remap on
    maps from cv2.undistortPoints (converged) of every output pixel, on a 320×180 frame."""
    size = (320, 180)
    camera = scaled_camera(K_OFF, 0.25)
    small = cv2.resize(road, size, interpolation=cv2.INTER_AREA)
    lens = Lens.from_opencv(camera, DIST, size)
    grid = np.stack(np.meshgrid(np.arange(size[0], dtype=np.float64), np.arange(size[1], dtype=np.float64)), -1)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    src = cv2.undistortPoints(grid.reshape(-1, 1, 2), camera, DIST, R=None, P=camera, criteria=criteria)
    src = src.reshape(size[1], size[0], 2).astype(np.float32)
    reference = cv2.remap(small, src[..., 0], src[..., 1], cv2.INTER_LINEAR)
    inside = (src[..., 0] >= 2) & (src[..., 0] <= size[0] - 3) & (src[..., 1] >= 2) & (src[..., 1] <= size[1] - 3)
    result = distort(small, lens, backend=backend)
    diff = np.abs(result.astype(np.float64) - reference).max(axis=2)[inside]
    assert diff.mean() <= 0.3 and diff.max() <= 5.0, (diff.mean(), diff.max())


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("fit", [("crop", "full"), ("full", "crop"), ("same", "same")])
def test_correct_undoes_distort_off_centre(ctx, road, fit, backend):
    """Round trip through both shaders with a principal point and pixel aspect (fits paired as in
    DESIGN: a distortion's 'crop' is a correction's 'full'); interior within 3 levels on average
    (two bilinear resamplings blur, as in test_distort.py)."""
    size = (320, 180)
    lens = Lens.from_opencv(scaled_camera(K_OFF, 0.25), DIST, size)
    small = cv2.resize(road, size, interpolation=cv2.INTER_AREA)
    back = correct(distort(small, lens, fit=fit[0], backend=backend), lens, fit=fit[1], backend=backend)
    inner = (slice(20, -20), slice(30, -30))
    diff = np.abs(back[inner].astype(np.float64) - small[inner])
    assert diff.mean() <= 3.0, diff.mean()


def frame_edge(size, n=2001):
    w, h = size
    t = np.linspace(0.0, 1.0, n)
    xs, ys = t * w - 0.5, t * h - 0.5
    return np.concatenate(
        [np.stack([xs, np.full_like(xs, -0.5)], 1), np.stack([xs, np.full_like(xs, h - 0.5)], 1),
         np.stack([np.full_like(ys, -0.5), ys], 1), np.stack([np.full_like(ys, w - 0.5), ys], 1)]
    )


LENSES = [
    Lens(-0.3, 0.06, 200 / 1280, -60 / 1280, 0.98),
    Lens(0.2, 0.05, -0.3, 0.1, 1.05),
    Lens(-0.6, 0.2, 0.01, 0.01, 1.0),
    Lens(0.1, -0.05, 0.45, -0.2, 0.9),
]


@pytest.mark.parametrize("lens", LENSES)
def test_frame_radius_and_fits_against_brute_force(lens):
    """frame_radius is the largest lens radius on the frame's edge; 'crop' is the largest scale whose
    output edge maps inside the input (0.5 % more and some of it leaves), 'full' the smallest that
    keeps the input's edge inside the output (0.5 % less and some leaves); both swap for distort."""
    size = (320, 180)
    w, h = size
    edge = frame_edge(size)
    points = glradial.lens.lens.pixels_to_lens(edge, size, lens.centre, lens.pixel_aspect)
    assert lens.frame_radius(size) == pytest.approx(np.hypot(*points.T).max(), rel=1e-12)
    assert lens.edge_radius(size) == pytest.approx(np.hypot(*points.T).min(), rel=1e-6)
    pp = np.array(lens.principal_point(size))

    def in_frame(p):
        tol = 1e-6
        return bool(np.all(p >= -0.5 - tol) and np.all(p[:, 0] <= w - 0.5 + tol) and np.all(p[:, 1] <= h - 0.5 + tol))

    crop = glradial.fit_scale(lens, size, "crop")

    def sources_inside(scale):  # output edge -> undistorted point (scaled about the principal point) -> source
        return in_frame(lens.distort_points((edge - pp) * scale + pp, size))

    assert sources_inside(crop) and not sources_inside(crop * 1.005)
    full = glradial.fit_scale(lens, size, "full")

    def input_visible(scale):
        return in_frame((lens.undistort_points(edge, size) - pp) / scale + pp)

    assert input_visible(full) and not input_visible(full * 0.995)
    assert glradial.fit_scale(lens, size, "crop", "distort") == pytest.approx(full)
    assert glradial.fit_scale(lens, size, "full", "distort") == pytest.approx(crop)


def test_principal_point_outside_the_frame():
    """'same' and a number work wherever the principal point is; 'crop'/'full' need it inside."""
    lens = Lens(-0.1, 0.0, 0.6, 0.0)
    image = np.full((18, 32, 3), 100, np.uint8)
    assert correct(image, lens, backend="cpu").shape == image.shape
    assert correct(image, lens, fit=0.9, backend="cpu").shape == image.shape
    with pytest.raises(ValueError, match=r"principal point .* lies outside the 32×18 frame"):
        correct(image, lens, fit="crop", backend="cpu")


def test_fold_over_uses_the_farthest_corner():
    """The fold-over check uses the frame corner farthest from the principal point: a lens that is
    valid centred on a 16:9 frame folds over once its principal point moves right."""
    centred = Lens(-0.9, 0.0)  # folds at sqrt(1 / 2.7) = 0.6086 > 0.5737 (16:9 corner radius)
    centred.check_frame((1280, 720))
    moved = Lens(-0.9, 0.0, 0.1, 0.0)  # farthest corner radius hypot(0.6, 0.28125) = 0.6627
    assert moved.frame_radius((1280, 720)) == pytest.approx(math.hypot(0.6, 0.28125))
    with pytest.raises(ValueError, match="folds over at radius 0.6086"):
        moved.check_frame((1280, 720))
    with pytest.raises(ValueError, match="folds over"):
        correct(np.zeros((72, 128), np.uint8), moved, backend="cpu")


def test_converters_refuse_or_keep_the_principal_point(lens):
    """Conventions whose two numbers cannot carry a principal point or pixel aspect refuse such a
    lens naming why; rescale and ffmpeg's cx/cy keep it; the centred case is unchanged."""
    for method in ("to_pixel", "to_height_normalised", "to_lensfun_poly5", "to_ffmpeg"):
        with pytest.raises(ValueError, match="principal point at cx=0.15625, cy=-0.046875"):
            getattr(lens, method)(SIZE)
    with pytest.raises(ValueError, match="pixel_aspect=0.98"):
        lens.to_normalised(0.5)
    with pytest.raises(ValueError, match="no pixel aspect"):
        lens.ffmpeg_options(SIZE)
    for s in (0.5, 1.7):
        back = lens.rescale(s).rescale(1 / s)
        for name in ("k1", "k2", "cx", "cy", "pixel_aspect"):
            assert getattr(back, name) == pytest.approx(getattr(lens, name), rel=1e-12), name
    centred = Lens.from_opencv(K_CENTRED, DIST, SIZE)
    assert centred.is_centred and centred.to_ffmpeg(SIZE) == centred.ffmpeg_options(SIZE)[2:]
    assert centred.ffmpeg_options(SIZE)[:2] == (0.5, 0.5)


def test_rescale_is_a_crop_about_the_image_centre(lens, pixels):
    """A centred crop of width W' = W/s sees Lens.rescale(s): the principal point keeps its pixel
    offset from the image centre, and points move identically."""
    big, small = SIZE, (640, 360)
    cropped = lens.rescale(2.0)
    shift = np.array([(big[0] - small[0]) / 2, (big[1] - small[1]) / 2])
    np.testing.assert_allclose(np.array(cropped.principal_point(small)) + shift, lens.principal_point(big), atol=1e-9)
    inside = pixels[(np.abs(pixels - [639.5, 359.5]) < [300, 170]).all(axis=1)]
    np.testing.assert_allclose(cropped.distort_points(inside - shift, small) + shift, lens.distort_points(inside, big), atol=1e-9)


def test_ffmpeg_options_off_centre():
    """ffmpeg lenscorrection with cx, cy (vf_lenscorrection.c: centre = integer pixel (int(cx W),
    int(cy H)), radii normalised by half the diagonal, output pixel = undistorted point): for a lens
    whose principal point is an integer pixel the written-out formula moves pixels exactly as the
    lens; from_ffmpeg inverts ffmpeg_options."""
    w, h = 1280, 720
    lens = Lens(-0.25, 0.05, (900 - 639.5) / w, (300 - 359.5) / w)
    cx, cy, k1, k2 = lens.ffmpeg_options((w, h))
    centre = np.array([int(cx * w), int(cy * h)], float)
    assert centre.tolist() == [900.0, 300.0]
    pts = np.random.default_rng(5).uniform([0, 0], [w - 1, h - 1], (200, 2))
    d = pts - centre
    r2 = np.sum(d * d, axis=1, keepdims=True) / (math.hypot(w, h) / 2) ** 2
    np.testing.assert_allclose(centre + d * (1 + k1 * r2 + k2 * r2 * r2), lens.distort_points(pts, (w, h)), atol=1e-9)
    back = Lens.from_ffmpeg(k1, k2, (w, h), cx, cy)
    for name in ("k1", "k2", "cx", "cy", "pixel_aspect"):
        assert getattr(back, name) == pytest.approx(getattr(lens, name), rel=1e-12, abs=1e-15), name


def test_lens_value_validation():
    with pytest.raises(ValueError, match="pixel_aspect must be positive, got 0"):
        Lens(0.1, 0.0, pixel_aspect=0.0)
    with pytest.raises(ValueError, match="cx must be finite"):
        Lens(0.1, 0.0, cx=float("nan"))
    with pytest.raises(TypeError, match="cy must be a real number"):
        Lens(0.1, 0.0, cy="0.1")
    assert Lens(-0.1, 0.02) == Lens(-0.1, 0.02, 0.0, 0.0, 1.0) and Lens(-0.1, 0.02).is_centred
