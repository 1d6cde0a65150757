"""Split a linked chain where it turns a corner: one chain must be one line.

Pieces of one orientation bin that touch, or that continue each other, are linked into chains by
:mod:`glradial.estimation.lines`. Where two pitch lines meet at a shallow image angle (the corner of the goal
area or the penalty box seen from the main camera, a touchline meeting the goal line far away), or
a line runs into an arc, the chain goes round the corner and no lens straightens it. This module
finds such breaks and cuts the chain there.

Convention: points are ``N x 2`` in pixels of the detection copy (any unit works: the tests are
ratios and :data:`MIN_BEND_PX` is in the points' unit), already undistorted with a rough lens (the
CNN's) and ordered along the chain. The rough lens leaves a smooth, nearly uniform curvature (a
wrong ``k1`` bends the whole line); a corner is a break: the two sides are each straight while the
whole is not. A uniformly curved arc halves into halves whose deviation is a quarter of the
whole's (the sagitta grows with the square of the length), so the test :data:`STRAIGHT_RATIO`
below a quarter cuts corners and leaves smooth curves (arcs, curved stands, the lens) in one piece
for the fit to judge.
"""

from __future__ import annotations

import numpy as np

#: A chain is examined only if some point lies this far (points' unit, px) from the chord.
MIN_BEND_PX = 2.0
#: Cut at the farthest point from the chord when both sides' largest deviations from their own
#: chords are at most this share of the whole's (a uniformly curved arc gives 1/4) plus
#: :data:`SIDE_NOISE_PX` (the largest deviation of a straight side's noisy points).
STRAIGHT_RATIO, SIDE_NOISE_PX = 0.12, 0.5
#: Sides shorter than this many points are not cut off (a stray point at an end is not a corner).
MIN_SIDE_POINTS = 6
#: Deepest recursion (a chain is cut into at most 2**MAX_DEPTH pieces).
MAX_DEPTH = 3


def chord_deviation(points: np.ndarray) -> tuple[float, int]:
    """Largest perpendicular distance of ``points`` (N x 2, ordered) from the chord between the first
    and last point, and the index where it occurs (``(0.0, 0)`` for fewer than 3 points)."""
    if len(points) < 3:
        return 0.0, 0
    a, b = points[0], points[-1]
    d = b - a
    norm = float(np.hypot(d[0], d[1]))
    if norm < 1e-12:
        dist = np.hypot(points[:, 0] - a[0], points[:, 1] - a[1])
    else:
        dist = np.abs((points[:, 0] - a[0]) * d[1] - (points[:, 1] - a[1]) * d[0]) / norm
    i = int(np.argmax(dist))
    return float(dist[i]), i


def split_at_corners(points: np.ndarray, depth: int = 0) -> list[slice]:
    """Slices of ``points`` (N x 2, ordered along the chain) that each follow one line (see the
    module docstring): the whole chain when it has no corner."""
    points = np.asarray(points, np.float64)
    n = len(points)
    whole, i = chord_deviation(points)
    if depth >= MAX_DEPTH or whole < MIN_BEND_PX or i < MIN_SIDE_POINTS or n - i < MIN_SIDE_POINTS:
        return [slice(0, n)]
    left, _ = chord_deviation(points[: i + 1])
    right, _ = chord_deviation(points[i:])
    if max(left, right) > STRAIGHT_RATIO * whole + SIDE_NOISE_PX:
        return [slice(0, n)]
    out = [s for s in split_at_corners(points[:i], depth + 1)]
    out += [slice(s.start + i, s.stop + i) for s in split_at_corners(points[i:], depth + 1)]
    return out
