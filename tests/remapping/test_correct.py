"""glradial.correct against OpenCV on real photographs, every dtype, channel count and backend.

Oracle: ``cv2.undistort(img, K, (k1, k2, 0, 0))`` with ``K = [[W, 0, (W-1)/2], [0, W, (H-1)/2],
[0, 0, 1]]`` (docs/DESIGN.md: with f = W OpenCV's coefficients equal ours), and for nearest / cubic
``cv2.remap`` on the maps of ``cv2.initUndistortRectifyMap`` with the same K. Photos are downscaled
to 320×180 (coefficients are resolution independent) to keep llvmpipe fast.

Tolerances (errors in 8-bit levels, i.e. scaled by 255 / the dtype's full scale, inside an interior
mask whose OpenCV source lies >= 2 px inside the input so border handling does not enter):
OpenCV quantises every sub-pixel position to 1/32 px (INTER_BITS = 5) and, for 8-bit, blends with
fixed-point weights; the shader interpolates at float32 positions. At a local gradient g (levels/px)
the two differ by up to g/64, plus a level of rounding for integer output. g <= 255 levels/px, so
no pixel may differ by more than 255/64 + 1 ~ 5 levels; the downscaled chessboard has such edges
(p99 2.0 measured) while flat areas agree. GL bounds: mean <= 0.25, p99 <= 2.5, max <= 5 (measured:
mean 0.05-0.16, p99 0.65-2.0, max 4). The CPU backend quantises exactly like OpenCV (same maps up to
float32 round-off), so it must be near identical: mean <= 0.01, max <= 5 (measured mean < 0.001).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import glradial
from glradial import Lens, correct

SIZE = (320, 180)
BARREL = (-0.3, 0.06)
PINCUSHION = (0.2, 0.05)
FULL_SCALE = {np.uint8: 255.0, np.uint16: 65535.0, np.float32: 1.0}


def camera(size):
    w, h = size
    return np.array([[w, 0.0, (w - 1) / 2], [0.0, w, (h - 1) / 2], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def photos(road, chessboard):
    return {
        "road": cv2.resize(road, SIZE, interpolation=cv2.INTER_AREA),
        "chessboard": cv2.resize(chessboard, SIZE, interpolation=cv2.INTER_AREA),
    }


def as_dtype(rgb: np.ndarray, dtype, channels: int | None) -> np.ndarray:
    """An RGB uint8 photo as the requested dtype and channel layout (None = H×W)."""
    if channels in (None, 1):
        image = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        if channels == 1:
            image = image[..., None]
    elif channels == 3:
        image = rgb
    else:
        alpha = np.linspace(0, 255, rgb.shape[1], dtype=np.uint8)[None, :, None].repeat(rgb.shape[0], 0)
        image = np.concatenate([rgb, alpha], axis=2)
    if dtype == np.uint16:
        return image.astype(np.uint16) * 257
    if dtype == np.float32:
        return image.astype(np.float32) / 255.0
    return image.copy()


def opencv_maps(k, size):
    return cv2.initUndistortRectifyMap(camera(size), np.array([k[0], k[1], 0.0, 0.0]), None, camera(size), size, cv2.CV_32FC1)


def interior(k, size, margin=2.0):
    map_x, map_y = opencv_maps(k, size)
    w, h = size
    return (map_x >= margin) & (map_x <= w - 1 - margin) & (map_y >= margin) & (map_y <= h - 1 - margin)


def level_errors(result, reference, dtype, mask):
    diff = np.abs(result.astype(np.float64) - reference.astype(np.float64)) * (255.0 / FULL_SCALE[dtype])
    if diff.ndim == 3:
        diff = diff.max(axis=2)
    return diff[mask]


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("channels", [None, 1, 3, 4], ids=["HxW", "C1", "C3", "C4"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32], ids=["u8", "u16", "f32"])
@pytest.mark.parametrize("k", [BARREL, PINCUSHION], ids=["barrel", "pincushion"])
def test_correct_matches_cv2_undistort(ctx, photos, k, dtype, channels, backend):
    mask = interior(k, SIZE)
    assert mask.mean() > 0.8
    for name, rgb in photos.items():
        image = as_dtype(rgb, dtype, channels)
        result = correct(image, *k, backend=backend, alpha="premultiplied")  # every channel as it is: cv2's oracle
        assert result.shape == image.shape and result.dtype == image.dtype
        reference = cv2.undistort(image, camera(SIZE), np.array([k[0], k[1], 0.0, 0.0])).reshape(image.shape)
        errors = level_errors(result, reference, dtype, mask)
        assert errors.max() <= 5.0, (name, errors.max())
        if backend == "cpu" and dtype != np.float32:
            # integer frames: the same 1/32-px fixed-point maps as cv2.undistort, so nearly identical
            assert errors.mean() <= 0.01, (name, errors.mean())
        else:  # exact float positions (the shader; float frames on the CPU: tests/remapping/test_float_maps.py)
            assert errors.mean() <= 0.25, (name, errors.mean())
            assert np.percentile(errors, 99) <= 2.5, (name, np.percentile(errors, 99))


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("k", [BARREL, PINCUSHION], ids=["barrel", "pincushion"])
def test_nearest_and_cubic_match_cv2_remap(ctx, photos, k, backend):
    """Nearest: the same source pixel except where a position lies within float round-off of a
    half pixel (float32 in the shader vs OpenCV's rounding of float32 maps): >= 99.5 % identical.
    Cubic: same kernel (Keys a = -0.75) as INTER_CUBIC; tolerances as the module docstring."""
    map_x, map_y = opencv_maps(k, SIZE)
    mask = interior(k, SIZE, margin=3.0)
    image = photos["road"]
    near = correct(image, *k, interpolation="nearest", backend=backend)
    ref = cv2.remap(image, map_x, map_y, cv2.INTER_NEAREST)
    same = np.all(near == ref, axis=2)[mask]
    assert same.mean() >= 0.995, same.mean()
    cubic = correct(image, *k, interpolation="cubic", backend=backend)
    ref = cv2.remap(image, map_x, map_y, cv2.INTER_CUBIC)
    errors = level_errors(cubic, ref, np.uint8, mask)
    assert errors.mean() <= 0.25 and np.percentile(errors, 99) <= 2.5, (errors.mean(), np.percentile(errors, 99))
    # cubic really is cubic: it differs from bilinear by much more than it differs from INTER_CUBIC
    linear = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR)
    assert level_errors(linear, ref, np.uint8, mask).mean() > 4 * errors.mean()


@pytest.mark.parametrize("interpolation", ["nearest", "linear", "cubic"])
@pytest.mark.parametrize("direction", ["correct", "distort"])
def test_gl_and_cpu_backends_agree(ctx, photos, interpolation, direction):
    """Both backends everywhere, borders included: the same border rule (fill outside the input's
    area, edge pixels repeated inside it). Tolerance as the module docstring, except that a pixel
    whose source lies within float32 round-off of the input's edge may take the fill on one backend
    only: at most 0.1 % of pixels may exceed 5 levels."""
    fn = getattr(glradial, direction)
    image = photos["chessboard"]
    for k in (BARREL, PINCUSHION):
        for fit in ("same", "crop", "full"):
            gl = fn(image, *k, fit=fit, interpolation=interpolation, fill=(10, 200, 30), backend="gl")
            cpu = fn(image, *k, fit=fit, interpolation=interpolation, fill=(10, 200, 30), backend="cpu")
            errors = level_errors(gl, cpu, np.uint8, np.ones(SIZE[::-1], bool))
            if interpolation == "nearest":
                assert (errors == 0).mean() >= 0.995
            else:
                assert errors.mean() <= 0.25 and np.percentile(errors, 99) <= 2.5, (k, fit, errors.mean())
                assert (errors > 5.0).mean() <= 0.001, (k, fit, (errors > 5.0).mean())


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_fill_value_and_channel_order(ctx, backend):
    """A pincushion correction at fit='same' leaves the corners without a source: they get the
    fill exactly (per channel, in frame units); channels are never swapped."""
    image = np.zeros((90, 160, 4), np.uint16)
    image[..., 0], image[..., 1], image[..., 2], image[..., 3] = 1000, 2000, 3000, 4000
    out = correct(image, 0.3, 0.1, fill=(11, 22, 33, 44), backend=backend)
    assert out[0, 0].tolist() == [11, 22, 33, 44]
    assert out[45, 80].tolist() == [1000, 2000, 3000, 4000]


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_fit_crop_has_no_empty_pixel_and_full_keeps_the_input(ctx, backend):
    """fit='crop': every output pixel has a source (no fill anywhere) for barrel and pincushion;
    fit='full': all four input corners (marked) stay inside the output frame."""
    w, h = 160, 90
    image = np.full((h, w), 200, np.uint8)
    for k in (BARREL, PINCUSHION):
        for interpolation in ("nearest", "linear", "cubic"):
            cropped = correct(image, *k, fit="crop", fill=0, interpolation=interpolation, backend=backend)
            assert cropped.min() == 200, (k, interpolation)
        same = correct(image, *k, fit="same", fill=0, backend=backend)
        assert (same.min() == 0) == (k == PINCUSHION), k  # pincushion 'same' does leave empty corners
        marked = np.zeros((h, w), np.float32)
        marked[:3, :3] = marked[:3, -3:] = marked[-3:, :3] = marked[-3:, -3:] = 1.0
        full = correct(marked, *k, fit="full", backend=backend)
        for rows in (slice(0, h // 2), slice(h // 2, h)):
            for cols in (slice(0, w // 2), slice(w // 2, w)):
                assert full[rows, cols].max() > 0.1, (k, rows, cols)


def test_fit_scales_closed_form_against_brute_force():
    """fit_scale against brute force on dense points of the frame's edge (pixel edges at -0.5 and
    W - 0.5): 'crop' is the largest scale whose output edge maps inside the input (0.5 % more and
    some of it leaves), 'full' the smallest that keeps the input's edge inside the output (0.5 %
    less and some of it leaves)."""
    size = (320, 180)
    w, h = size
    t = np.linspace(0.0, 1.0, 2001)
    xs, ys = t * w - 0.5, t * h - 0.5
    edge = np.concatenate(
        [np.stack([xs, np.full_like(xs, -0.5)], 1), np.stack([xs, np.full_like(xs, h - 0.5)], 1),
         np.stack([np.full_like(ys, -0.5), ys], 1), np.stack([np.full_like(ys, w - 0.5), ys], 1)]
    )
    centre = np.array([(w - 1) / 2, (h - 1) / 2])

    def in_frame(p):
        tol = 1e-6
        return bool(np.all(p >= -0.5 - tol) and np.all(p[:, 0] <= w - 0.5 + tol) and np.all(p[:, 1] <= h - 0.5 + tol))

    for k in (BARREL, PINCUSHION, (-0.6, 0.2), (0.1, -0.05)):
        lens = Lens(*k)
        crop = glradial.fit_scale(lens, size, "crop")

        def sources_inside(scale):  # output edge -> undistorted point (scaled) -> distorted source
            return in_frame(lens.distort_points((edge - centre) * scale + centre, size))

        assert sources_inside(crop) and not sources_inside(crop * 1.005), k
        full = glradial.fit_scale(lens, size, "full")

        def input_visible(scale):  # input edge -> undistorted point -> output pixel at this scale
            return in_frame((lens.undistort_points(edge, size) - centre) / scale + centre)

        assert input_visible(full) and not input_visible(full * 0.995), k
        # distortion swaps the roles of the two fits
        assert glradial.fit_scale(k, size, "crop", "distort") == pytest.approx(full)
        assert glradial.fit_scale(k, size, "full", "distort") == pytest.approx(crop)
    assert glradial.fit_scale(BARREL, size, "same") == 1.0


def test_identity_lens_is_exact(ctx):
    image = np.random.default_rng(1).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    for backend in ("gl", "cpu"):
        for interpolation in ("nearest", "linear", "cubic"):
            assert np.array_equal(correct(image, 0.0, 0.0, interpolation=interpolation, backend=backend), image)


def test_auto_backend_decision(ctx):
    from glradial.gl import egl
    from glradial.remapping import remap

    expected = "cpu" if egl.is_software_renderer(ctx) else "gl"
    assert remap.auto_backend() == expected
    image = np.zeros((20, 30, 3), np.uint8)
    assert correct(image, -0.1, 0.0).shape == image.shape


def test_render_texture_embeds_in_a_callers_pipeline(ctx, photos):
    """A caller's texture drawn into a caller's framebuffer (no CPU round trip) gives what
    correct() returns; a viewport draws into part of a larger framebuffer."""
    from glradial import Remapper
    from glradial.gl.egl import release_objects

    image = photos["road"]
    h, w = image.shape[:2]
    source = ctx.texture((w, h), 3, image.tobytes())
    target = ctx.texture((w + 40, h + 20), 4)
    fbo = ctx.framebuffer([target])
    try:
        remapper = Remapper(ctx)
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        remapper.render_texture(source, fbo, *BARREL, viewport=(40, 20, w, h), fill=(0.0, 0.0, 0.0, 1.0))
        drawn = np.frombuffer(fbo.read(components=4), np.uint8).reshape(h + 20, w + 40, 4)
        expected = correct(image, *BARREL, backend="gl")
        assert np.array_equal(drawn[20:, 40:, :3], expected)
        assert drawn[:20].max() == 0 and drawn[:, :40].max() == 0  # outside the viewport untouched
        remapper.render_texture(source, fbo, *BARREL, direction="distort", fit="crop", viewport=(40, 20, w, h))
        drawn = np.frombuffer(fbo.read(components=4), np.uint8).reshape(h + 20, w + 40, 4)
        assert np.array_equal(drawn[20:, 40:, :3], glradial.distort(image, *BARREL, fit="crop", backend="gl"))
        remapper.release()
    finally:
        release_objects(ctx, fbo, target, source)


def test_non_contiguous_frames_and_out(ctx, photos):
    image = photos["road"]
    view = image[::2, ::2]  # strided view
    for backend in ("gl", "cpu"):
        assert np.array_equal(correct(view, *BARREL, backend=backend),
                              correct(np.ascontiguousarray(view), *BARREL, backend=backend))
    from glradial import Remapper

    with Remapper(ctx) as remapper:
        out = np.empty_like(image)
        assert remapper.correct(image, *BARREL, out=out) is out
        assert np.array_equal(out, correct(image, *BARREL, backend="gl"))


def test_threads_each_get_their_own_context(photos):
    """Module-level calls from several threads at once: one EGL context and Remapper per thread,
    same results as on the main thread."""
    from concurrent.futures import ThreadPoolExecutor

    image = photos["chessboard"]
    expected = correct(image, *PINCUSHION, backend="gl")
    with ThreadPoolExecutor(3) as pool:
        results = list(pool.map(lambda _: correct(image, *PINCUSHION, backend="gl"), range(6)))
    for result in results:
        assert np.array_equal(result, expected)
