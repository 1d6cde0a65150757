"""The first guess of a broadcast frame's camera: the homography from the pitch plane to the image,
found from the white pitch lines alone (no detector trained on labelled frames).

Steps (docs/CAMERA_SEARCH.md has the details and the figures):

1. **Evidence** (:mod:`glradial.camera.white_lines`): a white-line mask on the grass of a 640-px wide
   work copy (undistorted by ``lens`` when one is given) and its straight lines.
2. **Hypotheses**: two pairs of lines whose meeting points can be the pitch's two vanishing points,
   matched to two template lines of each direction in the main camera's order
   (:mod:`glradial.camera.line_hypotheses`), and the centre circle's ellipse with the halfway line
   (:mod:`glradial.camera.circle_hypotheses`); kept only when the homography is a pinhole view with
   square pixels and a centred principal point from a plausible main-camera position (on the near
   touchline's side, 4-80 m up).
3. **Score**: the projected template against the mask's distance transform (:func:`coverage`).
4. **Refinement**: the best distinct hypotheses are refit to the mask pixels (:func:`refine`: robust
   ICP, point-to-marking distances, all 8 homography parameters) and scored again.

Conventions: ``template_points`` are metres on the pitch plane (origin at the centre spot, x along
the touchlines toward the goal on the right of the main camera's view, y toward the far touchline);
a :class:`Candidate`'s homography maps ``(x, y, 1)`` to pixels of the given frame at its own
resolution (pixel centres at integers), or of the frame undistorted by ``lens`` when one is given
(width-normalised ``(k1, k2)``, :class:`glradial.lens.lens.Lens`, same size and principal point).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..estimation.net_lines import estimate_net_lines
from ..lens.lens import Lens
from ..lens.metrics import max_displacement_px
from .circle_hypotheses import circle_homographies, ellipses, template_radius
from .line_hypotheses import camera_of, line_homographies, plausible, template_lines
from .white_lines import WhiteLines, hull, pair_vanishing_points, white_lines

#: Coverage scoring: a projected template point counts ``exp(-d² / 2 SIGMA²) - MISS_PENALTY`` per px
#: of marking it stands for, ``d`` its distance (work px) to the nearest mask pixel, where the work
#: copy is grass; a px of marking stands for at most MAX_POINT_WEIGHT px.
SIGMA, MISS_PENALTY, MAX_POINT_WEIGHT = 1.5, 0.3, 6.0
#: A template point is on the evidence within HIT_PX (work px) of a mask pixel.
HIT_PX = 2.0
#: Template points used for the quick score of every hypothesis and for the coarse score of the
#: QUICK_KEPT best (subsamples of the given ones).
QUICK_POINTS, QUICK_KEPT, COARSE_POINTS = 80, 200, 400
#: Hypotheses scored per batch (memory).
BATCH = 4096
#: Two homographies are distinct when the pitch points they see at a 3 x 3 grid over the image
#: differ by more than this (m).
DISTINCT_M = 1.5
#: ICP: matching bands (work px), one refit each, and the most mask pixels used.
ICP_BANDS = (16.0, 8.0, 5.0, 4.0)
#: The first ICP_ROUGH_BANDS bands run for every hypothesis, the rest only for those still distinct
#: after them.
ICP_ROUGH_BANDS = 1
#: Reweighted solves per band, and the Cauchy scale of the weights as a share of the band.
ICP_STEPS, ICP_CAUCHY = 2, 0.35
#: A pixel's nearest template point is looked for within this many bands (the points are spaced
#: along the markings; the band applies to the distance from the marking's tangent line).
ICP_REACH = 3.0
#: The most mask pixels the ICP uses, and the spacing (m) of the template points it matches them to.
ICP_MAX_POINTS, ICP_SPACING_M = 1200, 0.5
#: A frame has usable pitch structure when this share of the work copy is grass; a refined candidate
#: is kept when it is still a plausible main camera, its coverage score reaches MIN_SCORE px (work
#: copy) and MIN_SHARE of its projected marking on the field lies on the evidence.
MIN_GRASS, MIN_SCORE, MIN_SHARE = 0.15, 60.0, 0.5
#: A lens read from the frame's lines is strong when it moves some point of a 16:9 frame by at least
#: this many px at 1920 (:func:`glradial.lens.metrics.max_displacement_px` against no lens): frame-long
#: lines then bend by more than the ICP's last bands on the 640-px work copy, so the search, which
#: fits straight lines, is run on the frame undistorted with it (:func:`strong_lens`).
STRONG_LENS_PX = 30.0


@dataclass(frozen=True)
class Candidate:
    """One camera hypothesis of a frame.

    ``homography``: 3 x 3 float64, pitch ``(x, y, 1)`` metres -> frame pixels (module docstring).
    ``score``: higher is better: the length (frame px) of projected template marking that lands on
    white-line evidence, minus :data:`MISS_PENALTY` times the length that lands on grass without any
    (:func:`coverage`); ``share``: the share of the projected marking on the field that lies on
    the evidence (within :data:`HIT_PX` work px); candidates are ranked by ``score * share``.
    ``rms_px``: RMS point-to-marking distance (frame px) of the mask pixels matched in the last ICP
    band; ``matched``: how many there were. ``focal``: focal length in image
    widths and ``position``: camera centre (x, y, z metres) read from the homography with square
    pixels and a centred principal point (no lens).
    """

    homography: np.ndarray
    score: float
    share: float
    rms_px: float
    matched: int
    focal: float
    position: tuple[float, float, float]


def _check_inputs(frame_rgb, template_points, template_labels, lens, max_candidates):
    if not isinstance(frame_rgb, np.ndarray):
        raise TypeError(f"frame_rgb must be a numpy array, got {type(frame_rgb).__name__}")
    if frame_rgb.dtype != np.uint8 or frame_rgb.ndim != 3 or frame_rgb.shape[2] != 3:
        raise ValueError(f"frame_rgb must be an H x W x 3 uint8 RGB image, got {frame_rgb.dtype} {frame_rgb.shape}")
    if min(frame_rgb.shape[:2]) < 16:
        raise ValueError(f"frame_rgb is too small: {frame_rgb.shape}")
    points = np.asarray(template_points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 8 or not np.isfinite(points).all():
        raise ValueError(f"template_points must be a finite M x 2 array (M >= 8), got shape {points.shape}")
    labels = np.asarray(template_labels)
    if labels.shape != (len(points),) or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(f"template_labels must be {len(points)} integers, got {labels.dtype} {labels.shape}")
    if isinstance(max_candidates, bool) or not isinstance(max_candidates, numbers.Integral):
        raise TypeError(f"max_candidates must be an integer, got {max_candidates!r}")
    if max_candidates < 1:
        raise ValueError(f"max_candidates must be >= 1, got {max_candidates}")
    if lens is not None:
        try:
            k1, k2 = lens
            checked = Lens(float(k1), float(k2))
            checked.check_frame((frame_rgb.shape[1], frame_rgb.shape[0]))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"lens must be (k1, k2) or None, usable on the frame, got {lens!r}: {exc}") from None
        lens = checked
    return points, labels, lens


def _tangents(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Unit tangent (M x 2) of the marking at each template point: the principal direction of its
    nearest neighbours of the same label."""
    out = np.zeros_like(points)
    for label in np.unique(labels):
        idx = np.flatnonzero(labels == label)
        p = points[idx]
        k = min(5, len(p))
        _, nn = cKDTree(p).query(p, k=k)
        d = p[nn] - p[nn].mean(axis=1, keepdims=True)
        cov = np.einsum("mki,mkj->mij", d, d)
        out[idx] = np.linalg.eigh(cov)[1][:, :, 1]
    return out


def coverage(h: np.ndarray, points: np.ndarray, spacing: float, dist: np.ndarray, field: np.ndarray,
             share: bool = False, gain: np.ndarray | None = None) -> np.ndarray:
    """Coverage score (work px) of homographies ``h`` (N x 3 x 3): over the template ``points``
    (M x 2, ``spacing`` metres apart along the markings) that land on the field, the length of marking
    each stands for times ``exp(-d² / 2 SIGMA²) - MISS_PENALTY``, ``d`` from the distance transform
    ``dist`` of the line mask. With ``share``: also the share of that length within :data:`HIT_PX`
    of the mask (``2 x N``: scores, shares). ``gain``: :func:`_gain` of ``dist`` when the caller has it
    (the same values, looked up)."""
    height, width = dist.shape
    out = np.empty((2, len(h)))
    det = np.abs(np.linalg.det(h))
    # many hypotheses: each pixel's gain computed once for the image, then looked up (the same values)
    if gain is None and len(h) * len(points) > dist.size:
        gain = _gain(dist)
    x = np.vstack([points.T, np.ones(len(points))])
    on_field, flat_dist = field.ravel() > 0, dist.ravel()
    for s in range(0, len(h), BATCH):
        hb = h[s: s + BATCH]
        p = (hb.reshape(-1, 3) @ x).reshape(len(hb), 3, -1)  # x, y, w planes (N x M each)
        w = p[:, 2]
        with np.errstate(all="ignore"):
            aw = np.abs(w)
            length = np.minimum(np.sqrt(det[s: s + BATCH, None] / (aw * aw * aw)) * spacing, MAX_POINT_WEIGHT)  # not pow: 3x slower
            ix, iy = np.rint(p[:, 0] / w), np.rint(p[:, 1] / w)
            inside = (w > 0) & (ix >= 0) & (ix < width) & (iy >= 0) & (iy < height)
        flat = np.where(inside, iy * width + ix, 0).astype(np.intp)  # one index into the flat images
        length[~(inside & on_field[flat])] = 0.0
        d = flat_dist[flat]
        out[0, s: s + BATCH] = np.sum(length * (_gain(d) if gain is None else gain.ravel()[flat]), axis=1)
        if share:
            out[1, s: s + BATCH] = np.sum(length * (d <= HIT_PX), axis=1) / np.maximum(np.sum(length, axis=1), 1e-9)
    return out if share else out[0]


def _gain(d: np.ndarray) -> np.ndarray:
    """What a template point at distance ``d`` (work px) from the line mask counts per px of marking."""
    return np.exp(-0.5 * (d / SIGMA) ** 2) - MISS_PENALTY


def _grid_views(h: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pitch points (N x 9 x 2) seen at a 3 x 3 grid over a ``(W, H)`` image (NaN behind the camera)."""
    gx, gy = np.meshgrid(np.linspace(0.1, 0.9, 3) * size[0], np.linspace(0.3, 0.9, 3) * size[1])
    grid = np.stack([gx.ravel(), gy.ravel(), np.ones(9)], axis=1)
    with np.errstate(all="ignore"):
        p = np.einsum("nij,mj->nmi", np.linalg.inv(h), grid)
        return p[..., :2] / p[..., 2:3]


def _distinct_best(h: np.ndarray, score: np.ndarray, size: tuple[int, int], n: int) -> list[int]:
    """Indices of the ``n`` best-scoring homographies that see the image's grid differently."""
    chosen: list[int] = []
    views: list[np.ndarray] = []
    for k in np.argsort(-score):
        if not np.isfinite(score[k]) or len(chosen) >= n:
            break
        view = _grid_views(h[k: k + 1], size)[0]
        if any(np.nanmax(np.linalg.norm(view - v, axis=1)) <= DISTINCT_M for v in views):
            continue
        chosen.append(int(k))
        views.append(view)
    return chosen


def _line_fit(pm: np.ndarray, normal: np.ndarray, e: np.ndarray, depth: np.ndarray, weight: np.ndarray) -> np.ndarray | None:
    """The homography (normalised coordinates) minimising the weighted distances, along the image
    ``normal``, of the template points ``pm`` from the pixels ``e``: ``n . (h1 X, h2 X) - (n . e) h3 X``
    is linear in ``h``, divided by the current ``depth`` (h3 X) it is the distance in pixels; ``None``
    where the system is not finite."""
    x = np.column_stack([pm, np.ones(len(pm))])
    c = np.sum(normal * e, axis=1)
    a = np.hstack([normal[:, :1] * x, normal[:, 1:] * x, -c[:, None] * x]) * (np.sqrt(weight) / depth)[:, None]
    if not np.all(np.isfinite(a)):  # a degenerate step (template points at the horizon): no refit
        return None
    _, vecs = np.linalg.eigh(a.T @ a)
    return vecs[:, 0].reshape(3, 3)


def _normals(g: np.ndarray, pm: np.ndarray, tm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(projected points, depths, unit image normals)`` of template points ``pm`` with tangents
    ``tm`` through the homography ``g`` (the normal from the projection's derivative along ``tm``)."""
    p = g[:, :2] @ pm.T + g[:, 2:]
    depth = p[2]
    with np.errstate(all="ignore"):  # NaN where a point projects to infinity; caught by _line_fit
        q = (p[:2] / depth).T
        t = ((g[:2, :2] @ tm.T).T - q * (tm @ g[2, :2])[:, None]) / depth[:, None]
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1) / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return q, depth, normal


def _matches(g: np.ndarray, pts: np.ndarray, tangents: np.ndarray, e_all: np.ndarray, band: float):
    """``(pixels, template indices)`` of the evidence ``e_all`` whose nearest projected template
    point of ``pts`` (within :data:`ICP_REACH` bands) has its marking's tangent line within ``band``
    (all in the refinement's normalised units); ``None`` when too few."""
    q, depth, normal = _normals(g, pts, tangents)
    front = (depth > 0) & (np.abs(q[:, 0]) < 2) & (np.abs(q[:, 1]) < 2)
    if front.sum() < 8:
        return None
    idx = np.flatnonzero(front)
    dist, nn = cKDTree(q[idx]).query(e_all, distance_upper_bound=ICP_REACH * band)
    ok = np.isfinite(dist)
    e, m = e_all[ok], idx[nn[ok]]
    near = np.abs(np.sum((q[m] - e) * normal[m], axis=1)) <= band
    if near.sum() < 12:
        return None
    return e[near], m[near]


def refine(h: np.ndarray, evidence: np.ndarray, points: np.ndarray, tangents: np.ndarray,
           size: tuple[int, int], bands: tuple[float, ...] = ICP_BANDS) -> tuple[np.ndarray, float, int]:
    """Robust ICP of one homography (pitch m -> work px) to the mask pixels ``evidence`` (N x 2):
    in each of the ``bands`` (px), every pixel is matched to the marking of the nearest projected
    template point when its tangent line there passes within the band, and the homography is refit
    (all 8 parameters, linear in the homography's entries, Cauchy-weighted, :data:`ICP_STEPS`
    reweighted solves) to the pixels' distances from those tangent lines. Returns
    ``(h, rms px, matched)`` of the last band."""
    width, height = size
    norm = np.array([[2 / width, 0, -1], [0, 2 / width, -height / width], [0, 0, 1]])
    pitch_norm = np.diag([1 / 50, 1 / 50, 1.0])
    e_all = evidence @ norm[:2, :2].T + norm[:2, 2]
    g = norm @ h @ np.linalg.inv(pitch_norm)
    pts = points / 50
    last = None
    for band in bands:
        found = _matches(g, pts, tangents, e_all, band * 2 / width)
        if found is None:
            break
        last = e, m = found
        for _ in range(ICP_STEPS):
            q, depth, normal = (a[m] for a in _normals(g, pts, tangents))  # each template point once
            r = np.sum((q - e) * normal, axis=1) * width / 2
            weight = 1 / (1 + (r / (ICP_CAUCHY * band)) ** 2)
            g_new = _line_fit(pts[m], normal, e, depth, weight)
            if g_new is None:
                break
            g = g_new * np.sign(np.sum(g_new * g))
    rms, matched = np.inf, 0
    if last is not None:  # the last band's pixels against the final homography
        e, m = last
        q, _, normal = _normals(g, pts[m], tangents[m])
        r = np.sum((q - e) * normal, axis=1) * width / 2
        rms, matched = float(np.sqrt(np.mean(r**2))), int(len(r))
    return np.linalg.inv(norm) @ g @ pitch_norm, rms, matched


def _hypotheses(wl: WhiteLines, tpl: "_Template", size: tuple[int, int]) -> np.ndarray:
    """Plausible homographies (pitch m -> work px) from line correspondences and from the centre
    circle with the halfway line."""
    _, valid = pair_vanishing_points(wl.lines, wl.points)
    h = line_homographies(wl.lines, valid, hull(wl.points), tpl.xs, tpl.ys, size)
    if tpl.radius is not None:
        found = ellipses(wl.points, wl.lines, wl.mask.shape)
        h = np.concatenate([h, circle_homographies(found, wl.lines, tpl.radius, size)])
    return h[plausible(h, size)] if len(h) else h


def _to_frame(h: np.ndarray, frame_shape: tuple[int, ...], work_shape: tuple[int, ...]) -> np.ndarray:
    """A work-copy homography as one to frame pixels (pixel centres at integers in both; the scales
    from the two images' shapes, ``(H, W, ...)``)."""
    sy, sx = frame_shape[0] / work_shape[0], frame_shape[1] / work_shape[1]
    s = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1]])
    out = s @ h
    return out / np.linalg.norm(out)


@dataclass(frozen=True)
class _Template:
    """A template prepared for the search: its points (M x 2, m), their ``spacing`` (m), the x of
    its y-parallel lines and the y of its x-parallel ones, the centre circle's radius (m; ``None``
    without one), and the subsamples the scores and the ICP
    use (the ICP's with the markings' unit tangents)."""

    points: np.ndarray
    spacing: float
    xs: np.ndarray
    ys: np.ndarray
    radius: float | None
    quick: np.ndarray
    coarse: np.ndarray
    icp: np.ndarray
    icp_tangents: np.ndarray


@lru_cache(maxsize=4)
def _prepared(points_bytes: bytes, labels_bytes: bytes, labels_dtype: str) -> _Template:
    """The :class:`_Template` of a template given as the bytes of its float64 points and labels
    (cached: a video calls with the same template every frame)."""
    points = np.frombuffer(points_bytes, np.float64).reshape(-1, 2)
    labels = np.frombuffer(labels_bytes, np.dtype(labels_dtype))
    spacing = _spacing(points)
    xs, ys = template_lines(points, spacing)
    quick = max(1, len(points) // QUICK_POINTS)
    coarse = max(1, len(points) // COARSE_POINTS)
    icp = max(1, int(round(ICP_SPACING_M / spacing)))
    tangents = _tangents(points, labels)
    radius = template_radius(points, xs, ys)
    return _Template(points, spacing, xs, ys, radius, points[::quick], points[::coarse], points[::icp], tangents[::icp])


def _search(wl: WhiteLines, tpl: _Template, dist: np.ndarray, n: int, gain: np.ndarray) -> list[np.ndarray]:
    """The ``n`` best distinct hypotheses (pitch m -> work px) by coverage score times covered
    share (:func:`coverage`, ``gain`` the :func:`_gain` of ``dist``): all of them on the quick
    subsample, the best :data:`QUICK_KEPT` on the coarse one."""
    size = (wl.mask.shape[1], wl.mask.shape[0])
    h = _hypotheses(wl, tpl, size)
    if len(h) == 0:
        return []
    step = len(tpl.points) / len(tpl.quick)
    quick = np.prod(coverage(h, tpl.quick, tpl.spacing * step, dist, wl.field, share=True, gain=gain), axis=0)
    h = h[np.argsort(-quick)[:QUICK_KEPT]]
    step = len(tpl.points) / len(tpl.coarse)
    coarse = np.prod(coverage(h, tpl.coarse, tpl.spacing * step, dist, wl.field, share=True, gain=gain), axis=0)
    return [h[k] for k in _distinct_best(h, coarse, size, n)]


def first_guess(frame_rgb: np.ndarray, template_points: np.ndarray, template_labels: np.ndarray, *,
                lens: tuple[float, float] | None = None, max_candidates: int = 5) -> list[Candidate]:
    """Up to ``max_candidates`` camera hypotheses (:class:`Candidate`, best first) of a uint8 RGB
    broadcast frame seen by the main camera, from its white pitch lines and the template's markings
    (module docstring); ``[]`` when the frame has no usable pitch structure (too little grass, no two
    lines of each direction, or no hypothesis that covers enough of the marking evidence)."""
    points, labels, lens_ = _check_inputs(frame_rgb, template_points, template_labels, lens, max_candidates)
    tpl = _prepared(np.ascontiguousarray(points).tobytes(), np.ascontiguousarray(labels).tobytes(), labels.dtype.str)
    wl = white_lines(frame_rgb, lens_)
    if wl.grass < MIN_GRASS or len(wl.points) < 50:
        return []
    size = (wl.mask.shape[1], wl.mask.shape[0])
    dist = cv2.distanceTransform(1 - wl.mask, cv2.DIST_L2, 3)
    gain = _gain(dist)  # once for every coverage score of this frame
    evidence = wl.points[:: max(1, len(wl.points) // ICP_MAX_POINTS)]
    found: list[tuple[float, np.ndarray, float, int, float]] = []
    rough: list[np.ndarray] = []
    for h0 in _search(wl, tpl, dist, max_candidates, gain):  # the wide bands first: many hypotheses meet there
        h = refine(h0, evidence, tpl.icp, tpl.icp_tangents, size, ICP_BANDS[:ICP_ROUGH_BANDS])[0]
        if not any(_same_view(h, other, size) for other in rough):
            rough.append(h)
    for h0 in rough:
        h, rms, matched = refine(h0, evidence, tpl.icp, tpl.icp_tangents, size, ICP_BANDS[ICP_ROUGH_BANDS:])
        score, share = coverage(h[None], tpl.points, tpl.spacing, dist, wl.field, share=True, gain=gain)[:, 0]
        if (score >= MIN_SCORE and share >= MIN_SHARE and plausible(h[None], size)[0]
                and not any(_same_view(h, other[1], size) for other in found)):
            found.append((float(score), h, rms, matched, float(share)))
    out = []
    for score, h, rms, matched, share in sorted(found, key=lambda f: -f[0] * f[4]):
        focal, centre, _ = camera_of(h[None], size)
        out.append(Candidate(_to_frame(h, frame_rgb.shape, wl.mask.shape), score * wl.scale, share, rms * wl.scale, matched,
                             float(focal[0]), tuple(float(c) for c in centre[0])))
    return out


def _same_view(a: np.ndarray, b: np.ndarray, size: tuple[int, int]) -> bool:
    """Whether two homographies see the image's grid at pitch points within :data:`DISTINCT_M`."""
    views = _grid_views(np.stack([a, b]), size)
    return bool(np.nanmax(np.linalg.norm(views[0] - views[1], axis=1)) <= DISTINCT_M)


def _spacing(points: np.ndarray) -> float:
    """Median distance (m) between template points and their nearest neighbour."""
    d, _ = cKDTree(points).query(points, k=2)
    return float(np.median(d[:, 1]))


def strong_lens(frame_rgb: np.ndarray) -> Lens | None:
    """The lens the estimation layer's line fit (:func:`glradial.estimation.net_lines.estimate_net_lines`,
    ``method="lines"``) reads in a uint8 RGB frame when it is strong (:data:`STRONG_LENS_PX`) and
    usable on the frame, else ``None``. Its doubt verdict is not used: the reading is only where the
    camera fit starts (``first_guess(..., lens=)`` and the refinement's initial lens), and the
    camera's own doubt policy judges the result."""
    reading = estimate_net_lines(frame_rgb, "lines")
    lens = Lens(float(reading.k1), float(reading.k2))
    if float(max_displacement_px(np.array([lens.k1, lens.k2]), np.zeros(2))) < STRONG_LENS_PX:
        return None
    try:
        lens.check_frame((frame_rgb.shape[1], frame_rgb.shape[0]))
    except ValueError:
        return None
    return lens
