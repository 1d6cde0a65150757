"""Alpha: RGBA frames are interpolated premultiplied on both backends and returned in the
convention they came in.

Oracle: a key whose colour is pure red wherever it is visible (alpha > 0) and green under full
transparency (what a renderer leaves there). Any interpolation of the visible pixels must stay red:
an edge pixel's colour is a coverage-weighted mean of red taps. Straight interpolation lets the green
bleed into the edge (a fringe of tens of levels); the tolerance, 4 levels of 255, covers rounding of
the premultiply/divide in 8 bits at low coverage. The alpha channel itself must equal a plain
resampling of alpha (alpha is not multiplied by anything).
"""

from __future__ import annotations

import numpy as np
import pytest

import glradial

LENS = (-0.3, 0.05)


def key(dtype=np.uint8) -> np.ndarray:
    """144×256 RGBA, straight: a soft-edged disc of red over transparent green."""
    height, width = 144, 256
    y, x = np.mgrid[0:height, 0:width]
    radius = np.hypot(x - 150, y - 70)
    alpha = np.clip((50 - radius) / 6, 0, 1)  # a 6-pixel ramp
    full = 255 if dtype == np.uint8 else (65535 if dtype == np.uint16 else 1.0)
    frame = np.zeros((height, width, 4), np.float64)
    frame[..., 0] = np.where(alpha > 0, full, 0)
    frame[..., 1] = np.where(alpha > 0, 0, full)  # green only where nothing is visible
    frame[..., 3] = alpha * full
    return (np.rint(frame) if dtype != np.float32 else frame).astype(dtype)


def fringe(result: np.ndarray, full: float) -> float:
    """The largest colour error (8-bit levels) over visible pixels (alpha at least 2 levels)."""
    visible = result[..., 3] >= 2 * full / 255
    red, green, blue = (result[..., c].astype(np.float64)[visible] for c in range(3))
    return float(max(np.max(np.abs(full - red)), np.max(green), np.max(blue)) * 255 / full)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32], ids=["u8", "u16", "f32"])
@pytest.mark.parametrize("direction", ["correct", "distort"])
def test_straight_key_has_no_fringe(ctx, backend, dtype, direction):
    frame = key(dtype)
    full = 1.0 if dtype == np.float32 else float(np.iinfo(dtype).max)
    remap = getattr(glradial, direction)
    result = remap(frame, *LENS, backend=backend, interpolation="cubic" if dtype == np.float32 else "linear")
    assert result.dtype == frame.dtype and result.shape == frame.shape
    assert fringe(result, full) <= 4.0
    assert (result[..., 3] > 0).sum() > 1000  # the key is there
    # alpha itself: a plain resampling (every channel as it is)
    plain = remap(frame, *LENS, backend=backend, alpha="premultiplied",
                  interpolation="cubic" if dtype == np.float32 else "linear")
    np.testing.assert_allclose(result[..., 3].astype(np.float64), plain[..., 3].astype(np.float64), atol=full / 255)
    # the oracle can fail: straight interpolation (alpha="premultiplied" on straight data) fringes
    assert fringe(plain, full) > 20.0


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_premultiplied_frames_stay_premultiplied(ctx, backend):
    """A premultiplied key: resampled as it is, so colour never exceeds alpha and equals the plain
    remap of each channel; and the straight result, premultiplied, agrees with it within rounding."""
    straight = key(np.float32)
    premultiplied = straight.copy()
    premultiplied[..., :3] *= premultiplied[..., 3:4]
    result = glradial.distort(premultiplied, *LENS, backend=backend, alpha="premultiplied")
    assert np.all(result[..., 0] <= result[..., 3] + 1e-6) and float(np.abs(result[..., 1]).max()) < 1e-6
    from_straight = glradial.distort(straight, *LENS, backend=backend)
    np.testing.assert_allclose(from_straight[..., :3] * from_straight[..., 3:4], result[..., :3], atol=1e-5)


def test_remapper_and_batches_take_the_switch(ctx):
    frame = key()
    with glradial.Remapper() as remapper:
        out = np.empty_like(frame)
        result = remapper.correct(frame, *LENS, out=out)
        assert result is out and fringe(out, 255) <= 4.0
    batch = np.stack([frame, frame])
    np.testing.assert_array_equal(glradial.correct(batch, *LENS, backend="cpu")[1], glradial.correct(frame, *LENS, backend="cpu"))


@pytest.mark.parametrize("bad", ["unassociated", None, 1])
def test_unknown_alpha_is_a_value_error_naming_it(bad):
    with pytest.raises(ValueError, match="alpha must be one of 'straight', 'premultiplied'"):
        glradial.correct(key(), *LENS, backend="cpu", alpha=bad)
