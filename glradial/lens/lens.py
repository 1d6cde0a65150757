"""The two-coefficient radial lens as an immutable, validated value.

Convention (docs/DESIGN.md): lens coordinates have image width = 1 and their origin at the principal
point, by default the image centre, i.e. pixel ``((W - 1) / 2, (H - 1) / 2)`` with pixel centres at
integer coordinates. A pixel ``(x, y)`` of a ``W x H`` frame is the lens point
``p = ((x + 0.5 - W / 2) / W, (y + 0.5 - H / 2) / W)``. Frame sizes are ``(W, H)`` as in OpenCV.

A lens may carry a principal point off the centre and non-square pixels (an OpenCV calibration's
``cx, cy, fx != fy``): ``cx, cy`` are the principal point's offset from the image centre in width
units (x right, y down; pixel ``((W - 1) / 2 + cx W, (H - 1) / 2 + cy W)``), ``pixel_aspect = fy / fx``,
and the lens point of pixel ``(x, y)`` becomes
``p = ((x + 0.5 - W / 2) / W - cx, ((y + 0.5 - H / 2) / W - cy) / pixel_aspect)``: radii are still
normalised by the image width along x (``(x - cx_px) / W``), so ``k1 = k1_cv (W / fx)²``.

Forward model (undistorted -> distorted): ``p_d = p_u (1 + k1 r_u^2 + k2 r_u^4)``.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ..errors import check_count
from . import lensfuncs
from .options import (  # noqa: F401  (re-exported: the lens's option types)
    DIRECTIONS,
    FITS,
    INVERSES,
    Direction,
    Fit,
    InverseMethod,
    check_choice,
    check_positive,
    real_number,
)


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


def hfov_deg(focal: float | np.ndarray) -> float | np.ndarray:
    """Horizontal field of view (degrees) of a pinhole of ``focal`` image widths (lens units); element-wise
    for an array."""
    hfov = np.degrees(2.0 * np.arctan(0.5 / np.asarray(focal, dtype=np.float64)))
    return float(hfov) if hfov.ndim == 0 else hfov


def focal_from_hfov(hfov: float) -> float:
    """Focal length in image widths (lens units) of a horizontal field of view ``hfov`` (degrees, 0..180):
    ``0.5 / tan(hfov / 2)``."""
    if isinstance(hfov, bool) or not (isinstance(hfov, (int, float, np.number)) and 0.0 < float(hfov) < 180.0):
        raise ValueError(f"hfov must be in (0, 180) degrees, got {hfov!r}")
    return 0.5 / math.tan(math.radians(float(hfov)) / 2.0)


def pixels_to_lens(
    xy: np.ndarray, size: tuple[int, int], centre: tuple[float, float] = (0.0, 0.0), pixel_aspect: float = 1.0
) -> np.ndarray:
    """Pixel coordinates (N, 2), centres at integers -> lens coordinates (N, 2) about the principal
    point ``centre`` (offset from the image centre, width units) with ``pixel_aspect = fy / fx``;
    the defaults are the centred model."""
    width, height = frame_size(size)
    xy = np.asarray(xy, dtype=np.float64)
    return np.stack(
        [
            (xy[..., 0] + 0.5 - width / 2) / width - centre[0],
            ((xy[..., 1] + 0.5 - height / 2) / width - centre[1]) / pixel_aspect,
        ],
        axis=-1,
    )


def lens_to_pixels(
    p: np.ndarray, size: tuple[int, int], centre: tuple[float, float] = (0.0, 0.0), pixel_aspect: float = 1.0
) -> np.ndarray:
    """Lens coordinates (N, 2) -> pixel coordinates (N, 2); inverse of :func:`pixels_to_lens`."""
    width, height = frame_size(size)
    p = np.asarray(p, dtype=np.float64)
    return np.stack(
        [
            (p[..., 0] + centre[0]) * width + width / 2 - 0.5,
            (p[..., 1] * pixel_aspect + centre[1]) * width + height / 2 - 0.5,
        ],
        axis=-1,
    )


@dataclass(frozen=True)
class Plane:
    """A sampling lattice of a ``W x H`` frame: sample ``(i, j)`` of the plane (``width x height``
    samples) lies at the frame's pixel position ``(x0 + step_x i, y0 + step_y j)`` (pixel centres at
    integers). :meth:`full` is the frame itself; a chroma plane of subsampled YUV is coarser and
    offset by its siting (:func:`glradial.remapping.planes.yuv_planes`)."""

    width: int
    height: int
    x0: float = 0.0
    y0: float = 0.0
    step_x: float = 1.0
    step_y: float = 1.0

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            check_count(f"plane {name}", value, unit="samples")
        for name in ("x0", "y0"):
            real_number(name, getattr(self, name))
        for name in ("step_x", "step_y"):
            check_positive(name, getattr(self, name))

    @classmethod
    def full(cls, size: tuple[int, int]) -> "Plane":
        return cls(int(size[0]), int(size[1]))


def _points(xy: object) -> np.ndarray:
    array = np.asarray(xy)
    if array.dtype.kind not in "iuf":
        raise TypeError(f"points must be a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"points must be an N×2 array, got shape {array.shape}")
    return array.astype(np.float64)


@dataclass(frozen=True)
class Lens:
    """Radial lens ``(k1, k2)`` in width-normalised lens units (the paper's k̃1, k̃2), with an
    optional principal point and pixel aspect.

    ``cx``, ``cy``: the principal point's offset from the image centre in width units (x right,
    y down; 0, 0 = the centre, the paper's model and the estimator's); ``pixel_aspect = fy / fx``
    (1 = square pixels). See the module docstring for the lens coordinates they define. None of the
    five numbers changes when a frame is resized. ``Lens(0, 0)`` is a pinhole.

    Args:
        k1: second-order radial coefficient (width-normalised; negative: barrel).
        k2: fourth-order radial coefficient (width-normalised).
        cx: principal point's horizontal offset from the image centre, in image widths (x right).
        cy: principal point's vertical offset from the image centre, in image widths (y down).
        pixel_aspect: ``fy / fx`` (1 = square pixels), > 0.

    Raises:
        ValueError: a coefficient that is not a finite real number, or ``pixel_aspect <= 0``.

    Example:
        >>> import glradial
        >>> lens = glradial.Lens(-0.2, 0.05)
        >>> float(lens.forward_radius(0.5))  # 0.5 (1 - 0.2 * 0.25 + 0.05 * 0.0625)
        0.4765625
        >>> round(float(lens.inverse_radius(lens.forward_radius(0.5))), 9)
        0.5
        >>> round(lens.frame_radius((1920, 1080)), 4)  # the 16:9 corner, lens units
        0.5737
    """

    k1: float = 0.0
    k2: float = 0.0
    cx: float = 0.0
    cy: float = 0.0
    pixel_aspect: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "k1", real_number("k1", self.k1))
        object.__setattr__(self, "k2", real_number("k2", self.k2))
        object.__setattr__(self, "cx", real_number("cx", self.cx))
        object.__setattr__(self, "cy", real_number("cy", self.cy))
        object.__setattr__(self, "pixel_aspect", check_positive("pixel_aspect", self.pixel_aspect))

    @property
    def centre(self) -> tuple[float, float]:
        """The principal point ``(cx, cy)``: offset from the image centre in width units."""
        return (self.cx, self.cy)

    @property
    def is_centred(self) -> bool:
        """True for the paper's model: principal point at the image centre and square pixels."""
        return self.cx == 0.0 and self.cy == 0.0 and self.pixel_aspect == 1.0

    def principal_point(self, size: tuple[int, int]) -> tuple[float, float]:
        """The principal point in pixels of a ``(W, H)`` frame (centres at integers):
        ``((W - 1) / 2 + cx W, (H - 1) / 2 + cy W)``."""
        width, height = frame_size(size)
        return ((width - 1) / 2 + self.cx * width, (height - 1) / 2 + self.cy * width)

    # -- radial maps -------------------------------------------------------------------------
    def forward_radius(self, r_u: np.ndarray | float) -> np.ndarray:
        """Undistorted radius -> distorted radius, ``r (1 + k1 r^2 + k2 r^4)`` (lens units)."""
        r_u = np.asarray(r_u, dtype=np.float64)
        return r_u * lensfuncs.radial_factor(r_u * r_u, self.k1, self.k2)

    def inverse_radius(self, r_d: np.ndarray | float, method: InverseMethod = "exact") -> np.ndarray:
        """Distorted radius -> undistorted radius (lens units).

        ``method="exact"``: bounded Newton seeded by Drap-Lefevre, NaN where ``r_d`` lies beyond the
        largest radius the lens reaches. ``method="drap"``: the paper's four-term polynomial
        (up to 0.0015 image widths off inside the frame width at k1 = -0.7, 0.022 at the 16:9 corner:
        docs/CROPS.md; the paper's "about 0.002" holds only inside the frame width).
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

    def check_radius(self, radius: float, what: str = "the frame") -> None:
        """Raise ``ValueError`` if the lens folds over at an undistorted radius <= ``radius``."""
        fold = self.fold_radius()
        if fold <= radius:
            raise ValueError(
                f"lens k1={self.k1:g}, k2={self.k2:g} folds over at radius {fold:.4f} "
                f"(1 + 3 k1 r² + 5 k2 r⁴ <= 0) inside {what}, which uses radii up to {radius:.4f}"
            )

    def frame_radius(self, size: tuple[int, int]) -> float:
        """Lens-unit radius of the frame corner farthest from the principal point (closed form,
        exact): ``hypot(0.5 + |cx|, (H / 2W + |cy|) / pixel_aspect)``; :func:`corner_radius` for a
        centred lens. Frame corners are the outer pixel edges, as in :func:`corner_radius`."""
        width, height = frame_size(size)
        return math.hypot(0.5 + abs(self.cx), (0.5 * height / width + abs(self.cy)) / self.pixel_aspect)

    def edge_radius(self, size: tuple[int, int]) -> float:
        """Lens-unit distance from the principal point to the nearest frame edge (outer pixel edges):
        ``min(0.5 - |cx|, (H / 2W - |cy|) / pixel_aspect)``; ``ValueError`` when the principal
        point lies outside the frame (then no ray from it meets every edge and the fits' closed
        form does not apply)."""
        width, height = frame_size(size)
        half_height = 0.5 * height / width
        if abs(self.cx) > 0.5 or abs(self.cy) > half_height:
            px, py = self.principal_point((width, height))
            raise ValueError(
                f"the principal point (cx={self.cx:g}, cy={self.cy:g}; pixel ({px:g}, {py:g})) lies outside "
                f"the {width}×{height} frame: fit 'crop'/'full' needs it inside; use fit='same' or a number"
            )
        return min(0.5 - abs(self.cx), (half_height - abs(self.cy)) / self.pixel_aspect)

    def check_frame(self, size: tuple[int, int], scale: float = 1.0) -> None:
        """Raise ``ValueError`` if the lens folds over on any undistorted radius a ``(W, H)`` frame
        uses; ``scale`` multiplies the frame's radius (:meth:`frame_radius`, the corner farthest from
        the principal point; zoomed fits)."""
        width, height = frame_size(size)
        self.check_radius(self.frame_radius((width, height)) * scale, f"a {width}×{height} frame")

    # -- points ----------------------------------------------------------------------------
    def distort_points(self, xy: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Undistorted pixel coordinates (N, 2) -> distorted pixel coordinates (N, 2).

        Pixel centres at integer coordinates; principal point :meth:`principal_point`.
        """
        p_u = pixels_to_lens(_points(xy), size, self.centre, self.pixel_aspect)
        return lens_to_pixels(lensfuncs.distort_point(p_u, self.k1, self.k2), size, self.centre, self.pixel_aspect)

    def undistort_points(
        self, xy: np.ndarray, size: tuple[int, int], method: InverseMethod = "exact"
    ) -> np.ndarray:
        """Distorted pixel coordinates (N, 2) -> undistorted pixel coordinates (N, 2).

        ``method`` as in :meth:`inverse_radius`; rows with no undistorted point are NaN.
        """
        p_d = pixels_to_lens(_points(xy), size, self.centre, self.pixel_aspect)
        if method == "exact":
            p_u, valid = lensfuncs.undistort_point_exact(p_d, self.k1, self.k2)
            p_u = np.where(valid[:, None], p_u, np.nan)
        elif method == "drap":
            p_u = lensfuncs.undistort_point_drap(p_d, self.k1, self.k2)
        else:
            raise ValueError(f"method must be 'exact' or 'drap', got {method!r}")
        return lens_to_pixels(p_u, size, self.centre, self.pixel_aspect)

    # -- fits -----------------------------------------------------------------------------------
    def fit_scale(self, size: tuple[int, int], fit: Fit = "same", direction: Direction = "undistort") -> float:
        """Scale ``s`` between output lens coordinates and undistorted lens coordinates.

        Convention: ``undistort`` (correction): an output point ``q`` shows the undistorted point
        ``p_u = s q``, sampled from the input at ``p_d = P(p_u)``. ``distort``: an output point ``q``
        is the distorted point ``p_d = q``, sampled from the undistorted input at ``P⁻¹(q) / s``.
        So a distortion with scale ``s`` is the exact inverse of a correction with the same ``s``.

        ``fit``: ``"same"`` -> ``s = 1`` (the centre keeps its scale; equal to ``cv2.undistort``
        with ``newCameraMatrix = K``); ``"crop"`` -> the largest view in which every output pixel
        has a source; ``"full"`` -> the smallest view that keeps the whole input visible; a positive
        number is taken as ``s`` itself. ``s > 1`` zooms out, ``s < 1`` zooms in. Because a
        distortion's "crop" is a correction's "full" and vice versa, undo ``distort(x, fit="crop")``
        with ``correct(..., fit="full")`` (or pass the same number to both).

        Closed form: the frames are equal rectangles and a radial map keeps directions, so along a
        ray from the principal point whose frame boundary lies at radius ``ρ`` the condition is
        ``s ≤ G(ρ)`` (or ``≥``) with ``G(ρ) = P⁻¹(ρ) / ρ = 1 / D(P⁻¹(ρ))``, ``D(t) = 1 + k1 t + k2 t²``
        at ``t = r_u²``. The boundary radius is continuous in the ray's angle, so ``ρ`` runs over
        ``[edge_radius, frame_radius]`` (nearest edge to farthest corner from the principal point;
        ``[min(W, H) / 2W, corner radius]`` for a centred lens), and the extremes of ``D`` on that
        interval of ``t`` (its ends, or the vertex ``t = -k1 / 2k2`` when inside) give ``min G`` and
        ``max G``: exact, no search, also off centre and with non-square pixels (lens coordinates
        keep the frame a rectangle). undistort: crop = ``min G``, full = ``max G``; distort: crop =
        ``max G``, full = ``min G``. Raises ``ValueError`` where the lens never reaches the farthest
        corner (no exact inverse there) and the fit needs it, when the principal point lies outside
        the frame (crop/full), or for an unknown ``fit``/``direction``.
        """
        width, height = frame_size(size)
        direction = check_choice("direction", direction, DIRECTIONS)
        if isinstance(fit, (numbers.Real, np.floating, np.integer)) and not isinstance(fit, (bool, np.bool_)):
            return check_positive("fit scale", fit)
        fit = check_choice("fit", fit, FITS)
        if fit == "same":
            return 1.0
        rho = np.array([self.edge_radius((width, height)), self.frame_radius((width, height))])
        try:
            r_u = self.inverse_radius(rho, method="exact")
        except OverflowError:
            raise ValueError(f"fit={fit!r} is undefined for lens k1={self.k1:g}, k2={self.k2:g}: its inverse overflows") from None
        if not np.all(np.isfinite(r_u)):
            raise ValueError(
                f"fit={fit!r} is undefined for lens k1={self.k1:g}, k2={self.k2:g} on a {width}×{height} "
                f"frame: the lens never reaches radius {rho[1]:.4f} (the frame corner); use fit='same'"
            )
        t = [float(r_u[0]) ** 2, float(r_u[1]) ** 2]
        if self.k2 != 0.0:
            vertex = -self.k1 / (2.0 * self.k2)
            if t[0] < vertex < t[1]:
                t.append(vertex)
        factors = [1.0 + self.k1 * v + self.k2 * v * v for v in t]
        g_min, g_max = 1.0 / max(factors), 1.0 / min(factors)
        if direction == "undistort":
            return g_min if fit == "crop" else g_max
        return g_max if fit == "crop" else g_min

    # -- remap maps ----------------------------------------------------------------------------
    def maps(
        self,
        size: tuple[int, int],
        direction: Direction = "undistort",
        fit: Fit = "same",
        inverse: InverseMethod = "exact",
        dtype: type = np.float32,
        scale: float | None = None,
        plane: "Plane | None" = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(map_x, map_y)`` of shape ``(H, W)`` for ``cv2.remap`` (pixel centres at integers).

        ``dst[y, x] = src[map_y[y, x], map_x[y, x]]`` performs the correction (``"undistort"``) or
        the distortion (``"distort"``) of a ``(W, H)`` frame with the :meth:`fit_scale` convention;
        ``scale`` overrides ``fit``. Output pixels with no source (no inverse, distort only) get
        :data:`NO_SOURCE`, far outside any frame, so ``cv2.remap(..., borderMode=BORDER_CONSTANT)``
        fills them with the border value. ``inverse`` (distort only): ``"exact"`` or ``"drap"``.
        Raises ``ValueError`` if the lens folds over on the frame (:meth:`check_frame`).

        ``plane`` (a :class:`Plane`, e.g. the chroma plane of a 4:2:0 frame): the maps of that plane
        instead, shape ``(plane.height, plane.width)``: its sample ``(i, j)`` lies at the frame's pixel
        position ``(x0 + step_x i, y0 + step_y j)`` and the maps are in the plane's own pixel
        coordinates (``i = (x - x0) / step_x``), so the plane is remapped on its own.
        """
        width, height = frame_size(size)
        plane = plane or Plane.full((width, height))
        direction = check_choice("direction", direction, DIRECTIONS)
        inverse = check_choice("inverse", inverse, INVERSES)
        if np.dtype(dtype) not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise TypeError(f"maps dtype must be float32 or float64, got {np.dtype(dtype)}")
        s = self.fit_scale((width, height), fit, direction) if scale is None else check_positive("scale", scale)
        self.check_frame((width, height), s)
        if direction == "undistort" and np.dtype(dtype) == np.dtype(np.float32):
            return self._undistort_maps_opencv((width, height), s, plane)
        xs = (plane.x0 + plane.step_x * np.arange(plane.width, dtype=np.float64) + 0.5 - width / 2) / width - self.cx
        ys = ((plane.y0 + plane.step_y * np.arange(plane.height, dtype=np.float64) + 0.5 - height / 2) / width
              - self.cy) / self.pixel_aspect
        q = np.stack(np.meshgrid(xs, ys), axis=-1)
        valid = None
        if direction == "undistort":
            source = lensfuncs.distort_point(q * s, self.k1, self.k2)
        elif inverse == "exact":
            p_u, valid = lensfuncs.undistort_point_exact(q, self.k1, self.k2)
            source = p_u / s
        else:
            source = lensfuncs.undistort_point_drap(q, self.k1, self.k2) / s
        map_x = ((source[..., 0] + self.cx) * width + width / 2 - 0.5 - plane.x0) / plane.step_x
        map_y = ((source[..., 1] * self.pixel_aspect + self.cy) * width + height / 2 - 0.5 - plane.y0) / plane.step_y
        if valid is not None:
            map_x = np.where(valid, map_x, NO_SOURCE)
            map_y = np.where(valid, map_y, NO_SOURCE)
        return map_x.astype(dtype), map_y.astype(dtype)

    def _undistort_maps_opencv(self, size: tuple[int, int], s: float, plane: "Plane") -> tuple[np.ndarray, np.ndarray]:
        """float32 correction maps from ``cv2.initUndistortRectifyMap`` (~5 ms at 1080p against
        ~70 ms for the float64 NumPy path, which stays the reference and agrees within float32
        rounding): with ``K, dist = to_opencv(size)`` (``K = [[W, 0, cx], [0, W a, cy], [0, 0, 1]]``,
        principal point ``cx, cy`` in pixels, ``a`` the pixel aspect, ``dist = (k1, k2, 0, 0, 0)``)
        and the new camera matrix ``K`` with focal lengths divided by ``s``, OpenCV maps an output pixel to ``p_u = s q`` and samples
        ``P(p_u)``, exactly the convention above. A ``plane`` is a frame of its own whose camera
        matrix has the focal lengths divided by the steps and the principal point moved by the origin."""
        import cv2

        camera, distortion = self.to_opencv(size)
        camera[0] = (camera[0] - [0.0, 0.0, plane.x0]) / plane.step_x
        camera[1] = (camera[1] - [0.0, 0.0, plane.y0]) / plane.step_y
        output = camera.copy()
        output[0, 0] /= s
        output[1, 1] /= s
        return cv2.initUndistortRectifyMap(camera, distortion, None, output, (plane.width, plane.height), cv2.CV_32FC1)

    # -- converters ----------------------------------------------------------------------------
    def rescale(self, s: float) -> "Lens":
        """The same lens for lens coordinates ``r' = s r``: ``k1' = k1 / s²``, ``k2' = k2 / s⁴``,
        principal point offset ``(s cx, s cy)``, pixel aspect unchanged (exact for any lens).

        Example: a centred crop of width ``W'`` out of a ``W``-wide frame has ``s = W / W'``.
        """
        s = check_positive("s", s)
        s2 = s * s
        if (s2 == 0.0 and self.k1) or (s2 * s2 == 0.0 and self.k2):
            raise ValueError(f"s={s:g} rescales lens k1={self.k1:g}, k2={self.k2:g} beyond the float range")
        k1, k2 = (self.k1 / s2 if self.k1 else 0.0), (self.k2 / s2 / s2 if self.k2 else 0.0)
        if not (math.isfinite(k1) and math.isfinite(k2)):
            raise ValueError(f"s={s:g} rescales lens k1={self.k1:g}, k2={self.k2:g} beyond the float range")
        return Lens(k1, k2, self.cx * s, self.cy * s, self.pixel_aspect)

    def _require_centred(self, convention: str) -> None:
        """``ValueError`` unless the lens is centred with square pixels: ``convention``'s pair of
        coefficients cannot carry a principal point or a pixel aspect."""
        if not self.is_centred:
            raise ValueError(
                f"{convention} coefficients describe a lens centred on the frame with square pixels; this lens "
                f"has its principal point at cx={self.cx:g}, cy={self.cy:g} (width units from the centre) and "
                f"pixel_aspect={self.pixel_aspect:g}, which two numbers cannot carry: use to_opencv (exact for "
                f"any principal point and pixel aspect)"
            )

    def _normalised(self, radius: float) -> tuple[float, float]:
        """``(k1, k2)`` for radii divided by ``radius`` lens units (no check of the centre)."""
        radius = check_positive("radius", radius)
        return self.k1 * radius**2, self.k2 * radius**4

    def to_normalised(self, radius: float) -> tuple[float, float]:
        """Coefficients for coordinates normalised by ``radius`` lens units (r' = r / radius) of a
        centred lens; ``ValueError`` for a lens with a principal point or pixel aspect (use
        :meth:`rescale`, which keeps them)."""
        self._require_centred("normalised")
        return self._normalised(radius)

    @classmethod
    def from_normalised(cls, k1: float, k2: float, radius: float) -> "Lens":
        """Inverse of :meth:`to_normalised` (a centred lens)."""
        return cls(k1, k2).rescale(check_positive("radius", radius))

    def to_pixel(self, size: tuple[int, int]) -> tuple[float, float]:
        """Pixel-unit ("apparent") coefficients: ``k̂1 = k1 / W²``, ``k̂2 = k2 / W⁴``
        (``r_d = r_u (1 + k̂1 r_u² + k̂2 r_u⁴)`` with radii in pixels from the frame centre).
        ``ValueError`` for an off-centre lens or non-square pixels."""
        width, _ = frame_size(size)
        self._require_centred("pixel-unit")
        return self._normalised(1.0 / width)

    @classmethod
    def from_pixel(cls, k1: float, k2: float, size: tuple[int, int]) -> "Lens":
        """Inverse of :meth:`to_pixel`."""
        width, _ = frame_size(size)
        return cls.from_normalised(k1, k2, 1.0 / width)

    def to_height_normalised(self, size: tuple[int, int]) -> tuple[float, float]:
        """Coefficients for radii divided by the frame height (``r' = r W / H``), the convention of
        the paper authors' released code: ``k1' = k1 (H/W)²``, ``k2' = k2 (H/W)⁴``. ``ValueError``
        for an off-centre lens or non-square pixels."""
        width, height = frame_size(size)
        self._require_centred("height-normalised")
        return self._normalised(height / width)

    @classmethod
    def from_height_normalised(cls, k1: float, k2: float, size: tuple[int, int]) -> "Lens":
        """Inverse of :meth:`to_height_normalised`."""
        width, height = frame_size(size)
        return cls.from_normalised(k1, k2, height / width)

    def to_lensfun_poly5(self, size: tuple[int, int]) -> tuple[float, float]:
        """lensfun ``poly5`` coefficients: ``r_d = r_u (1 + k1 r_u² + k2 r_u⁴)``, the same direction
        as ours, with radii normalised by half the shorter frame side. lensfun additionally rescales
        by the ratio of crop factors when the calibration camera differs from the image's; apply that
        factor with :meth:`rescale` yourself. ``ValueError`` for an off-centre lens or non-square
        pixels (lensfun's poly5 is centred)."""
        width, height = frame_size(size)
        self._require_centred("lensfun poly5")
        return self._normalised(0.5 * min(width, height) / width)

    @classmethod
    def from_lensfun_poly5(cls, k1: float, k2: float, size: tuple[int, int]) -> "Lens":
        """Inverse of :meth:`to_lensfun_poly5`."""
        width, height = frame_size(size)
        return cls.from_normalised(k1, k2, 0.5 * min(width, height) / width)

    def to_ffmpeg(self, size: tuple[int, int]) -> tuple[float, float]:
        """``(k1, k2)`` for ffmpeg's ``lenscorrection`` filter (``cx = cy = 0.5``).

        ffmpeg samples, for each OUTPUT pixel at radius ``r_tgt`` from the centre, the source at
        ``r_src = r_tgt (1 + k1 (r_tgt/r0)² + k2 (r_tgt/r0)⁴)``, ``r0`` = half the image diagonal:
        the output is the undistorted image and the polynomial is our forward model, i.e. the filter
        performs :func:`glradial.correct` with ``fit="same"``. Conversion: radii normalised by the
        corner radius, ``k1_ff = k1 R²``, ``k2_ff = k2 R⁴`` with ``R = ½ sqrt(1 + (H/W)²)``.
        Not represented: ffmpeg centres at integer pixel ``(W // 2, H // 2)``, half a pixel right of
        and below our ``((W-1)/2, (H-1)/2)`` for even sizes, and uses nearest-neighbour sampling by
        default. Raises ``ValueError`` outside ffmpeg's accepted range ``[-1, 1]``, and for an
        off-centre lens or non-square pixels (the pair carries no centre; see :meth:`ffmpeg_options`).
        """
        self._require_centred("ffmpeg lenscorrection k1, k2")
        return self.ffmpeg_options(size)[2:]

    def ffmpeg_options(self, size: tuple[int, int]) -> tuple[float, float, float, float]:
        """``(cx, cy, k1, k2)`` options of ffmpeg's ``lenscorrection`` filter for this lens on a
        ``(W, H)`` frame, off-centre principal points included: ``cx_ff = 0.5 + cx``,
        ``cy_ff = 0.5 + cy W / H`` (fractions of the width and height; ffmpeg's centre is the
        integer pixel ``(int(cx_ff W), int(cy_ff H))``, i.e. our principal point rounded half up),
        ``k`` as :meth:`to_ffmpeg` (ffmpeg normalises by half the diagonal whatever the centre).
        ``ValueError`` for non-square pixels (the filter has no pixel aspect), for a principal point
        outside the frame or coefficients outside ffmpeg's ranges ``[0, 1]`` and ``[-1, 1]``."""
        width, height = frame_size(size)
        if self.pixel_aspect != 1.0:
            raise ValueError(
                f"ffmpeg's lenscorrection has no pixel aspect; this lens has pixel_aspect={self.pixel_aspect:g}"
            )
        k1, k2 = self._normalised(corner_radius((width, height)))
        cx, cy = 0.5 + self.cx, 0.5 + self.cy * width / height
        for name, value, low in (("cx", cx, 0.0), ("cy", cy, 0.0), ("k1", k1, -1.0), ("k2", k2, -1.0)):
            if not low <= value <= 1.0:
                raise ValueError(f"ffmpeg lenscorrection accepts {name} in [{low:g}, 1], this lens needs {value:g}")
        return cx, cy, k1, k2

    @classmethod
    def from_ffmpeg(cls, k1: float, k2: float, size: tuple[int, int], cx: float = 0.5, cy: float = 0.5) -> "Lens":
        """Inverse of :meth:`ffmpeg_options` (the lens that ``lenscorrection=cx=..:cy=..:k1=..:k2=..``
        corrects; ``cx``, ``cy`` as ffmpeg's, default the centre)."""
        width, height = frame_size(size)
        lens = cls.from_normalised(k1, k2, corner_radius((width, height)))
        cx, cy = real_number("cx", cx), real_number("cy", cy)
        return cls(lens.k1, lens.k2, cx - 0.5, (cy - 0.5) * height / width)

    def to_opencv(self, size: tuple[int, int], focal: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(camera_matrix, dist_coeffs)`` for OpenCV: ``K = [[fx, 0, cx_px], [0, fx · pixel_aspect,
        cy_px], [0, 0, 1]]`` (float64 3×3) with the principal point :meth:`principal_point`,
        ``dist = (k1_cv, k2_cv, 0, 0, 0)`` with ``k1_cv = k1 (fx/W)²``, ``k2_cv = k2 (fx/W)⁴``;
        ``fx = focal`` defaults to ``W`` (then the numbers are equal). Exact for every lens:
        ``cv2.undistort(img, K, dist)`` then equals ``correct(img, lens)``."""
        width, height = frame_size(size)
        f = float(width) if focal is None else check_positive("focal", focal)
        k1, k2 = self._normalised(f / width)
        px, py = self.principal_point((width, height))
        camera = np.array([[f, 0.0, px], [0.0, f * self.pixel_aspect, py], [0.0, 0.0, 1.0]])
        return camera, np.array([k1, k2, 0.0, 0.0, 0.0])

    @classmethod
    def from_opencv(
        cls,
        camera_matrix: object,
        dist_coeffs: object,
        size: tuple[int, int],
        *,
        approximate: bool = False,
        tolerance: float = 1e-6,
    ) -> "Lens":
        """Lens from an OpenCV calibration of a ``(W, H)`` frame: ``k1 = k1_cv (W/fx)²``,
        ``k2 = k2_cv (W/fx)⁴``, ``cx = (cx_px - (W-1)/2) / W``, ``cy = (cy_px - (H-1)/2) / W``,
        ``pixel_aspect = fy / fx``: exact for any camera matrix (principal point anywhere, fx != fy).

        A principal point within ``tolerance · f`` pixels of the frame centre and ``|fx - fy| <=
        tolerance · f`` (``f = sqrt(fx fy)``) are snapped to the centred model with ``f`` (pass
        ``tolerance=0`` to keep them). ``p1, p2, k3, ...`` must be zero (within ``tolerance``):
        otherwise ``ValueError`` naming them, unless ``approximate=True``, which drops them.
        ``dist_coeffs`` may have 4, 5, 8, 12 or 14 entries, as OpenCV accepts.
        """
        width, height = frame_size(size)
        k = _real_array("camera_matrix", camera_matrix)
        if k.shape != (3, 3):
            raise ValueError(f"camera_matrix must be 3×3, got shape {k.shape}")
        if not np.allclose(k[2], [0.0, 0.0, 1.0]) or k[0, 1] != 0.0 or k[1, 0] != 0.0:
            raise ValueError(f"camera_matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {k.tolist()}")
        fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
        if fx <= 0.0 or fy <= 0.0:
            raise ValueError(f"camera_matrix focal lengths must be positive, got fx={fx:g}, fy={fy:g}")
        d = _real_array("dist_coeffs", dist_coeffs).ravel()
        if d.size not in (4, 5, 8, 12, 14):
            raise ValueError(f"dist_coeffs must have 4, 5, 8, 12 or 14 entries, got {d.size}: {d.tolist()}")
        tolerance = real_number("tolerance", tolerance)
        if not approximate:
            names = ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y"]
            extra = [f"{n}={v:g}" for n, v in zip(names[2:], d[2:]) if abs(v) > tolerance]
            if extra:
                raise ValueError(
                    "OpenCV calibration is not exactly a two-coefficient radial lens: terms glradial cannot "
                    "represent: " + ", ".join(extra) + ". Pass approximate=True to keep k1, k2 only."
                )
        f = math.sqrt(fx * fy)
        offset_x, offset_y = cx - (width - 1) / 2, cy - (height - 1) / 2
        if abs(offset_x) <= tolerance * f and abs(offset_y) <= tolerance * f:
            offset_x = offset_y = 0.0
        if abs(fx - fy) <= tolerance * f:
            fx = fy = f
        k1, k2 = float(d[0]) * (width / fx) ** 2, float(d[1]) * (width / fx) ** 4
        return cls(k1, k2, offset_x / width, offset_y / width, fy / fx)



#: Map value (pixels) that :meth:`Lens.maps` writes where an output pixel has no source: far outside
#: any frame, so ``cv2.remap`` with a constant border fills it (any interpolation kernel).
NO_SOURCE = -1.0e4


def _real_array(name: str, value: object) -> np.ndarray:
    try:
        array = np.asarray(value)
    except Exception as err:  # ragged nested lists and the like
        raise TypeError(f"{name} must be a numeric array, got {value!r} ({err})") from None
    if array.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be a real numeric array, got dtype {array.dtype}: {value!r}")
    array = array.astype(np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {array.tolist()}")
    return array


def as_lens(value: object) -> Lens:
    """The one adapter to a :class:`Lens`: a ``Lens`` (or a ``LensEstimate``) as it is, a
    ``(k1, k2)`` pair as the centred lens; what a frame -> lens callback may return."""
    if isinstance(value, Lens):
        return value
    try:
        k1, k2 = value  # type: ignore[misc]
    except (TypeError, ValueError):
        raise TypeError(f"a lens must be a glradial.Lens or a (k1, k2) pair, got {type(value).__name__} {value!r}") from None
    return Lens(float(k1), float(k2))
