"""correct/distort's calling forms: a Lens (or subclass, or an estimate) or k1, k2; float64 frames;
batches N×H×W×C. Oracles: the same call with k1, k2, the float32 frame, and frame-by-frame calls."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import pytest

import glradial
from glradial import Lens, Remapper, correct, distort

SIZE = (160, 90)
LENS = Lens(-0.3, 0.06)
OFF = Lens(-0.25, 0.04, 0.05, -0.03, 0.98)


@dataclass(frozen=True)
class TaggedLens(Lens):
    """A Lens subclass with one more field, as an estimate object would be."""

    source: str = "test"


@pytest.fixture(scope="module")
def photo(road):
    return cv2.resize(road, SIZE, interpolation=cv2.INTER_AREA)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("fn", [correct, distort], ids=["correct", "distort"])
def test_lens_and_coefficients_are_the_same_call(ctx, photo, fn, backend):
    by_numbers = fn(photo, -0.3, 0.06, fit="crop", backend=backend)
    assert np.array_equal(fn(photo, LENS, fit="crop", backend=backend), by_numbers)
    assert np.array_equal(fn(photo, TaggedLens(-0.3, 0.06), fit="crop", backend=backend), by_numbers)
    assert np.array_equal(fn(photo, -0.3, backend=backend), fn(photo, -0.3, 0.0, backend=backend))  # k2 defaults to 0
    # an off-centre Lens really reaches the backend (it differs from its centred coefficients)
    assert not np.array_equal(fn(photo, OFF, backend=backend), fn(photo, OFF.k1, OFF.k2, backend=backend))
    with pytest.raises(TypeError, match="not both"):
        fn(photo, LENS, 0.06, backend=backend)


def test_remapper_and_fit_scale_take_a_lens(ctx, photo):
    with Remapper(ctx) as remapper:
        assert np.array_equal(remapper.correct(photo, OFF), correct(photo, OFF, backend="gl"))
        assert np.array_equal(remapper.distort(photo, OFF, fit="full"), distort(photo, OFF, fit="full", backend="gl"))
    assert glradial.fit_scale(OFF, SIZE, "crop") == OFF.fit_scale(SIZE, "crop")


def test_correct_takes_an_estimate(photo):
    """glradial.correct(img, glradial.estimate(img)): the issue's first failing line."""
    estimate = glradial.estimate(photo)
    assert isinstance(estimate, Lens)
    out = correct(photo, estimate, backend="cpu", apply_doubtful=True)
    assert np.array_equal(out, correct(photo, estimate.k1, estimate.k2, backend="cpu"))
    if estimate.doubtful:  # the default doubt policy leaves the frame as it is
        assert np.array_equal(correct(photo, estimate, backend="cpu"), photo)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("fn", [correct, distort], ids=["correct", "distort"])
def test_float64_equals_float32_within_float32_precision(ctx, photo, fn, backend):
    """float64 in, float64 out, computed in float32: equal to the float32 frame's result cast up."""
    frame64 = photo.astype(np.float64) / 255.0 + 1e-9  # below float32's resolution near 1
    out = fn(frame64, OFF, fit="full", fill=0.25, backend=backend)
    assert out.dtype == np.float64 and out.shape == frame64.shape
    expected = fn(frame64.astype(np.float32), OFF, fit="full", fill=0.25, backend=backend).astype(np.float64)
    np.testing.assert_array_equal(out, expected)
    # and it is a real correction of the values, not a copy: compare with the uint8 path (1/255 scale)
    as_u8 = fn(photo, OFF, fit="full", fill=64, backend=backend).astype(np.float64) / 255.0
    assert np.abs(out - as_u8).mean() < 1.0 / 255.0


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("layout", ["NHWC3", "NHWC1", "NHWC4-f64"])
def test_batch_equals_frame_by_frame(ctx, photo, layout, backend):
    frames = np.stack([photo, photo[::-1], np.roll(photo, 40, axis=1)])  # three different frames
    if layout == "NHWC1":
        frames = frames[..., :1]
    elif layout == "NHWC4-f64":
        alpha = np.full(frames.shape[:3] + (1,), 200, np.uint8)
        frames = np.concatenate([frames, alpha], axis=3).astype(np.float64) / 255.0
    out = correct(frames, OFF, fit="crop", backend=backend)
    assert out.shape == frames.shape and out.dtype == frames.dtype
    for index, frame in enumerate(frames):
        assert np.array_equal(out[index], correct(frame, OFF, fit="crop", backend=backend)), index
    distorted = distort(frames, LENS, backend=backend)
    assert np.array_equal(distorted[1], distort(frames[1], LENS, backend=backend))


def test_module_functions_survive_a_second_context_on_the_thread(ctx, photo):
    """README's sequence: glradial.correct (the thread's context), then a Remapper() with its own
    context, released; the thread's context must be current again for the next call (it used to
    read back garbage with GL_INVALID_OPERATION: mean 111 levels off)."""
    before = correct(photo, LENS, backend="gl")
    with Remapper() as own:
        assert np.array_equal(own.correct(photo, LENS), before)
    assert np.array_equal(correct(photo, LENS, backend="gl"), before)
    assert ctx.error == "GL_NO_ERROR"


def test_render_texture_takes_a_lens(ctx, photo):
    from glradial.gl.egl import release_objects

    h, w = photo.shape[:2]
    source = ctx.texture((w, h), 3, np.ascontiguousarray(photo).tobytes())
    target = ctx.texture((w, h), 4)
    fbo = ctx.framebuffer([target])
    try:
        with Remapper(ctx) as remapper:
            remapper.render_texture(source, fbo, OFF, fit="crop")
            drawn = np.frombuffer(fbo.read(components=4), np.uint8).reshape(h, w, 4)
            assert np.array_equal(drawn[..., :3], correct(photo, OFF, fit="crop", backend="gl"))
            with pytest.raises(TypeError, match="not both"):
                remapper.render_texture(source, fbo, OFF, 0.1)
    finally:
        release_objects(ctx, fbo, target, source)
