"""Alpha conventions for resampling RGBA frames: interpolate premultiplied, return what came in.

A key (alpha) and its fill must be interpolated *premultiplied*: a tap's colour counts in proportion
to its coverage. Interpolating straight (unassociated) colour lets the colour hidden under fully
transparent pixels bleed into the edge of the key: a fringe.

Conventions (``alpha=``):

* ``"straight"``: colour channels are not multiplied by alpha (PNG, TIFF, ProRes 4444, VP9 alpha,
  as FFmpeg decodes them). The frame is premultiplied in float32, resampled, and divided by the
  resampled alpha again, so the result is straight too. Where the resampled alpha is 0 the colour
  is 0 (it is undefined there). Integer frames are rounded and clipped back to their range.
* ``"premultiplied"``: colour channels are already multiplied by alpha (OpenEXR, most compositors'
  textures). Every channel is resampled as it is, which is the premultiplied interpolation; also
  the choice for four channels that are not colour plus alpha.

Only frames with 4 channels (R, G, B, A; alpha last) are affected; 1- and 3-channel frames are
resampled as they are with either convention.
"""

from __future__ import annotations

from typing import Callable, Sequence

import cv2
import numpy as np

from ..lens.options import ALPHAS, Alpha, check_choice

__all__ = ["Alpha", "ALPHAS", "check_alpha", "remap_with_alpha"]


def check_alpha(alpha: object) -> str:
    """``alpha`` if it is one of :data:`~glradial.lens.options.ALPHAS`, else a ``ValueError`` naming it."""
    return check_choice("alpha", alpha, ALPHAS)


def _needs_premultiply(frame: object, alpha: str) -> bool:
    return (alpha == "straight" and isinstance(frame, np.ndarray) and frame.ndim in (3, 4) and frame.shape[-1] == 4
            and frame.dtype in (np.uint8, np.uint16, np.float32, np.float64) and frame.size > 0)


def remap_with_alpha(
    frame: np.ndarray,
    fill: float | Sequence[float],
    alpha: str,
    remap: Callable[[np.ndarray, float | Sequence[float]], np.ndarray],
) -> np.ndarray:
    """``remap(frame, fill)`` (any resampling that treats channels alike and keeps shape and dtype)
    with a straight-alpha RGBA ``frame`` (or batch, alpha last) premultiplied before and divided
    after; anything else is passed through. ``fill`` is in the frame's convention and units.

    uint8 frames are premultiplied exactly in 16-bit fixed point (``c a``, ``a 255``) and resampled
    as uint16; other dtypes in float32. Both use OpenCV's vectorised arithmetic."""
    if not _needs_premultiply(frame, check_alpha(alpha)):
        return remap(frame, fill)
    unit = 1.0 if frame.dtype.kind == "f" else float(np.iinfo(frame.dtype).max)
    if np.size(fill) not in (1, 4):
        return remap(frame, fill)  # the remap's own error for a fill of the wrong length
    fill_values = np.broadcast_to(np.asarray(fill, dtype=np.float64).ravel(), (4,))
    if unit != 1.0 and not all(0 <= v <= unit for v in fill_values):
        raise ValueError(f"fill {fill!r} is outside the range of {frame.dtype} (0..{unit:g})")
    one = _premultiplied_u8 if frame.dtype == np.uint8 else _premultiplied_float
    if frame.ndim == 4:
        return np.stack([one(image, fill_values, unit, remap) for image in frame])
    return one(frame, fill_values, unit, remap)


def _premultiplied_u8(frame: np.ndarray, fill: np.ndarray, unit: float, remap) -> np.ndarray:
    """uint8: ``(c a, a 255)`` as uint16 (exact), resampled, then one division by ``(a', a', a',
    65025)`` scaled by 255 gives colour and alpha back as rounded, saturated uint8 (0 where
    ``a' = 0``: OpenCV's integer division by zero)."""
    alpha = np.ascontiguousarray(frame[..., 3])
    work = cv2.multiply(frame, cv2.merge([alpha, alpha, alpha, np.full_like(alpha, 255)]), dtype=cv2.CV_16U)
    result = remap(work, [*(fill[:3] * fill[3]), fill[3] * 255])
    coverage = np.ascontiguousarray(result[..., 3])
    divisor = cv2.merge([coverage, coverage, coverage, np.full_like(coverage, 65025)])
    return cv2.divide(result, divisor, scale=255, dtype=cv2.CV_8U)


def _premultiplied_float(frame: np.ndarray, fill: np.ndarray, unit: float, remap) -> np.ndarray:
    """uint16 and float frames: premultiplied in float32, resampled, divided by the resampled alpha
    (colour 0 where it is 0), rounded and clipped back for uint16."""
    work = frame.astype(np.float32)
    alpha = work[..., 3] * np.float32(1 / unit)
    work = cv2.multiply(work, cv2.merge([alpha, alpha, alpha, np.ones_like(alpha)]))
    result = remap(work, [*(fill[:3] * fill[3] / unit), fill[3]])
    coverage = result[..., 3] * np.float32(1 / unit)
    inverse = np.divide(1.0, coverage, out=np.zeros_like(coverage), where=coverage > 0)
    result = cv2.multiply(result, cv2.merge([inverse, inverse, inverse, np.ones_like(inverse)]))
    if frame.dtype.kind == "u":
        np.rint(result, out=result)
        np.clip(result, 0, unit, out=result)
    return result.astype(frame.dtype, copy=False)
