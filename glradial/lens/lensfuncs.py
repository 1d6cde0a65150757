"""NumPy twins of the lens functions in ``shaders/common.glsl``.

Every function here has a GLSL function of the same name in ``common.glsl``; ``tests/lens/test_twins.py``
renders each GLSL function into a float texture and holds the two together. Change both or neither.

Convention (docs/DESIGN.md, written once here and in the GLSL header):

* Lens coordinates ``p = (u - 0.5, (v - 0.5) * H / W)``: image width = 1, origin at the image centre
  (the principal point), x right, y down.  ``aspect_hw = H / W``.
* A lens may carry a principal point ``centre = (cx, cy)`` (its offset from the image centre in width
  units, x right, y down) and a pixel aspect ``pixel_aspect = fy / fx``; then
  ``p = (u - 0.5 - cx, ((v - 0.5) * H / W - cy) / pixel_aspect)`` (radii still normalised by the image
  width along x). ``centre = (0, 0)``, ``pixel_aspect = 1`` is the centred model above.
* Texture coordinates ``u = (x + 0.5) / W``, ``v = (y + 0.5) / H`` with pixel centres at integer
  ``(x, y)`` and ``v = 0`` the first row in memory (the top of the image).
* A lens is ``(k1, k2)`` in those units. Forward (undistorted -> distorted):
  ``p_d = p_u * (1 + k1 r_u^2 + k2 r_u^4)``.
* Points are arrays of shape ``(..., 2)``; radii are arrays of any shape. Everything is float64.
"""

from __future__ import annotations

import numpy as np

#: Newton steps of the exact inverse (GLSL ``LENS_NEWTON_STEPS``). Eight steps from the
#: Drap-Lefevre seed reach float64 round-off for every lens of the paper's range.
LENS_NEWTON_STEPS = 8

#: Largest residual |P(r_u) - r_d| (lens units) for which the exact inverse counts as found (GLSL
#: ``LENS_INVERSE_TOLERANCE``; float32 Newton in GLSL reaches ~1e-7).
LENS_INVERSE_TOLERANCE = 1.0e-4

#: Radius that stands for "no fold-over at any radius" (GLSL ``LENS_RADIUS_UNBOUNDED``): far beyond
#: any radius a frame can use (the corner of a 1:10 strip is ~5 lens units).
LENS_RADIUS_UNBOUNDED = 1.0e6


def lens_from_uv(
    uv: np.ndarray, aspect_hw: float, centre: tuple[float, float] = (0.0, 0.0), pixel_aspect: float = 1.0
) -> np.ndarray:
    """Texture coordinates (..., 2) in <0;1> -> lens coordinates (..., 2), width-normalised, about
    the principal point ``centre`` (offset from the image centre, width units) with pixel aspect
    ``pixel_aspect = fy / fx``; the defaults are the centred model."""
    uv = np.asarray(uv, dtype=np.float64)
    return np.stack(
        [uv[..., 0] - 0.5 - centre[0], ((uv[..., 1] - 0.5) * aspect_hw - centre[1]) / pixel_aspect], axis=-1
    )


def uv_from_lens(
    p: np.ndarray, aspect_hw: float, centre: tuple[float, float] = (0.0, 0.0), pixel_aspect: float = 1.0
) -> np.ndarray:
    """Lens coordinates (..., 2) -> texture coordinates (..., 2); inverse of :func:`lens_from_uv`."""
    p = np.asarray(p, dtype=np.float64)
    return np.stack([p[..., 0] + centre[0] + 0.5, (p[..., 1] * pixel_aspect + centre[1]) / aspect_hw + 0.5], axis=-1)


def radial_factor(r2: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """``D = 1 + k1 r^2 + k2 r^4`` from the squared undistorted radius ``r2``."""
    r2 = np.asarray(r2, dtype=np.float64)
    return 1.0 + k1 * r2 + k2 * r2 * r2


def radial_slope(r: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """``d/dr [r D(r)] = 1 + 3 k1 r^2 + 5 k2 r^4``; the lens folds over where this is <= 0."""
    r2 = np.asarray(r, dtype=np.float64) ** 2
    return 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2


def fold_radius(k1: float, k2: float) -> float:
    """Smallest radius > 0 where :func:`radial_slope` reaches 0, or ``LENS_RADIUS_UNBOUNDED``.

    Solves ``1 + 3 k1 s + 5 k2 s^2 = 0`` for ``s = r^2`` and keeps the smallest positive root.
    """
    a, b = 5.0 * k2, 3.0 * k1
    roots: list[float] = []
    if abs(a) < 1e-15:
        if b < 0.0:
            roots.append(-1.0 / b)
    else:
        disc = b * b - 4.0 * a
        if disc >= 0.0:
            sq = np.sqrt(disc)
            roots += [(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)]
    positive = [s for s in roots if s > 0.0]
    return float(np.sqrt(min(positive))) if positive else LENS_RADIUS_UNBOUNDED


def fold_radii(k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """:func:`fold_radius` of many lenses at once (arrays that broadcast; same roots, same
    ``LENS_RADIUS_UNBOUNDED`` where the map never folds)."""
    a, b = 5.0 * np.asarray(k2, np.float64), 3.0 * np.asarray(k1, np.float64)
    a, b = np.broadcast_arrays(a, b)
    linear = np.abs(a) < 1e-15
    with np.errstate(divide="ignore", invalid="ignore"):
        s_linear = np.where(b < 0.0, -1.0 / b, np.inf)
        disc = b * b - 4.0 * a
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        roots = np.stack([(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)])
    roots = np.where(np.isfinite(roots) & (roots > 0.0), roots, np.inf).min(axis=0)
    s_min = np.where(linear, s_linear, roots)
    return np.where(np.isfinite(s_min), np.sqrt(np.where(np.isfinite(s_min), s_min, 1.0)), LENS_RADIUS_UNBOUNDED)


def distort_point(p_u: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Forward model: undistorted lens point(s) -> distorted, ``p_u (1 + k1 r^2 + k2 r^4)``."""
    p_u = np.asarray(p_u, dtype=np.float64)
    r2 = np.sum(p_u * p_u, axis=-1, keepdims=True)
    return p_u * radial_factor(r2, k1, k2)


def drap_coefficients(k1: float, k2: float) -> tuple[float, float, float, float]:
    """Drap-Lefevre inverse coefficients (b1, b2, b3, b4) for k3 = k4 = 0 (docs/DESIGN.md)."""
    return (
        -k1,
        3.0 * k1**2 - k2,
        -12.0 * k1**3 + 8.0 * k1 * k2,
        55.0 * k1**4 - 55.0 * k1**2 * k2 + 5.0 * k2**2,
    )


def undistort_point_drap(p_d: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Approximate inverse (the paper's): ``p_u = p_d (1 + b1 r^2 + b2 r^4 + b3 r^6 + b4 r^8)``,
    ``r = |p_d|``."""
    p_d = np.asarray(p_d, dtype=np.float64)
    b1, b2, b3, b4 = drap_coefficients(k1, k2)
    r2 = np.sum(p_d * p_d, axis=-1, keepdims=True)
    return p_d * (1.0 + r2 * (b1 + r2 * (b2 + r2 * (b3 + r2 * b4))))


def undistort_radius_exact(r_d: np.ndarray, k1: float, k2: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact inverse of the radial map: solve ``r (1 + k1 r^2 + k2 r^4) = r_d`` for ``r >= 0``.

    Bounded Newton: seeded by Drap-Lefevre, each step clamped to ``[0, fold_radius]`` (the branch on
    which the map is increasing), ``LENS_NEWTON_STEPS`` steps (fewer once a step changes
    no radius: the same result). Returns ``(r_u, valid)``; ``valid``
    is False where ``r_d`` lies beyond the largest distorted radius the lens reaches (no undistorted
    point maps there, e.g. outside the image circle of a strong barrel lens).

    ``k1``, ``k2`` may be arrays that broadcast against ``r_d`` (many lenses at once, e.g. ``N × 1``
    lenses against ``M`` radii -> ``N × M``).
    """
    r_d = np.asarray(r_d, dtype=np.float64)
    if np.ndim(k1) or np.ndim(k2):
        k1, k2 = np.broadcast_arrays(np.asarray(k1, np.float64), np.asarray(k2, np.float64))
        r_fold = fold_radii(k1, k2)
    else:
        r_fold = fold_radius(k1, k2)
    b1, b2, b3, b4 = drap_coefficients(k1, k2)
    rd2 = r_d * r_d
    r = np.clip(r_d * (1.0 + rd2 * (b1 + rd2 * (b2 + rd2 * (b3 + rd2 * b4)))), 0.0, r_fold)
    r = _newton(r, r_d, k1, k2, r_fold)
    residual = np.abs(r * radial_factor(r * r, k1, k2) - r_d)
    valid = residual <= LENS_INVERSE_TOLERANCE * np.maximum(1.0, r_d)
    return r, valid


def _newton(r: np.ndarray, r_d: np.ndarray, k1, k2, r_fold) -> np.ndarray:
    """The Newton steps of :func:`undistort_radius_exact` from the seed ``r``: ``r -= f / slope``
    with ``f = r D(r) - r_d`` and the slope :func:`radial_slope` (floored at 1e-6), clamped to
    ``[0, r_fold]``; in place on preallocated buffers (the line fit calls this on lens grids), the
    same arithmetic, in the same order, as :func:`radial_factor` and :func:`radial_slope`."""
    r = np.array(r, dtype=np.float64)  # a fresh (L, M) buffer, broadcast like the lens and the radii
    k1_3, k2_5 = 3.0 * k1, 5.0 * k2
    r2, f, slope, t, before = (np.empty_like(r) for _ in range(5))
    for _ in range(LENS_NEWTON_STEPS):
        np.copyto(before, r)
        np.multiply(r, r, out=r2)
        np.multiply(k1, r2, out=f)
        np.add(1.0, f, out=f)
        np.multiply(k2, r2, out=t)
        np.multiply(t, r2, out=t)
        np.add(f, t, out=f)
        np.multiply(r, f, out=f)
        np.subtract(f, r_d, out=f)  # r (1 + k1 r^2 + k2 r^4) - r_d
        np.multiply(k1_3, r2, out=slope)
        np.add(1.0, slope, out=slope)
        np.multiply(k2_5, r2, out=t)
        np.multiply(t, r2, out=t)
        np.add(slope, t, out=slope)
        np.maximum(slope, 1e-6, out=slope)
        np.divide(f, slope, out=f)  # the step
        np.subtract(r, f, out=r)
        np.maximum(r, 0.0, out=r)
        np.minimum(r, r_fold, out=r)
        # every radius at a fixed point of the step (converged to the last bit, held at 0 or the fold
        # radius, or NaN): the remaining steps would change nothing, so stopping is exact
        if not ((r != before) & (r == r)).any():
            break
    return r


def undistort_point_exact(p_d: np.ndarray, k1: float, k2: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact inverse for points (..., 2): ``(p_u, valid)`` with ``valid`` of shape (...)."""
    p_d = np.asarray(p_d, dtype=np.float64)
    r_d = np.sqrt(np.sum(p_d * p_d, axis=-1))
    r_u, valid = undistort_radius_exact(r_d, k1, k2)
    scale = np.where(r_d > 0.0, r_u / np.where(r_d > 0.0, r_d, 1.0), 1.0)
    return p_d * scale[..., None], valid
