"""Lens correction of planar YUV frames plane by plane: no conversion to RGB and back.

A frame of ``W x H`` pixels in planar YUV holds a luma plane (``W x H`` samples) and two chroma
planes, subsampled by ``2^shift_x`` across and ``2^shift_y`` down (4:2:0: 1, 1; 4:2:2: 1, 0;
4:4:4: 0, 0). Each plane is remapped with the maps of its own sampling lattice
(:class:`glradial.lens.lens.Plane`, :meth:`glradial.lens.lens.Lens.maps` with ``plane``), so every
sample shows the same point of the scene as in the RGB path, with no colour conversion and half
the samples of RGB at 4:2:0.

Chroma siting (where a chroma sample lies among the luma samples, in luma pixels with pixel
centres at integers): chroma sample ``(i, j)`` lies at ``(x0 + 2^shift_x i, (2^shift_y - 1) / 2 +
2^shift_y j)``; vertically midway between the luma rows it covers (4:2:0 in MPEG-2, H.264, HEVC and
JPEG alike), horizontally co-sited with the first luma column (``x0 = 0``, siting ``"left"``: the
default of MPEG-2, H.264, HEVC and of BT.601/709 4:2:2) or midway (``x0 = (2^shift_x - 1) / 2``,
``"center"``: JPEG/MJPEG). PyAV does not expose a stream's stated chroma location, so it is assumed
from the codec (:func:`chroma_siting`). Top-left siting (some BT.2020 4:2:0) is taken as left: its
chroma is then placed half a luma row off, below what a viewer sees.

Samples with no source (their source position lies outside the frame's area, in luma pixels, as
in :mod:`glradial.remapping.remap`) get ``fill``: black is :func:`black` (luma 16, chroma 128 at 8
bits in limited range; luma 0 in full range), what the RGB path's black turns into.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from ..lens.lens import Lens, Plane
from ..lens.options import CHROMA_SITINGS, DIRECTIONS, INTERPOLATIONS, INVERSES, check_choice
from .remap import CV_INTERPOLATION, checked_scale, cpu_maps

__all__ = ["yuv_planes", "chroma_siting", "black", "remap_planes", "CENTRED_CHROMA_CODECS"]

#: decoders whose 4:2:x chroma is sited midway between luma columns (JPEG's convention)
CENTRED_CHROMA_CODECS = frozenset({"mjpeg", "jpeg2000", "jpegls", "ljpeg"})


def chroma_siting(codec: str) -> str:
    """The horizontal chroma siting assumed for a stream decoded by ``codec`` (module docstring)."""
    return "center" if codec in CENTRED_CHROMA_CODECS else "left"


def yuv_planes(size: tuple[int, int], shift: tuple[int, int], siting: str = "left") -> list[Plane]:
    """The lattices of the luma and the two chroma planes of a ``size`` (W, H) frame whose chroma is
    subsampled by ``2^shift[0]`` across and ``2^shift[1]`` down, sited as ``siting``."""
    siting = check_choice("siting", siting, CHROMA_SITINGS)
    width, height = int(size[0]), int(size[1])
    step_x, step_y = 2 ** int(shift[0]), 2 ** int(shift[1])
    chroma = Plane(-(-width // step_x), -(-height // step_y), 0.0 if siting == "left" else (step_x - 1) / 2,
                   (step_y - 1) / 2, float(step_x), float(step_y))
    return [Plane.full((width, height)), chroma, chroma]


def black(bits: int, full_range: bool) -> tuple[int, int, int]:
    """Black as (Y, U, V) samples of ``bits`` per component, full range (JPEG) or limited (video)."""
    return (0 if full_range else 16 << (bits - 8), 1 << (bits - 1), 1 << (bits - 1))


def remap_planes(
    planes: Sequence[np.ndarray],
    lens: Lens,
    lattices: Sequence[Plane],
    out: Sequence[np.ndarray],
    *,
    fill: Sequence[float],
    direction: str = "undistort",
    fit: object = "same",
    interpolation: str = "linear",
    inverse: str = "exact",
) -> None:
    """Correct (``direction="undistort"``) or distort each of ``planes`` (2-D uint8 or uint16 arrays,
    e.g. views of a decoded frame's planes; the first is the full frame, :class:`Plane.full`) with
    ``lens`` into ``out`` (arrays of the same shapes and dtype, e.g. views of a new frame's planes),
    on the CPU (``cv2.remap``, maps cached per lens and lattice). ``fit``, ``interpolation``,
    ``inverse`` as in :func:`glradial.correct`, for the whole frame; ``fill`` one value per plane.
    Linear interpolation remaps from float32 maps (:func:`~glradial.remapping.remap.cpu_maps`
    ``float_maps``): bilinear at the exact float32 position, where the RGB path rounds positions
    to 1/32 px; the two differ by at most a level plus that rounding (docs/CORE.md)."""
    if len(planes) != len(lattices) or len(out) != len(planes) or len(fill) != len(planes):
        raise ValueError(f"give one lattice, output and fill per plane: {len(planes)} planes, {len(lattices)} "
                         f"lattices, {len(out)} outputs, {len(fill)} fills")
    size = (lattices[0].width, lattices[0].height)
    for index, (plane, lattice, target) in enumerate(zip(planes, lattices, out)):
        shape = (lattice.height, lattice.width)
        if plane.shape != shape or target.shape != shape or plane.dtype not in (np.uint8, np.uint16) or target.dtype != plane.dtype:
            raise ValueError(f"plane {index} must be a {shape[1]}×{shape[0]} uint8 or uint16 array, and its output alike; "
                             f"got {plane.shape} {plane.dtype} -> {target.shape} {target.dtype}")
    direction = check_choice("direction", direction, DIRECTIONS)
    interpolation = check_choice("interpolation", interpolation, INTERPOLATIONS)
    inverse = check_choice("inverse", inverse, INVERSES)
    scale = checked_scale(lens, size, direction, fit)
    for plane, lattice, target, value in zip(planes, lattices, out, fill):
        full = lattice == Plane.full(size)  # keyed as the RGB path's maps (shared with it unless linear: float maps)
        map1, map2, outside = cpu_maps(lens, size, direction, scale, inverse, interpolation == "nearest",
                                       None if full else lattice, float_maps=interpolation == "linear")
        result = cv2.remap(plane, map1, map2, CV_INTERPOLATION[interpolation], dst=target,
                           borderMode=cv2.BORDER_REPLICATE)
        if not np.may_share_memory(result, target):  # OpenCV wrote a new array instead
            target[...] = result
        if outside.size:
            if target.flags.c_contiguous:
                target.reshape(-1)[outside] = value
            else:  # a plane with padded rows
                target[np.unravel_index(outside, target.shape)] = value
