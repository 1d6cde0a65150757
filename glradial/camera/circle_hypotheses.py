"""Pitch-to-image homographies from the centre circle and the halfway line, for views where fewer
than two lines of one direction are in sight (the centre circle, the halfway line, a touchline).

The circle's image is an ellipse; the halfway line is a diameter. Where the line meets the ellipse
are the circle points (0, +r) (the upper one: the far side) and (0, -r); the tangents there are the
images of the lines y = ±r, which are parallel to the touchlines, so they meet in the touchlines'
vanishing point. One parameter is left (the circle and one diameter keep a one-parameter family of
projective maps): where the circle's centre is seen along the halfway line. It is sampled; each
sample gives the line through the centre toward that vanishing point, which meets the ellipse at
(±r, 0), and four correspondences give a homography. The plausibility test and the coverage score
of the first guess choose among them, and the refinement fits the rest.

Conventions as in :mod:`glradial.camera.line_hypotheses` (work-copy pixels, pitch metres, main
camera on the near touchline).
"""

from __future__ import annotations

import cv2
import numpy as np

from .line_hypotheses import front_facing, projective_basis
from .white_lines import Line

#: The centre circle is looked for within this distance (m) of the centre spot in the template.
CIRCLE_SEARCH_M = 20.0
#: Mask pixels this close (px) to a straight line are left out of the ellipse search...
LINE_BAND = 3.0
#: ...unless the line is a piece of a curve: its pixels bend, along it, with a curvature (the
#: quadratic term of their offset from it, 1/px) of at least CURVE_MIN, CURVE_SIGMAS standard errors
#: from zero. A flattened centre circle's sides are cut into Hough lines; their curvature at a
#: 640-px work copy is 1e-3 or more (b / a² of an ellipse of semi-axes a, b ≤ 320 px), a touchline
#: bent by a broadcast lens under 1e-4 (a few px of sagitta over the frame).
CURVE_MIN, CURVE_SIGMAS = 3e-4, 3.0
#: Components (8-connected) of the remaining pixels tried, largest first, alone and in pairs, and the
#: fewest pixels one needs.
MAX_COMPONENTS, MIN_COMPONENT_PIXELS = 6, 25
#: An ellipse's semi-axes are within AXIS_RANGE (px); at most MAX_ELLIPSES of the best are kept.
AXIS_RANGE, MAX_ELLIPSES = (6.0, 800.0), 3
#: The fit is refit (at most FIT_ROUNDS times) to the pixels within TRIM_PX of the last ellipse,
#: from the group's components and the others (a player's limb or a line touching the circle drops
#: out, the arc's other pieces join); kept when at least MIN_INLIER_SHARE of the group lies on the
#: last one and its pixels lie on it with an RMS of at most MAX_TRIMMED_RMS px (pixels spread evenly
#: over the +-TRIM_PX band would give 1.44 px; a painted line 2-3 px wide gives 0.6-0.9 px).
TRIM_PX, FIT_ROUNDS, MIN_INLIER_SHARE, MAX_TRIMMED_RMS = 2.5, 3, 0.5, 1.1
#: The group's own first fit must pass within TRIM_PX of this share of its pixels (an arc whose
#: pieces carry a player's limb or a line's end reaches 0.34-0.45 before the refits; pixels of no
#: common ellipse stay far under).
FIRST_SHARE = 0.25
#: Each fit takes at most about this many of its pixels, evenly spread (every k-th).
FIT_POINTS = 300
#: The halfway line passes the ellipse's centre within this share of its smaller semi-axis.
DIAMETER_OFFSET = 0.35
#: Where the circle's centre may be seen between the far and the near crossing (share of the way).
CENTRE_SAMPLES = np.linspace(0.2, 0.7, 51)


def template_radius(points: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> float | None:
    """The centre circle's radius (m) read from the template points (M x 2): the points off the
    straight lines (``xs``, ``ys``) within :data:`CIRCLE_SEARCH_M` of the centre spot, when they lie
    on one circle (spread of their distances under 1 %); ``None`` when there is none."""
    off = ~np.isin(np.round(points[:, 0], 3), np.round(xs, 3)) & ~np.isin(np.round(points[:, 1], 3), np.round(ys, 3))
    r = np.hypot(points[off, 0], points[off, 1])
    r = r[(r > 1.0) & (r < CIRCLE_SEARCH_M)]
    if len(r) < 16 or np.std(r) > 0.01 * np.median(r):
        return None
    return float(np.median(r))


def _conic(ellipse) -> np.ndarray:
    """The 3 x 3 conic matrix (x^T C x = 0) of a ``cv2.fitEllipse`` result."""
    (cx, cy), (w, h), angle = ellipse
    a, b = w / 2, h / 2
    t = np.radians(angle)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    q = rot @ np.diag([1 / a**2, 1 / b**2]) @ rot.T
    centre = np.array([cx, cy])
    c = np.zeros((3, 3))
    c[:2, :2] = q
    c[:2, 2] = c[2, :2] = -q @ centre
    c[2, 2] = centre @ q @ centre - 1
    return c


def _distances(conic: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Sampson distances (px) of ``points`` (N x 2, or N x 3 homogeneous with w = 1) from the conic:
    ``x^T C x / (2 |(C x)_xy|)``, written out on the x and y columns (a 3 x 3 product per point costs
    numpy more in its matrix and row-sum calls than in the arithmetic)."""
    px, py, c = points[:, 0], points[:, 1], conic
    gx = px * c[0, 0] + py * c[1, 0] + c[2, 0]
    gy = px * c[0, 1] + py * c[1, 1] + c[2, 1]
    value = px * gx + py * gy + (px * c[0, 2] + py * c[1, 2] + c[2, 2])
    return value / np.maximum(2 * np.hypot(gx, gy), 1e-12)


def _rms(conic: np.ndarray, points: np.ndarray) -> float:
    """RMS Sampson distance (px) of ``points`` (N x 2) from the conic."""
    return float(np.sqrt(np.mean(_distances(conic, points) ** 2)))


def _near(points: np.ndarray, line: Line) -> np.ndarray:
    """Which ``points`` lie within :data:`LINE_BAND` of ``line`` along its extent."""
    d = np.array([-line.abc[1], line.abc[0]])
    lo, hi = np.sort(line.ends @ d)
    along = points @ d
    return (np.abs(points @ line.abc[:2] + line.abc[2]) <= LINE_BAND) & (along >= lo - 2) & (along <= hi + 2)


def curved(points: np.ndarray, line: Line) -> bool:
    """Whether the pixels ``points`` of ``line`` bend along it: the least-squares quadratic of their
    offset from the line against their position along it has a curvature (1/px) of at least
    :data:`CURVE_MIN`, :data:`CURVE_SIGMAS` standard errors from zero."""
    if len(points) < 8:
        return False
    along = (points - line.centre) @ np.array([-line.abc[1], line.abc[0]])
    scale = max(float(np.std(along)), 1e-9)
    s = (along - along.mean()) / scale
    a = np.stack([np.ones_like(s), s, s * s - 1.0])  # 3 x N: the quadratic's basis, centred
    r = points @ line.abc[:2] + line.abc[2]
    normal = a @ a.T
    coef = np.linalg.solve(normal, a @ r)
    sigma2 = float(np.sum((r - coef @ a) ** 2)) / max(len(r) - 3, 1)
    c, sd = abs(coef[2]) / scale**2, np.sqrt(sigma2 * np.linalg.inv(normal)[2, 2]) / scale**2
    return bool(c >= CURVE_MIN and c >= CURVE_SIGMAS * sd)


def _off_lines(points: np.ndarray, lines: list[Line]) -> np.ndarray:
    """The ``points`` farther than :data:`LINE_BAND` from every straight line's extent (the pixels of
    lines that are pieces of a curve, :func:`curved`, stay)."""
    keep = np.ones(len(points), bool)
    for line in lines:
        near = _near(points, line)
        if not curved(points[near], line):
            keep &= ~near
    return points[keep]


def _fit_ellipse(pts: np.ndarray, pool: np.ndarray, found: list[tuple]) -> tuple[int, np.ndarray, tuple] | None:
    """``(pixels on it, conic, cv2 ellipse)`` fitted to the pixels ``pts`` (N x 2), then refit to the
    pixels of ``pool`` (the group's and the other components') within :data:`TRIM_PX` of it until
    they stay the same (:data:`FIT_ROUNDS` at most), so an arc broken by players or a line is fitted
    whole (``pool``: N x 3, homogeneous); ``None`` when its axes leave :data:`AXIS_RANGE`, under
    :data:`MIN_INLIER_SHARE` of ``pts`` stay on it, its pixels lie on it with an RMS above
    :data:`MAX_TRIMMED_RMS`, or a refit meets one of the ellipses ``found`` from other groups."""
    inliers, count = pts, -1
    for _ in range(FIT_ROUNDS):
        step = max(1, len(inliers) // FIT_POINTS)  # evenly thinned: the cost, not the fit, grows with more
        ellipse = cv2.fitEllipse(inliers[::step, :2].astype(np.float32))
        axes = np.array(ellipse[1]) / 2
        if not (np.all(np.isfinite(axes)) and AXIS_RANGE[0] <= axes.min() and axes.max() <= AXIS_RANGE[1]):
            return None
        if count >= 0 and any(_same_ellipse(ellipse, other[2]) for other in found):
            return None  # the same arc reached from another group
        conic = _conic(ellipse)
        if count < 0 and np.mean(np.abs(_distances(conic, pts)) <= TRIM_PX) < FIRST_SHARE:
            return None  # the group's pixels are not one arc (a player, a board, two markings)
        inliers = pool[np.abs(_distances(conic, pool)) <= TRIM_PX]
        if len(inliers) < 2 * MIN_COMPONENT_PIXELS or len(inliers) == count:
            break
        count = len(inliers)
    if len(inliers) < 2 * MIN_COMPONENT_PIXELS or np.mean(np.abs(_distances(conic, pts)) <= TRIM_PX) < MIN_INLIER_SHARE:
        return None
    return (len(inliers), conic, ellipse) if _rms(conic, inliers) <= MAX_TRIMMED_RMS else None


def ellipses(points: np.ndarray, lines: list[Line], shape: tuple[int, int]) -> list[tuple[np.ndarray, tuple]]:
    """Ellipses among the mask pixels ``points`` (N x 2, px of a work copy of ``shape`` (H, W)) not
    on the straight ``lines`` (:func:`_off_lines`): ``(conic 3 x 3, cv2 ellipse)`` of the fits to one or
    two of its largest components (:func:`_fit_ellipse`), distinct, most pixels on them first."""
    rest = _off_lines(points, lines)
    if len(rest) < MIN_COMPONENT_PIXELS:
        return []
    mask = np.zeros(shape, np.uint8)
    ix, iy = rest[:, 0].astype(int), rest[:, 1].astype(int)
    mask[iy, ix] = 1
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    big = [k for k in np.argsort(-stats[:, cv2.CC_STAT_AREA]) if k and stats[k, cv2.CC_STAT_AREA] >= MIN_COMPONENT_PIXELS]
    label_of = labels[iy, ix]
    pieces = {k: rest[label_of == k] for k in big[:MAX_COMPONENTS]}
    groups = [[k] for k in pieces] + [[a, b] for i, a in enumerate(pieces) for b in list(pieces)[i + 1:]]
    pool = np.column_stack([rest, np.ones(len(rest))])
    found: list[tuple] = []
    covered: list[set] = []  # the components on each ellipse found: a group of them gives it again
    for group in groups:
        pts = np.concatenate([pieces[k] for k in group])
        if len(pts) < 2 * MIN_COMPONENT_PIXELS or any(set(group) <= c for c in covered):
            continue
        fitted = _fit_ellipse(pts, pool, found)
        if fitted is not None:
            found.append(fitted)
            covered.append({k for k, p in pieces.items()
                            if np.mean(np.abs(_distances(fitted[1], p)) <= TRIM_PX) >= MIN_INLIER_SHARE})
    kept: list[tuple[np.ndarray, tuple]] = []
    for _, conic, ellipse in sorted(found, key=lambda f: -f[0]):
        if len(kept) < MAX_ELLIPSES and not any(_same_ellipse(ellipse, other) for _, other in kept):
            kept.append((conic, ellipse))
    return kept


def _same_ellipse(a: tuple, b: tuple) -> bool:
    """Whether two ``cv2`` ellipses have centres and axes within :data:`TRIM_PX` of each other (the
    same pixels fitted from two groups)."""
    return bool(np.hypot(a[0][0] - b[0][0], a[0][1] - b[0][1]) <= TRIM_PX
                and np.all(np.abs(np.sort(a[1]) - np.sort(b[1])) <= 2 * TRIM_PX))


def _meet(conic: np.ndarray, lines: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each homogeneous line (K x 3) meets the conic: ``(points K x 2 x 2, upper (smaller y)
    first; ok K)``, ``ok`` False where a line misses it."""
    lines = np.atleast_2d(lines)
    d = np.stack([-lines[:, 1], lines[:, 0]], axis=1)
    p0 = -lines[:, 2:3] * lines[:, :2] / np.sum(lines[:, :2] ** 2, axis=1, keepdims=True)
    x0 = np.column_stack([p0, np.ones(len(p0))])
    dd = np.column_stack([d, np.zeros(len(d))])
    a = np.einsum("ki,ij,kj->k", dd, conic, dd)
    b = 2 * np.einsum("ki,ij,kj->k", dd, conic, x0)
    c = np.einsum("ki,ij,kj->k", x0, conic, x0)
    disc = b * b - 4 * a * c
    ok = (np.abs(a) > 1e-300) & (disc > 0)
    with np.errstate(all="ignore"):
        t = (-b[:, None] + np.array([-1.0, 1.0]) * np.sqrt(np.where(ok, disc, 0.0))[:, None]) / (2 * a[:, None])
    pts = p0[:, None, :] + t[..., None] * d[:, None, :]
    swap = pts[:, 0, 1] > pts[:, 1, 1]
    pts[swap] = pts[swap][:, ::-1]
    return pts, ok


def _homogeneous(p: np.ndarray) -> np.ndarray:
    return np.append(p, 1.0)


def circle_homographies(ellipse_list, lines: list[Line], radius: float, size: tuple[int, int]) -> np.ndarray:
    """Homographies (N x 3 x 3, pitch m -> work px; sign and scale as
    :func:`glradial.camera.line_hypotheses.front_facing`) from each ellipse with each line through it
    as the halfway line, for each sampled centre (module docstring); ``radius``: the template's
    centre-circle radius (m)."""
    pitch = np.array([[0, radius, 1], [0, -radius, 1], [1, 0, 0], [radius, 0, 1]], float)
    p_inv = np.linalg.inv(projective_basis(pitch[None])[0])
    out = []
    for conic, ellipse in ellipse_list:
        centre = np.array(ellipse[0])
        minor = min(ellipse[1]) / 2
        for line in lines:
            if abs(line.abc[:2] @ centre + line.abc[2]) > DIAMETER_OFFSET * minor + 1.0:
                continue
            crossing, ok = _meet(conic, line.abc)
            if not ok[0]:
                continue
            far, near = _homogeneous(crossing[0, 0]), _homogeneous(crossing[0, 1])
            vp = np.cross(conic @ far, conic @ near)  # the tangents meet at the touchlines' vanishing point
            seen = crossing[0, 0] + CENTRE_SAMPLES[:, None] * (crossing[0, 1] - crossing[0, 0])
            side, ok = _meet(conic, np.cross(np.column_stack([seen, np.ones(len(seen))]), vp))
            right = side[np.arange(len(side)), np.argmax(side[:, :, 0], axis=1)][ok]
            img = np.stack([np.broadcast_to(far, (len(right), 3)), np.broadcast_to(near, (len(right), 3)),
                            np.broadcast_to(vp, (len(right), 3)), np.column_stack([right, np.ones(len(right))])], axis=1)
            out.append(projective_basis(img) @ p_inv)
    if not out:
        return np.zeros((0, 3, 3))
    return front_facing(np.concatenate(out), np.array([(size[0] - 1) / 2, (size[1] - 1) / 2]))
