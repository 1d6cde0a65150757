"""The exact inverse of one lens as a short Chebyshev series, for shaders that invert many points of it.

Used by the crop renderer (``shaders/crop.frag``, ``CROP_INVERSE_SERIES``): a crop's every pixel
inverts the same lens, and a per-pixel Newton solve is a third of its shader time on a software
rasteriser. Instead, per lens and on the CPU (float64, all lenses of a batch at once):

* The exact inverse (:func:`glradial.lens.lensfuncs.undistort_radius_exact`, bounded Newton) is written
  ``r_u = r_d · s(t)`` with ``t = r_d²`` (lens units, image width = 1), and ``s`` is fitted on
  ``t ∈ [0, r_c²]`` (``r_c`` = the frame's corner radius) by a Chebyshev series of degree
  :data:`SERIES_DEGREE` in ``x = 2 t / r_c² − 1``: least squares on :data:`FIT_NODES` Chebyshev nodes.
* The series is accepted only if every ``r_d ≤ r_c`` has an exact inverse (the lens covers the whole
  frame) and, on a check grid of :data:`CHECK_POINTS` radii uniform in ``t`` (both ends included),
  ``|r_d · s_fit − r_u| ≤`` :data:`SERIES_TOLERANCE` lens units. Lenses that fail (near fold-over,
  or with unreachable corners) keep the per-pixel Newton inverse.

The shader evaluates ``s`` with Clenshaw's recurrence; :func:`series_radius` is its NumPy twin.
Its accuracy and acceptance rate on the paper's lenses: docs/CROPS.md.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .lensfuncs import undistort_radius_exact

#: Degree of the series (the shader takes its 11 coefficients as three vec4, the twelfth slot spare).
SERIES_DEGREE = 10
#: Largest accepted |series - exact| in lens units: 0.0013 px of a 1280-wide frame, below the
#: float32 evaluation error of the GLSL Newton inverse's own results near the corners.
SERIES_TOLERANCE = 1.0e-6
#: Least-squares nodes (Chebyshev points of the first kind in x).
FIT_NODES = 32
#: Radii of the acceptance check, uniform in t = r_d^2 from 0 to r_c^2.
CHECK_POINTS = 129


@lru_cache(maxsize=1)
def _fit_operator() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x of the fit nodes, pseudo-inverse of their Chebyshev-Vandermonde matrix, that matrix of the
    check grid; its column 1 is the check grid's x)."""
    j = np.arange(FIT_NODES)
    x_fit = np.cos(np.pi * (j + 0.5) / FIT_NODES)[::-1]
    pinv = np.linalg.pinv(np.polynomial.chebyshev.chebvander(x_fit, SERIES_DEGREE))
    x_check = np.linspace(-1.0, 1.0, CHECK_POINTS)
    return x_fit, pinv, np.polynomial.chebyshev.chebvander(x_check, SERIES_DEGREE)


def fit_inverse_series(k1: np.ndarray, k2: np.ndarray, corner: float) -> tuple[np.ndarray, np.ndarray]:
    """Series of the exact inverse for ``N`` lenses on a frame of corner radius ``corner`` (lens units).

    Returns ``(coefficients, accepted)``: ``N × (SERIES_DEGREE + 1)`` float64 Chebyshev coefficients
    of ``s(x)`` (lowest first) and an ``N`` bool mask of the lenses whose series is usable (see the
    module docstring); coefficients of rejected lenses are still returned but must not be used.
    """
    k1 = np.atleast_1d(np.asarray(k1, np.float64))[:, None]
    k2 = np.atleast_1d(np.asarray(k2, np.float64))[:, None]
    if not (np.isfinite(corner) and corner > 0.0):
        raise ValueError(f"corner radius must be finite and > 0, got {corner!r}")
    x_fit, pinv, check_basis = _fit_operator()
    x_check = check_basis[:, 1]
    c2 = corner * corner
    rd_fit = np.sqrt((x_fit + 1.0) * 0.5 * c2)  # > 0: first-kind nodes exclude x = -1
    rd_check = np.sqrt((x_check + 1.0) * 0.5 * c2)
    r_u, valid = undistort_radius_exact(np.concatenate([rd_fit, rd_check]), k1, k2)
    coefficients = (r_u[:, :FIT_NODES] / rd_fit) @ pinv.T
    error = np.abs(rd_check * (coefficients @ check_basis.T) - r_u[:, FIT_NODES:])
    accepted = valid.all(axis=1) & (error.max(axis=1) <= SERIES_TOLERANCE)
    return coefficients, accepted


def series_radius(r_d: np.ndarray, coefficients: np.ndarray, corner: float) -> np.ndarray:
    """``r_u = r_d · s(2 r_d² / r_c² − 1)`` for one lens's coefficients (the shader's evaluation)."""
    r_d = np.asarray(r_d, np.float64)
    x = 2.0 * r_d * r_d / (corner * corner) - 1.0
    return r_d * np.polynomial.chebyshev.chebval(x, np.asarray(coefficients, np.float64))
