"""Robust ``(k1, k2)`` from line chains: the lens that makes the chains straight.

Convention:
    Chains come from :func:`glradial.estimation.lines.detect_chains`: points in lens units of the frame (image
    width = 1, origin at the centre). Residuals are stated in pixels of the **distorted** frame at
    the detection width ``evidence.width`` (``w`` below): for a lens ``k`` a chain's points are
    undistorted with the exact inverse, a total-least-squares line is fitted to them, and the mean
    squared perpendicular distance is scaled back to the distorted frame by the chain's mean
    magnification ``r_d / r_u`` (``e_c(k)``, px²).

Cost (minimised over ``k1`` in :data:`K1_RANGE`):
    ``sum_c rho(n_c e_c / (SIGMA_POINT² + n_c SIGMA_FLOOR²)) + ((k2 - m(k1)) / K2_PRIOR_SIGMA)²
    + ((k1 - k1_prior) / K1_PRIOR_SIGMA)²``

    * ``n_c`` points of chain ``c``; the per-chain error floor ``SIGMA_FLOOR`` bounds what a long
      chain can claim, and each chain enters once (not once per point), so many short chains near
      the centre, whose residual hardly depends on the lens, cannot outvote a long chain near the
      frame edge, whose residual does.
    * ``rho(x) = T log(1 + x / T)``: a chain that no lens straightens (an arc, a curved stand, a
      mis-linked chain) costs at most logarithmically.
    * ``m`` is :func:`glradial.lens.metrics.manifold_k2`: k2 is held loosely to the manifold unless the
      lines pin it; ``k1_prior`` is the CNN's estimate (a weak prior; the fallback when lines are
      missing is the estimator's job).

Screening (before the fit): a chain is kept only if some lens on the manifold over the k1 range
straightens it (RMS at most :data:`STRAIGHT_RMS` px) AND the choice of lens changes its residual
(RMS at least :data:`INFORMATIVE_RMS` px somewhere on the range). Circles, arcs and bowl-shaped
stands fail the first test; lines through the frame centre (straight under every lens) fail the
second and are not counted.

Uncertainty: the cost's curvature at the minimum (a quadratic fitted to a 3 x 3 stencil) gives a
covariance of ``(k1, k2)``, scaled by the reduced chi² when above 1; :attr:`LineFit.sigma_px` is the
largest standard deviation of the radial displacement over the 16:9 frame, in px at 1920 wide
(:data:`glradial.lens.metrics.REPORT_WIDTH`). It is a raw 1-sigma figure; :mod:`glradial.estimation.estimator`
turns it into a calibrated 90 % bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..lens import lensfuncs
from ..lens.metrics import CORNER_RADIUS_16_9, REPORT_WIDTH, manifold_k2
from .lines import LineEvidence

#: Range of k1 searched (lens units): real broadcast and pitch cameras reach -0.72.
K1_RANGE = (-1.0, 0.4)
#: Coarse search step along the manifold (k1, lens units).
K1_STEP = 0.025
#: Points per chain after averaging consecutive points in groups.
MAX_CHAIN_POINTS = 32
#: Per-point localisation noise and per-chain error floor (px of the detection copy).
SIGMA_POINT, SIGMA_FLOOR = 0.25, 0.08
#: Robust loss scale (chi² units) of one chain.
ROBUST_T = 3.0
#: Loose prior of k2 around the manifold, and of k1 around the CNN (lens units).
K2_PRIOR_SIGMA, K1_PRIOR_SIGMA = 0.05, 0.3
#: Screening thresholds (px RMS of the detection copy).
STRAIGHT_RMS, INFORMATIVE_RMS = 0.4, 1.0
#: A fit needs at least this many chains that agree with it: one chain cannot be checked against
#: anything (an arc that some lens straightens passes screening on its own).
MIN_CHAINS = 2
#: A chain whose residual at the fitted lens exceeds this many floors is reported as not used.
USED_CHI = 3.0
#: After the first fit, chains above this many times the median chain residual (chi) are dropped.
OUTLIER_CHI = 2.0
#: Points farther than this (px, and 3 robust sigmas) from their chain's line at the coarse lens are dropped.
TRIM_PX = 1.0


@dataclass(frozen=True)
class LineFit:
    """Result of :func:`fit_lines`: the lens, its raw 1-sigma displacement uncertainty (px at 1920),
    the chains that agree with it, the chains that passed screening, and whether a fit was made."""

    k1: float
    k2: float
    sigma_px: float
    chains: int
    candidates: int
    ok: bool


def _compact(evidence: LineEvidence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Average each chain's consecutive points into at most MAX_CHAIN_POINTS groups.

    Returns points (M, 2), chain index (M,), original point count per chain (C,)."""
    pts, idx, counts = [], [], []
    for c, chain in enumerate(evidence.chains):
        p = chain.points
        groups = min(MAX_CHAIN_POINTS, len(p))
        edges = np.linspace(0, len(p), groups + 1).astype(np.intp)
        sums = np.add.reduceat(p, edges[:-1], axis=0)
        pts.append(sums / np.diff(edges)[:, None])
        idx.append(np.full(groups, c))
        counts.append(len(p))
    if not pts:
        return np.zeros((0, 2)), np.zeros(0, np.intp), np.zeros(0)
    return np.concatenate(pts), np.concatenate(idx), np.asarray(counts, np.float64)


def _undistort_radius(r_d: np.ndarray, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
    """Exact inverse radius for L lenses (``k1``, ``k2`` of shape (L, 1)) and M radii -> (L, M);
    NaN where a lens folds over before reaching the radius."""
    b1, b2, b3, b4 = lensfuncs.drap_coefficients(k1, k2)
    rd2 = r_d * r_d
    r = r_d * (1.0 + rd2 * (b1 + rd2 * (b2 + rd2 * (b3 + rd2 * b4))))
    for _ in range(4):
        r2 = r * r
        f = r * (1.0 + r2 * (k1 + k2 * r2)) - r_d
        slope = 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2)
        r = r - f / np.maximum(slope, 1e-6)
    r2 = r * r
    slope = 1.0 + r2 * (3.0 * k1 + 5.0 * k2 * r2)
    bad = (np.abs(r * (1.0 + r2 * (k1 + k2 * r2)) - r_d) > 1e-7) | (slope <= 0.0) | (r < 0.0)
    return np.where(bad, np.nan, r)


class _Problem:
    """Chains of one frame in the form the cost needs (lens units; px = lens * width)."""

    def __init__(self, points: np.ndarray, chain: np.ndarray, counts: np.ndarray, width: int) -> None:
        self.points, self.chain, self.counts, self.width = points, chain, counts, float(width)
        self.n = len(counts)
        self.r_d = np.hypot(points[:, 0], points[:, 1])
        self.unit = points / np.maximum(self.r_d, 1e-12)[:, None]

    def subset(self, keep: np.ndarray) -> "_Problem":
        """Only the chains where ``keep`` (C,) is true (renumbered)."""
        new_index = np.cumsum(keep) - 1
        mask = keep[self.chain]
        return _Problem(self.points[mask], new_index[self.chain[mask]], self.counts[keep], int(self.width))

    def chain_mse(self, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
        """Mean squared distorted-frame residual (px²) per lens and chain -> (L, C); inf where invalid."""
        k1 = np.asarray(k1, np.float64).reshape(-1, 1)
        k2 = np.asarray(k2, np.float64).reshape(-1, 1)
        n_lens = len(k1)
        r_u = _undistort_radius(self.r_d[None, :], k1, k2)
        x = self.unit[:, 0] * r_u
        y = self.unit[:, 1] * r_u
        mag = self.r_d[None, :] / np.maximum(r_u, 1e-12)
        mag = np.where(self.r_d[None, :] > 1e-9, mag, 1.0)
        index = (np.arange(n_lens)[:, None] * self.n + self.chain[None, :]).ravel()
        size = n_lens * self.n
        cnt = np.bincount(index, minlength=size)
        safe = np.maximum(cnt, 1)

        def mean(v: np.ndarray) -> np.ndarray:
            return np.bincount(index, v.ravel(), size) / safe

        mx, my = mean(x), mean(y)
        cxx = mean(x * x) - mx * mx
        cyy = mean(y * y) - my * my
        cxy = mean(x * y) - mx * my
        lam = 0.5 * (cxx + cyy) - np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        lam = np.maximum(lam, 0.0) * mean(mag) ** 2 * self.width**2
        lam = lam.reshape(n_lens, self.n)
        invalid = np.isnan(r_u).any(axis=1)
        lam[invalid] = np.inf
        lam[np.isnan(lam)] = np.inf
        return lam

    def chi2(self, k1: np.ndarray, k2: np.ndarray, mse: np.ndarray | None = None) -> np.ndarray:
        """Per lens and chain ``n_c e_c / (SIGMA_POINT² + n_c SIGMA_FLOOR²)`` -> (L, C) (``mse``:
        :meth:`chain_mse` of these lenses when already computed)."""
        e = self.chain_mse(k1, k2) if mse is None else mse
        return self.counts * e / (SIGMA_POINT**2 + self.counts * SIGMA_FLOOR**2)


def _cost(problem: _Problem, k1: np.ndarray, k2: np.ndarray, prior_k1: float | None,
          mse: np.ndarray | None = None) -> np.ndarray:
    k1 = np.asarray(k1, np.float64)
    k2 = np.asarray(k2, np.float64)
    chi = problem.chi2(k1, k2, mse)
    total = (ROBUST_T * np.log1p(chi / ROBUST_T)).sum(axis=1)
    total = total + ((k2 - manifold_k2(k1)) / K2_PRIOR_SIGMA) ** 2
    if prior_k1 is not None:
        total = total + ((k1 - prior_k1) / K1_PRIOR_SIGMA) ** 2
    outside = (k1 < K1_RANGE[0] - 1e-9) | (k1 > K1_RANGE[1] + 1e-9)
    return np.where(outside | ~np.isfinite(total), np.inf, total)


def _trim(problem: _Problem, k1: float, k2: float) -> _Problem:
    """Drop points far from their chain's line at lens ``(k1, k2)`` (a player's edge linked in)."""
    r_u = _undistort_radius(problem.r_d, np.float64(k1), np.float64(k2))
    if np.isnan(r_u).any():
        return problem
    p = problem.unit * r_u[:, None]
    keep = np.ones(len(p), bool)
    scale = problem.width * problem.r_d / np.maximum(r_u, 1e-12)
    for c in range(problem.n):
        m = problem.chain == c
        q = p[m]
        centre = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - centre, full_matrices=False)
        d = np.abs((q - centre) @ vt[1]) * scale[m]
        robust = 1.4826 * np.median(d)
        keep[np.flatnonzero(m)] = d <= max(TRIM_PX, 3.0 * robust)
    counts = np.bincount(problem.chain[keep], minlength=problem.n).astype(np.float64)
    ratio = counts / np.maximum(np.bincount(problem.chain, minlength=problem.n), 1)
    out = _Problem(problem.points[keep], problem.chain[keep], problem.counts * ratio, int(problem.width))
    return out


def _displacement_sigma(cov: np.ndarray) -> float:
    """Largest 1-sigma radial displacement (px at REPORT_WIDTH) over the 16:9 frame for a (k1, k2) covariance."""
    r = np.linspace(0.0, CORNER_RADIUS_16_9, 64)
    g = np.stack([r**3, r**5], axis=1) * REPORT_WIDTH
    var = np.einsum("ni,ij,nj->n", g, cov, g)
    return float(np.sqrt(max(float(var.max()), 0.0)))


def _refine(problem: _Problem, k1: float, k2: float, prior_k1: float | None) -> tuple[float, float, np.ndarray | None]:
    """Newton steps on a quadratic fitted to a 3 x 3 stencil of the cost -> (k1, k2, Hessian)."""
    h1, h2 = 0.02, 0.02
    hessian = None
    for _ in range(6):
        d1, d2 = np.meshgrid([-h1, 0.0, h1], [-h2, 0.0, h2])
        c = _cost(problem, k1 + d1.ravel(), k2 + d2.ravel(), prior_k1).reshape(3, 3)
        if not np.isfinite(c).all():
            h1, h2 = h1 / 2, h2 / 2
            continue
        g = np.array([(c[1, 2] - c[1, 0]) / (2 * h1), (c[2, 1] - c[0, 1]) / (2 * h2)])
        a = (c[1, 2] - 2 * c[1, 1] + c[1, 0]) / h1**2
        b = (c[2, 1] - 2 * c[1, 1] + c[0, 1]) / h2**2
        ab = (c[2, 2] - c[2, 0] - c[0, 2] + c[0, 0]) / (4 * h1 * h2)
        hessian = np.array([[a, ab], [ab, b]])
        try:
            eig = np.linalg.eigvalsh(hessian)
            step = -np.linalg.solve(hessian, g) if eig.min() > 0 else -g / max(abs(eig).max(), 1e-9)
        except np.linalg.LinAlgError:
            break
        # limit the step to the trust region, and accept it only if the cost falls
        scale = min(1.0, 0.1 / max(np.abs(step).max(), 1e-12))
        step = step * scale
        accepted = False
        for _ in range(4):
            trial = _cost(problem, np.array([k1 + step[0]]), np.array([k2 + step[1]]), prior_k1)[0]
            if trial <= c[1, 1]:
                k1, k2 = k1 + float(step[0]), k2 + float(step[1])
                accepted = True
                break
            step = step / 4
        if not accepted or np.abs(step).max() < 1e-4:
            h1, h2 = max(h1 / 2, 0.004), max(h2 / 2, 0.004)
            if not accepted:
                break
    return k1, k2, hessian


def fit_lines(evidence: LineEvidence, prior: tuple[float, float] | None = None) -> LineFit:
    """Fit ``(k1, k2)`` to the chains of ``evidence`` (see the module docstring).

    ``prior``: the CNN's ``(k1, k2)`` (only k1 is used, as a weak prior). Returns a :class:`LineFit`
    with ``ok=False`` (and the prior, or ``(0, 0)``, as the lens) when no chain passes screening.
    """
    fallback = prior if prior is not None else (0.0, 0.0)
    prior_k1 = float(prior[0]) if prior is not None else None
    points, chain, counts = _compact(evidence)
    problem = _Problem(points, chain, counts, evidence.width)
    if problem.n == 0:
        return LineFit(float(fallback[0]), float(fallback[1]), math.inf, 0, 0, False)
    grid = np.arange(K1_RANGE[0], K1_RANGE[1] + 1e-9, K1_STEP)
    mse = problem.chain_mse(grid, manifold_k2(grid))  # (L, C)
    best = np.min(mse, axis=0)
    worst = np.max(np.where(np.isfinite(mse), mse, 0.0), axis=0)
    keep = (best <= STRAIGHT_RMS**2) & (worst >= INFORMATIVE_RMS**2)
    if not keep.any():
        return LineFit(float(fallback[0]), float(fallback[1]), math.inf, 0, 0, False)
    problem = problem.subset(keep)
    candidates = problem.n
    cost = _cost(problem, grid, manifold_k2(grid), prior_k1, mse[:, keep])
    k1 = float(grid[int(np.argmin(cost))])
    k2 = float(manifold_k2(k1))
    problem = _trim(problem, k1, k2)
    k1, k2, hessian = _refine(problem, k1, k2, prior_k1)
    # drop the chains the fitted lens does not straighten (arcs that passed screening, mis-linked
    # chains) and fit again with the rest
    chi = problem.chi2(np.array([k1]), np.array([k2]))[0]
    inliers = chi <= OUTLIER_CHI**2 * max(1.0, float(np.median(chi)))
    if 0 < inliers.sum() < problem.n:
        problem = problem.subset(inliers)
        k1, k2, hessian = _refine(problem, k1, k2, prior_k1)
    chi = problem.chi2(np.array([k1]), np.array([k2]))[0]
    used = int(np.sum(chi <= USED_CHI**2))
    sigma = math.inf
    if hessian is not None:
        try:
            eig = np.linalg.eigvalsh(hessian)
            if eig.min() > 0:
                cov = 2.0 * np.linalg.inv(hessian)
                dof = max(problem.n - 2, 1)
                reduced = float(np.sum(np.minimum(chi, ROBUST_T * 4))) / dof
                cov = cov * max(1.0, reduced)
                sigma = _displacement_sigma(cov)
        except np.linalg.LinAlgError:
            pass
    return LineFit(float(k1), float(k2), sigma, used, candidates, used >= MIN_CHAINS and math.isfinite(sigma))
