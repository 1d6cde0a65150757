"""One lens per shot: a joint robust fit over the line chains of all sampled frames of a shot and
the frame-to-frame matches between them.

Model (width-normalised lens, DESIGN.md): a static or panning camera has one lens ``(k1, k2)``. When
the picture zooms (the log scale ``z`` of each sampled frame, measured from frame-to-frame
homographies, spans more than :data:`ZOOM_MIN`), the lens follows the zoom as a smooth function of
it: ``k1(z) = a0 + a1 z + a2 z^2`` and ``k2(z) = m(k1(z)) + b0`` (``m`` the manifold of real
lenses, :func:`glradial.lens.metrics.manifold_k2`; ``z`` centred on the shot's mid zoom). A quadratic in
focal length corrects broadcast zooms as well as per-frame models (Alvarez, Gomez & Henriquez, JMIV
2012); ``a2`` is held loosely to 0 (:data:`ZOOM_CURVE_SIGMA`).

Residuals (their squares summed, minimised by damped Newton steps on the cost's curvature,
:meth:`_Problem.solve`; Cauchy loss of scale ``sqrt(ROBUST_T)`` chi, so a chain
or match that no lens explains costs at most logarithmically):

* **lines** -- one per chain, as in :mod:`glradial.estimation.line_fit`: the chain undistorted with its frame's
  lens, a total-least-squares line through it, ``chi = sqrt(n e / (SIGMA_POINT^2 + n SIGMA_FLOOR^2))``
  (``e`` the mean squared distance, px of the detection copy, scaled back to the distorted frame).
  Chains that no lens on the manifold straightens, or that no lens choice changes, are screened out
  first; after a first fit, chains far above the median are dropped.
* **frame-to-frame** -- one per match: both frames undistorted with their lenses, the least-squares
  homography of the pair (solved inside the residual: variable projection), the transfer error
  over :data:`MATCH_SIGMA` px of the matching copy, weighted so one pair counts as at most
  :data:`MATCH_CAP` points. Only under the right lens does one homography fit them (a camera turning
  and zooming about its centre); a static camera gives identity pairs that say nothing.
* **priors** -- ``k1`` loosely to the per-frame estimates' median (:data:`K1_PRIOR_SIGMA`), ``b0``
  to 0 (:data:`K2_PRIOR_SIGMA`).

Uncertainty (``uncertainty_px``, a ~90 % bound on the maximum displacement error over the 16:9
frame, px at 1920, the meaning of :class:`glradial.LensEstimate`): the fit's covariance (the inverse
curvature of its cost, :func:`_hessian`, scaled by the chains' reduced chi^2, whatever its size: the
noise level the lines show) gives a 1-sigma displacement ``s``. The frames of one shot
are **not** independent evidence (a static camera shows the same lines in every frame), so ``s`` is
multiplied by ``sqrt(S / V)``: ``S`` sampled frames count as ``V`` independent views, ``V = 1 +`` the
new picture the camera brought into view (pan in frame widths plus the zoom's log range), at most
``S``. A static shot of 100 frames is then as sure as its single best frame, not 10x surer. The bound
is :data:`BOUND_SCALE` ``x`` that plus :data:`BOUND_FLOOR_PX`; for a static shot (no zoom, a pan
under :data:`PAN_MIN`) :data:`STATIC_BOUND_SCALE` instead. The two are calibrated apart (split
conformal, ``bench/eval_shots.py --calibrate``, on the clips of ``scripts/make_clips.py``; docs/eval/shots.md,
"The bound"): a static shot's lens rests on the lines of one view alone, a moving shot's also
on its frame pairs and, zooming, on a lens interpolated between its samples.

The per-frame estimates read the shot too: when they all state a bound (a
:class:`glradial.LensEstimate`, calibrated per frame by the trust model) and their median, stating
their median bound plus their spread (the furthest of them from the median: a zooming lens's
range, or estimators that disagree), is surer than the joint fit, the shot takes it (the fit's
chains stand in for no extra evidence there: the estimates read the same lines, through the
single-frame fit's fuller model). A static shot (one view, one lens) takes its frames' median, stating
their median bound (plus their typical scatter where they scatter further than they state): it is never worse than its frames (on the real wide camera the joint fit of
its pooled chains read 8.9 px where its frames read 5.9, docs/eval/shots.md); it falls back to the
joint fit (whichever of the two states less) only when that median is doubtful (most frames doubtful,
or its bound above the run's threshold). A fit that
few chains leave loose (a pure zoom: its frame pairs tie the lens at one zoom to the next, not the
lens itself) does not stand. A zooming shot needs estimates :data:`ZOOM_FALLBACK_RATIO` times
surer (their one lens, median and bound as above): their one lens cannot follow the zoom, and when
they win the shot reads them as a lens that does where they allow (below). The choice itself is
made on their one lens's bound, as before: the two readings' bounds are not calibrated alike.

**A zoom read by its frames follows the zoom** (:func:`_zoom_of_frames`): with
:data:`ZOOM_FRAMES_MIN` estimates or more (two with frame pairs, three without) (a sample with few lines gets one of its own,
:data:`glradial.video.shot_evidence.FEW_CHAINS`), ``k1`` is a line in the measured log zoom, its
level the estimates' weighted mean and its slope the one under which the frame pairs fit (they tie
the lens at one zoom to the lens at the next); its bound carries the level's uncertainty to every
zoom the shot's frames reach. With fewer estimates, one lens (their median), which cannot follow
the zoom: it stays doubtful (:func:`judged_by_benefit`).

Doubt (reason strings are machine-readable): ``no_geometry`` (fewer than :data:`MIN_CHAINS` chains
pass screening and the camera did not pan :data:`PAN_MIN`: nothing but the per-frame
estimates fixes the lens: the shot takes them as above, doubtful when their bound exceeds the
threshold or when they say so themselves), ``uncertain`` (bound above the run's threshold),
``fold_over`` (the lens folds over inside the frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import ndtri

from ..estimation.line_fit import (
    K1_PRIOR_SIGMA,
    K2_PRIOR_SIGMA,
    OUTLIER_CHI,
    ROBUST_T,
    SIGMA_FLOOR,
    SIGMA_POINT,
    STRAIGHT_RMS,
)
from ..estimation.lines import LineEvidence
from ..estimation.trust import shift_px
from ..lens.lens import Lens
from ..lens.lensfuncs import undistort_radius_exact
from ..lens.metrics import CORNER_RADIUS_16_9, REPORT_WIDTH, manifold_k2, max_displacement_px
from .frame_motion import Matches, homographies_of
from .lens_track import DOUBTFUL_PX

__all__ = ["ShotSample", "ShotEvidence", "FittedShotLens", "fit_shot", "joint_fit", "load_solver", "ZOOM_MIN", "BOUND_SCALE",
           "STATIC_BOUND_SCALE", "BOUND_FLOOR_PX"]

#: a shot whose sampled log zoom spans more than this (about 6 % in focal length) gets the zoom model
ZOOM_MIN = 0.06
#: loose prior of the zoom model's curvature a2 (lens units per log-zoom^2)
ZOOM_CURVE_SIGMA = 0.5
#: localisation noise of a tracked corner (px of the matching copy)
MATCH_SIGMA = 0.3
#: one pair of frames counts as at most this many independent matches (the points of one pair share
#: the tracker's and the homography's errors)
MATCH_CAP = 60
#: points per chain after averaging consecutive points in groups; and the residual range (px of the
#: detection copy, RMS) over the lenses of the manifold below which a chain says too little about
#: the lens to enter. The shot fit's own values (the single-frame fit of
#: :mod:`glradial.estimation.line_fit` keeps 16 points and 0.7 px): pooled over many frames, the
#: weakly curved chains it admits add their systematic error more than their information.
MAX_CHAIN_POINTS = 32
INFORMATIVE_RMS = 1.0
#: typical size of each parameter (a0, a1, a2, b0; static: a0, b0) for the solver's steps
PARAMETER_SCALE = (0.05, 0.2, 0.5, 0.02)
#: the solver (:meth:`_Problem.solve`) stops when a step gains less than this fraction of the cost,
#: or moves less than SOLVE_XTOL (units of PARAMETER_SCALE), or after SOLVE_MAX_STEPS trial steps
SOLVE_FTOL, SOLVE_XTOL, SOLVE_MAX_STEPS = 1e-8, 1e-5, 60
#: two zoom starts whose costs differ by less than this fraction reached one minimum (:func:`_solve_zoom`)
SAME_MINIMUM = 1e-6
#: finite-difference step of the cost's curvature (:func:`_hessian`), in units of PARAMETER_SCALE
HESSIAN_STEP = 0.02
#: grid of k1 (on the manifold) for screening chains and seeding the fit
K1_GRID = np.arange(-1.0, 0.4 + 1e-9, 0.05)
#: calibrated multiplier from the 1-sigma displacement (redundancy-corrected) to the 90 % bound, and
#: the floor added to it (px at 1920): the error of a frame's own residual distortion and of the
#: model (see the module docstring and docs/eval/shots.md)
BOUND_SCALE = 1.02
BOUND_FLOOR_PX = 1.0
#: the same multiplier for a static shot (not zooming, panned less than :data:`PAN_MIN`), calibrated
#: apart (docs/eval/shots.md, "The bound"): its lens rests on the lines of one view alone, a
#: moving shot's also on its frame pairs and, zooming, on a lens that follows the zoom between samples
#: (the bound covers every frame, the fit sees only the samples)
STATIC_BOUND_SCALE = 0.59
#: stated bound when the shot has no geometric evidence (px at 1920): the CNN's alone
NO_GEOMETRY_PX = 16.0
#: a zooming shot takes its per-frame estimates instead of the joint fit only when they state a
#: bound this many times smaller: one lens for the whole zoom cannot follow it (their spread, in
#: their bound, only covers that), so the zoom model stands unless the lines leave it loose
ZOOM_FALLBACK_RATIO = 2.0
#: a zoom read by its per-frame estimates follows the zoom (:func:`_zoom_of_frames`) when at least
#: this many of them state a bound: with frame pairs (they give the slope, the estimates the level),
#: without (the estimates give both); either way their residual about the model then checks it
ZOOM_FRAMES_MIN = (2, 3)
#: the slopes of k1 per unit log zoom a zoom read by its frames may take (:func:`_slope_of_pairs`)
#: and the grid they are first searched on (0.1 apart), and the step in its level (k1) by which the slope's dependence on the level is measured
SLOPE_RANGE, SLOPE_GRID = (-2.0, 2.0), 41
LEVEL_STEP = 0.01
#: a stated ~90 % bound over this is its 1-sigma (the two-sided 90 % point of a normal)
Z90 = float(ndtri(0.95))
#: a shot has geometric evidence of its lens when at least this many chains pass screening...
MIN_CHAINS = 2
#: ...or the camera panned at least this far (frame widths). A static camera's frame pairs say
#: nothing, and a pure zoom about the centre only ties the lens at one zoom to the lens at another
#: (the map between the frames is radial: any lens at the first zoom has a matching one at the
#: second), so neither reads the lens without lines.
PAN_MIN = 0.1


@dataclass(frozen=True)
class ShotSample:
    """One sampled frame of a shot: its index, its line chains (``None``: not detected) and the
    per-frame estimate (a :class:`glradial.Lens` or a :class:`glradial.LensEstimate`; ``None``: none)."""

    frame: int
    evidence: LineEvidence | None = None
    estimate: Lens | None = None


@dataclass
class ShotEvidence:
    """What one shot shows: ``samples`` in frame order, ``pairs`` ``(i, j, Matches)`` between samples
    ``i`` and ``j``, ``zoom`` the log scale of every sample relative to the first (0 without
    motion evidence), ``travel`` the new picture brought into view (frame widths; pans add their
    centre shift, zooms their |log scale| change) and ``pan`` the pans' part of it."""

    samples: list[ShotSample] = field(default_factory=list)
    pairs: list[tuple[int, int, Matches]] = field(default_factory=list)
    zoom: list[float] = field(default_factory=list)
    travel: float = 0.0
    pan: float = 0.0

    def log_zooms(self) -> np.ndarray:
        """``zoom`` as an array, one per sample (zeros when the motion evidence does not cover
        every sample)."""
        n = len(self.samples)
        return np.asarray(self.zoom if len(self.zoom) == n else [0.0] * n, np.float64)

    def camera(self) -> str:
        """How the camera moved: "zoom" (the sampled log zoom spans more than :data:`ZOOM_MIN`: the
        lens follows the zoom), "pan" (panned at least :data:`PAN_MIN` frame widths) or "static"
        (its bound is calibrated apart, :data:`STATIC_BOUND_SCALE`)."""
        if float(np.ptp(self.log_zooms())) > ZOOM_MIN:
            return "zoom"
        return "pan" if self.pan >= PAN_MIN else "static"


def _estimates(samples: list[ShotSample]) -> list[Lens]:
    """The samples' per-frame estimates, in frame order, leaving out samples without one."""
    return [s.estimate for s in samples if s.estimate is not None]


@dataclass(frozen=True)
class FittedShotLens:
    """The lens of one shot (see the module docstring). ``theta`` the model's parameters
    (``[a0, b0]`` or ``[a0, a1, a2, b0]``), ``centre`` the log zoom they are centred on, ``chains``
    and ``matches`` the evidence that agreed with the fit, ``views`` the independent views counted;
    ``source`` "joint" (the joint fit) or "frames" (the per-frame estimates), ``sigma_px`` the joint
    fit's 1-sigma displacement (px at 1920; NaN for "frames") and ``static`` whether its bound is a
    static shot's (:data:`STATIC_BOUND_SCALE`)."""

    theta: tuple[float, ...]
    centre: float
    uncertainty_px: float
    doubtful: bool
    reason: str
    chains: int
    matches: int
    views: float
    zooming: bool
    source: str = "joint"
    sigma_px: float = math.nan
    static: bool = False

    def lens_at(self, log_zoom: float | np.ndarray) -> np.ndarray:
        """``(k1, k2)`` at the log zoom(s) given (``(..., 2)``)."""
        return _lens(np.asarray(self.theta, np.float64), np.asarray(log_zoom, np.float64) - self.centre)


def load_solver() -> None:
    """Import ``scipy.optimize`` (the bounded 1-D search of a zoom read by its frames,
    :func:`_slope_of_pairs`; about half a second of CPU the first time) now, e.g. on a worker thread
    while the first frames decode, rather than at the first such shot's fit. (The joint fit's own
    solver is :meth:`_Problem.solve`, no import.)"""
    import scipy.optimize  # noqa: F401


def _lens(theta: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``(k1, k2)`` at the log zooms ``z`` (``(..., 2)``); ``theta`` one parameter vector, or ``(K,
    n)`` of them against ``z`` ``(S,)`` (-> ``(K, S, 2)``)."""
    theta = np.asarray(theta, np.float64)
    t = [theta[..., i, None] if theta.ndim > 1 else theta[i] for i in range(theta.shape[-1])]
    if len(t) == 2:
        k1 = np.broadcast_to(t[0], np.broadcast_shapes(np.shape(t[0]), np.shape(z))).astype(np.float64)
        return np.stack([k1, manifold_k2(k1) + t[1]], axis=-1)
    k1 = t[0] + t[1] * z + t[2] * z * z
    return np.stack([k1, manifold_k2(k1) + t[3]], axis=-1)


class _Undistort:
    """Undistorts a fixed set of points, each with the lens of its sample, for one lens array after
    another: :func:`glradial.lens.lensfuncs.undistort_radius_exact` on the radii laid out one row per
    sample (padded with 0, a fixed point of its Newton steps), so the per-lens work is done once
    per sample instead of once per point (and, where every sample has one lens, the radii as they
    are). The same arithmetic, element by element, as
    :func:`~glradial.lens.lensfuncs.undistort_point_exact` with that sample's lens."""

    def __init__(self, points: np.ndarray, sample: np.ndarray) -> None:
        self.points = np.asarray(points, np.float64)
        self.r_d = np.sqrt(np.sum(self.points * self.points, axis=-1))
        self.rows = np.asarray(sample, np.intp)
        counts = np.bincount(self.rows, minlength=1)
        order = np.argsort(self.rows, kind="stable")
        self.cols = np.empty_like(self.rows)
        self.cols[order] = np.arange(len(order)) - (np.cumsum(counts) - counts)[self.rows[order]]
        self.padded = np.zeros((len(counts), int(counts.max())))
        self.padded[self.rows, self.cols] = self.r_d

    def __call__(self, lenses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(p_u, valid)`` of the points, point ``n`` undistorted with ``lenses[sample[n]]``
        (``lenses`` ``(S, 2)``, or ``(K, S, 2)`` for K lens sets at once: ``(K, N, 2)``, ``(K, N)``)."""
        rows = len(self.padded)
        if np.all(lenses[..., :rows, :] == lenses[..., :1, :]):  # one lens per set (not zooming): no padding
            r_u, valid = undistort_radius_exact(self.r_d, lenses[..., 0, 0:1], lenses[..., 0, 1:2])
        else:
            r_u, valid = undistort_radius_exact(self.padded, lenses[..., :rows, 0:1], lenses[..., :rows, 1:2])
            r_u, valid = r_u[..., self.rows, self.cols], valid[..., self.rows, self.cols]
        scale = np.where(self.r_d > 0.0, r_u / np.where(self.r_d > 0.0, self.r_d, 1.0), 1.0)
        return self.points * scale[..., None], valid


class _Chains:
    """The chains of all sampled frames, compacted (as in line_fit) and grouped by sample."""

    def __init__(self, samples: list[ShotSample]) -> None:
        pts, chain, sample, counts, widths = [], [], [], [], []
        for s, item in enumerate(samples):
            if item.evidence is None:
                continue
            for c in item.evidence.chains:
                groups = min(MAX_CHAIN_POINTS, len(c.points))
                edges = np.linspace(0, len(c.points), groups + 1).astype(np.intp)
                pts.append(np.add.reduceat(c.points, edges[:-1], axis=0) / np.diff(edges)[:, None])
                chain.append(np.full(groups, len(counts)))
                sample.append(s)
                counts.append(len(c.points))
                widths.append(item.evidence.width)
        self.points = np.concatenate(pts) if pts else np.zeros((0, 2))
        self.chain = np.concatenate(chain) if chain else np.zeros(0, np.intp)
        self.sample = np.asarray(sample, np.intp)
        self.counts = np.asarray(counts, np.float64)
        self.width = np.asarray(widths, np.float64)

    @property
    def n(self) -> int:
        return len(self.counts)

    def subset(self, keep: np.ndarray) -> "_Chains":
        out = object.__new__(_Chains)
        index = np.flatnonzero(keep)
        renumber = np.full(self.n, -1)
        renumber[index] = np.arange(len(index))
        point_keep = keep[self.chain]
        out.points, out.chain = self.points[point_keep], renumber[self.chain[point_keep]]
        out.sample, out.counts, out.width = self.sample[index], self.counts[index], self.width[index]
        return out

    def chi2(self, lenses: np.ndarray) -> np.ndarray:
        """Per-chain chi^2 with sample ``s`` undistorted by ``lenses[s]`` (NaN where the lens cannot);
        ``lenses`` ``(S, 2)``, or ``(K, S, 2)`` (-> ``(K, chains)``)."""
        if self.n == 0:
            return np.zeros(np.shape(lenses)[:-2] + (0,))
        if getattr(self, "_undistort", None) is None:
            self._undistort = _Undistort(self.points, self.sample[self.chain])
        r_d = np.hypot(self.points[:, 0], self.points[:, 1])
        p_u, valid = self._undistort(lenses)
        r_u = np.hypot(p_u[..., 0], p_u[..., 1])
        mag = np.where(r_u > 1e-9, r_d / np.maximum(r_u, 1e-9), 1.0)
        starts = np.flatnonzero(np.r_[True, np.diff(self.chain) != 0])
        size = np.diff(np.r_[starts, len(self.chain)]).astype(np.float64)
        mean = np.add.reduceat(p_u, starts, axis=-2) / size[:, None]
        d = p_u - mean[..., self.chain, :]
        dx, dy = d[..., 0], d[..., 1]
        sxx, syy, sxy = (np.add.reduceat(v, starts, axis=-1) / size for v in (dx**2, dy**2, dx * dy))
        mse = 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
        gain = np.add.reduceat(mag, starts, axis=-1) / size
        bad = np.add.reduceat((~valid).astype(np.float64), starts, axis=-1) > 0
        mse_px = np.maximum(mse, 0.0) * (gain * self.width) ** 2
        chi2 = self.counts * mse_px / (SIGMA_POINT**2 + self.counts * SIGMA_FLOOR**2)
        return np.where(bad, np.nan, chi2)

    def rms_px(self, lenses: np.ndarray) -> np.ndarray:
        chi2 = self.chi2(lenses)
        return np.sqrt(chi2 * (SIGMA_POINT**2 + self.counts * SIGMA_FLOOR**2) / self.counts)


class _Pairs:
    """The frame-to-frame matches of a shot, compacted once: every pair's points of both frames in one
    array (undistorted in one call per evaluation, each point with its own sample's lens), each
    pair's ``a`` and ``b`` points as rows of a padded ``(pairs, most matches)`` index (``mask`` the
    real ones), and each pair's residual weight."""

    def __init__(self, pairs: list[tuple[int, int, Matches]]) -> None:
        pts = [p for _, _, m in pairs for p in (m.a, m.b)]
        sizes = np.array([len(m) for _, _, m in pairs], np.intp)
        if pts:
            sample = np.repeat(np.ravel([(i, j) for i, j, _ in pairs]).astype(np.intp), np.repeat(sizes, 2))
            self.undistort = _Undistort(np.concatenate(pts), sample)
        starts = np.cumsum(np.r_[0, 2 * sizes])[:-1]
        column = np.arange(int(sizes.max()) if len(sizes) else 0)
        self.mask = column < sizes[:, None]
        self.a = starts[:, None] + np.where(self.mask, column, 0)
        self.b = self.a + sizes[:, None]
        self.weight = np.array([math.sqrt(min(1.0, MATCH_CAP / len(m))) * m.width / MATCH_SIGMA for _, _, m in pairs])

    def residuals(self, lenses: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
        """Transfer residuals of every match, pairs in order (see the module docstring): each pair's
        least-squares homography (:func:`glradial.video.frame_motion.homographies_of`, all pairs in
        one solve; ``near``: the pairs' homographies under lenses close to these, refined from);
        ``lenses`` ``(S, 2)``, or ``(K, S, 2)`` (-> ``(K, residuals)``). Keeps the homographies in
        ``homographies``."""
        if not len(self.weight):
            return np.zeros(np.shape(lenses)[:-2] + (0,))
        undistorted, _ = self.undistort(lenses)
        ua, ub = undistorted[..., self.a, :], undistorted[..., self.b, :]  # (..., pairs, matches, 2)
        h, ok = homographies_of(ua, ub, self.mask, start=near)
        self.homographies = h
        with np.errstate(divide="ignore", invalid="ignore"):
            q = ua @ np.swapaxes(h[..., :, :2], -1, -2) + h[..., None, :, 2]
            out = (q[..., :2] / q[..., 2:3] - ub) * self.weight[:, None, None]
        out = np.where(ok[..., None, None], out, 1e3)
        return out[..., self.mask, :].reshape(out.shape[:-3] + (-1,))


@dataclass(frozen=True)
class _Solution:
    """A solved fit: its parameters and cost (half the sum of squared residuals)."""

    x: np.ndarray
    cost: float


class _Problem:
    """The residuals of one shot for a parameter vector, or for ``(K, n)`` of them at once (one
    vectorised evaluation: the solver's finite differences, the seed's grid, the curvature's
    stencil; see the module docstring)."""

    def __init__(self, chains: _Chains, pairs: list, z: np.ndarray, prior_k1: float, redundancy: float = 1.0) -> None:
        self.chains, self.pairs, self.z, self.prior_k1 = chains, pairs, z, prior_k1
        self.matches = _Pairs(pairs)
        self.redundancy = redundancy
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def lenses(self, theta: np.ndarray) -> np.ndarray:
        return _lens(theta, self.z)

    def data(self, theta: np.ndarray, near: np.ndarray | None = None, pairs: bool = True) -> np.ndarray:
        lenses = self.lenses(theta)
        chi2 = self.chains.chi2(lenses)
        pairs = self.matches.residuals(lenses, near) if pairs else np.zeros(chi2.shape[:-1] + (0,))
        return np.concatenate([np.sqrt(np.where(np.isfinite(chi2), chi2, 1e6)), pairs], axis=-1)

    def priors(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, np.float64)
        out = [(theta[..., 0] - self.prior_k1) / K1_PRIOR_SIGMA, theta[..., -1] / K2_PRIOR_SIGMA]
        if theta.shape[-1] == 4:
            out.append(theta[..., 2] / ZOOM_CURVE_SIGMA)
        return np.stack(out, axis=-1)

    def residuals(self, theta: np.ndarray, near: np.ndarray | None = None, pairs: bool = True) -> np.ndarray:
        """Data residuals through the robust loss (``sign(r) sqrt(T log(1 + r^2 / T))``, so the
        solver's squares are the Cauchy cost, divided by the shot's redundancy: S sampled frames
        that show V independent views weigh as V frames against the priors) and the priors, kept
        quadratic. ``theta`` ``(n,)`` or ``(K, n)`` (-> ``(K, residuals)``); ``near``: the frame
        pairs' homographies at a ``theta`` close by (:meth:`_Pairs.residuals`); without ``pairs``,
        the chains' and the priors' alone."""
        data = self.data(theta, near, pairs)
        robust = np.sign(data) * np.sqrt(ROBUST_T * np.log1p(data * data / ROBUST_T) / self.redundancy)
        out = np.concatenate([robust, self.priors(theta)], axis=-1)
        if np.ndim(theta) == 1 and near is None and pairs:
            self._last = (np.array(theta, np.float64), out, getattr(self.matches, "homographies", None))
        return out

    def at(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """The residuals at ``theta`` and the frame pairs' homographies there (the solver's last
        evaluation when it was at ``theta``)."""
        x0 = np.asarray(theta, np.float64)
        if self._last is None or not np.array_equal(self._last[0], x0):
            self.residuals(x0)
        return self._last[1], self._last[2]

    def solve(self, theta: np.ndarray) -> "_Solution":
        """The cost's minimum from ``theta``: damped Newton steps (Levenberg-Marquardt on the
        curvature, :func:`_stencil`, in units of PARAMETER_SCALE), until a step gains, or the
        quadratic model promises, less than :data:`SOLVE_FTOL` of the cost, or a step would move
        less than :data:`SOLVE_XTOL`."""
        theta = np.asarray(theta, np.float64)
        scale = np.asarray(PARAMETER_SCALE[: len(theta) - 1] + PARAMETER_SCALE[-1:])
        r = self.at(theta)[0]
        cost = 0.5 * float(r @ r)
        gradient, hessian = _stencil(self, theta)[1:]
        damping, evaluations = 0.0, 0
        while evaluations < SOLVE_MAX_STEPS:
            g, h = gradient * scale, hessian * np.outer(scale, scale)
            floor = max(0.0, -float(np.linalg.eigvalsh(h)[0])) * 1.01 + 1e-9 * float(np.abs(h).max() or 1.0)
            step = -np.linalg.solve(h + (floor + damping) * np.eye(len(theta)), g)
            if -(g @ step + 0.5 * step @ h @ step) <= SOLVE_FTOL * cost or np.max(np.abs(step)) <= SOLVE_XTOL:
                break  # the model promises no gain worth a step
            r = self.residuals(theta + step * scale)
            trial_cost, evaluations = 0.5 * float(r @ r), evaluations + 1
            if trial_cost < cost:
                gain, theta, cost = cost - trial_cost, theta + step * scale, trial_cost
                moved, change = step * scale, _stencil(self, theta, curvature=False)[1] - gradient
                gradient = gradient + change
                if change @ moved > 0.0:  # BFGS: the curvature along the step, as the gradient saw it
                    seen = hessian @ moved
                    hessian = hessian + np.outer(change, change) / (change @ moved) - np.outer(seen, seen) / (moved @ seen)
                damping /= 4.0
                if gain <= SOLVE_FTOL * cost:
                    break
            else:
                damping = max(4.0 * damping, 1e-3 * float(np.abs(h).max() or 1.0))
        return _Solution(theta, cost)


def _screen(chains: _Chains) -> np.ndarray:
    """Chains some lens on the manifold straightens AND whose residual the lens choice changes."""
    if chains.n == 0:
        return np.zeros(0, bool)
    n_samples = int(chains.sample.max()) + 1
    rms = chains.rms_px(_lens(np.stack([K1_GRID, np.zeros_like(K1_GRID)], axis=1), np.zeros(n_samples)))
    best = np.nanmin(np.where(np.isfinite(rms), rms, np.inf), axis=0)
    worst = np.nanmax(np.where(np.isfinite(rms), rms, 0.0), axis=0)
    return (best <= STRAIGHT_RMS) & (worst >= INFORMATIVE_RMS)


def _seed(problem: _Problem) -> np.ndarray:
    """Best static lens on the manifold grid (robust cost + prior), as ``[a0, b0]``. With
    :data:`MIN_CHAINS` chains or more, of the chains and priors alone, the whole grid in one
    evaluation (the frame pairs move the minimum, not its basin: the same fits on all 47 shots of
    the eval clips); else of every residual, every other grid point, then the two between which
    its best lies."""
    def best(index: np.ndarray, pairs: bool = True) -> int:
        r = problem.residuals(np.stack([K1_GRID[index], np.zeros(len(index))], axis=1), pairs=pairs)
        return int(index[np.argmin(np.sum(r * r, axis=1))])

    if problem.chains.n >= MIN_CHAINS:
        return np.array([K1_GRID[best(np.arange(len(K1_GRID)), pairs=False)], 0.0])

    coarse = best(np.arange(0, len(K1_GRID), 2))
    return np.array([K1_GRID[best(np.array([i for i in (coarse - 1, coarse, coarse + 1) if 0 <= i < len(K1_GRID)]))], 0.0])


def _solve_zoom(problem: _Problem, static: np.ndarray, evidence: ShotEvidence):
    """The zoom model's fit, the best of several starts: the slope of the per-frame estimates' k1
    over the log zoom, the static lens, the static k1 with k2 on the manifold (a static fit can
    settle where a k2 offset mimics the zoom's average). Once two starts reach one minimum (costs
    within :data:`SAME_MINIMUM` relative) the rest are not run: on the 12 zooming shots of the
    eval clips all three always met (bench/fit_ab.py)."""
    starts = [np.array([static[0], 0.0, 0.0, static[1]]), np.array([static[0], 0.0, 0.0, 0.0])]
    known = [(z, s.estimate.k1) for z, s in zip(problem.z, evidence.samples) if s.estimate is not None]
    if len(known) >= 2 and np.ptp([z for z, _ in known]) > 0:
        slope, intercept = np.polyfit(*zip(*known), 1)
        starts.insert(0, np.array([intercept, slope, 0.0, 0.0]))
    results: list = []
    for start in starts:
        results.append(problem.solve(start))
        costs = sorted(r.cost for r in results)
        if len(costs) >= 2 and costs[1] - costs[0] <= SAME_MINIMUM * costs[0]:
            break
    return min(results, key=lambda r: r.cost)


def _stencil(problem: _Problem, theta: np.ndarray, curvature: bool = True) -> tuple[float, np.ndarray, np.ndarray | None]:
    """The fit's cost (half the sum of its squared residuals) at ``theta``, its gradient and its
    curvature, by central differences of steps ``h`` = :data:`HESSIAN_STEP` x the parameters'
    typical size, every point in one evaluation: ``theta``, ``theta +- 2 h_i`` (gradient, and the
    diagonal over ``4 h_i^2``) and ``theta +- h_i +- h_j`` (the cross terms over ``4 h_i h_j``).
    The curvature, not the Gauss-Newton ``J^T J``: a chain's residual is the square root of its
    chi^2, whose slope vanishes at the chain's own best lens, so ``J^T J`` misses the information of
    every chain that no lens straightens exactly (real lines, most of them), overstates a line
    fit's spread many times and sends a Gauss-Newton solver creeping along the valley it leaves.
    Without ``curvature``: the gradient alone (the cost and the curvature NaN, None)."""
    n = len(theta)
    step = HESSIAN_STEP * np.asarray(PARAMETER_SCALE[: n - 1] + PARAMETER_SCALE[-1:])
    unit = np.eye(n) * step
    cross = [(i, j) for i in range(n) for j in range(i + 1, n)]
    points = [theta] + [theta + sign * 2.0 * unit[i] for i in range(n) for sign in (1.0, -1.0)]
    if curvature:
        points += [theta + si * unit[i] + sj * unit[j] for i, j in cross for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
    else:
        points = points[1:]
    r = problem.residuals(np.array(points), problem.at(theta)[1])
    cost = 0.5 * np.sum(r * r, axis=1)
    if not curvature:
        return math.nan, (cost[0::2] - cost[1::2]) / (4.0 * step), None
    plus, minus = cost[1 : 2 * n + 1 : 2], cost[2 : 2 * n + 1 : 2]
    gradient = (plus - minus) / (4.0 * step)
    hessian = np.diag((plus - 2.0 * cost[0] + minus) / (4.0 * step**2))
    for (i, j), (pp, pm, mp, mm) in zip(cross, cost[2 * n + 1 :].reshape(-1, 4)):
        hessian[i, j] = hessian[j, i] = (pp - pm - mp + mm) / (4.0 * step[i] * step[j])
    return float(cost[0]), gradient, hessian


def _hessian(problem: _Problem, theta: np.ndarray) -> np.ndarray:
    """The curvature of the fit's cost at ``theta`` (:func:`_stencil`)."""
    return _stencil(problem, np.asarray(theta, np.float64))[2]


def _sigma_px(problem: _Problem, result, radius: float) -> float:
    """1-sigma of the maximum displacement over ``radius`` (px at 1920) from the fit's covariance
    (the inverse curvature of its cost, :func:`_hessian`), the largest over the sampled zooms."""
    chi2 = problem.chains.chi2(problem.lenses(result.x))
    # the chains' own scatter sets the noise level (frame pairs of a still camera fit exactly and
    # would pretend to a precision the lines do not have)
    reduced = float(np.mean(np.minimum(np.nan_to_num(chi2, nan=4.0 * ROBUST_T), 4.0 * ROBUST_T))) if len(chi2) >= MIN_CHAINS else 1.0
    values, vectors = np.linalg.eigh(_hessian(problem, np.asarray(result.x, np.float64)))
    if not values.max() > 0:
        return math.inf
    cov = (vectors / np.maximum(values, 1e-12 * values.max())) @ vectors.T * reduced
    r = np.linspace(0.0, radius, 64)
    basis = np.stack([r**3, r**5], axis=1)
    worst = 0.0
    for z in np.unique(problem.z):
        grad = np.empty((2, len(result.x)))
        for p in range(len(result.x)):
            step = np.zeros(len(result.x))
            step[p] = 1e-6
            grad[:, p] = (_lens(result.x + step, np.asarray(z)) - _lens(result.x - step, np.asarray(z))) / 2e-6
        var = np.einsum("ri,ij,rj->r", basis, grad @ cov @ grad.T, basis)
        worst = max(worst, float(np.sqrt(np.max(np.maximum(var, 0.0)))))
    return worst * REPORT_WIDTH


def _fallback(evidence: ShotEvidence, doubtful_px: float, why: str = "no_geometry", static: bool = False) -> FittedShotLens:
    """The shot read from its per-frame estimates alone: their median, stating their median bound
    (:data:`NO_GEOMETRY_PX` where they state none; never less for being many: they read the same
    picture) plus their spread (the largest maximum displacement between the median and any of
    them: a zooming lens's range, or estimators that disagree); for a ``static`` shot (one view, one
    lens) their median bound: each estimate's bound is calibrated to cover it 90 % of the time and
    their median is at least as close as the typical one (their scatter within their bounds is noise
    the median removes, not a range of lenses; one estimate far out does not move the median), plus
    their typical scatter (the median distance from their median) where that exceeds what they state. Doubtful (reason ``why``) when that bound exceeds
    ``doubtful_px``, or (reason theirs) when most per-frame estimates say they are doubtful."""
    estimates = _estimates(evidence.samples)
    k = np.median([[e.k1, e.k2] for e in estimates], axis=0) if estimates else np.zeros(2)
    stated = [float(getattr(e, "uncertainty_px", NO_GEOMETRY_PX)) for e in estimates]
    distances = max_displacement_px(np.array([[e.k1, e.k2] for e in estimates]), k) if estimates else np.zeros(1)
    median = float(np.median(stated)) if stated else NO_GEOMETRY_PX
    if static and estimates:  # their typical scatter, when it exceeds what they state, adds to it
        scatter = float(np.median(distances))
        bound = median if scatter <= median else median + scatter
    else:
        bound = median + float(np.max(distances))
    theirs = [str(getattr(e, "reason", "") or "doubtful") for e in estimates if getattr(e, "doubtful", False)]
    reason = why if not bound <= doubtful_px else ""
    if 2 * len(theirs) > len(estimates):
        reason = max(set(theirs), key=theirs.count)
    theta = (float(k[0]), float(k[1] - manifold_k2(k[0])))
    return FittedShotLens(theta, 0.0, bound, bool(reason), reason, 0, 0, 1.0, False, "frames", static=static)


def _zoom_of_frames(evidence: ShotEvidence, doubtful_px: float, why: str) -> FittedShotLens | None:
    """A zoom read by its per-frame estimates and its frame pairs, following the zoom:
    ``k1(z) = L + a1 (z - zbar)`` (``z`` the measured log zoom; a generic first-order model in the
    log of the focal length, as :mod:`glradial.camera.shot_lens` fits for the pitch camera: nothing
    of how any clip's lens was made to follow its zoom), ``k2 = m(k1) + b0``.

    * The **level** ``L`` (``k1`` at ``zbar``, the estimates' weighted mean zoom) is the estimates'
      weighted mean ``k1``, each weighted by the inverse square of the 1-sigma its stated bound gives
      (bound / :data:`Z90`, over the lens's displacement per unit ``k1``, :func:`_px_per_k1`); ``b0``
      their weighted mean offset from the manifold.
    * The **slope** ``a1``: a pure zoom's frame pairs tie the lens at one zoom to the lens at
      another, not to a level (module docstring), so given ``L`` they fix it (:func:`_slope_of_pairs`);
      without pairs, the estimates' own weighted line.

    Bound at a zoom: :data:`Z90` times the level's 1-sigma (its weighted mean's, scaled up by the
    estimates' reduced chi^2 about the model when they scatter more than they state, and by ``S /
    V``: ``S`` estimates of overlapping pictures count as ``V`` views, as in the joint fit) carried
    to that zoom through the slope's dependence on the level (or, without pairs, the line's
    covariance there), in px at 1920. It grows away from ``zbar``: wider where the model
    extrapolates. The shot's bound is the largest over its sampled zooms and one sampling step past
    each end (its frames beyond the samples). ``None`` with fewer than :data:`ZOOM_FRAMES_MIN`
    estimates that state a bound, or when they span less than :data:`ZOOM_MIN` of log zoom."""
    zoom = evidence.log_zooms()
    picked = [(float(z), s.estimate) for z, s in zip(zoom, evidence.samples)
              if s.estimate is not None and math.isfinite(float(getattr(s.estimate, "uncertainty_px", math.nan)))]
    paired = any(len(m) >= 4 for _, _, m in evidence.pairs)
    if len(picked) < ZOOM_FRAMES_MIN[0 if paired else 1] or np.ptp([z for z, _ in picked]) <= ZOOM_MIN:
        return None
    centre = float(0.5 * (zoom.min() + zoom.max()))
    z = np.array([z for z, _ in picked]) - centre
    k = np.array([[e.k1, e.k2] for _, e in picked], np.float64)
    bound = np.maximum([e.uncertainty_px for _, e in picked], BOUND_FLOOR_PX)  # no estimate is surer than the floor
    b0 = float(np.sum((k[:, 1] - manifold_k2(k[:, 0])) / bound**2) / np.sum(1.0 / bound**2))
    weight = (Z90 * _px_per_k1(k[:, 0], b0) / bound) ** 2  # 1 / sigma^2 of each estimate's k1
    zbar, level = float(np.sum(weight * z) / np.sum(weight)), float(np.sum(weight * k[:, 0]) / np.sum(weight))
    views = min(float(len(z)), 1.0 + float(evidence.travel))
    steps = np.diff(zoom)
    at = np.r_[zoom, [zoom[0] - steps[0], zoom[-1] + steps[-1]] if len(steps) else []] - centre
    pairs = _slope_of_pairs(evidence, centre, zbar, level, b0)
    if pairs is not None:
        slope, coupling = pairs
        dof = len(z) - 1
        gain = np.abs(1.0 + coupling * (at - zbar))  # how a level error carries to each zoom
        variance = np.full(len(at), 1.0 / np.sum(weight))
    else:
        slope = float(np.sum(weight * (z - zbar) * k[:, 0]) / np.sum(weight * (z - zbar) ** 2))
        dof, gain = len(z) - 2, np.ones(len(at))
        variance = 1.0 / np.sum(weight) + (at - zbar) ** 2 / np.sum(weight * (z - zbar) ** 2)
    chi2 = float(np.sum(weight * (k[:, 0] - level - slope * (z - zbar)) ** 2)) / dof
    k1 = level + slope * (at - zbar)
    sigma = np.sqrt(variance * max(1.0, chi2) * len(z) / views) * gain
    stated = float(np.max(Z90 * sigma * _px_per_k1(k1, b0)))
    frames = _fallback(evidence, doubtful_px, why)  # the estimates' own doubt, as for one lens
    reason = frames.reason if frames.reason not in ("", why) else why if not stated <= doubtful_px else ""
    theta = (level - slope * zbar, slope, 0.0, b0)
    return FittedShotLens(theta, centre, stated, bool(reason), reason, 0, sum(len(m) for _, _, m in evidence.pairs), views,
                    True, "frames")


def _slope_of_pairs(evidence: ShotEvidence, centre: float, zbar: float, level: float, b0: float) -> tuple[float, float] | None:
    """The slope ``a1`` of ``k1(z) = level + a1 (z - zbar)`` (``k2 = m(k1) + b0``) under which the
    shot's frame pairs fit best (their transfer residuals, as in the joint fit), and how it moves
    per unit of ``level`` (a level error carries to the other zooms through it); ``None`` without
    pairs. A grid over :data:`SLOPE_RANGE`, then bounded Brent around its best."""
    pairs = [p for p in evidence.pairs if len(p[2]) >= 4]
    if not pairs:
        return None
    matches, z = _Pairs(pairs), evidence.log_zooms() - centre

    def best(at_level: float, bounds: tuple[float, float]) -> float:
        def cost(a1: float) -> float:
            r = matches.residuals(_lens(np.array([at_level - a1 * zbar, a1, 0.0, b0]), z))
            return float(r @ r)

        from scipy.optimize import minimize_scalar

        return float(minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-4}).x)

    grid = np.linspace(*SLOPE_RANGE, SLOPE_GRID)
    thetas = np.stack([level - grid * zbar, grid, np.zeros_like(grid), np.full_like(grid, b0)], axis=1)
    i = int(np.argmin(np.sum(matches.residuals(_lens(thetas, z)) ** 2, axis=1)))
    slope = best(level, (grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]))
    near = (slope - 2.0 * (grid[1] - grid[0]), slope + 2.0 * (grid[1] - grid[0]))
    coupling = (best(level + LEVEL_STEP, near) - best(level - LEVEL_STEP, near)) / (2.0 * LEVEL_STEP)
    return slope, coupling


def _px_per_k1(k1: np.ndarray, b0: float, step: float = 1e-3) -> np.ndarray:
    """How far the lens ``(k1, m(k1) + b0)`` moves per unit of ``k1`` along it (px at 1920, max
    displacement over the 16:9 frame)."""
    k1 = np.asarray(k1, np.float64)
    here = np.stack([k1, manifold_k2(k1) + b0], axis=-1)
    there = np.stack([k1 + step, manifold_k2(k1 + step) + b0], axis=-1)
    return max_displacement_px(there, here) / step


def fit_shot(evidence: ShotEvidence, *, doubtful_px: float = DOUBTFUL_PX, radius: float = CORNER_RADIUS_16_9) -> FittedShotLens:
    """The lens of one shot from all its evidence (see the module docstring). ``doubtful_px``: a
    bound above it makes the shot doubtful unless correcting helps even at the bound
    (:func:`judged_by_benefit`); ``radius``: the frame's corner radius (lens units)."""
    if not evidence.samples:
        raise ValueError("a shot needs at least one sampled frame")
    return judged_by_benefit(_chosen(evidence, doubtful_px, radius), evidence)


def _read_by_frames(evidence: ShotEvidence, doubtful_px: float, why: str) -> FittedShotLens:
    """The shot read by its per-frame estimates alone: a zoom's lens following the zoom where they
    allow (:func:`_zoom_of_frames`), else their one lens (:func:`_fallback`)."""
    if evidence.camera() == "zoom":
        zoom = _zoom_of_frames(evidence, doubtful_px, why)
        if zoom is not None:
            return zoom
    return _fallback(evidence, doubtful_px, why)


def _bounded(estimates: list) -> bool:
    """Whether there are per-frame estimates and each states its own bound (``uncertainty_px``)."""
    return bool(estimates) and all(hasattr(e, "uncertainty_px") for e in estimates)


def _chosen(evidence: ShotEvidence, doubtful_px: float, radius: float) -> FittedShotLens:
    """The joint fit or the frames' median (:func:`fit_shot`), before the benefit verdict. The joint
    fit is not run where it would be set aside unread (a static shot whose frames are sure)."""
    geometry = _geometry(evidence)
    if geometry is None:
        return _read_by_frames(evidence, doubtful_px, "no_geometry")
    estimates = _estimates(evidence.samples)
    bounded = _bounded(estimates)
    if bounded and evidence.camera() == "static":  # never worse than its frames: their median, when sure enough
        frames = _fallback(evidence, doubtful_px, "uncertain", static=True)
        if not frames.doubtful:
            return frames
    shot = _joint(evidence, *geometry, doubtful_px, radius)
    if not bounded:
        return shot  # estimates that state no bound cannot be weighed against the fit's
    fallback = _fallback(evidence, doubtful_px, "uncertain")
    if fallback.uncertainty_px * (ZOOM_FALLBACK_RATIO if shot.zooming else 1.0) < shot.uncertainty_px:
        return _read_by_frames(evidence, doubtful_px, "uncertain")  # a zoom: following it where they allow
    return shot


def judged_by_benefit(shot: FittedShotLens, evidence: ShotEvidence) -> FittedShotLens:
    """Doubt by benefit for a shot, as for a frame (:func:`glradial.estimation.trust.benefit_doubt`):
    a shot that is doubtful only because its bound exceeds ``doubtful_px`` (``uncertain``,
    ``no_geometry``) is sure when that bound stays below the smallest shift of its lens from the
    identity over its samples (px at 1920): correcting helps even if the lens is off by the whole
    bound. A 150 px barrel read stating 15 px is applied; a near-pinhole one stating 15 px is not.
    Other reasons (``fold_over``, the frames' own doubt) stand, and so does a frames-only bound when
    the per-frame estimates state none of their own (it is then :data:`NO_GEOMETRY_PX`, not a
    calibrated bound), or when the shot zooms and its frames gave it one lens: that lens cannot
    follow the zoom, and their bound covers only the zooms they were read at (a zoom over the real
    stadium panorama, read at 20-60 px stating 52, was applied where it made the zoom's end worse
    than uncorrected, docs/eval/shots.md). A zoom its frames read as a lens that follows it
    (:func:`_zoom_of_frames`, ``zooming``) is judged by its bound like any other shot."""
    if not shot.doubtful or shot.reason not in ("uncertain", "no_geometry"):
        return shot
    estimates = _estimates(evidence.samples)
    if shot.source == "frames" and not _bounded(estimates):
        return shot
    if shot.source == "frames" and evidence.camera() == "zoom" and not shot.zooming:
        return shot
    lenses = np.atleast_2d(shot.lens_at(evidence.log_zooms() if shot.zooming else np.zeros(1)))
    smallest_shift = min(shift_px((float(k1), float(k2))) for k1, k2 in lenses)
    if shot.uncertainty_px < smallest_shift:
        return replace(shot, doubtful=False, reason="")
    return shot


def joint_fit(evidence: ShotEvidence, *, doubtful_px: float = DOUBTFUL_PX,
              radius: float = CORNER_RADIUS_16_9) -> FittedShotLens | None:
    """The joint fit of the shot's chains and matches alone (``None``: no geometric evidence, see
    the module docstring); :func:`fit_shot` weighs it against the per-frame estimates."""
    geometry = _geometry(evidence)
    return None if geometry is None else _joint(evidence, *geometry, doubtful_px, radius)


def _geometry(evidence: ShotEvidence) -> tuple[_Chains, list] | None:
    """The shot's screened chains and its frame pairs with matches; ``None`` when they are no
    geometric evidence of its lens (fewer than :data:`MIN_CHAINS` chains and no pan)."""
    chains = _Chains(evidence.samples)
    chains = chains.subset(_screen(chains)) if chains.n else chains
    pairs = [p for p in evidence.pairs if len(p[2]) >= 4]
    if chains.n < MIN_CHAINS and not (pairs and evidence.pan >= PAN_MIN):
        return None
    return chains, pairs


def _joint(evidence: ShotEvidence, chains: _Chains, pairs: list, doubtful_px: float, radius: float) -> FittedShotLens:
    """:func:`joint_fit` on the evidence :func:`_geometry` kept."""
    estimates = _estimates(evidence.samples)
    prior_k1 = float(np.median([e.k1 for e in estimates])) if estimates else 0.0
    zoom, camera = evidence.log_zooms(), evidence.camera()
    zooming = camera == "zoom"
    centre = float(0.5 * (zoom.min() + zoom.max())) if zooming else 0.0
    informative = len({int(s) for s in chains.sample} | {i for i, _, _ in pairs} | {j for _, j, _ in pairs})
    views = min(float(informative), 1.0 + float(evidence.travel))
    problem = _Problem(chains, pairs, zoom - centre, prior_k1, informative / views)
    result = problem.solve(_seed(problem))
    if zooming:
        result = _solve_zoom(problem, result.x, evidence)
    if chains.n:
        chi2 = chains.chi2(problem.lenses(result.x))
        keep = chi2 <= OUTLIER_CHI**2 * max(1.0, float(np.nanmedian(chi2)))
        if 0 < keep.sum() < chains.n:
            problem.chains = chains = chains.subset(keep)
            result = problem.solve(result.x)
    return _result(problem, result, views, centre, zooming, camera == "static", doubtful_px, radius)


def _result(problem: _Problem, result, views: float, centre: float, zooming: bool, static: bool,
            doubtful_px: float, radius: float) -> FittedShotLens:
    sigma = _sigma_px(problem, result, CORNER_RADIUS_16_9)
    bound = (STATIC_BOUND_SCALE if static else BOUND_SCALE) * sigma + BOUND_FLOOR_PX
    lenses = problem.lenses(result.x)
    folds = any(Lens(float(k1), float(k2)).fold_radius() <= radius for k1, k2 in lenses)
    reason = "fold_over" if folds else "uncertain" if not bound <= doubtful_px else ""
    matches = sum(len(m) for _, _, m in problem.pairs)
    return FittedShotLens(tuple(float(v) for v in result.x), centre, float(bound), bool(reason), reason,
                    problem.chains.n, matches, views, zooming, "joint", float(sigma), static)
