"""Lens conventions of graphics engines: OpenLensIO/OpenTrackIO (mm), Unreal Engine's spherical
model and 3DEqualizer's "Radial - Standard, Degree 4", each defined once from :class:`glradial.Lens`.

glradial's lens (module :mod:`glradial.lens`): width-normalised lens coordinates about the
principal point, forward model undistorted -> distorted, ``p_d = p_u (1 + k1 r_u² + k2 r_u⁴)``.

**OpenLensIO** (SMPTE RIS-OSVP, "OpenLensIO Lens Model" v1.0, sections 1.1, 2, 4.1, 4.2): screen
coordinates ``ε`` in mm from the centre of the sensor's active area (x right, y down); a ``W``-pixel
wide frame spans the sensor width ``w`` mm, so ``ε = (pixel - centre) · w / W``. The radial term is
``R = (1 + k1 r² + k3 r⁴ + k5 r⁶) / (1 + k2 r² + k4 r⁴ + k6 r⁶)`` with ``r`` in mm: odd-numbered
coefficients in the numerator, even-numbered in the denominator (``radial = [k1, ..., k6]``).
``"Brown-Conrady U-D"`` applies ``R`` to undistorted coordinates and gives distorted ones (the
direction of glradial's model, so the conversion is exact: ``k1 = k1_glradial / w²``, ``k3 =
k2_glradial / w⁴``, the rest 0); ``"Brown-Conrady D-U"`` (the schema's default) maps distorted to
undistorted and is a least-squares fit here (:func:`openlensio_du_fit`). The principal point is
both the centre of projection and of distortion: ``projectionOffset ΔP = (cx w, cy w)`` mm,
``distortionOffset ΔC = 0``. OpenLensIO has no pixel aspect: a lens with ``pixel_aspect != 1`` is
refused.

**Unreal Engine** (CameraCalibration plugin, ``FSphericalDistortionParameters``: "refer to the
OpenCV camera calibration documentation"): OpenCV's model ``x_d = x_u (1 + K1 r² + K2 r⁴ + K3 r⁶)
+ tangential`` with ``x = (u - c_x) / f_x`` (undistorted -> distorted, exact from
:meth:`Lens.to_opencv`), focal length ``FxFy = (f_x / W, f_y / H)`` and ``PrincipalPoint`` in
fractions of the frame (0.5, 0.5 = the centre).

**3DEqualizer** ("Radial - Standard, Degree 4" of 3DE4's lens distortion plug-in kit): distorted ->
undistorted, ``x_u = x_d (1 + c2 r² + c4 r⁴)`` (plus decentering terms, written 0 here) in
diagonally normalised coordinates: origin at the lens centre, unit = half the frame diagonal
(``0.5 · hypot(W, H)`` px), so ``r = 1`` at a corner of a centred lens. The direction is the
inverse of glradial's model, so ``c2, c4`` are a least-squares fit (:func:`tde4_radial_deg4`).

Fits minimise the squared pixel error of the undistorted position over a grid of distorted-frame
points (pixel edges included) and state the largest and the RMS error in pixels of the frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..lens.lens import Lens, frame_size
from ..lens.options import DISTORTION_MODELS, real_number

__all__ = [
    "UndistortionFit", "openlensio_radial", "lens_from_openlensio", "openlensio_du_fit", "projection_offset_mm",
    "unreal_spherical", "tde4_radial_deg4", "fit_undistortion", "MODEL_UD", "MODEL_DU",
    "MODEL_NAMES",
]

#: OpenLensIO's model string of each direction of :data:`glradial.lens.options.DISTORTION_MODELS`
MODEL_NAMES = {direction: f"Brown-Conrady {direction}" for direction in DISTORTION_MODELS}
MODEL_UD = MODEL_NAMES["U-D"]
MODEL_DU = MODEL_NAMES["D-U"]

#: distorted-frame grid the fits sample (columns, rows), frame edges included
FIT_GRID = (65, 37)


@dataclass(frozen=True)
class UndistortionFit:
    """A fitted distorted -> undistorted model: ``coefficients`` in the model's own units,
    ``max_error_px`` / ``rms_error_px`` of the undistorted position over the frame (pixels of the
    ``W x H`` frame the fit was made on)."""

    coefficients: tuple[float, ...]
    max_error_px: float
    rms_error_px: float


def _require_square_pixels(lens: Lens, convention: str) -> None:
    if lens.pixel_aspect != 1.0:
        raise ValueError(
            f"{convention} has no pixel aspect; this lens has pixel_aspect={lens.pixel_aspect:g} (fy / fx): "
            "use the Unreal (OpenCV) convention, which carries fx and fy"
        )


def _sensor_width(sensor_width_mm: float) -> float:
    width = real_number("sensor_width_mm", sensor_width_mm)
    if width <= 0.0:
        raise ValueError(f"sensor_width_mm must be positive, got {width:g}")
    return width


def openlensio_radial(lens: Lens, sensor_width_mm: float) -> list[float]:
    """The six OpenLensIO radial coefficients of ``lens`` for the "Brown-Conrady U-D" model (exact):
    ``[k1 / w², 0, k2 / w⁴, 0, 0, 0]`` with ``w`` the sensor width in mm (units mm⁻², mm⁻⁴)."""
    w = _sensor_width(sensor_width_mm)
    _require_square_pixels(lens, "OpenLensIO")
    return [lens.k1 / w**2, 0.0, lens.k2 / w**4, 0.0, 0.0, 0.0]


def projection_offset_mm(lens: Lens, sensor_width_mm: float) -> tuple[float, float]:
    """OpenLensIO's ``projectionOffset`` ΔP: the principal point's offset from the sensor centre in
    mm, ``(cx w, cy w)`` (x right, y down)."""
    w = _sensor_width(sensor_width_mm)
    return lens.cx * w, lens.cy * w


def lens_from_openlensio(
    radial: list[float], sensor_width_mm: float, projection_offset: tuple[float, float] = (0.0, 0.0)
) -> Lens:
    """Inverse of :func:`openlensio_radial` (with :func:`projection_offset_mm`): the glradial lens of
    "Brown-Conrady U-D" coefficients; ``ValueError`` when a coefficient glradial cannot carry
    (denominator terms, r⁶) is not zero."""
    w = _sensor_width(sensor_width_mm)
    values = [real_number(f"radial[{i}]", v) for i, v in enumerate(radial)]
    if not 1 <= len(values) <= 6:
        raise ValueError(f"radial must have 1 to 6 coefficients, got {len(values)}")
    values += [0.0] * (6 - len(values))
    extra = [f"k{i + 1}={v:g}" for i, v in enumerate(values) if i not in (0, 2) and v != 0.0]
    if extra:
        raise ValueError("glradial's lens has numerator r², r⁴ terms only; these OpenLensIO coefficients are not "
                         "zero: " + ", ".join(extra))
    dx, dy = (real_number("projection_offset x", projection_offset[0]), real_number("projection_offset y", projection_offset[1]))
    return Lens(values[0] * w**2, values[2] * w**4, dx / w, dy / w)


def fit_undistortion(
    lens: Lens,
    size: tuple[int, int],
    model: Callable[[np.ndarray, np.ndarray], np.ndarray],
    n_params: int,
) -> UndistortionFit:
    """Least-squares fit of a distorted -> undistorted radial model to ``lens`` on a ``(W, H)``
    frame: ``model(r², params)`` is the factor ``x_u / x_d`` with coordinates about the principal
    point in units of half the frame diagonal. ``ValueError`` where a frame point has no
    undistorted point (the lens never reaches it)."""
    from scipy.optimize import least_squares

    width, height = frame_size(size)
    xs = np.linspace(-0.5, width - 0.5, FIT_GRID[0])
    ys = np.linspace(-0.5, height - 0.5, FIT_GRID[1])
    distorted = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    undistorted = lens.undistort_points(distorted, (width, height))
    if not np.all(np.isfinite(undistorted)):
        raise ValueError(f"lens k1={lens.k1:g}, k2={lens.k2:g} has no undistorted point for part of a {width}×{height} "
                         "frame: no distorted -> undistorted model can be fitted")
    centre = np.array(lens.principal_point((width, height)))
    unit = 0.5 * math.hypot(width, height)
    d, u = (distorted - centre) / unit, (undistorted - centre) / unit
    r2 = np.sum(d * d, axis=1, keepdims=True)

    def residuals(params: np.ndarray) -> np.ndarray:
        return ((d * model(r2, params) - u) * unit).ravel()

    solution = least_squares(residuals, np.zeros(n_params), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    error = residuals(solution.x).reshape(-1, 2)
    error = np.hypot(error[:, 0], error[:, 1])
    return UndistortionFit(tuple(float(v) for v in solution.x), float(error.max()), float(np.sqrt(np.mean(error**2))))


def _rational(r2: np.ndarray, p: np.ndarray) -> np.ndarray:
    """OpenLensIO's R with numerator r², r⁴, r⁶ and denominator r² terms: p = (k1, k3, k5, k2)."""
    return (1.0 + r2 * (p[0] + r2 * (p[1] + r2 * p[2]))) / (1.0 + p[3] * r2)


def _polynomial(r2: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``1 + p0 r² + p1 r⁴ (+ p2 r⁶)``."""
    factor = 1.0
    for i, value in enumerate(p):
        factor = factor + value * r2 ** (i + 1)
    return factor


def openlensio_du_fit(lens: Lens, size: tuple[int, int], sensor_width_mm: float) -> UndistortionFit:
    """A "Brown-Conrady D-U" OpenLensIO model of ``lens`` on a ``(W, H)`` frame spanning
    ``sensor_width_mm``: coefficients ``(k1, ..., k6)`` in mm units (numerator r², r⁴, r⁶ and
    denominator r² fitted; k4 = k6 = 0), errors in px of the frame. The rational form is used when
    its denominator stays positive out to the farthest frame corner, else the r², r⁴, r⁶
    polynomial."""
    w = _sensor_width(sensor_width_mm)
    _require_square_pixels(lens, "OpenLensIO")
    width, height = frame_size(size)
    unit_mm = 0.5 * math.hypot(width, height) * w / width  # half diagonal in mm: the fit's unit
    fit = fit_undistortion(lens, size, _rational, 4)
    reach = (lens.frame_radius((width, height)) * width / (0.5 * math.hypot(width, height))) ** 2 * 1.5
    k1, k3, k5, k2 = fit.coefficients
    if not 1.0 + k2 * reach > 0.0:  # 1 + k2 r² is linear in r²: positive at both ends = positive between
        fit = fit_undistortion(lens, size, _polynomial, 3)
        (k1, k3, k5), k2 = fit.coefficients, 0.0
    radial = (k1 / unit_mm**2, k2 / unit_mm**2, k3 / unit_mm**4, 0.0, k5 / unit_mm**6, 0.0)
    return UndistortionFit(radial, fit.max_error_px, fit.rms_error_px)


def unreal_spherical(lens: Lens, size: tuple[int, int], focal_px: float) -> dict:
    """Unreal Engine's spherical lens model of ``lens`` (exact): ``K1, K2, K3, P1, P2`` (OpenCV's,
    undistorted -> distorted, radii in focal lengths), ``FxFy`` = focal lengths over the frame
    width and height, ``PrincipalPoint`` in fractions of the frame (0.5 = centre; OpenCV's pixel
    centres at integers, so ``(c_x + 0.5) / W``). ``focal_px``: the horizontal focal length in
    pixels (``focal_mm / sensor_width_mm · W``)."""
    width, height = frame_size(size)
    camera, dist = lens.to_opencv((width, height), focal_px)
    return {
        "K1": float(dist[0]), "K2": float(dist[1]), "K3": float(dist[4]), "P1": float(dist[2]), "P2": float(dist[3]),
        "FxFy": [float(camera[0, 0]) / width, float(camera[1, 1]) / height],
        "PrincipalPoint": [(float(camera[0, 2]) + 0.5) / width, (float(camera[1, 2]) + 0.5) / height],
    }


def tde4_radial_deg4(lens: Lens, size: tuple[int, int]) -> dict:
    """3DEqualizer "Radial - Standard, Degree 4" parameters of ``lens`` on a ``(W, H)`` frame:
    ``"Distortion - Degree 2"`` (c2) and ``"Quartic Distortion - Degree 4"`` (c4) fitted, the
    decentering terms (U, V - Degree 2 and 4), ``"Phi - Cylindric Direction"`` and ``"B - Cylindric
    Bending"`` 0, the lens centre offset in pixels from the frame centre, and the fit's errors."""
    _require_square_pixels(lens, "3DEqualizer's Radial - Standard, Degree 4 (as written here)")
    width, height = frame_size(size)
    fit = fit_undistortion(lens, (width, height), _polynomial, 2)
    c2, c4 = fit.coefficients
    return {
        "model": "3DE4 Radial - Standard, Degree 4",
        "Distortion - Degree 2": c2, "U - Degree 2": 0.0, "V - Degree 2": 0.0,
        "Quartic Distortion - Degree 4": c4, "U - Degree 4": 0.0, "V - Degree 4": 0.0,
        "Phi - Cylindric Direction": 0.0, "B - Cylindric Bending": 0.0,
        "lens_center_offset_px": [lens.cx * width, lens.cy * width],
        "fit_max_error_px": fit.max_error_px, "fit_rms_error_px": fit.rms_error_px,
    }
