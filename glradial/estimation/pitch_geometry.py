"""Pitch-plane evidence beyond straightness: vanishing points of line families and conics.

A pitch is a plane with a known drawing. Once the lens is removed, the image is a pinhole view of
that plane, so

* the lines of one family (parallel on the pitch: touchlines, goal lines and the box lines parallel
  to them) meet in one **vanishing point** (possibly at infinity), two families when both are in
  view; a wrong lens bends and turns lines by different amounts at different places, and they stop
  meeting in a point;
* the centre circle and the penalty arcs are **conics** (ellipses): a wrong lens adds higher-order
  terms that no conic follows.

These constrain ``(k1, k2)`` where each line alone is too short to (a few short lines near the
centre still have to agree on a vanishing point). :mod:`glradial.estimation.line_fit` adds them to its cost.

Convention: all coordinates are lens units (image width = 1, origin at the principal point),
undistorted with the lens being tried; arrays carry a leading lens axis ``L``. A line is given by
its unit normal ``n`` and offset ``c`` (``n . p = c``), its centre and its half-length. Residuals are
returned in lens units; the caller scales them to pixels.
"""

from __future__ import annotations

import numpy as np

#: A line joins a family when pointing it at the family's vanishing point moves its ends by at most
#: this much (lens units; 2 px of an 800-px detection copy).
FAMILY_TOL = 1.25e-3
#: Two pieces are one line when each centre lies this close (lens units; 8 px of an 800-px copy) to
#: the other's line and their directions agree within SAME_LINE_ANGLE (radians).
SAME_LINE_TOL, SAME_LINE_ANGLE = 1e-2, 0.03
#: ...and the line's direction at most this far (radians) from the vanishing point's: a short piece
#: points nowhere in particular.
FAMILY_ANGLE = 0.01
#: A line counts towards a family only through a piece at least this long (half-length, lens units;
#: 100 px of a 1280-px frame): a short piece points at many places within tolerance.
FAMILY_MIN_HALF_LENGTH = 0.04
#: Distinct lines a family needs (two lines always meet; a third can pass near their point by chance in a
#: frame of many lines, a fourth rarely does).
MIN_FAMILY_LINES = 5
#: At most this many families (a pitch has two directions of lines).
MAX_FAMILIES = 2
#: Arcs join one conic when a conic through all of them fits within this RMS (lens units; 1 px of an
#: 800-px detection copy), and the conic is an ellipse.
CONIC_MERGE_TOL = 1.25e-3


def line_params(mx, my, cxx, cyy, cxy) -> tuple[np.ndarray, np.ndarray]:
    """Total-least-squares lines from point moments (centre ``mx, my``, central second moments):
    ``(normal (..., 2), offset (...))`` with ``normal . p = offset``."""
    theta = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # direction of the largest spread
    normal = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
    return normal, normal[..., 0] * mx + normal[..., 1] * my


def _vanishing_point(normal, offset, weight) -> np.ndarray:
    """Homogeneous point (..., 3), unit norm, minimising sum w (n . v_xy - c v_w)^2 over lines (..., K)."""
    lines = np.concatenate([normal, -offset[..., None]], axis=-1) * np.sqrt(weight)[..., None]
    scatter = np.einsum("...ki,...kj->...ij", lines, lines)
    _, vecs = np.linalg.eigh(scatter)
    return vecs[..., :, 0]


def end_offsets(normal, offset, centre, half_length, vp) -> np.ndarray:
    """How far (lens units) each line's ends move when it is turned about its centre to point at the
    homogeneous point ``vp`` (broadcast over the leading axes): ``half_length * sin(angle)``."""
    towards = vp[..., None, :2] - vp[..., None, 2:3] * centre  # direction from the centre to vp
    length = np.maximum(np.hypot(towards[..., 0], towards[..., 1]), 1e-12)
    across = normal[..., 0] * vp[..., None, 0] + normal[..., 1] * vp[..., None, 1] - offset * vp[..., None, 2]
    return half_length * np.abs(across) / length


def family_residuals(normal, offset, centre, half_length, labels) -> np.ndarray:
    """Per lens and line, the end offset (:func:`end_offsets`) from its family's least-squares
    vanishing point; 0 for lines in no family (``labels < 0``). Shapes: ``normal`` (L, C, 2),
    ``offset`` (L, C), ``centre`` (L, C, 2), ``half_length`` (L, C), ``labels`` (C,) -> (L, C)."""
    out = np.zeros(offset.shape)
    for f in np.unique(labels[labels >= 0]):
        m = labels == f
        vp = _vanishing_point(normal[:, m], offset[:, m], half_length[:, m] ** 2)
        out[:, m] = end_offsets(normal[:, m], offset[:, m], centre[:, m], half_length[:, m], vp)
    return out


def same_lines(normal, offset, centre, tol: float = SAME_LINE_TOL) -> np.ndarray:
    """Label per line (C,) such that pieces of one straight line (each centre within ``tol`` of the
    other's line, directions within :data:`SAME_LINE_ANGLE`) share a label: pieces of one line all
    pass through any point of it, so they must count once in a family. Loose on purpose (pieces far
    apart, seen through a rough lens): joining two lines only makes a family harder to form."""
    n = len(offset)
    across = np.abs(centre @ normal.T - offset[None, :])  # [i, j]: centre i from line j
    parallel = np.abs(normal[:, 0, None] * normal[None, :, 1] - normal[:, 1, None] * normal[None, :, 0]) <= SAME_LINE_ANGLE
    same = (across <= tol) & (across.T <= tol) & parallel
    label = np.arange(n)
    for i, j in zip(*np.nonzero(np.triu(same, 1))):
        label[label == label[j]] = label[i]
    return label


def find_families(normal, offset, centre, half_length, tol: float = FAMILY_TOL) -> np.ndarray:
    """Group lines (one lens: ``normal`` (C, 2), ``offset`` (C,), ``centre`` (C, 2), ``half_length``
    (C,)) into families that share a vanishing point: the point where two lines meet that the most
    other distinct lines point at (ends within ``tol`` and direction within :data:`FAMILY_ANGLE`),
    at least :data:`MIN_FAMILY_LINES` distinct lines (:func:`same_lines`) with a piece of
    :data:`FAMILY_MIN_HALF_LENGTH`, then the same among the rest. Returns labels (C,): family 0, 1 or -1 (none)."""
    n = len(offset)
    labels = np.full(n, -1)
    line_id = same_lines(normal, offset, centre, tol)
    onehot = (line_id[:, None] == np.unique(line_id)[None, :]).astype(np.float64)
    homogeneous = np.concatenate([normal, -offset[:, None]], axis=1)
    for family in range(MAX_FAMILIES):
        free = np.flatnonzero(labels < 0)
        i, j = np.triu_indices(len(free), 1)
        distinct = line_id[free[i]] != line_id[free[j]]
        i, j = i[distinct], j[distinct]
        if len(i) == 0:
            break
        vp = np.cross(homogeneous[free[i]], homogeneous[free[j]])
        vp /= np.maximum(np.linalg.norm(vp, axis=1, keepdims=True), 1e-18)
        off = end_offsets(normal[None, free], offset[None, free], centre[None, free], half_length[free], vp)
        inside = (off <= tol) & (off <= FAMILY_ANGLE * half_length[free])
        pointing = inside & (half_length[free] >= FAMILY_MIN_HALF_LENGTH)  # long enough to count
        lines = ((pointing.astype(np.float64) @ onehot[free]) > 0).sum(axis=1)
        score = lines - np.where(inside, off, 0.0).sum(axis=1) / (tol * n)
        best = int(np.argmax(score))
        if lines[best] < MIN_FAMILY_LINES:
            break
        labels[free[inside[best]]] = family
    return labels


def _normalised(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (..., M, 2) centred on their mean and scaled to unit RMS radius -> (points, scale (...))."""
    centred = points - points.mean(axis=-2, keepdims=True)
    scale = np.sqrt(np.mean(np.sum(centred**2, axis=-1), axis=-1))
    scale = np.maximum(scale, 1e-12)
    return centred / scale[..., None, None], scale


def conic_fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Algebraic conic fit of points (..., M, 2) -> ``(rms, ellipse, scale)``: the RMS Sampson
    distance (points' unit) of the best conic, whether it is an ellipse, and the normalisation scale."""
    p, scale = _normalised(points)
    x, y = p[..., 0], p[..., 1]
    design = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=-1)
    _, vecs = np.linalg.eigh(np.einsum("...mi,...mj->...ij", design, design))
    a, b, c, d, e, f = np.moveaxis(vecs[..., :, 0], -1, 0)
    value = np.einsum("...mi,...i->...m", design, vecs[..., :, 0])
    gx = 2 * a[..., None] * x + b[..., None] * y + d[..., None]
    gy = b[..., None] * x + 2 * c[..., None] * y + e[..., None]
    sampson = value / np.maximum(np.hypot(gx, gy), 1e-12)
    rms = np.sqrt(np.mean(sampson**2, axis=-1)) * scale
    return rms, b * b - 4 * a * c < 0, scale


def conic_rms(points: np.ndarray, group: np.ndarray, n_groups: int) -> np.ndarray:
    """RMS Sampson distance (lens units) of the best conic through each group's points, per lens:
    ``points`` (L, M, 2), ``group`` (M,) in 0..n_groups-1 -> (L, n_groups)."""
    out = np.empty((points.shape[0], n_groups))
    for g in range(n_groups):
        out[:, g] = conic_fit(points[:, group == g])[0]
    return out


def group_arcs(arcs: list[np.ndarray], tol: float = CONIC_MERGE_TOL) -> np.ndarray:
    """Join arcs (each ``N x 2``, one lens) that lie on one ellipse, longest first: an arc joins the
    first group whose conic through both stays an ellipse within ``tol`` RMS. Returns a group label
    per arc (groups of a single arc included)."""
    order = np.argsort([-len(a) for a in arcs])
    labels = np.full(len(arcs), -1)
    members: list[list[int]] = []
    for k in order:
        for g, group in enumerate(members):
            rms, ellipse, _ = conic_fit(np.concatenate([arcs[i] for i in group + [int(k)]]))
            if ellipse and rms <= tol:
                group.append(int(k))
                labels[k] = g
                break
        else:
            labels[k] = len(members)
            members.append([int(k)])
    return labels
