"""Bad input to correct / distort / Remapper / Lens: a ValueError or TypeError naming the problem,
never a crash or a silent wrong image; and no EGL still leaves the CPU backend working."""

from __future__ import annotations

import threading

import numpy as np
import pytest

import glradial
from glradial import Lens, Remapper, correct, distort
from glradial.gl import egl
from glradial.remapping import remap

FRAME = np.zeros((18, 32, 3), np.uint8)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("fn", [correct, distort], ids=["correct", "distort"])
@pytest.mark.parametrize(
    "k1, k2, error, words",
    [
        (float("nan"), 0.0, ValueError, "k1 must be finite"),
        (0.0, float("inf"), ValueError, "k2 must be finite"),
        ("0.1", 0.0, TypeError, "k1 must be a real number"),
        (0.1, "x", TypeError, "k2 must be a real number"),
        (Lens(0.1, 0.0), 0.0, TypeError, r"give a Lens or the coefficients k1, k2, not both: got Lens .* and k2=0.0"),
        ((0.1, 0.0), None, TypeError, r"k1 must be a real number \(or lens a glradial.Lens\), got tuple"),
        (1j, 0.0, TypeError, "k1 must be a real number"),
        (True, 0.0, TypeError, "k1 must be a real number"),
        (np.array([0.1, 0.2]), 0.0, TypeError, "k1 must be a real number"),
    ],
)
def test_bad_coefficients(ctx, fn, backend, k1, k2, error, words):
    with pytest.raises(error, match=words):
        fn(FRAME, k1, k2, backend=backend)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("fn", [correct, distort], ids=["correct", "distort"])
def test_fold_over_names_the_radius(ctx, fn, backend):
    """k = (-1.5, 0): 1 - 4.5 r² = 0 at r = 0.4714 < the 16:9 corner radius 0.5737."""
    with pytest.raises(ValueError, match=r"folds over at radius 0\.4714.*up to 0\.5737"):
        fn(np.zeros((90, 160), np.uint8), -1.5, 0.0, backend=backend)
    # k1 = -0.6 folds at sqrt(1/1.8) = 0.7454: fine at scale 1.2 (radii up to 0.688), refused at
    # scale 1.4 (radii up to 1.4 · 0.5737 = 0.8031): the fit scale enters the radius
    fn(np.zeros((90, 160), np.uint8), -0.6, 0.0, fit=1.2, backend=backend)
    with pytest.raises(ValueError, match=r"folds over at radius 0\.7454.*up to 0\.8031"):
        fn(np.zeros((90, 160), np.uint8), -0.6, 0.0, fit=1.4, backend=backend)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize(
    "frame, error, words",
    [
        (np.zeros((0, 32, 3), np.uint8), ValueError, "frame is empty"),
        (np.zeros((18, 0), np.uint8), ValueError, "frame is empty"),
        (np.zeros((18, 32, 2), np.uint8), ValueError, r"C in \(1, 3, 4\).*2 channels"),
        (np.zeros((18, 32, 5), np.uint8), ValueError, r"C in \(1, 3, 4\).*5 channels"),
        (np.zeros((2, 2, 18, 32, 3), np.uint8), ValueError, r"or a batch N×H×W×C .* 5-D array"),
        (np.zeros((0, 18, 32, 3), np.uint8), ValueError, "frame batch is empty"),
        (np.zeros((2, 18, 32, 2), np.uint8), ValueError, r"batch must be N×H×W×C with C in \(1, 3, 4\)"),
        (np.zeros(32, np.uint8), ValueError, "1-D array"),
        (np.zeros((18, 32, 3), np.complex64), TypeError, "dtype must be uint8, uint16, float32 or float64, got complex64"),
        (np.zeros((18, 32, 3), object), TypeError, "got object"),
        (np.full((18, 32), "a"), TypeError, "got <U1"),
        (np.zeros((18, 32, 3), np.float16), TypeError, "got float16"),
        (np.full((18, 32, 3), 1e39), ValueError, "float64 frame holds values beyond float32's range"),
        (np.zeros((18, 32, 3), bool), TypeError, "got bool"),
        ([[0, 1], [2, 3]], TypeError, "frame must be a NumPy array, got list"),
        ("image.png", TypeError, "frame must be a NumPy array, got str"),
    ],
)
def test_bad_frames(ctx, frame, error, words, backend):
    with pytest.raises(error, match=words):
        correct(frame, -0.1, 0.0, backend=backend)


@pytest.mark.parametrize("backend", ["gl", "cpu", "auto"])
def test_unknown_options(ctx, backend):
    with pytest.raises(ValueError, match="fit must be one of 'same', 'crop', 'full', got 'cover'"):
        correct(FRAME, -0.1, 0.0, fit="cover", backend=backend)
    with pytest.raises(ValueError, match="fit scale must be positive, got -1"):
        correct(FRAME, -0.1, 0.0, fit=-1.0, backend=backend)
    with pytest.raises(ValueError, match="interpolation must be one of .*got 'bilinear'"):
        correct(FRAME, -0.1, 0.0, interpolation="bilinear", backend=backend)
    with pytest.raises(ValueError, match="inverse must be one of 'exact', 'drap', got 'newton'"):
        distort(FRAME, -0.1, 0.0, inverse="newton", backend=backend)
    with pytest.raises(ValueError, match=r"fill must be a scalar or 3 values .*got \(1, 2\)"):
        correct(FRAME, -0.1, 0.0, fill=(1, 2), backend=backend)
    with pytest.raises(ValueError, match="fill 300 is outside the range of uint8"):
        correct(FRAME, -0.1, 0.0, fill=300, backend=backend)
    with pytest.raises(ValueError, match="fill must be finite"):
        correct(FRAME.astype(np.float32), -0.1, 0.0, fill=float("nan"), backend=backend)


def test_unknown_backend():
    with pytest.raises(ValueError, match="backend must be one of 'auto', 'gl', 'cpu', got 'cuda'"):
        correct(FRAME, -0.1, 0.0, backend="cuda")


def test_frame_over_the_texture_limit(ctx):
    """A frame wider than GL_MAX_TEXTURE_SIZE: backend='gl' refuses naming the limit, without
    allocating the frame's texture; 'cpu' and 'auto' still work (a 1-row strip keeps it small)."""
    limit = egl.max_texture_size(ctx)
    wide = np.zeros((1, limit + 1), np.uint8)
    with pytest.raises(ValueError, match=f"exceeds this GL driver's texture limit of {limit}"):
        correct(wide, -0.01, 0.0, backend="gl")
    assert correct(wide, -0.01, 0.0, backend="cpu").shape == wide.shape
    assert correct(wide, -0.01, 0.0, backend="auto").shape == wide.shape
    with pytest.raises(ValueError, match="exceeds cv2.remap's limit of 32766"):
        correct(np.zeros((1, 40000), np.uint8), -0.01, 0.0, backend="cpu")


@pytest.mark.parametrize(
    "camera, dist, error, words",
    [
        (np.eye(2), np.zeros(4), ValueError, r"camera_matrix must be 3×3, got shape \(2, 2\)"),
        ([[100, 0, 15.5], [0, 100, 8.5], [0, 1, 1]], np.zeros(4), ValueError, r"\[\[fx, 0, cx\]"),
        ([[100, 3, 15.5], [0, 100, 8.5], [0, 0, 1]], np.zeros(4), ValueError, r"\[\[fx, 0, cx\]"),
        ([[-100, 0, 15.5], [0, 100, 8.5], [0, 0, 1]], np.zeros(4), ValueError, "focal lengths must be positive"),
        ([[np.nan, 0, 15.5], [0, 100, 8.5], [0, 0, 1]], np.zeros(4), ValueError, "camera_matrix must be finite"),
        ([["a", 0, 15.5], [0, 100, 8.5], [0, 0, 1]], np.zeros(4), TypeError, "camera_matrix must be a real numeric"),
        ([[100, 0, 15.5], [0, 100, 8.5], [0, 0]], np.zeros(4), TypeError, "camera_matrix must be a numeric array"),
        (np.diag([100.0, 100.0, 1.0]) + [[0, 0, 15.5], [0, 0, 8.5], [0, 0, 0]], np.zeros(3), ValueError, "4, 5, 8, 12 or 14 entries, got 3"),
        (np.diag([100.0, 100.0, 1.0]) + [[0, 0, 15.5], [0, 0, 8.5], [0, 0, 0]], [0.1, 0.0, 0.01, 0.0], ValueError, "p1=0.01"),
        (np.diag([100.0, 100.0, 1.0]) + [[0, 0, 15.5], [0, 0, 8.5], [0, 0, 0]], [0.1, 0, 0, 0, 0.2], ValueError, "k3=0.2"),
        (np.diag([100.0, 100.0, 1.0]) + [[0, 0, 15.5], [0, 0, 8.5], [0, 0, 0]], [np.inf, 0, 0, 0], ValueError, "dist_coeffs must be finite"),
    ],
)
def test_malformed_opencv_calibrations(camera, dist, error, words):
    with pytest.raises(error, match=words):
        Lens.from_opencv(camera, dist, (32, 18))


def test_bad_sizes_and_scales():
    lens = Lens(-0.1, 0.0)
    with pytest.raises(TypeError, match="size must be"):
        lens.maps(320)
    with pytest.raises(ValueError, match="size width must be positive, got 0"):
        lens.maps((0, 10))
    with pytest.raises(TypeError, match="size height must be an integer"):
        lens.to_pixel((10, 2.5))
    with pytest.raises(ValueError, match="s must be positive"):
        lens.rescale(0.0)
    with pytest.raises(ValueError, match="direction must be one of 'undistort', 'distort', got 'forward'"):
        lens.maps((32, 18), direction="forward")
    with pytest.raises(ValueError, match="ffmpeg lenscorrection accepts k1 in \\[-1, 1\\]"):
        Lens(-5.0, 0.0).to_ffmpeg((32, 18))


def test_released_remapper_refuses(ctx):
    remapper = Remapper(ctx)
    remapper.correct(FRAME, -0.1, 0.0)
    remapper.release()
    remapper.release()  # idempotent
    with pytest.raises(RuntimeError, match="released"):
        remapper.correct(FRAME, -0.1, 0.0)


def test_egl_unavailable_names_library_and_cpu_still_works(ctx, monkeypatch):
    with pytest.raises(egl.GLUnavailableError) as info:
        egl.create_context(libegl="libnonexistent.so")
    message = str(info.value)
    assert isinstance(info.value, ValueError), "bad environment must reach callers that catch ValueError"
    assert "libnonexistent.so" in message and egl.EGL_PACKAGES in message and "backend='cpu'" in message

    def no_egl():
        raise egl.GLUnavailableError("cannot create a headless OpenGL context through EGL (libEGL.so.1)")

    # a fresh process state: no cached auto decision, no per-thread Remapper, EGL missing
    monkeypatch.setattr(egl, "thread_context", no_egl)
    monkeypatch.setattr(remap, "_auto_choice", {})
    monkeypatch.setattr(egl, "_local", threading.local())
    image = np.random.default_rng(0).integers(0, 256, (18, 32, 3), dtype=np.uint8)
    expected = correct(image, -0.2, 0.0, backend="cpu")
    assert np.array_equal(correct(image, -0.2, 0.0), expected)  # auto falls back to the CPU
    assert remap.auto_backend() == "cpu"
    with pytest.raises(egl.GLUnavailableError, match="libEGL.so.1"):
        correct(image, -0.2, 0.0, backend="gl")


def test_exports():
    assert glradial.correct is correct and glradial.distort is distort and glradial.Remapper is Remapper
