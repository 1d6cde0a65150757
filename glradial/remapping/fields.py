"""Interlaced frames: each field corrected (or distorted) on its own geometry.

An interlaced frame holds two fields taken at different instants: the top field on rows 0, 2, 4 ...
and the bottom field on rows 1, 3, 5 ... Remapping the woven frame mixes the two instants wherever
the map moves a pixel vertically by a fraction of a line. Instead each field is remapped as a picture
of its own, half as tall, whose row ``i`` lies on frame row ``2 i + parity``:

* its pixels are twice as tall as wide: the lens's pixel aspect ``fy / fx`` is halved;
* its principal point sits where the frame's does, in field rows: the offset below the field's
  centre, in image widths, is ``(cy_px - parity) / 2 - (H_field - 1) / 2`` over ``W``, with
  ``cy_px = (H - 1) / 2 + cy W`` the frame's principal point row. For an even frame height
  this is ``cy / 2 + (1 - 2 parity) / (4 W)``: a quarter line down for the top field, up for the bottom.
* both fields use the frame's scale (the fit of the whole frame), so they stay registered.

Field *order* (which field comes first in time: TFF, BFF) does not change this geometry; it is kept
for the encoder (:mod:`glradial.media.video_io`).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..lens.lens import Lens
from ..lens.options import FIELD_ORDERS

__all__ = ["FIELD_ORDERS", "field_lens", "remap_fields"]


def field_lens(lens: Lens, size: tuple[int, int], parity: int) -> Lens:
    """The lens of field ``parity`` (0: rows 0, 2, ...; 1: rows 1, 3, ...) of a ``(W, H)`` frame,
    in the field's own pixel grid (module docstring)."""
    if parity not in (0, 1):
        raise ValueError(f"parity must be 0 (top field) or 1 (bottom field), got {parity!r}")
    width, height = size
    if height < 2:
        raise ValueError(f"an interlaced frame needs at least 2 rows, got a {width}×{height} frame")
    field_rows = (height - parity + 1) // 2
    principal_row = (height - 1) / 2 + lens.cy * width
    cy = ((principal_row - parity) / 2 - (field_rows - 1) / 2) / width
    return Lens(lens.k1, lens.k2, lens.cx, cy, lens.pixel_aspect / 2)


def remap_fields(frame: np.ndarray, lens: Lens, scale: float, remap: Callable[[np.ndarray, Lens, float], np.ndarray]) -> np.ndarray:
    """``frame`` (``H x W (x C)``) with each field remapped by ``remap(field, field_lens, scale)``
    (``scale``: the whole frame's fit scale, :func:`glradial.fit_scale`) and woven back."""
    height, width = frame.shape[:2]
    out = np.empty_like(frame)
    for parity in (0, 1):
        field = np.ascontiguousarray(frame[parity::2])
        out[parity::2] = remap(field, field_lens(lens, (width, height), parity), scale)
    return out
