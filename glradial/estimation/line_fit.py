"""Robust ``(k1, k2)`` from line chains: the lens that makes the chains straight.

Convention:
    Chains come from :func:`glradial.estimation.lines.detect_chains`: points in lens units of the frame (image
    width = 1, origin at the centre). Residuals are stated in pixels of the **distorted** frame at
    the detection width ``evidence.width`` (``w`` below): for a lens ``k`` a chain's points are
    undistorted with the exact inverse, a total-least-squares line is fitted to them, and the mean
    squared perpendicular distance is scaled back to the distorted frame by the chain's mean
    magnification ``r_d / r_u`` (``e_c(k)``, px²).

Cost (grid over ``k1`` in :data:`K1_RANGE`, refined within :data:`K1_LIMITS`):
    ``sum_c rho(n_c e_c / (SIGMA_POINT² + n_c SIGMA_FLOOR²)) + sum_c rho((v_c / SIGMA_VANISHING)²)
    + sum_g rho(n_g q_g / (SIGMA_POINT² + n_g SIGMA_FLOOR²)) + ((k2 - m(k1)) / K2_PRIOR_SIGMA)²
    + ((k1 - k1_prior) / K1_PRIOR_SIGMA)²``

    * ``n_c`` points of chain ``c``; the per-chain error floor ``SIGMA_FLOOR`` bounds what a long
      chain can claim, and each chain enters once (not once per point), so many short chains near
      the centre, whose residual hardly depends on the lens, cannot outvote a long chain near the
      frame edge, whose residual does.
    * ``v_c`` (px): how far the ends of chain ``c`` miss the least-squares vanishing point of its
      family once undistorted (:mod:`glradial.estimation.pitch_geometry`): families of at least
      :data:`~glradial.estimation.pitch_geometry.MIN_FAMILY_LINES` distinct lines that meet in one
      point at the coarse lens; lines that miss by more than :data:`FAMILY_CHI` sigmas at the first
      fitted lens leave their family before the second fit.
    * ``q_g`` (px²): mean squared Sampson distance of the points of arc group ``g`` (arcs that no
      lens straightens, joined when one ellipse fits them at the coarse lens) from their best conic.
    * ``rho(x) = T log(1 + x / T)``: a chain that no lens straightens (an arc, a curved stand, a
      mis-linked chain) costs at most logarithmically.
    * ``m`` is :func:`glradial.lens.metrics.manifold_k2`: k2 is held loosely to the manifold unless the
      lines pin it; ``k1_prior`` is the CNN's estimate (a weak prior; the fallback when lines are
      missing is the estimator's job).

Screening (before the fit): a chain is kept only if some lens on the manifold over the k1 range
straightens it (RMS at most :data:`STRAIGHT_RMS` px). It enters the straightness cost only if the
choice of lens changes its residual (RMS at least :data:`INFORMATIVE_RMS` px somewhere on the
range); a line through the frame centre is straight under every lens, yet its direction still
counts for its family's vanishing point. Circles, arcs and bowl-shaped stands fail the first test
and are tried as conics.

Uncertainty: the cost's curvature at the minimum (a quadratic fitted to a 3 x 3 stencil) gives a
covariance of ``(k1, k2)``, scaled by the reduced chi² when above 1; :attr:`LineFit.sigma_px` is the
largest standard deviation of the radial displacement over the 16:9 frame, in px at 1920 wide
(:data:`glradial.lens.metrics.REPORT_WIDTH`). It is a raw 1-sigma figure; :mod:`glradial.estimation.net_lines`
turns it into a calibrated 90 % bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..lens import lensfuncs
from ..lens.metrics import CORNER_RADIUS_16_9, REPORT_WIDTH, manifold_k2
from . import decentring, pitch_geometry
from .lines import LineEvidence

#: Range of k1 searched (lens units): real broadcast and pitch cameras reach -0.72.
K1_RANGE = (-1.0, 0.4)
#: The refinement may leave the searched range up to these limits (a lens at k1 = -1.0 is then an
#: interior minimum, not one pinned to the edge of the search).
K1_LIMITS = (-1.3, 0.6)
#: Coarse search step along the manifold (k1, lens units).
K1_STEP = 0.025
#: Points per chain after averaging consecutive points in groups.
MAX_CHAIN_POINTS = 16
#: Per-point localisation noise and per-chain error floor (px of the detection copy).
SIGMA_POINT, SIGMA_FLOOR = 0.25, 0.08
#: Robust loss scale (chi² units) of one chain.
ROBUST_T = 3.0
#: Loose prior of k2 around the manifold, and of k1 around the CNN (lens units).
K2_PRIOR_SIGMA, K1_PRIOR_SIGMA = 0.1, 0.6
#: The refinement stops once an accepted step lowers the cost by less than this (chi² units: a change
#: of 1 is one standard deviation, so 0.01 moves the lens by about a tenth of its own 1-sigma).
REFINE_COST_TOL = 0.01
#: Screening thresholds (px RMS of the detection copy).
STRAIGHT_RMS, INFORMATIVE_RMS = 0.4, 0.7
#: A fit needs at least this many chains that agree with it: one chain cannot be checked against
#: anything (an arc that some lens straightens passes screening on its own).
MIN_CHAINS = 2
#: A chain whose residual at the fitted lens exceeds this many floors is reported as not used.
USED_CHI = 3.0
#: After the first fit, chains above this many times the median chain residual (chi) are dropped.
OUTLIER_CHI = 2.0
#: Points farther than this (px, and 3 robust sigmas) from their chain's line at the coarse lens are dropped.
TRIM_PX = 1.0
#: Vanishing-point term: px (detection copy) a line's ends may miss its family's vanishing point
#: (painted lines are not exactly parallel, the pitch not exactly flat).
SIGMA_VANISHING = 0.5
#: After the first refinement, a line whose ends miss its family's vanishing point by more than this
#: many SIGMA_VANISHING leaves the family.
FAMILY_CHI = 3.0
#: Conics are tried only when fewer informative line chains than this passed screening.
CONIC_BELOW_LINES = 4
#: Arcs (chains no lens straightens) with fewer points are not tried as conics, and only the
#: MAX_ARCS longest are (the centre circle and two penalty arcs give a few each).
MIN_ARC_POINTS, MAX_ARCS = 24, 8


@dataclass(frozen=True)
class LineFit:
    """Result of :func:`fit_lines`.

    Fields (units: lens units for ``k1``, ``k2``; px at 1920 wide, :data:`REPORT_WIDTH`, for
    ``sigma_px`` and ``rms_px``):

    * ``k1``, ``k2``: the lens (the prior, or ``(0, 0)``, when no fit was made);
    * ``sigma_px``: raw 1-sigma of the maximum radial displacement over the 16:9 frame from
      ``cov`` (``inf`` without a fit); :mod:`glradial.estimation.lens_estimate` turns it into a bound;
    * ``chains``: line chains that agree with the fit (chi at most :data:`USED_CHI`);
    * ``candidates``: line chains that passed screening;
    * ``ok``: a fit was made from at least :data:`MIN_CHAINS` agreeing chains and has a finite,
      positive-definite covariance; when false, ``reason`` says why;
    * ``rms_px``: RMS perpendicular residual of the points of the chains used, at the fitted lens
      (distorted frame, px at 1920; ``inf`` without a fit);
    * ``cov``: the ``(k1, k2)`` covariance ``((var k1, cov), (cov, var k2))`` (lens units², from the
      cost's curvature, scaled by the reduced chi² when above 1); ``None`` without a fit;
    * ``condition``: ratio of the largest to the smallest eigenvalue of the cost's Hessian (large:
      k1 and k2 trade off along a valley; ``inf`` without a positive-definite Hessian);
    * ``families``: families of lines that share a vanishing point used in the cost (0, 1 or 2);
    * ``conics``: groups of arcs fitted as one ellipse used in the cost (centre circle, penalty arcs);
    * ``reach``: farthest point of the chains used from the principal point, as a share of the 16:9
      corner radius (a lens read from chains near the centre is extrapolated to the corners);
    * ``difficulty``: ``sigma_px * (1 + 2 / (chains + families + conics)) / max(reach, 0.25)``,
      larger is harder (``inf`` when not ``ok``): a per-frame scale for calibrating a bound;
    * ``reason``: ``""`` when ``ok``; else one of :data:`REASONS` (machine-readable);
    * ``centre_shift_px``: how far the lens moves when decentring terms are fitted with it on the
      chains used (:func:`glradial.estimation.decentring.centre_shift_px`, px at 1920): large where the
      centred model does not hold the frame (a principal point off centre); NaN when not measured.
    """

    k1: float
    k2: float
    sigma_px: float
    chains: int
    candidates: int
    ok: bool
    rms_px: float = math.inf
    cov: tuple[tuple[float, float], tuple[float, float]] | None = None
    condition: float = math.inf
    families: int = 0
    conics: int = 0
    reach: float = 0.0
    difficulty: float = math.inf
    reason: str = ""
    centre_shift_px: float = math.nan


#: Values of :attr:`LineFit.reason` when the fit fails: no chain at all; no chain that some lens
#: straightens and whose residual depends on the lens; fewer than MIN_CHAINS chains agree with
#: the fit; the cost's curvature gives no covariance (flat or saddle).
REASONS = ("no_chains", "no_line_candidates", "too_few_chains", "ill_conditioned")


def _failed(fallback: tuple[float, float], reason: str, candidates: int = 0) -> LineFit:
    return LineFit(float(fallback[0]), float(fallback[1]), math.inf, 0, candidates, False, reason=reason)


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
    """The lens model's exact inverse (:func:`~glradial.lens.lensfuncs.undistort_radius_exact`:
    Drap-Lefevre seed, Newton clamped at the fold radius) for lenses ``k1``, ``k2`` that broadcast
    against the radii (e.g. (L, 1) against (M,) -> (L, M)); NaN where a lens does not reach the radius."""
    r_u, valid = lensfuncs.undistort_radius_exact(r_d, k1, k2)
    return np.where(valid, r_u, np.nan)


class _Problem:
    """Chains of one frame in the form the cost needs (lens units; px = lens * width).

    ``family``: per chain, the vanishing-point family it belongs to (-1: none; set by
    :func:`_families`); ``arcs``: the conic groups (an :class:`_Arcs`) or ``None``;
    ``informative``: per chain, whether the lens changes its straightness (a chain through the
    centre does not, yet its direction counts for its vanishing point)."""

    def __init__(self, points: np.ndarray, chain: np.ndarray, counts: np.ndarray, width: int,
                 family: np.ndarray | None = None, arcs: "_Arcs | None" = None,
                 informative: np.ndarray | None = None) -> None:
        self.points, self.chain, self.counts, self.width = points, chain, counts, float(width)
        self.n = len(counts)
        self.r_d = np.hypot(points[:, 0], points[:, 1])
        self.unit = points / np.maximum(self.r_d, 1e-12)[:, None]
        self.family = np.full(self.n, -1) if family is None else family
        self.arcs = arcs
        self.informative = np.ones(self.n, bool) if informative is None else informative

    def subset(self, keep: np.ndarray) -> "_Problem":
        """Only the chains where ``keep`` (C,) is true (renumbered)."""
        new_index = np.cumsum(keep) - 1
        mask = keep[self.chain]
        return _Problem(self.points[mask], new_index[self.chain[mask]], self.counts[keep], int(self.width),
                        self.family[keep], self.arcs, self.informative[keep])

    def moments(self, k1: np.ndarray, k2: np.ndarray) -> dict:
        """Per lens and chain (L, C): centre ``mx``, ``my``, central second moments ``cxx``, ``cyy``,
        ``cxy`` of the undistorted points (lens units), mean magnification ``mag`` (r_d / r_u) and
        ``invalid`` (L,) where the lens cannot undistort every point."""
        k1 = np.asarray(k1, np.float64).reshape(-1, 1)
        k2 = np.asarray(k2, np.float64).reshape(-1, 1)
        n_lens = len(k1)
        r_u = _undistort_radius(self.r_d[None, :], k1, k2)
        x = self.unit[:, 0] * r_u
        y = self.unit[:, 1] * r_u
        mag = np.where(self.r_d[None, :] > 1e-9, self.r_d[None, :] / np.maximum(r_u, 1e-12), 1.0)
        index = (np.arange(n_lens)[:, None] * self.n + self.chain[None, :]).ravel()
        size = n_lens * self.n
        safe = np.maximum(np.bincount(index, minlength=size), 1)

        def mean(v: np.ndarray) -> np.ndarray:
            return (np.bincount(index, v.ravel(), size) / safe).reshape(n_lens, self.n)

        mx, my = mean(x), mean(y)
        return {"mx": mx, "my": my, "cxx": mean(x * x) - mx * mx, "cyy": mean(y * y) - my * my,
                "cxy": mean(x * y) - mx * my, "mag": mean(mag), "invalid": np.isnan(r_u).any(axis=1)}

    def chain_mse(self, k1: np.ndarray, k2: np.ndarray, m: dict | None = None) -> np.ndarray:
        """Mean squared distorted-frame residual (px²) per lens and chain -> (L, C); inf where invalid."""
        m = self.moments(k1, k2) if m is None else m
        cxx, cyy, cxy = m["cxx"], m["cyy"], m["cxy"]
        lam = 0.5 * (cxx + cyy) - np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        lam = np.maximum(lam, 0.0) * m["mag"] ** 2 * self.width**2
        lam[m["invalid"]] = np.inf
        lam[np.isnan(lam)] = np.inf
        return lam

    def chi2(self, k1: np.ndarray, k2: np.ndarray, mse: np.ndarray | None = None) -> np.ndarray:
        """Per lens and chain ``n_c e_c / (SIGMA_POINT² + n_c SIGMA_FLOOR²)`` -> (L, C) (``mse``:
        :meth:`chain_mse` of these lenses when already computed)."""
        e = self.chain_mse(k1, k2) if mse is None else mse
        return self.counts * e / (SIGMA_POINT**2 + self.counts * SIGMA_FLOOR**2)

    def family_chi2(self, m: dict) -> np.ndarray:
        """Per lens and chain, (px offset of the chain's ends from its family's vanishing point /
        SIGMA_VANISHING)² -> (L, C); 0 for chains in no family."""
        if not (self.family >= 0).any():
            return np.zeros_like(m["mx"])
        if m["invalid"].any():  # such lenses cost inf through chain_mse; keep these rows finite
            m = {key: np.where(m["invalid"][:, None], 0.0, m[key]) for key in ("mx", "my", "cxx", "cyy", "cxy", "mag")}
        normal, offset = pitch_geometry.line_params(m["mx"], m["my"], m["cxx"], m["cyy"], m["cxy"])
        spread = 0.5 * (m["cxx"] + m["cyy"]) + np.sqrt(0.25 * (m["cxx"] - m["cyy"]) ** 2 + m["cxy"] ** 2)
        half = np.sqrt(3.0 * np.maximum(spread, 0.0))  # half-length of a uniform segment
        centre = np.stack([m["mx"], m["my"]], axis=-1)
        off = pitch_geometry.family_residuals(normal, offset, centre, half, self.family)
        return (off * m["mag"] * self.width / SIGMA_VANISHING) ** 2

    def chain_rms_px(self, k1: float, k2: float, used: np.ndarray) -> float:
        """RMS point residual (px at REPORT_WIDTH) of the chains where ``used``, at one lens."""
        mse = self.chain_mse(np.array([k1]), np.array([k2]))[0]
        weight = self.counts * used
        return float(np.sqrt(np.sum(weight * mse) / max(np.sum(weight), 1e-12))) * REPORT_WIDTH / self.width


class _Arcs:
    """Groups of arc points that should lie on one conic once undistorted (lens units)."""

    def __init__(self, points: np.ndarray, group: np.ndarray, counts: np.ndarray, width: float) -> None:
        self.points, self.group, self.counts, self.width = points, group, counts, float(width)
        self.n = len(counts)
        self.r_d = np.hypot(points[:, 0], points[:, 1])
        self.unit = points / np.maximum(self.r_d, 1e-12)[:, None]

    def subset(self, keep: np.ndarray) -> "_Arcs | None":
        if not keep.any():
            return None
        mask = keep[self.group]
        return _Arcs(self.points[mask], (np.cumsum(keep) - 1)[self.group[mask]], self.counts[keep], self.width)

    def mse(self, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
        """Mean squared distorted-frame distance (px²) of each group's points from its best conic,
        per lens -> (L, G); inf where the lens cannot undistort every point."""
        k1 = np.asarray(k1, np.float64).reshape(-1, 1)
        k2 = np.asarray(k2, np.float64).reshape(-1, 1)
        r_u = _undistort_radius(self.r_d[None, :], k1, k2)
        bad = np.isnan(r_u).any(axis=1)
        r_u = np.where(np.isnan(r_u), self.r_d[None, :], r_u)
        pts = self.unit[None, :, :] * r_u[:, :, None]
        rms = pitch_geometry.conic_rms(pts, self.group, self.n)
        mag = np.ones_like(rms)
        for g in range(self.n):
            sel = self.group == g
            mag[:, g] = np.mean(self.r_d[sel] / np.maximum(r_u[:, sel], 1e-12), axis=1)
        out = (rms * mag * self.width) ** 2
        out[bad] = np.inf
        return out

    def chi2(self, k1: np.ndarray, k2: np.ndarray) -> np.ndarray:
        return self.counts * self.mse(k1, k2) / (SIGMA_POINT**2 + self.counts * SIGMA_FLOOR**2)


def _robust(chi: np.ndarray) -> np.ndarray:
    return ROBUST_T * np.log1p(chi / ROBUST_T)


def _cost(problem: _Problem, k1: np.ndarray, k2: np.ndarray, prior_k1: float | None,
          mse: np.ndarray | None = None) -> np.ndarray:
    k1 = np.asarray(k1, np.float64)
    k2 = np.asarray(k2, np.float64)
    m = problem.moments(k1, k2) if mse is None or (problem.family >= 0).any() else None
    chi = problem.chi2(k1, k2, problem.chain_mse(k1, k2, m) if mse is None else mse)
    total = _robust(chi[:, problem.informative]).sum(axis=1)  # the others count for their family only
    total = total + np.where(np.isinf(chi).any(axis=1), np.inf, 0.0)
    if (problem.family >= 0).any():
        total = total + _robust(problem.family_chi2(m)).sum(axis=1)
    if problem.arcs is not None:
        total = total + _robust(problem.arcs.chi2(k1, k2)).sum(axis=1)
    total = total + ((k2 - manifold_k2(k1)) / K2_PRIOR_SIGMA) ** 2
    if prior_k1 is not None:
        total = total + ((k1 - prior_k1) / K1_PRIOR_SIGMA) ** 2
    outside = (k1 < K1_LIMITS[0]) | (k1 > K1_LIMITS[1])
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
        robust = 1.4826 * _median(d)
        keep[np.flatnonzero(m)] = d <= max(TRIM_PX, 3.0 * robust)
    counts = np.bincount(problem.chain[keep], minlength=problem.n).astype(np.float64)
    ratio = counts / np.maximum(np.bincount(problem.chain, minlength=problem.n), 1)
    return _Problem(problem.points[keep], problem.chain[keep], problem.counts * ratio, int(problem.width),
                    problem.family, problem.arcs, problem.informative)


def _median(a: np.ndarray) -> float:
    """``np.median`` of a 1-D float array without NaN (the same value: the middle element, or the
    mean of the middle two), by one partial sort and without np.median's overhead (hot in :func:`_trim`)."""
    half = len(a) // 2
    if len(a) == 0:
        return float("nan")
    if len(a) % 2:
        return np.partition(a, half)[half]
    part = np.partition(a, (half - 1, half))
    return (part[half - 1] + part[half]) / 2.0


def _displacement_sigma(cov: np.ndarray) -> float:
    """Largest 1-sigma radial displacement (px at REPORT_WIDTH) over the 16:9 frame for a (k1, k2) covariance."""
    r = np.linspace(0.0, CORNER_RADIUS_16_9, 64)
    g = np.stack([r**3, r**5], axis=1) * REPORT_WIDTH
    var = np.einsum("ni,ij,nj->n", g, cov, g)
    return float(np.sqrt(max(float(var.max()), 0.0)))


def _refine(problem: _Problem, k1: float, k2: float, prior_k1: float | None,
            h: float = 0.02) -> tuple[float, float, np.ndarray | None]:
    """Newton steps on a quadratic fitted to a 3 x 3 stencil (half-width ``h``, shrinking to 0.004)
    of the cost -> (k1, k2, Hessian); stops once a step is below 1e-4 on the smallest stencil or
    lowers the cost by less than REFINE_COST_TOL."""
    h1, h2 = h, h
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
        # the step, then a quarter of it, ... (one batched evaluation): the first that lowers the cost
        steps = step[None, :] * (0.25 ** np.arange(4))[:, None]
        trial = _cost(problem, k1 + steps[:, 0], k2 + steps[:, 1], prior_k1)
        falls = np.flatnonzero(trial <= c[1, 1])
        accepted = len(falls) > 0
        step = steps[falls[0]] if accepted else steps[-1] / 4
        if accepted:
            k1, k2 = k1 + float(step[0]), k2 + float(step[1])
            if c[1, 1] - trial[falls[0]] < REFINE_COST_TOL:  # converged: the step changed the cost by a trifle
                break
        if not accepted or np.abs(step).max() < 1e-4:
            if not accepted or max(h1, h2) <= 0.004:
                break
            h1, h2 = max(h1 / 4, 0.004), max(h2 / 4, 0.004)
    return k1, k2, hessian


def _grid_minimum(grid: np.ndarray, cost: np.ndarray) -> float:
    """k1 of the smallest ``cost`` on the evenly spaced ``grid``, refined by the parabola through it
    and its two neighbours (the coarse lens decides which points are trimmed)."""
    i = int(np.argmin(cost))
    if 0 < i < len(grid) - 1 and np.isfinite(cost[i - 1:i + 2]).all():
        a, b, c = cost[i - 1:i + 2]
        curvature = a - 2 * b + c
        if curvature > 0:
            return float(grid[i] + 0.5 * (a - c) / curvature * (grid[1] - grid[0]))
    return float(grid[i])


def _arc_candidates(problem: _Problem, best: np.ndarray) -> np.ndarray:
    """Chains that no lens straightens (``best`` RMS² above STRAIGHT_RMS²) with enough points to be
    tried as arcs of a conic."""
    ids = np.flatnonzero((best > STRAIGHT_RMS**2) & (problem.counts >= MIN_ARC_POINTS))
    return ids[np.argsort(-problem.counts[ids], kind="stable")[:MAX_ARCS]]


def _conics(full: _Problem, arc_ids: np.ndarray, k1: float, k2: float, grid: np.ndarray) -> _Arcs | None:
    """Arcs of ``full`` (chains ``arc_ids``) joined into ellipses at lens ``(k1, k2)``
    (:func:`glradial.estimation.pitch_geometry.group_arcs`), kept where some lens on the manifold
    makes them a conic within STRAIGHT_RMS and the lens choice matters (INFORMATIVE_RMS)."""
    if len(arc_ids) < 2:
        return None
    arcs = []
    for c in arc_ids:
        p = full.points[full.chain == c]
        r_u = _undistort_radius(np.hypot(p[:, 0], p[:, 1]), np.float64(k1), np.float64(k2))
        if np.isnan(r_u).any():
            return None
        arcs.append(p / np.maximum(np.hypot(p[:, 0], p[:, 1]), 1e-12)[:, None] * r_u[:, None])
    labels = pitch_geometry.group_arcs(arcs)
    multi = np.bincount(labels) >= 2  # one arc of <= 30 degrees of turn fits a conic under any lens
    if not multi.any():
        return None
    sel = multi[labels]
    ids, groups = arc_ids[sel], (np.cumsum(multi) - 1)[labels[sel]]
    mask = np.isin(full.chain, ids)
    group_of_chain = dict(zip(ids.tolist(), groups.tolist()))
    group = np.array([group_of_chain[c] for c in full.chain[mask].tolist()], np.intp)
    counts = np.bincount(groups, full.counts[ids], int(multi.sum()))
    result = _Arcs(full.points[mask], group, counts, full.width)
    mse = result.mse(grid, manifold_k2(grid))
    best, worst = np.min(mse, axis=0), np.max(np.where(np.isfinite(mse), mse, 0.0), axis=0)
    return result.subset((best <= STRAIGHT_RMS**2) & (worst >= INFORMATIVE_RMS**2))


def _families(problem: _Problem, k1: float, k2: float) -> np.ndarray:
    """Vanishing-point family of each chain of ``problem`` at lens ``(k1, k2)`` (-1: none)."""
    m = {key: v[0] if key != "invalid" else v for key, v in problem.moments(np.array([k1]), np.array([k2])).items()}
    if m["invalid"].any():
        return np.full(problem.n, -1)
    normal, offset = pitch_geometry.line_params(m["mx"], m["my"], m["cxx"], m["cyy"], m["cxy"])
    spread = 0.5 * (m["cxx"] + m["cyy"]) + np.sqrt(0.25 * (m["cxx"] - m["cyy"]) ** 2 + m["cxy"] ** 2)
    half = np.sqrt(3.0 * np.maximum(spread, 0.0))
    centre = np.stack([m["mx"], m["my"]], axis=-1)
    return pitch_geometry.find_families(normal, offset, centre, half)


def _family_inliers(problem: _Problem, k1: float, k2: float) -> np.ndarray:
    """Family labels with the lines that miss their vanishing point at lens ``(k1, k2)`` by more
    than FAMILY_CHI sigmas taken out, and families left with fewer than the lines they need dropped
    (lines that met by chance at the coarse lens, not parallels on the pitch)."""
    chi = problem.family_chi2(problem.moments(np.array([k1]), np.array([k2])))[0]
    labels = np.where(chi <= FAMILY_CHI**2, problem.family, -1)
    for f in np.unique(labels[labels >= 0]):
        if np.sum(labels == f) < pitch_geometry.MIN_FAMILY_LINES:
            labels[labels == f] = -1
    return labels


def _covariance(problem: _Problem, hessian: np.ndarray | None, chi: np.ndarray) -> tuple[np.ndarray | None, float]:
    """(k1, k2) covariance from the cost's Hessian (scaled by the reduced chi² when above 1) and the
    Hessian's condition number; ``(None, inf)`` when it is not positive definite."""
    if hessian is None or not np.isfinite(hessian).all():
        return None, math.inf
    eig = np.linalg.eigvalsh(hessian)
    if eig.min() <= 0:
        return None, math.inf
    dof = max(int(problem.informative.sum()) - 2, 1)  # the chains in the straightness cost
    reduced = float(np.sum(np.minimum(chi[problem.informative], ROBUST_T * 4))) / dof
    return 2.0 * np.linalg.inv(hessian) * max(1.0, reduced), float(eig.max() / eig.min())


def _centre_shift(problem: _Problem, used: np.ndarray, k1: float, k2: float) -> float:
    """:func:`glradial.estimation.decentring.centre_shift_px` of the chains where ``used`` (C,), with the
    fit's per-chain weights (shared among each chain's points) and its k2 prior."""
    mask = used[problem.chain]
    per_chain = np.bincount(problem.chain[mask], minlength=problem.n)[used]
    counts = problem.counts[used]
    weight = counts / (np.maximum(per_chain, 1) * (SIGMA_POINT**2 + counts * SIGMA_FLOOR**2))
    chain = (np.cumsum(used) - 1)[problem.chain[mask]]
    return decentring.centre_shift_px(problem.points[mask], chain, weight, problem.width, k1, k2, K2_PRIOR_SIGMA)


def _result(problem: _Problem, k1: float, k2: float, hessian, candidates: int, family_counts: bool = False) -> LineFit:
    """The :class:`LineFit` of a finished fit (diagnostics, ``ok`` and ``reason``; with
    ``family_counts`` a vanishing-point family counts as one agreeing chain towards MIN_CHAINS)."""
    chi = problem.chi2(np.array([k1]), np.array([k2]))[0]
    used_mask = (chi <= USED_CHI**2) & problem.informative
    used = int(used_mask.sum())
    cov, condition = _covariance(problem, hessian, chi)
    sigma = _displacement_sigma(cov) if cov is not None else math.inf
    families = int(sum(np.sum(problem.family == f) >= pitch_geometry.MIN_FAMILY_LINES for f in range(pitch_geometry.MAX_FAMILIES)))
    conics = problem.arcs.n if problem.arcs is not None else 0
    used_points = used_mask[problem.chain]
    reach = float(problem.r_d[used_points].max() / CORNER_RADIUS_16_9) if used_points.any() else 0.0
    agreeing = used + (families if family_counts else 0)
    ok = agreeing >= MIN_CHAINS and math.isfinite(sigma)
    reason = "" if ok else ("too_few_chains" if agreeing < MIN_CHAINS else "ill_conditioned")
    difficulty = sigma * (1.0 + 2.0 / max(used + families + conics, 1)) / max(reach, 0.25) if ok else math.inf
    shift = _centre_shift(problem, used_mask, k1, k2) if ok else math.nan
    return LineFit(float(k1), float(k2), sigma, used, candidates, ok, problem.chain_rms_px(k1, k2, used_mask),
                   None if cov is None else (tuple(map(float, cov[0])), tuple(map(float, cov[1]))),
                   condition, families, conics, reach, difficulty, reason, shift)


def fit_lines(evidence: LineEvidence, prior: tuple[float, float] | None = None, family_counts: bool = False) -> LineFit:
    """Fit ``(k1, k2)`` to the chains of ``evidence`` (see the module docstring).

    ``prior``: the CNN's ``(k1, k2)`` (only k1 is used, as a weak prior). ``family_counts``: a family
    of lines sharing a vanishing point counts as one agreeing chain towards :data:`MIN_CHAINS` (mowing
    stripes run towards their vanishing point, nearly radial, so few of them are bent enough to
    count on their own; :mod:`glradial.estimation.soft_lines`). Returns a :class:`LineFit`
    with ``ok=False``, a ``reason`` (and the prior, or ``(0, 0)``, as the lens) when no fit was made.
    """
    fallback = prior if prior is not None else (0.0, 0.0)
    prior_k1 = float(prior[0]) if prior is not None else None
    full = _Problem(*_compact(evidence), evidence.width)
    if full.n == 0:
        return _failed(fallback, "no_chains")
    grid = np.arange(K1_RANGE[0], K1_RANGE[1] + 1e-9, K1_STEP)
    mse = full.chain_mse(grid, manifold_k2(grid))  # (L, C)
    best = np.min(mse, axis=0)
    worst = np.max(np.where(np.isfinite(mse), mse, 0.0), axis=0)
    keep = best <= STRAIGHT_RMS**2
    full.informative = worst >= INFORMATIVE_RMS**2
    if not (keep & full.informative).any():
        return _failed(fallback, "no_line_candidates")
    problem = full.subset(keep)
    candidates = int(problem.informative.sum())
    k1 = _grid_minimum(grid, _cost(problem, grid, manifold_k2(grid), prior_k1, mse[:, keep]))
    k2 = float(manifold_k2(k1))
    problem = _trim(problem, k1, k2)
    problem.family = _families(problem, k1, k2)
    problem = problem.subset(problem.informative | (problem.family >= 0))  # the rest would weigh nothing
    if candidates < CONIC_BELOW_LINES:  # where lines are few: conics added nothing measurable beside many
        problem.arcs = _conics(full, _arc_candidates(full, best), k1, k2, grid)
    k1, k2, hessian = _refine(problem, k1, k2, prior_k1)
    # drop the chains the fitted lens does not straighten (arcs that passed screening, mis-linked
    # chains) and fit again with the rest
    chi = problem.chi2(np.array([k1]), np.array([k2]))[0]
    inliers = chi <= OUTLIER_CHI**2 * max(1.0, float(np.median(chi[problem.informative])))
    families = _family_inliers(problem, k1, k2)
    if (0 < (inliers & problem.informative).sum() and inliers.sum() < problem.n) or (families != problem.family).any():
        problem.family = families
        problem = problem.subset(inliers)
        k1, k2, hessian = _refine(problem, k1, k2, prior_k1, h=0.008)
    return _result(problem, k1, k2, hessian, candidates, family_counts)
