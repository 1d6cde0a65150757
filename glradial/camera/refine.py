"""The joint refinement of pose, focal length and lens against the pitch markings (ICP style).

Evidence: white-line points of the distorted frame (:func:`glradial.camera.white_lines.line_points`). Model: the
template's elements sampled every :data:`SAMPLE_STEP` metres and projected through the camera, lens
included (:meth:`glradial.camera.model.Camera.project`). Each round assigns every evidence point to its
nearest projected marking segment (within a gate that shrinks round by round, and with a line
direction within :data:`MAX_ANGLE_DEG`), then ``scipy.optimize.least_squares`` (soft-L1 loss) moves
the rotation (a rotation vector about the current one), the camera position, log focal length and
``(k1, k2)`` to shrink the point-to-projected-segment distances. The lens is held at its start for the
first rounds (the pinhole first) and carries a weak prior toward the Lopez-Antequera manifold (a
straight-line view cannot tell ``k2`` from ``k1`` well).

Residuals are stated in pixels of a 1280-wide frame (:data:`REFERENCE_WIDTH`), whatever the frame's
size, so the gates, the loss scale and the reported RMS are comparable across sizes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..lens.lens import Lens
from ..lens.lensfuncs import fold_radii
from ..lens.metrics import manifold_k2
from ..pitch.template import PitchTemplate
from .model import Camera, lens_points_to_pitch, project_many
from .white_lines import DETECT_WIDTH

#: Residuals are in px of a frame this wide.
REFERENCE_WIDTH = 1280.0
#: Template sampling (metres) for the projected segments.
SAMPLE_STEP = 1.0
#: Gates (px at 1280) of the assignment rounds; the lens is free from round :data:`LENS_FROM` on.
GATES = (40.0, 20.0, 10.0, 5.0, 3.0)
LENS_FROM = 2
#: Largest angle (degrees) between an evidence point's line direction and its assigned segment.
MAX_ANGLE_DEG = 25.0
#: Scale (px at 1280) of the soft-L1 loss: residuals beyond it count linearly.
LOSS_SCALE = 1.5
#: Prior on the lens: ``k2`` within :data:`K2_PRIOR` of the manifold, ``k1`` within :data:`K1_PRIOR` of 0,
#: each worth as much as :data:`PRIOR_POINTS` evidence points off by one loss scale.
K2_PRIOR, K1_PRIOR, PRIOR_POINTS = 0.08, 0.6, 20.0
#: Least-squares evaluations per round.
MAX_NFEV = 30
#: Relative tolerances (cost and step) of the last round's least squares (scipy's default) and of the
#: rounds before it, whose camera only sets the next, narrower gate's assignment.
FINAL_TOL, ROUND_TOL = 1e-8, 1e-4
#: A projected marking sample is supported by evidence this close (px at 1280)...
SUPPORT_PX = 4.0
#: ...and counts only where a painted line (about this wide, metres) is at least this many px wide on
#: the detection copy (far lines of a wide view are not detected).
LINE_WIDTH_M, MIN_VISIBLE_PX = 0.12, 1.0
#: An element counts as used when at least this many inliers lie on it.
MIN_ELEMENT_POINTS = 12
#: An element counts as drawn in the frame when at least this many of its samples (every
#: :data:`SAMPLE_STEP` metres) project inside it where a line would be detectable, and as missing when
#: less than :data:`MISSING_SHARE` of those have evidence (a marking drawn where the frame shows none).
MIN_DRAWN_SAMPLES, MISSING_SHARE = 8, 0.2
#: Evidence points that the camera puts on the pitch (within this margin, metres, of its outline) are
#: the ones a right camera should explain (those off it: crowd, boards, graphics).
PITCH_MARGIN_M = 2.0


@dataclass(frozen=True)
class Samples:
    """The template sampled for projection: ``points`` (M x 2 metres), ``element`` (M, index into
    ``labels``), ``next`` (M, the index of the following sample of the same element, -1 at the end)."""

    points: np.ndarray
    element: np.ndarray
    next: np.ndarray
    labels: tuple[str, ...]


@lru_cache(maxsize=16)
def template_samples(pitch: PitchTemplate, step: float = SAMPLE_STEP) -> Samples:
    """The markings of ``pitch`` as :class:`Samples` every ``step`` metres (built once per template
    and step: every refinement of every frame reads them; the arrays are read-only)."""
    pts, elem, nxt, labels = [], [], [], []
    start = 0
    for i, (label, p) in enumerate(pitch.polylines(step)):
        labels.append(label)
        pts.append(p)
        elem.append(np.full(len(p), i))
        n = np.arange(start + 1, start + len(p) + 1)
        n[-1] = -1
        nxt.append(n)
        start += len(p)
    arrays = [np.concatenate(pts), np.concatenate(elem), np.concatenate(nxt)]
    for array in arrays:
        array.flags.writeable = False
    return Samples(*arrays, tuple(labels))


class Coverage(NamedTuple):
    """How well the frame shows the markings a camera draws in it (:func:`element_support`): ``support``
    (:func:`support`), ``drawn`` (markings drawn: :data:`MIN_DRAWN_SAMPLES`) and ``missing`` (those of
    them the frame barely shows: :data:`MISSING_SHARE`)."""

    support: float
    drawn: int
    missing: int


def _of_coverage(name: str) -> property:
    """A read-only attribute of the fit's :class:`Coverage`."""
    return property(lambda self: getattr(self.coverage, name), doc=f"``coverage.{name}``")


@dataclass(frozen=True)
class Fit:
    """The refined camera and how well it fits: ``rms_px`` (RMS of the inliers' distances, px at
    1280), ``inliers`` (evidence points within the last gate), ``share`` (inliers / evidence points),
    ``elements`` (labels of the markings with at least :data:`MIN_ELEMENT_POINTS` inliers),
    ``log_focal_sd`` (standard deviation of log focal from the last round's Jacobian; infinite where
    the markings seen do not fix it), ``cost`` (the robust cost per evidence point), ``coverage``
    (:class:`Coverage`: ``support``, the share of the markings projected inside the frame that have an
    evidence point within :data:`SUPPORT_PX`, low when the camera draws markings where the frame has
    none; the markings ``drawn`` and ``missing``; each also an attribute of the fit), ``spread`` (how
    far the inliers' line directions are from one direction: ``1 - |mean(exp(2i angle))|``, 0 when every
    inlier runs the same way, e.g. parallel lines only; about 1 for two perpendicular families or a
    circle), ``pitch_share`` (inliers among the evidence points the camera puts on the pitch:
    :data:`PITCH_MARGIN_M`; 0 when none)."""

    camera: Camera
    rms_px: float
    inliers: int
    share: float
    elements: tuple[str, ...]
    log_focal_sd: float
    cost: float
    coverage: Coverage = Coverage(0.0, 0, 0)
    spread: float = 1.0
    pitch_share: float = 0.0

    support = _of_coverage("support")
    drawn = _of_coverage("drawn")
    missing = _of_coverage("missing")


def _camera(x: np.ndarray, base: Camera) -> Camera:
    rot = Rotation.from_rotvec(x[:3]).as_matrix() @ base.rotation
    return Camera(rot, x[3:6], math.exp(x[6]), base.size, Lens(float(x[7]), float(x[8])))


def _segments(camera: Camera, samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """Projected samples (M x 2 px, NaN where not seen) and whether each is usable."""
    xy = camera.project(samples.points)
    uv, z = camera.undistorted_lens_points(samples.points)
    # beyond 1.2 x the frame's corner radius the lens polynomial is not the lens any more
    r = np.hypot(uv[:, 0], uv[:, 1])
    ok = (z > 0.5) & (r < 1.2 * 0.5 * math.hypot(1.0, camera.size[1] / camera.size[0])) & np.isfinite(xy).all(1)
    return xy, ok


def assign(camera: Camera, samples: Samples, xy: np.ndarray, angle: np.ndarray, gate: float):
    """For each evidence point, ``(sample index a, following index b, distance px at 1280)`` of its
    nearest projected segment, and the mask of points assigned within ``gate``."""
    proj, ok = _segments(camera, samples)
    scale = REFERENCE_WIDTH / camera.size[0]
    idx = np.flatnonzero(ok)
    if len(idx) < 2:
        return None
    _, near = cKDTree(proj[idx]).query(xy)
    k = idx[near]
    best_a, best_b, best_d = k.copy(), k.copy(), np.full(len(xy), np.inf)
    prev = np.full(len(samples.points), -1)
    has_next = samples.next >= 0
    prev[samples.next[has_next]] = np.flatnonzero(has_next)
    for a, b in ((prev[k], k), (k, samples.next[k])):
        good = (a >= 0) & (b >= 0)
        a, b = np.where(good, a, 0), np.where(good, b, 0)
        good &= ok[a] & ok[b]
        d, along = _line_distance(xy, proj[a], proj[b])
        seg_dir = np.arctan2(proj[b, 1] - proj[a, 1], proj[b, 0] - proj[a, 0])
        diff = np.abs((seg_dir - angle + np.pi / 2) % np.pi - np.pi / 2)
        d = np.where(good & (along > -0.5) & (along < 1.5) & (diff < math.radians(MAX_ANGLE_DEG)), d * scale, np.inf)
        better = d < best_d
        best_a, best_b, best_d = np.where(better, a, best_a), np.where(better, b, best_b), np.where(better, d, best_d)
    return best_a, best_b, best_d, best_d < gate


def _line_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance of points ``p`` to the lines through ``a``, ``b`` (rows), and the position along."""
    ab = b - a
    length = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-9)
    ap = p - a
    cross = (ab[:, 0] * ap[:, 1] - ab[:, 1] * ap[:, 0]) / length
    along = (ap * ab).sum(1) / (length * length)
    return np.abs(cross), along


class _Problem:
    """The residuals of one round (fixed assignment) for a batch of parameter vectors, and their
    forward-difference Jacobian computed as one batch."""

    def __init__(self, base: Camera, samples: Samples, xy: np.ndarray, a: np.ndarray, b: np.ndarray,
                 with_lens: bool, free: np.ndarray) -> None:
        self.base, self.xy, self.with_lens = base, xy, with_lens
        self.last: tuple[np.ndarray, np.ndarray] | None = None  # the last residuals asked for, and where
        self.free, self.full = free, _params(base)
        # each template sample projected once however many points are assigned to its segments
        used, index = np.unique(np.concatenate([a, b]), return_inverse=True)
        self.points = np.column_stack([samples.points[used], np.zeros(len(used))])
        self.ia, self.ib = index[: len(a)], index[len(a):]
        self.scale = REFERENCE_WIDTH / base.size[0]
        # a held lens folds at one radius for every row (computed once, not per evaluation)
        self.fold = None if with_lens else fold_radii(np.array([base.lens.k1]), np.array([base.lens.k2]))

    def batch(self, free: np.ndarray) -> np.ndarray:
        """Residuals (B x R) of rows of the free parameters (``self.free`` of the 9)."""
        x = np.tile(self.full, (len(free), 1))
        x[:, self.free] = free
        rot = np.matmul(Rotation.from_rotvec(x[:, :3]).as_matrix(), self.base.rotation)
        fold = None if self.fold is None else np.broadcast_to(self.fold, len(x))
        proj = project_many(rot, x[:, 3:6], np.exp(x[:, 6]), x[:, 7], x[:, 8], self.base.size, self.points, fold)
        p0 = proj[:, self.ia]
        ab = proj[:, self.ib] - p0
        length = np.maximum(np.hypot(ab[..., 0], ab[..., 1]), 1e-9)
        ap = self.xy[None] - p0
        r = (ab[..., 0] * ap[..., 1] - ab[..., 1] * ap[..., 0]) / length * self.scale
        r = np.where(np.isfinite(r), r, 1e3)
        if self.with_lens:
            k1, k2 = x[:, 7], x[:, 8]
            w = LOSS_SCALE * math.sqrt(PRIOR_POINTS)
            r = np.column_stack([r, w * (k2 - manifold_k2(k1)) / K2_PRIOR, w * k1 / K1_PRIOR])
        return r

    def residuals(self, x: np.ndarray) -> np.ndarray:
        self.last = (x.copy(), self.batch(x[None])[0])
        return self.last[1]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        steps = FD_STEP * np.maximum(1.0, np.abs(x))
        if self.last is not None and np.array_equal(self.last[0], x):  # least_squares asks where it just evaluated
            r0, r = self.last[1], self.batch(x + np.diag(steps))
        else:
            r = self.batch(np.vstack([x, x + np.diag(steps)]))
            r0, r = r[0], r[1:]
        return ((r - r0) / steps[:, None]).T


#: Relative forward-difference step of the Jacobian.
FD_STEP = 1e-6


def _params(camera: Camera) -> np.ndarray:
    return np.r_[0.0, 0.0, 0.0, camera.position, math.log(camera.focal), camera.lens.k1, camera.lens.k2]


def refine(camera: Camera, xy: np.ndarray, angle: np.ndarray, pitch: PitchTemplate | None = None,
           *, fit_lens: bool = True, gates: tuple[float, ...] = GATES, lens_from: int = LENS_FROM,
           support_xy: np.ndarray | cKDTree | None = None, hold_position: int = 0, max_nfev: int = MAX_NFEV) -> Fit | None:
    """The camera that best fits the white-line points ``xy`` (N x 2 px of ``camera``'s frame, line
    directions ``angle``) from the start ``camera`` (see the module docstring), the lens free from
    round ``lens_from``; ``None`` when no round finds enough assigned points to fit. ``support_xy``:
    the points :func:`support` is measured on (default ``xy``; all the frame's points when ``xy`` is
    a thinned copy), or a ``cKDTree`` of them (built once for the several refinements of one frame). The camera position is held for the first ``hold_position`` rounds; each round
    evaluates the residuals at most ``max_nfev`` times, to the relative tolerance :data:`ROUND_TOL` before
    the last round and :data:`FINAL_TOL` in it."""
    samples = template_samples(pitch or PitchTemplate())
    result = None
    for round_, gate in enumerate(gates):
        found = assign(camera, samples, xy, angle, gate)
        if found is None or int(found[3].sum()) < 12:
            return None
        a, b, _, use = found
        with_lens = fit_lens and round_ >= min(lens_from, len(gates) - 1)
        x0 = _params(camera)
        free = np.arange(9 if with_lens else 7)
        if round_ < hold_position:
            free = np.array([0, 1, 2, 6])  # rotation and focal length first, from a far start
        problem = _Problem(camera, samples, xy[use], a[use], b[use], with_lens, free)
        tol = FINAL_TOL if round_ == len(gates) - 1 else ROUND_TOL  # a round before the last only sets its gate's assignment
        result = least_squares(problem.residuals, x0[free], jac=problem.jacobian, loss="soft_l1",
                               f_scale=LOSS_SCALE, x_scale="jac", max_nfev=max_nfev, ftol=tol, xtol=tol)
        x = x0.copy()
        x[free] = result.x
        try:
            camera = _camera(x, camera)
        except ValueError:
            return None
    return _summary(camera, samples, xy, angle, gates[-1], result, xy if support_xy is None else support_xy)


def _summary(camera: Camera, samples: Samples, xy, angle, gate: float, result, support_xy) -> Fit | None:
    found = assign(camera, samples, xy, angle, gate)
    if found is None:
        return None
    a, _, d, use = found
    inl = d[use]
    counts = np.bincount(samples.element[a[use]], minlength=len(samples.labels))
    elements = tuple(lab for lab, c in zip(samples.labels, counts) if c >= MIN_ELEMENT_POINTS)
    jac = result.jac[: len(result.fun)]
    sigma2 = float(np.mean(np.minimum(inl, 3 * LOSS_SCALE) ** 2)) if len(inl) else 1.0
    try:
        cov = np.linalg.inv(jac.T @ jac) * max(sigma2, 0.25)
        sd = float(math.sqrt(max(cov[6, 6], 0.0)))
    except np.linalg.LinAlgError:
        sd = math.inf
    rms = float(np.sqrt(np.mean(inl ** 2))) if len(inl) else math.inf
    spread = 1.0 - float(abs(np.mean(np.exp(2j * angle[use])))) if use.any() else 0.0
    on = _on_pitch(camera, xy, samples)
    return Fit(camera, rms, int(use.sum()), float(use.mean()), elements, sd, float(result.cost) / max(len(xy), 1),
               element_support(camera, samples, support_xy), spread, float(use[on].mean()) if on.any() else 0.0)


def _on_pitch(camera: Camera, xy: np.ndarray, samples: Samples) -> np.ndarray:
    """Which evidence points ``xy`` ``camera`` puts on the pitch (the template's extent plus
    :data:`PITCH_MARGIN_M`)."""
    half = np.abs(samples.points).max(axis=0) + PITCH_MARGIN_M
    m = lens_points_to_pitch(camera, xy)
    with np.errstate(invalid="ignore"):
        return (np.abs(m[:, 0]) <= half[0]) & (np.abs(m[:, 1]) <= half[1])


def support(camera: Camera, samples: Samples, xy: np.ndarray) -> float:
    """Share of the template samples projected inside the frame, where a painted line would be wide
    enough to detect (:data:`LINE_WIDTH_M` seen at least :data:`MIN_VISIBLE_PX` wide on the detection
    copy, the lens's squeeze included: :func:`lens_width_scale`), with an evidence point within
    :data:`SUPPORT_PX` (0 when none is inside)."""
    return element_support(camera, samples, xy).support


def element_support(camera: Camera, samples: Samples, xy: np.ndarray | cKDTree) -> Coverage:
    """``Coverage(support, drawn, missing)``: :func:`support`, the number of markings drawn in the frame
    (at least :data:`MIN_DRAWN_SAMPLES` detectable samples) and how many of those have evidence at less
    than :data:`MISSING_SHARE` of their samples; ``xy``: the evidence points or a ``cKDTree`` of them."""
    proj, ok = _segments(camera, samples)
    width, height = camera.size
    uv, depth = camera.undistorted_lens_points(samples.points)
    ahead = np.where(samples.next >= 0, samples.next, np.arange(len(samples.next)))
    tangent = uv[ahead] - uv  # along the marking (zero at an element's last sample: taken as radial)
    with np.errstate(divide="ignore", invalid="ignore"):
        seen_px = camera.focal * DETECT_WIDTH * LINE_WIDTH_M / depth * lens_width_scale(camera.lens, uv, tangent)
    ok &= (proj[:, 0] >= 0) & (proj[:, 0] <= width - 1) & (proj[:, 1] >= 0) & (proj[:, 1] <= height - 1)
    ok &= seen_px >= MIN_VISIBLE_PX
    tree = xy if isinstance(xy, cKDTree) else cKDTree(xy)
    if not ok.any() or tree.n == 0:
        return Coverage(0.0, 0, 0)
    d, _ = tree.query(proj[ok])
    near = d * REFERENCE_WIDTH / width < SUPPORT_PX
    n = np.bincount(samples.element[ok], minlength=len(samples.labels))
    hit = np.bincount(samples.element[ok], weights=near, minlength=len(samples.labels))
    drawn = n >= MIN_DRAWN_SAMPLES
    return Coverage(float(np.mean(near)), int(drawn.sum()), int(np.sum(drawn & (hit < MISSING_SHARE * n))))


def lens_width_scale(lens: Lens, uv: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """How much ``lens`` widens (> 1) or squeezes (< 1) a thin line at the undistorted lens points
    ``uv`` (N x 2, image widths from the principal point) running along ``tangent`` (N x 2, any
    length): the width across the line after the lens's forward map over the width before. The map
    scales radially by its slope ``s = d r_d / d r_u`` and tangentially by ``t = r_d / r_u``; a strip
    along the unit direction ``(c, s')`` (radial, tangential components) keeps its area ``s t`` per
    length and its length scales by ``|(s c, t s')|``, so its width scales by
    ``s t / sqrt((s c)^2 + (t s')^2)`` (``t`` along a radial line, ``s`` across; 1 at the centre)."""
    r = np.hypot(uv[:, 0], uv[:, 1])
    slope = np.asarray(lens.slope(r), dtype=np.float64)
    stretch = np.asarray(lens.forward_radius(r), dtype=np.float64) / np.maximum(r, 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        radial = uv / np.maximum(r, 1e-12)[:, None]
        length = np.hypot(tangent[:, 0], tangent[:, 1])
        cos = np.where(length > 0, np.abs(np.sum(tangent * radial, axis=1)) / np.maximum(length, 1e-12), 1.0)
    sin = np.sqrt(np.maximum(0.0, 1.0 - cos**2))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = slope * stretch / np.hypot(slope * cos, stretch * sin)
    return np.where(r > 1e-9, scale, 1.0)
