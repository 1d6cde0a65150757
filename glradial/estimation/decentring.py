"""How much a line fit's lens leans on the principal point sitting at the frame centre.

The estimator's model is a radial lens about the frame centre. A camera whose principal point sits
off centre (the shared wide camera's by about 6.5 % of the width) bends lines in a way that model
cannot reproduce: to first order in the offset ``c`` a radial lens about ``c`` is the centred lens
plus Brown's decentring distortion with ``(p1, p2) = -k1 (cx, cy)``
(``dx = p1 (r² + 2x²) + 2 p2 x y``, ``dy = 2 p1 x y + p2 (r² + 2y²)``). The line fit then reads the
centred lens that best straightens its own chains, which differs from the centred lens a
checkerboard calibration over the whole frame reports, by an amount the centred fit's own
uncertainty does not see.

:func:`centre_shift_px` measures it on the chains the fit used: one Gauss-Newton step of the joint
fit of ``(k1, k2, p1, p2)`` from the fitted lens (the chains' straightness, each chain's line
refitted, with the fit's own per-chain weights and its k2 prior), and reports how far the lens moves
when the decentring terms are free (held by a loose prior, :data:`OFFSET_SIGMA`): the maximum radial
displacement between the fitted ``(k1, k2)``
and the jointly fitted one over the 16:9 frame, px at 1920
(:func:`glradial.lens.metrics.max_displacement_px`). It is 0 for lines that a centred lens
straightens exactly and grows where the chains' curvature left after the centred fit has the
position dependence a principal-point offset gives, or where the chains cannot tell a centred lens
from a decentred one. :mod:`glradial.estimation.trust` turns it into a term of the stated bound,
calibrated split-conformally on rendered off-centre views (``bench/misfit_calibration.py``).

Convention: points in lens units of the frame (image width = 1, origin at the frame centre), as
:mod:`glradial.estimation.line_fit` holds them; residuals in px of the detection copy (``width`` px
wide), scaled by each chain's mean magnification as the fit's are.
"""

from __future__ import annotations

import math

import numpy as np

from ..lens import lensfuncs
from ..lens.metrics import manifold_k2, max_displacement_px

#: Fewest chains the joint fit is made from: with three, one chain's bend decides between a
#: centred and a decentred lens (on real stadium views, three-chain fits moved by 50-120 px), so the
#: decentring terms are not measured.
MIN_CHAINS = 4
#: Prior of the principal point's offset from the centre (width units, 1 sigma; the decentring terms
#: get ``|k1| OFFSET_SIGMA``, at least ``K1_FLOOR OFFSET_SIGMA``): real cameras keep it within a few
#: per cent of the width (the shared wide camera: 6.5 %), so this only holds back a few chains that
#: cannot tell a centred lens from a decentred one from reading offsets of a third of the frame.
OFFSET_SIGMA, K1_FLOOR = 0.15, 0.02


def _fields(u: np.ndarray) -> np.ndarray:
    """Per undistorted point (M, 2): the displacement fields of ``k1``, ``k2``, ``p1``, ``p2`` ->
    (M, 4, 2) (lens units per unit coefficient)."""
    x, y = u[:, 0], u[:, 1]
    r2 = x * x + y * y
    return np.stack([u * r2[:, None], u * (r2 * r2)[:, None],
                     np.stack([r2 + 2.0 * x * x, 2.0 * x * y], axis=1),
                     np.stack([2.0 * x * y, r2 + 2.0 * y * y], axis=1)], axis=1)


def _per_chain(values: np.ndarray, chain: np.ndarray, n: int) -> np.ndarray:
    """Sum of ``values`` (M,) or (M, K) per chain -> (n,) or (n, K)."""
    if values.ndim == 1:
        return np.bincount(chain, values, n)
    return np.stack([np.bincount(chain, values[:, j], n) for j in range(values.shape[1])], axis=1)


def _residual_columns(u: np.ndarray, chain: np.ndarray, n: int, scale: np.ndarray,
                      moved: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point's signed distance from its chain's total-least-squares line (``d``, M) and its
    change per unit coefficient (``g``, M x 4: the undistorted points ``moved`` along its normal),
    both in px (``scale`` per point) and with the chain's own line refitted (the part a shift and a
    turn of the line absorb removed)."""
    count = np.maximum(np.bincount(chain, minlength=n), 1).astype(np.float64)
    mean = _per_chain(u, chain, n) / count[:, None]
    q = u - mean[chain]
    cxx, cyy, cxy = (_per_chain(v, chain, n) / count for v in (q[:, 0] ** 2, q[:, 1] ** 2, q[:, 0] * q[:, 1]))
    angle = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # the line's direction
    tangent = np.stack([np.cos(angle), np.sin(angle)], axis=1)[chain]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    along = np.sum(q * tangent, axis=1)
    columns = np.concatenate([np.sum(q * normal, axis=1)[:, None], np.einsum("mjk,mk->mj", moved, normal)], axis=1)
    columns = columns * scale[:, None]
    columns -= (_per_chain(columns, chain, n) / count[:, None])[chain]
    spread = np.maximum(np.bincount(chain, along * along, n), 1e-30)
    columns -= along[:, None] * (_per_chain(along[:, None] * columns, chain, n) / spread[:, None])[chain]
    return columns[:, 0], columns[:, 1:]


def centre_shift_px(points: np.ndarray, chain: np.ndarray, weight: np.ndarray, width: float,
                    k1: float, k2: float, k2_sigma: float) -> float:
    """How far the fitted lens ``(k1, k2)`` moves when decentring terms are fitted with it (module
    docstring): px at 1920, NaN with fewer than :data:`MIN_CHAINS` chains or where the lens cannot
    undistort every point or the joint fit is singular.

    ``points`` (M, 2): the points of the chains the fit used (lens units); ``chain`` (M,): their
    chain, ``0..C-1``; ``weight`` (C,): each point's weight in its chain (1 / px², the fit's
    per-chain weight over its point count); ``width``: px of the detection copy; ``k2_sigma``: the
    fit's prior on k2 about :func:`glradial.lens.metrics.manifold_k2` (lens units).
    """
    n = int(chain.max()) + 1 if len(chain) else 0
    if n < MIN_CHAINS:
        return math.nan
    r_d = np.hypot(points[:, 0], points[:, 1])
    r_u, valid = lensfuncs.undistort_radius_exact(r_d, np.float64(k1), np.float64(k2))
    if not np.all(valid):
        return math.nan
    u = points / np.maximum(r_d, 1e-12)[:, None] * r_u[:, None]
    r2 = r_u * r_u
    a = lensfuncs.radial_factor(r2, k1, k2)
    b = 2.0 * k1 + 4.0 * k2 * r2
    fields = _fields(u)
    # the forward map's Jacobian is a I + b u uᵀ: a field F moves the undistorted point by -J⁻¹ F
    along_u = np.einsum("mjk,mk->mj", fields, u)
    moved = -(fields / a[:, None, None] - (b / (a * (a + b * r2)))[:, None, None] * along_u[:, :, None] * u[:, None, :])
    magnification = _per_chain(np.where(r_u > 0, r_d / np.maximum(r_u, 1e-12), 1.0), chain, n) / np.bincount(chain, minlength=n)
    d, g = _residual_columns(u, chain, n, (magnification * width)[chain], moved)
    w = weight[chain]
    slope = (manifold_k2(k1 + 1e-4) - manifold_k2(k1 - 1e-4)) / 2e-4
    prior = np.array([-slope, 1.0, 0.0, 0.0]) / k2_sigma
    offset = (k2 - manifold_k2(k1)) / k2_sigma
    decentring = 1.0 / (max(abs(k1), K1_FLOOR) * OFFSET_SIGMA) ** 2
    hessian = g.T @ (g * w[:, None]) + np.outer(prior, prior) + np.diag([0.0, 0.0, decentring, decentring])
    try:
        step = -np.linalg.solve(hessian, g.T @ (w * d) + prior * offset)
    except np.linalg.LinAlgError:
        return math.nan
    if not np.all(np.isfinite(step)):
        return math.nan
    return float(max_displacement_px(np.array([k1 + step[0], k2 + step[1]]), np.array([k1, k2])))
