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

from typing import Callable, Literal, Sequence

import numpy as np

__all__ = ["Alpha", "ALPHA_CONVENTIONS", "check_alpha", "remap_with_alpha"]

Alpha = Literal["straight", "premultiplied"]
ALPHA_CONVENTIONS = ("straight", "premultiplied")


def check_alpha(alpha: object) -> str:
    """``alpha`` if it is one of :data:`ALPHA_CONVENTIONS`, else a ``ValueError`` naming it."""
    if not isinstance(alpha, str) or alpha not in ALPHA_CONVENTIONS:
        raise ValueError(f"alpha must be one of {', '.join(map(repr, ALPHA_CONVENTIONS))}, got {alpha!r}")
    return alpha


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
    after; anything else is passed through. ``fill`` is in the frame's convention and units."""
    if not _needs_premultiply(frame, check_alpha(alpha)):
        return remap(frame, fill)
    unit = 1.0 if frame.dtype.kind == "f" else float(np.iinfo(frame.dtype).max)
    work = frame.astype(np.float32)
    work[..., :3] *= work[..., 3:4] / np.float32(unit)
    fill_values = np.broadcast_to(np.asarray(fill, dtype=np.float64).ravel(), (4,)) if np.size(fill) in (1, 4) else None
    if fill_values is None:
        return remap(frame, fill)  # the remap's own error for a fill of the wrong length
    if unit != 1.0 and not all(0 <= v <= unit for v in fill_values):
        raise ValueError(f"fill {fill!r} is outside the range of {frame.dtype} (0..{unit:g})")
    premultiplied_fill = [*(fill_values[:3] * fill_values[3] / unit), fill_values[3]]
    result = remap(work, premultiplied_fill)
    coverage = result[..., 3:4] / np.float32(unit)
    with np.errstate(divide="ignore", invalid="ignore"):
        result[..., :3] = np.where(coverage > 0, result[..., :3] / coverage, 0.0)
    if frame.dtype.kind == "u":
        return np.clip(np.rint(result), 0, unit).astype(frame.dtype)
    return result.astype(frame.dtype, copy=False)
