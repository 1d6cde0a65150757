"""glradial.media.frames.to_rgb8: the one frame coercion (known answers per dtype and layout)."""

from __future__ import annotations

import numpy as np
import pytest

from glradial.media.frames import to_rgb8


def test_layouts_and_dtypes():
    grey = np.array([[0, 128], [255, 7]], np.uint8)
    out = to_rgb8(grey)
    assert out.shape == (2, 2, 3) and out.flags.c_contiguous and np.all(out == grey[:, :, None])
    rgba = np.dstack([grey, grey + 1, grey + 2, np.full_like(grey, 9)])
    assert np.array_equal(to_rgb8(rgba), rgba[:, :, :3])
    # 16-bit: 65535 -> 255, 257 k -> k, and halves round up (257 * 3 + 129 -> 4)
    sixteen = np.array([[0, 65535, 257 * 100, 257 * 3 + 129]], np.uint16)
    assert to_rgb8(sixteen)[0, :, 0].tolist() == [0, 255, 100, 4]
    # floats in [0, 1] scale by 255 and round; outside is clipped
    floats = np.array([[0.0, 1.0, 0.5, -0.2, 1.5]], np.float32)
    assert to_rgb8(floats)[0, :, 1].tolist() == [0, 255, 128, 0, 255]


def test_bad_frames_name_the_argument():
    with pytest.raises(TypeError, match="panorama must be a NumPy array"):
        to_rgb8([[1, 2]], "panorama")
    with pytest.raises(ValueError, match=r"frame must be H×W.*\(2, 2, 2\)"):
        to_rgb8(np.zeros((2, 2, 2), np.uint8))
    with pytest.raises(TypeError, match="int32"):
        to_rgb8(np.zeros((2, 2), np.int32))
    with pytest.raises(ValueError, match="NaN"):
        to_rgb8(np.full((2, 2), np.nan))
