"""Pitch-to-image homographies from line correspondences: two pairs of image lines whose meeting
points can be the pitch's two vanishing points, assigned to two template lines of each direction,
four lines -> the four corners of a pitch rectangle -> one homography; the pinhole reading of a
homography (focal length, camera centre) and the cheap test that a real main camera could have
taken the view.

Conventions: image coordinates are pixels of the work copy (:mod:`glradial.camera.white_lines`);
pitch coordinates are metres, x along the touchlines, y toward the far touchline. The main camera
stands on the near touchline (y < 0) looking across the pitch, so along the image's downward
direction the x-parallel lines (touchlines, box sides) come in decreasing y, and along the image's
rightward direction the y-parallel lines (goal lines, box fronts, the halfway line) in increasing x:
each hypothesis keeps that order, which both prunes the search and resolves the pitch's half-turn
symmetry.
"""

from __future__ import annotations

import itertools
from functools import lru_cache

import numpy as np

from ..lens.lens import focal_from_hfov
from .model import plane_views
from .white_lines import Line

#: A template line: at least this many template points share one x (or y), and they stand for at
#: least this length of marking (m; their count times the template's spacing).
TEMPLATE_LINE_POINTS, TEMPLATE_LINE_LENGTH = 8, 3.0
#: Plausible main cameras: horizontal field of view (degrees), height above the pitch (m), distance
#: behind the near touchline's side of the centre (y, m) and along it (|x|, m).
HFOV_RANGE = (3.0, 100.0)
HEIGHT_RANGE = (4.0, 80.0)
Y_RANGE = (-250.0, -15.0)
MAX_ABS_X = 150.0
#: A homography is a pinhole view with square pixels and the principal point at the centre when its
#: two pitch axes map to orthogonal rays of equal length: at most this |cosine| and this norm ratio.
MAX_AXIS_COSINE, MAX_AXIS_RATIO = 0.2, 1.3
#: Two vanishing points are the pitch's directions only with the horizon through them within this
#: roll (degrees) and, unless one is far out (directions from the centre within FAR_VP_COSINE of
#: orthogonal), with a focal length in HFOV_RANGE.
MAX_ROLL_DEG, FAR_VP_COSINE = 12.0, 0.15
#: Line pixels may lie this far (px) above the horizon (line noise, pixels off the pitch).
HORIZON_MARGIN = 3.0
#: Line quads tried per frame: the pairs of line pairs whose meeting points most lines point at
#: (ends within POINTING_PX px, direction within POINTING_ANGLE radians), then the longest.
MAX_QUADS, POINTING_PX, POINTING_ANGLE = 48, 2.5, 0.05


def _longest_run(along: np.ndarray, spacing: float) -> float:
    """Length (m) of the longest stretch of ``along`` (sorted coordinates) with no gap over two
    spacings: how much continuous marking a set of points on one straight line makes."""
    if len(along) < 2:
        return 0.0
    breaks = np.flatnonzero(np.diff(along) > 2.0 * spacing)
    starts = np.concatenate([[0], breaks + 1])
    stops = np.concatenate([breaks, [len(along) - 1]])
    return float(np.max(along[stops] - along[starts]))


def template_lines(points: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """``(xs, ys)``: the x of the template's straight lines parallel to the y axis (goal lines, box
    fronts, halfway line) and the y of those parallel to the x axis (touchlines, box sides), read from
    the template points (``M x 2``, metres, ``spacing`` apart along the markings): a value many
    points share over a continuous length of marking (ends of other markings that happen to share a
    coordinate, as the circle's and the goal lines' crossings of y = 0 do, make no line)."""
    out = []
    for axis in (0, 1):
        key = np.round(points[:, axis], 3)
        values, counts = np.unique(key, return_counts=True)
        keep = [v for v, n in zip(values, counts)
                if n >= TEMPLATE_LINE_POINTS and _longest_run(np.sort(points[key == v, 1 - axis]), spacing) >= TEMPLATE_LINE_LENGTH]
        out.append(np.array(keep, dtype=np.float64))
    return out[0], out[1]


def _order(abc: np.ndarray, centre: np.ndarray, axis: int) -> np.ndarray:
    """Line pairs ``abc`` (P x 2 x 3) each sorted along the image direction ``axis`` (1: downward,
    0: rightward), measured where they cross the line through ``centre`` across their mean
    direction."""
    d = np.stack([-abc[..., 1], abc[..., 0]], axis=-1)
    d[:, 1] *= np.sign(np.sum(d[:, 0] * d[:, 1], axis=1) + 1e-12)[:, None]
    mean = d.sum(axis=1)
    across = np.stack([-mean[:, 1], mean[:, 0]], axis=1)
    across *= np.where(across[:, axis] < 0, -1.0, 1.0)[:, None]
    with np.errstate(all="ignore"):
        t = -(abc[..., :2] @ centre + abc[..., 2]) / np.einsum("pkj,pj->pk", abc[..., :2], across)
    swap = t[:, 0] > t[:, 1]
    out = abc.copy()
    out[swap] = abc[swap][:, ::-1]
    return out


def projective_basis(p: np.ndarray) -> np.ndarray:
    """Projective bases (N x 3 x 3) mapping e1, e2, e3, (1, 1, 1) to the homogeneous points
    ``p`` (N x 4 x 3)."""
    m = np.transpose(p[:, :3], (0, 2, 1))
    with np.errstate(all="ignore"):
        lam = np.linalg.solve(m + 1e-300, p[:, 3][..., None])[..., 0]
    return m * lam[:, None, :]


def _pitch_quads(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The pitch rectangles (R x 4 x 3) of two template lines of each direction: y pairs far to
    near, x pairs left to right, corners as in :func:`line_homographies`."""
    quads = []
    for (ya, yb), (xc, xd) in itertools.product(itertools.combinations(np.sort(ys)[::-1], 2),
                                                 itertools.combinations(np.sort(xs), 2)):
        quads.append([[xc, ya, 1], [xd, ya, 1], [xd, yb, 1], [xc, yb, 1]])
    return np.array(quads, float).reshape(-1, 4, 3)


def _normalised_vp(vp: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Homogeneous points (N x 3, px) about the image centre in image widths, unit norm."""
    width, height = size
    v = np.stack([vp[:, 0] - (width - 1) / 2 * vp[:, 2], vp[:, 1] - (height - 1) / 2 * vp[:, 2], width * vp[:, 2]], axis=1)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


def vanishing_pairs(vp: np.ndarray, size: tuple[int, int], hull: np.ndarray) -> np.ndarray:
    """Which pairs of vanishing points (``vp`` P x 3) can be the pitch's two orthogonal directions
    seen by a pinhole camera with a centred principal point, square pixels and a small roll: P x P
    booleans (focal length in :data:`HFOV_RANGE`, roll within :data:`MAX_ROLL_DEG`, and the line
    pixels' convex hull ``hull`` (K x 2) below the horizon through the two, the sky's side up)."""
    v = _normalised_vp(vp, size)
    dot = v[:, None, 0] * v[None, :, 0] + v[:, None, 1] * v[None, :, 1]
    ww = v[:, None, 2] * v[None, :, 2]
    with np.errstate(all="ignore"):
        f2 = -dot / ww
        f_lo, f_hi = (focal_from_hfov(h) for h in HFOV_RANGE[::-1])
        focal_ok = (f2 >= f_lo**2) & (f2 <= f_hi**2)
        # nearly parallel lines (a vanishing point far out) say little about the focal length
        norm = np.hypot(v[:, 0], v[:, 1])
        far = np.abs(dot) <= FAR_VP_COSINE * norm[:, None] * norm[None, :]
        horizon = np.cross(v[:, None, :], v[None, :, :])  # in the normalised coordinates of v
        roll = np.degrees(np.arctan2(np.abs(horizon[..., 0]), np.abs(horizon[..., 1])))
        horizon *= np.where(horizon[..., 1:2] < 0, -1.0, 1.0)  # positive below the horizon (y down)
        horizon /= np.maximum(np.hypot(horizon[..., 0], horizon[..., 1]), 1e-300)[..., None]
        width, height = size
        h_norm = np.column_stack([hull[:, 0] - (width - 1) / 2, hull[:, 1] - (height - 1) / 2, np.full(len(hull), width)]) / width
        below = np.einsum("pqk,mk->pqm", horizon, h_norm).min(axis=2) >= -HORIZON_MARGIN / width
    return (focal_ok | far) & (roll <= MAX_ROLL_DEG) & below


def _pointing(lines: list[Line], vp: np.ndarray) -> np.ndarray:
    """Whether each line points at each homogeneous point ``vp`` (P x 3): P x L booleans; a line
    points at a point when turning it about its centre to pass through the point moves its ends by at
    most :data:`POINTING_PX` and turns it by at most :data:`POINTING_ANGLE`."""
    abc = np.array([line.abc for line in lines])
    centre = np.array([line.centre for line in lines])
    half = np.array([line.half_length for line in lines])
    towards = vp[:, None, :2] - vp[:, None, 2:3] * centre[None]
    norm = np.maximum(np.linalg.norm(towards, axis=2), 1e-300)
    sin = np.abs(np.einsum("plk,lk->pl", towards, abc[:, :2])) / norm
    return (sin <= POINTING_ANGLE) & (half[None] * sin <= POINTING_PX)


def line_homographies(lines: list[Line], valid_vp: np.ndarray, hull: np.ndarray, xs: np.ndarray,
                      ys: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Every homography (N x 3 x 3, pitch -> work px, sign: positive depth at the image centre,
    unit norm) that sends two template lines of each direction onto two pairs of image lines
    whose meeting points can be the pitch's vanishing points (``valid_vp``, per line pair: off the
    hull of the line pixels ``hull``, :func:`vanishing_pairs`), either pair in either role, in the main camera's order
    (module docstring)."""
    if len(lines) < 4 or len(xs) < 2 or len(ys) < 2:
        return np.zeros((0, 3, 3))
    abc = np.array([line.abc for line in lines])
    i, j = np.triu_indices(len(lines), 1)
    keep = valid_vp
    i, j = i[keep], j[keep]
    vp = np.cross(abc[i], abc[j])
    p, q = np.nonzero(vanishing_pairs(vp, size, hull))
    pointing = _pointing(lines, vp)
    # four distinct lines, and neither pair's lines point at the other pair's meeting point
    apart = ~(pointing[p, i[q]] | pointing[p, j[q]] | pointing[q, i[p]] | pointing[q, j[p]])
    p, q = p[apart], q[apart]  # ordered pairs: p is the x-parallel pair, q the y-parallel one
    if len(p) == 0:
        return np.zeros((0, 3, 3))
    support = np.array([line.support for line in lines])
    family = pointing @ support  # support of all the lines through each meeting point
    rank = family[p] + family[q] + 0.5 * (support[i[p]] + support[j[p]] + support[i[q]] + support[j[q]])
    best = np.argsort(-rank)[:MAX_QUADS]
    p, q = p[best], q[best]
    centre = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2])
    a = _order(np.stack([abc[i[p]], abc[j[p]]], axis=1), centre, 1)
    b = _order(np.stack([abc[i[q]], abc[j[q]]], axis=1), centre, 0)
    corners = np.stack([np.cross(a[:, 0], b[:, 0]), np.cross(a[:, 0], b[:, 1]),
                        np.cross(a[:, 1], b[:, 1]), np.cross(a[:, 1], b[:, 0])], axis=1)
    img = projective_basis(corners)
    inv = _pitch_bases(xs.tobytes(), ys.tobytes())
    with np.errstate(all="ignore"):
        h = np.matmul(img[:, None], inv[None]).reshape(-1, 3, 3)
    return front_facing(h, centre)


@lru_cache(maxsize=8)
def _pitch_bases(xs_bytes: bytes, ys_bytes: bytes) -> np.ndarray:
    """The inverse projective bases (R x 3 x 3) of the template's line rectangles
    (:func:`_pitch_quads` of the float64 ``xs``, ``ys`` given as bytes): the same for every frame."""
    with np.errstate(all="ignore"):
        inv = np.linalg.inv(projective_basis(_pitch_quads(np.frombuffer(xs_bytes), np.frombuffer(ys_bytes))))
    inv.flags.writeable = False
    return inv


def front_facing(h: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The finite homographies of ``h`` with the sign that gives the pitch point seen at image point
    ``centre`` a positive depth ``(h X)_3``, scaled to unit norm."""
    h = h[np.isfinite(h).all(axis=(1, 2))]
    with np.errstate(all="ignore"):
        # h⁻¹ c = adj(h) c / det h, adj(h)'s columns the cross products of h's rows (of rows 1, 2 and
        # 2, 0 only the third component is read)
        c01 = np.cross(h[:, 0], h[:, 1])
        c12 = h[:, 1, 0] * h[:, 2, 1] - h[:, 1, 1] * h[:, 2, 0]
        c20 = h[:, 2, 0] * h[:, 0, 1] - h[:, 2, 1] * h[:, 0, 0]
        seen_w = centre[0] * c12 + centre[1] * c20 + c01[:, 2]
        det = np.sum(h[:, 2] * c01, axis=1)
        h = h * np.sign(seen_w * det)[:, None, None]
        h = h / np.sqrt(np.sum(h**2, axis=(1, 2)))[:, None, None]
    return h[np.isfinite(h).all(axis=(1, 2)) & (np.abs(det) > 0)]


def _pinhole(h: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(focal, metric, m)``: the focal length (image widths, NaN where none fits) of homographies
    ``h`` read as views with a centred principal point and square pixels
    (:func:`glradial.camera.model.plane_views`), whether their two pitch axes then map to orthogonal
    rays of equal length, and the scaled ``[r1 r2 t]`` (up to sign) of each."""
    focal, g = plane_views(h, size)
    with np.errstate(all="ignore"):
        n1 = np.sqrt(np.sum(g[:, :, 0] ** 2, axis=1))
        n2 = np.sqrt(np.sum(g[:, :, 1] ** 2, axis=1))
        cosine = np.abs(np.sum(g[:, :, 0] * g[:, :, 1], axis=1)) / (n1 * n2)
        metric = (cosine <= MAX_AXIS_COSINE) & (np.maximum(n1 / n2, n2 / n1) <= MAX_AXIS_RATIO)
    return focal, metric, g


def camera_of(h: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(focal, centre, metric)`` of homographies ``h`` (N x 3 x 3, pitch m -> px of a ``(W, H)``
    image) read as pinhole views with square pixels and the principal point at the image centre:
    the focal length in image widths (NaN where none fits), the camera centre (N x 3, metres, z up)
    and whether the two pitch axes map to orthogonal rays of equal length (:data:`MAX_AXIS_COSINE`)."""
    focal, metric, m = _pinhole(h, size)
    return focal, _centres(m), metric


def _centres(m: np.ndarray) -> np.ndarray:
    """Camera centres (N x 3, metres, z up) of the scaled ``[r1 r2 t]`` (up to sign) ``m`` of
    :func:`_pinhole`."""
    with np.errstate(all="ignore"):
        r1, r2, t = m[:, :, 0], m[:, :, 1], m[:, :, 2]
        # sign: the pitch point seen at the image centre, m⁻¹ e3 ∝ row0 × row1, lies in front
        seen = np.cross(m[:, 0], m[:, 1])
        scale = np.sign(np.sum(m[:, 2] * seen, axis=1) * seen[:, 2])
        r1, r2, t = r1 * scale[:, None], r2 * scale[:, None], t * scale[:, None]
        r3 = np.cross(r1, r2)
        return -np.stack([np.sum(r1 * t, axis=1), np.sum(r2 * t, axis=1), np.sum(r3 * t, axis=1)], axis=1)


def plausible(h: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Whether each homography (N x 3 x 3) is a view a main camera could take (module constants)."""
    focal, metric, m = _pinhole(h, size)
    with np.errstate(all="ignore"):
        hfov = np.degrees(2 * np.arctan(0.5 / focal))
    ok = metric & (hfov >= HFOV_RANGE[0]) & (hfov <= HFOV_RANGE[1])
    idx = np.flatnonzero(ok)
    centre = _centres(m[idx])  # each homography's reading is its own: the same as camera_of(h[idx])
    with np.errstate(all="ignore"):
        ok[idx] = (centre[:, 2] >= HEIGHT_RANGE[0]) & (centre[:, 2] <= HEIGHT_RANGE[1])
        ok[idx] &= (centre[:, 1] >= Y_RANGE[0]) & (centre[:, 1] <= Y_RANGE[1]) & (np.abs(centre[:, 0]) <= MAX_ABS_X)
    return ok
