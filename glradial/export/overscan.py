"""Overscan: how much wider than the frame an engine renders undistorted graphics so that, once
distorted by the lens, they fill the whole frame (OpenLensIO v1.0, section 2.1 and appendix A.1).

Definition (OpenLensIO A.1): take every point ``ε_d`` of the distorted frame rectangle (its outer
pixel edges), undistort it (``ε_u``), and measure from the screen centre (projection-matrix
characterisation) or from the principal point (field-of-view characterisation); the overscanned
width ``w_Ω = 2 max(max |ε_u,x|, (w / h) max |ε_u,y|)`` and ``Ω = w_Ω / w``. The schema asks for the
larger of the two characterisations; a lens that needs none (pincushion) gets ``Ω = 1`` (the
schema's minimum). The lens map is one-to-one on the frame, so the extremes lie on the image of the
frame's boundary, which is what :func:`overscan_factor` samples (every half pixel).

The overscanned render: an undistorted image whose field is ``Ω`` times the frame's in both
directions, scaled about the screen centre (OpenLensIO eq. 7: ``ε_Ω = ε_u / Ω``). Its normalised
coordinates ``(u, v)`` (0..1 edge to edge, origin top-left, v down) do not depend on its
resolution; :func:`overscan_size` gives the pixel size that keeps the frame's pixel pitch.
"""

from __future__ import annotations

import math

import numpy as np

from ..lens.lens import Lens, frame_size, pixels_to_lens
from ..lens.options import real_number

__all__ = [
    "overscan_factor", "track_overscan", "overscan_size", "overscan_uv", "from_overscan_uv", "uv_maps",
    "distort_overscanned",
]

#: spacing (px) of the frame-boundary points :func:`overscan_factor` undistorts
BOUNDARY_STEP_PX = 0.5


def _factor(value: object) -> float:
    factor = real_number("overscan", value)
    if factor < 1.0:
        raise ValueError(f"overscan must be >= 1 (1 = none), got {factor:g}")
    return factor


def _boundary(width: int, height: int) -> np.ndarray:
    """Points (N, 2) every :data:`BOUNDARY_STEP_PX` along the outer pixel edges of the frame."""
    xs = np.linspace(-0.5, width - 0.5, int(math.ceil(width / BOUNDARY_STEP_PX)) + 1)
    ys = np.linspace(-0.5, height - 0.5, int(math.ceil(height / BOUNDARY_STEP_PX)) + 1)
    top, bottom = np.stack([xs, np.full_like(xs, -0.5)], 1), np.stack([xs, np.full_like(xs, height - 0.5)], 1)
    left, right = np.stack([np.full_like(ys, -0.5), ys], 1), np.stack([np.full_like(ys, width - 0.5), ys], 1)
    return np.concatenate([top, bottom, left, right])


def overscan_factor(lens: Lens, size: tuple[int, int]) -> float:
    """OpenLensIO's overscan ``Ω >= 1`` of ``lens`` on a ``(W, H)`` frame: the larger of the
    projection-matrix and field-of-view characterisations (module docstring). ``ValueError`` when
    part of the frame has no undistorted point (the lens never reaches it: no overscan suffices)."""
    width, height = frame_size(size)
    undistorted = lens.undistort_points(_boundary(width, height), (width, height))
    if not np.all(np.isfinite(undistorted)):
        raise ValueError(f"lens k1={lens.k1:g}, k2={lens.k2:g} never reaches the corners of a {width}×{height} frame: "
                         "no overscan makes undistorted graphics fill it")
    factors = [1.0]
    for origin in (((width - 1) / 2, (height - 1) / 2), lens.principal_point((width, height))):
        reach_x = np.max(np.abs(undistorted[:, 0] - origin[0]))
        reach_y = np.max(np.abs(undistorted[:, 1] - origin[1]))
        factors.append(2.0 * max(reach_x, reach_y * width / height) / width)
    return float(max(factors))


def track_overscan(lenses: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """:func:`overscan_factor` of each row ``(k1, k2)`` of ``lenses`` (N, 2) (centred lenses, e.g. a
    lens track's), computed once per distinct lens; its maximum is a track's static
    ``distortionOverscanMax``."""
    lenses = np.asarray(lenses, dtype=np.float64).reshape(-1, 2)
    distinct, inverse = np.unique(lenses, axis=0, return_inverse=True)
    factors = np.array([overscan_factor(Lens(float(k1), float(k2)), size) for k1, k2 in distinct])
    return factors[np.asarray(inverse).ravel()] if len(lenses) else np.zeros(0)


def overscan_size(size: tuple[int, int], overscan: float) -> tuple[int, int]:
    """Pixel size of an overscanned render that keeps the frame's pixel pitch: the smallest
    ``(W', H') >= (Ω W, Ω H)`` with ``W' - W`` and ``H' - H`` even (equal margins on both sides)."""
    width, height = frame_size(size)
    factor = _factor(overscan)
    return (width + 2 * math.ceil((factor * width - width) / 2 - 1e-9),
            height + 2 * math.ceil((factor * height - height) / 2 - 1e-9))


def overscan_uv(xy: np.ndarray, size: tuple[int, int], overscan: float) -> np.ndarray:
    """Undistorted pixel positions (..., 2) of a ``(W, H)`` frame (centres at integers) -> normalised
    coordinates ``(u, v)`` of the overscanned render: ``u = 0.5 + (x + 0.5 - W / 2) / (Ω W)``."""
    width, height = frame_size(size)
    factor = _factor(overscan)
    xy = np.asarray(xy, dtype=np.float64)
    return np.stack([0.5 + (xy[..., 0] + 0.5 - width / 2) / (factor * width),
                     0.5 + (xy[..., 1] + 0.5 - height / 2) / (factor * height)], axis=-1)


def from_overscan_uv(uv: np.ndarray, size: tuple[int, int], overscan: float) -> np.ndarray:
    """Inverse of :func:`overscan_uv`."""
    width, height = frame_size(size)
    factor = _factor(overscan)
    uv = np.asarray(uv, dtype=np.float64)
    return np.stack([(uv[..., 0] - 0.5) * factor * width + width / 2 - 0.5,
                     (uv[..., 1] - 0.5) * factor * height + height / 2 - 0.5], axis=-1)


def _pixel_uv(width: int, height: int) -> np.ndarray:
    """Normalised coordinates of the pixel centres of a ``W x H`` grid (H, W, 2)."""
    return np.stack(np.meshgrid((np.arange(width) + 0.5) / width, (np.arange(height) + 0.5) / height), axis=-1)


def uv_maps(lens: Lens, size: tuple[int, int], direction: str, overscan: float = 1.0) -> np.ndarray:
    """Where each output pixel of a ``(W, H)`` grid samples its source, as normalised source
    coordinates (H, W, 2) (0..1 edge to edge, origin top-left, v down; NaN: no source).

    ``"distort"``: the output is the distorted frame, the source the overscanned undistorted render
    (``overscan = 1``: the undistorted frame itself). ``"undistort"``: the output is the
    overscanned undistorted render (OpenLensIO eq. 8), the source the distorted frame. ``ValueError``
    if the lens folds over on the radii the map uses."""
    width, height = frame_size(size)
    factor = _factor(overscan)
    grid = _pixel_uv(width, height).reshape(-1, 2)
    if direction == "distort":
        pixels = grid * [width, height] - 0.5
        return overscan_uv(lens.undistort_points(pixels, (width, height)), (width, height), factor).reshape(height, width, 2)
    if direction != "undistort":
        raise ValueError(f"direction must be 'undistort' or 'distort', got {direction!r}")
    undistorted = from_overscan_uv(grid, (width, height), factor)
    corners = from_overscan_uv(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]), (width, height), factor)
    radius = np.max(np.hypot(*pixels_to_lens(corners, (width, height), lens.centre, lens.pixel_aspect).T))
    lens.check_radius(float(radius), f"the {factor:g}× overscanned {width}×{height} frame")
    distorted = lens.distort_points(undistorted, (width, height))
    return ((distorted + 0.5) / [width, height]).reshape(height, width, 2)


def distort_overscanned(
    render: np.ndarray, lens: Lens, size: tuple[int, int], overscan: float, *, interpolation: str = "linear",
    border_value: float = 0.0,
) -> np.ndarray:
    """Distort an overscanned undistorted ``render`` (any resolution; its field ``overscan`` times
    the frame's, e.g. :func:`overscan_size`) into the ``(W, H)`` distorted frame with ``cv2.remap``
    (``"nearest"``, ``"linear"`` or ``"cubic"``); pixels whose source lies outside the render get
    ``border_value``. With ``overscan >=`` :func:`overscan_factor` there are none."""
    import cv2

    flags = {"nearest": cv2.INTER_NEAREST, "linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC}
    if interpolation not in flags:
        raise ValueError(f"interpolation must be 'nearest', 'linear' or 'cubic', got {interpolation!r}")
    render = np.asarray(render)
    if render.ndim not in (2, 3) or render.shape[0] < 1 or render.shape[1] < 1:
        raise ValueError(f"render must be an H×W or H×W×C image, got shape {render.shape}")
    source_h, source_w = render.shape[:2]
    uv = uv_maps(lens, size, "distort", overscan)
    uv = np.where(np.isfinite(uv), uv, -1.0e4)
    map_x = (uv[..., 0] * source_w - 0.5).astype(np.float32)
    map_y = (uv[..., 1] * source_h - 0.5).astype(np.float32)
    return cv2.remap(render, map_x, map_y, flags[interpolation], borderMode=cv2.BORDER_CONSTANT, borderValue=border_value)
