"""The pitch template as first_guess takes it, until the camera package's own template lands: the
markings of tests/pitch_template.py moved to centre-spot coordinates (x along the touchlines,
y toward the far touchline, metres) and resampled every ``step`` metres, one integer label per
polyline, plus the 32 keypoints of the Bundesliga labels' convention."""

from __future__ import annotations

import numpy as np
import pitch_template

#: The pitch_template polylines have their origin at a corner; first_guess's pitch at the centre spot.
SHIFT = np.array([-pitch_template.LENGTH / 2, -pitch_template.WIDTH / 2])


def _resample(polyline: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` metres of arc length along ``polyline`` (N x 2), both ends included."""
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], max(2, int(round(s[-1] / step)) + 1))
    return np.stack([np.interp(t, s, polyline[:, 0]), np.interp(t, s, polyline[:, 1])], axis=1)


def template(step: float = 0.25, parts=("lines", "circle", "arcs")) -> tuple[np.ndarray, np.ndarray]:
    """``(points M x 2, labels M)`` of the markings of ``parts`` (pitch_template.markings)."""
    lines = pitch_template.markings(parts)
    points = [_resample(line, step) + SHIFT for line in lines]
    labels = [np.full(len(p), k) for k, p in enumerate(points)]
    return np.concatenate(points), np.concatenate(labels)


def keypoints() -> np.ndarray:
    """The 32 keypoints (metres, centre-spot origin) in the order of the Bundesliga labels (README of
    ../shared/data/broadcast_bundesliga/keypoints)."""
    gx, ga, gb = 52.5, 47.0, 36.0
    left = [(-gx, 34), (-gx, 20.16), (-gx, 9.16), (-gx, -9.16), (-gx, -20.16), (-gx, -34), (-ga, 9.16), (-ga, -9.16),
            (-41.5, 0), (-gb, 20.16), (-gb, 7.31), (-gb, -7.31), (-gb, -20.16)]
    middle = [(0, 34), (0, 9.15), (0, -9.15), (0, -34)]
    right = [(gb, 20.16), (gb, 7.31), (gb, -7.31), (gb, -20.16), (41.5, 0), (ga, 9.16), (ga, -9.16),
             (gx, 34), (gx, 20.16), (gx, 9.16), (gx, -9.16), (gx, -20.16), (gx, -34)]
    return np.array(left + middle + right + [(-9.15, 0), (9.15, 0)], float)
