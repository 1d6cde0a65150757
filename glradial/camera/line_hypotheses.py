"""Pitch-to-image homographies from line correspondences: two image lines of each family assigned
to two template lines of each direction, four lines -> the four corners of a pitch rectangle -> one
homography; then the cheap test that a real main camera could have taken the view.

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

import numpy as np

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


def template_lines(points: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """``(xs, ys)``: the x of the template's straight lines parallel to the y axis (goal lines, box
    fronts, halfway line) and the y of those parallel to the x axis (touchlines, box sides), read from
    the template points (``M x 2``, metres, ``spacing`` apart along the markings): a value many
    points share over a length of marking."""
    out = []
    for axis in (0, 1):
        values, counts = np.unique(np.round(points[:, axis], 3), return_counts=True)
        out.append(values[(counts >= TEMPLATE_LINE_POINTS) & (counts * spacing >= TEMPLATE_LINE_LENGTH)])
    return out[0], out[1]


def _order(lines: list[Line], centre: np.ndarray, axis: int) -> list[Line]:
    """``lines`` of one family sorted along the image direction ``axis`` (1: downward, 0: rightward),
    measured where they cross the line through ``centre`` across the family's mean direction."""
    d = np.array([[-line.abc[1], line.abc[0]] for line in lines])
    d *= np.sign(d @ d[0] + 1e-12)[:, None]
    across = np.array([-d.mean(axis=0)[1], d.mean(axis=0)[0]])
    if across[axis] < 0:
        across = -across
    t = []
    for line in lines:
        denom = line.abc[:2] @ across
        t.append(-(line.abc[:2] @ centre + line.abc[2]) / denom if abs(denom) > 1e-9 else np.inf)
    return [lines[k] for k in np.argsort(t)]


def _basis(p: np.ndarray) -> np.ndarray:
    """Projective bases (N x 3 x 3) mapping e1, e2, e3, (1, 1, 1) to the homogeneous points
    ``p`` (N x 4 x 3)."""
    m = np.transpose(p[:, :3], (0, 2, 1))
    lam = np.linalg.solve(m + 1e-300, p[:, 3][..., None])[..., 0]
    return m * lam[:, None, :]


def _image_quads(fam_a: list[Line], fam_b: list[Line]) -> np.ndarray:
    """Corner points (Q x 4 x 3) of each pair of ordered lines of ``fam_a`` (the x-parallel
    candidates, top to bottom) with each pair of ``fam_b`` (left to right): corners in the order
    (a_i, b_k), (a_i, b_l), (a_j, b_l), (a_j, b_k)."""
    a = np.array([line.abc for line in fam_a])
    b = np.array([line.abc for line in fam_b])
    quads = []
    for (i, j), (k, m) in itertools.product(itertools.combinations(range(len(a)), 2),
                                             itertools.combinations(range(len(b)), 2)):
        quads.append([np.cross(a[i], b[k]), np.cross(a[i], b[m]), np.cross(a[j], b[m]), np.cross(a[j], b[k])])
    return np.array(quads, float).reshape(-1, 4, 3)


def _pitch_quads(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """The matching pitch rectangles (R x 4 x 3): y pairs far to near, x pairs left to right."""
    quads = []
    for (ya, yb), (xc, xd) in itertools.product(itertools.combinations(np.sort(ys)[::-1], 2),
                                                 itertools.combinations(np.sort(xs), 2)):
        quads.append([[xc, ya, 1], [xd, ya, 1], [xd, yb, 1], [xc, yb, 1]])
    return np.array(quads, float).reshape(-1, 4, 3)


def line_homographies(fam_a: list[Line], fam_b: list[Line], xs: np.ndarray, ys: np.ndarray,
                      centre: np.ndarray) -> np.ndarray:
    """Every homography (N x 3 x 3, pitch -> work px) that sends two template lines of each direction
    onto two image lines of each family, in the main camera's order (module docstring)."""
    if len(fam_a) < 2 or len(fam_b) < 2 or len(xs) < 2 or len(ys) < 2:
        return np.zeros((0, 3, 3))
    img = _basis(_image_quads(_order(fam_a, centre, 1), _order(fam_b, centre, 0)))
    pitch = _basis(_pitch_quads(xs, ys))
    with np.errstate(all="ignore"):
        inv = np.linalg.inv(pitch)
        h = np.einsum("qij,rjk->qrik", img, inv).reshape(-1, 3, 3)
        h = h[np.isfinite(h).all(axis=(1, 2))]
        # sign: the pitch point seen at the image centre has a positive depth (h X)_3
        seen = np.linalg.solve(h, np.tile([centre[0], centre[1], 1.0], (len(h), 1))[..., None])[..., 0]
        h *= np.sign(seen[:, 2])[:, None, None]
        h /= np.linalg.norm(h, axis=(1, 2))[:, None, None]
    return h[np.isfinite(h).all(axis=(1, 2))]


def camera_of(h: np.ndarray, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(focal, centre, metric)`` of homographies ``h`` (N x 3 x 3, pitch m -> px of a ``(W, H)``
    image) read as pinhole views with square pixels and the principal point at the image centre:
    the focal length in image widths (NaN where none fits), the camera centre (N x 3, metres, z up)
    and whether the two pitch axes map to orthogonal rays of equal length (:data:`MAX_AXIS_COSINE`)."""
    width, height = size
    shift = np.array([[1 / width, 0, -(width - 1) / 2 / width], [0, 1 / width, -(height - 1) / 2 / width], [0, 0, 1]])
    g = np.einsum("ij,njk->nik", shift, h)
    a1, b1, c1 = g[:, 0, 0], g[:, 1, 0], g[:, 2, 0]
    a2, b2, c2 = g[:, 0, 1], g[:, 1, 1], g[:, 2, 1]
    u = np.stack([a1 * a2 + b1 * b2, a1 * a1 + b1 * b1 - a2 * a2 - b2 * b2], axis=1)
    v = np.stack([c1 * c2, c1 * c1 - c2 * c2], axis=1)
    with np.errstate(all="ignore"):
        w = -np.sum(u * v, axis=1) / np.sum(u * u, axis=1)  # 1 / focal^2, least squares
        focal = np.where(w > 0, 1 / np.sqrt(np.abs(w)), np.nan)
        k_inv = np.stack([1 / focal, 1 / focal, np.ones_like(focal)], axis=1)[:, :, None]
        m = g * k_inv
        r1, r2, t = m[:, :, 0], m[:, :, 1], m[:, :, 2]
        n1, n2 = np.linalg.norm(r1, axis=1), np.linalg.norm(r2, axis=1)
        metric = (np.abs(np.sum(r1 * r2, axis=1)) / (n1 * n2) <= MAX_AXIS_COSINE) & (np.maximum(n1 / n2, n2 / n1) <= MAX_AXIS_RATIO)
        scale = 2 / (n1 + n2)
        # sign: the pitch point seen at the image centre lies in front of the camera
        seen = np.linalg.solve(g, np.tile([0.0, 0.0, 1.0], (len(g), 1))[..., None])[..., 0]
        depth = np.sum(m[:, 2, :] * seen, axis=1) * seen[:, 2]
        scale = scale * np.sign(depth)
        r1, r2, t = r1 * scale[:, None], r2 * scale[:, None], t * scale[:, None]
        r3 = np.cross(r1, r2)
        centre = -np.stack([np.sum(r1 * t, axis=1), np.sum(r2 * t, axis=1), np.sum(r3 * t, axis=1)], axis=1)
    return focal, centre, metric


def plausible(h: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Whether each homography (N x 3 x 3) is a view a main camera could take (module constants)."""
    focal, centre, metric = camera_of(h, size)
    with np.errstate(all="ignore"):
        hfov = np.degrees(2 * np.arctan(0.5 / focal))
        ok = metric & (hfov >= HFOV_RANGE[0]) & (hfov <= HFOV_RANGE[1])
        ok &= (centre[:, 2] >= HEIGHT_RANGE[0]) & (centre[:, 2] <= HEIGHT_RANGE[1])
        ok &= (centre[:, 1] >= Y_RANGE[0]) & (centre[:, 1] <= Y_RANGE[1]) & (np.abs(centre[:, 0]) <= MAX_ABS_X)
    return ok & np.isfinite(focal)
