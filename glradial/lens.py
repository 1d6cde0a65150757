"""The two-coefficient radial lens as an immutable, validated value.

Convention (DESIGN.md): lens coordinates have image width = 1 and their origin at the image centre,
which is the principal point, i.e. pixel ``((W - 1) / 2, (H - 1) / 2)`` with pixel centres at integer
coordinates. A pixel ``(x, y)`` of a ``W x H`` frame is the lens point
``p = ((x + 0.5 - W / 2) / W, (y + 0.5 - H / 2) / W)``. Frame sizes are ``(W, H)`` as in OpenCV.

Forward model (undistorted -> distorted): ``p_d = p_u (1 + k1 r_u^2 + k2 r_u^4)``.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Literal

import numpy as np

from . import lensfuncs

InverseMethod = Literal["exact", "drap"]


def _coefficient(name: str, value: object) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, np.floating, np.integer)):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__} {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {number}")
    return number


def frame_size(size: object) -> tuple[int, int]:
    """Validate a frame size ``(W, H)`` of positive integers and return it as a tuple."""
    try:
        width, height = size  # type: ignore[misc]
    except (TypeError, ValueError):
        raise TypeError(f"size must be (width, height), got {size!r}") from None
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Integral, np.integer)):
            raise TypeError(f"size {name} must be an integer, got {value!r}")
        if value <= 0:
            raise ValueError(f"size {name} must be positive, got {value}")
    return int(width), int(height)


def corner_radius(size: tuple[int, int]) -> float:
    """Lens-unit radius of the frame corner: ``0.5 * sqrt(1 + (H / W)^2)`` (0.5737 for 16:9)."""
    width, height = frame_size(size)
    return 0.5 * math.hypot(1.0, height / width)


def pixels_to_lens(xy: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pixel coordinates (N, 2), centres at integers -> lens coordinates (N, 2)."""
    width, height = frame_size(size)
    xy = np.asarray(xy, dtype=np.float64)
    return np.stack([(xy[..., 0] + 0.5 - width / 2) / width, (xy[..., 1] + 0.5 - height / 2) / width], axis=-1)


def lens_to_pixels(p: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Lens coordinates (N, 2) -> pixel coordinates (N, 2); inverse of :func:`pixels_to_lens`."""
    width, height = frame_size(size)
    p = np.asarray(p, dtype=np.float64)
    return np.stack([p[..., 0] * width + width / 2 - 0.5, p[..., 1] * width + height / 2 - 0.5], axis=-1)


def _points(xy: object) -> np.ndarray:
    array = np.asarray(xy)
    if array.dtype.kind not in "iuf":
        raise TypeError(f"points must be a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"points must be an N×2 array, got shape {array.shape}")
    return array.astype(np.float64)


@dataclass(frozen=True)
class Lens:
    """Radial lens ``(k1, k2)`` in width-normalised lens units (the paper's k̃1, k̃2).

    The coefficients do not change when a frame is resized. ``Lens(0, 0)`` is a pinhole.
    """

    k1: float = 0.0
    k2: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "k1", _coefficient("k1", self.k1))
        object.__setattr__(self, "k2", _coefficient("k2", self.k2))

    # -- radial maps -------------------------------------------------------------------------
    def forward_radius(self, r_u: np.ndarray | float) -> np.ndarray:
        """Undistorted radius -> distorted radius, ``r (1 + k1 r^2 + k2 r^4)`` (lens units)."""
        r_u = np.asarray(r_u, dtype=np.float64)
        return r_u * lensfuncs.radial_factor(r_u * r_u, self.k1, self.k2)

    def inverse_radius(self, r_d: np.ndarray | float, method: InverseMethod = "exact") -> np.ndarray:
        """Distorted radius -> undistorted radius (lens units).

        ``method="exact"``: bounded Newton seeded by Drap-Lefevre, NaN where ``r_d`` lies beyond the
        largest radius the lens reaches. ``method="drap"``: the paper's four-term polynomial
        (round-trip error up to ~0.002 lens units at the extremes of its k1 range).
        """
        r_d = np.asarray(r_d, dtype=np.float64)
        if method == "exact":
            r_u, valid = lensfuncs.undistort_radius_exact(r_d, self.k1, self.k2)
            return np.where(valid, r_u, np.nan)
        if method == "drap":
            b1, b2, b3, b4 = self.inverse_coefficients()
            s = r_d * r_d
            return r_d * (1.0 + s * (b1 + s * (b2 + s * (b3 + s * b4))))
        raise ValueError(f"method must be 'exact' or 'drap', got {method!r}")

    def inverse_coefficients(self) -> tuple[float, float, float, float]:
        """Drap-Lefevre inverse coefficients ``(b1, b2, b3, b4)`` (k3 = k4 = 0)."""
        return lensfuncs.drap_coefficients(self.k1, self.k2)

    def slope(self, r_u: np.ndarray | float) -> np.ndarray:
        """``d r_d / d r_u = 1 + 3 k1 r^2 + 5 k2 r^4``; the lens folds over where it is <= 0."""
        return lensfuncs.radial_slope(r_u, self.k1, self.k2)

    # -- validity on a frame -------------------------------------------------------------------
    def fold_radius(self) -> float:
        """Smallest undistorted radius where the map folds over (``inf`` if it never does)."""
        radius = lensfuncs.fold_radius(self.k1, self.k2)
        return math.inf if radius >= lensfuncs.LENS_RADIUS_UNBOUNDED else radius

    def max_valid_radius(self) -> float:
        """Largest undistorted radius (lens units) on which the lens is one-to-one."""
        return self.fold_radius()

    def check_radius(self, radius: float, what: str = "the frame") -> None:
        """Raise ``ValueError`` if the lens folds over at an undistorted radius <= ``radius``."""
        fold = self.fold_radius()
        if fold <= radius:
            raise ValueError(
                f"lens k1={self.k1:g}, k2={self.k2:g} folds over at radius {fold:.4f} "
                f"(1 + 3 k1 r² + 5 k2 r⁴ <= 0) inside {what}, which uses radii up to {radius:.4f}"
            )

    def check_frame(self, size: tuple[int, int], scale: float = 1.0) -> None:
        """Raise ``ValueError`` if the lens folds over on any undistorted radius a ``(W, H)`` frame
        uses; ``scale`` multiplies the frame's corner radius (zoomed fits)."""
        width, height = frame_size(size)
        self.check_radius(corner_radius((width, height)) * scale, f"a {width}×{height} frame")

    # -- points ----------------------------------------------------------------------------
    def distort_points(self, xy: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Undistorted pixel coordinates (N, 2) -> distorted pixel coordinates (N, 2).

        Pixel centres at integer coordinates; principal point at the frame centre.
        """
        p_u = pixels_to_lens(_points(xy), size)
        return lens_to_pixels(lensfuncs.distort_point(p_u, self.k1, self.k2), size)

    def undistort_points(
        self, xy: np.ndarray, size: tuple[int, int], method: InverseMethod = "exact"
    ) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) -> undistorted pixel coordinates (N, 2).

        ``method`` as in :meth:`inverse_radius`; rows with no undistorted point are NaN.
        """
        p_d = pixels_to_lens(_points(xy), size)
        if method == "exact":
            p_u, valid = lensfuncs.undistort_point_exact(p_d, self.k1, self.k2)
            p_u = np.where(valid[:, None], p_u, np.nan)
        elif method == "drap":
            p_u = lensfuncs.undistort_point_drap(p_d, self.k1, self.k2)
        else:
            raise ValueError(f"method must be 'exact' or 'drap', got {method!r}")
        return lens_to_pixels(p_u, size)
