"""glradial's own first guess of a frame's camera (a fallback for a dedicated first-guess search): a
small dictionary of synthetic main-camera views scored by chamfer distance against the white lines.

The dictionary: cameras 30 or 55 m behind the near touchline at the halfway line (18 or 26 m up), pan
within ±60 degrees, tilt 6-36 degrees, horizontal field of view 8-60 degrees, steps a third of the
field of view. Each view's template samples are projected once per frame shape (pinhole, no lens),
looked up in the distance transform of the white-line points drawn at :data:`SCORE_WIDTH` px, and
scored by the mean truncated distance (lower is better); a view needs :data:`MIN_SAMPLES` samples in
the frame. The best views (as plane homographies to the frame's undistorted pixels) go to the
refinement, which is what recovers the actual camera position.
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

from ..lens.lens import frame_size
from ..pitch.template import PitchTemplate
from .model import Camera

#: Width (px) of the image the dictionary is scored on.
SCORE_WIDTH = 320
#: Distances beyond this (px at :data:`SCORE_WIDTH`) count as this.
TRUNCATE = 10.0
#: A view must put this many template samples (every 2 m) in the frame.
MIN_SAMPLES = 25
#: Camera positions (x, y, z metres) of the dictionary.
POSITIONS = ((0.0, -64.0, 18.0), (0.0, -89.0, 26.0))
FOVS = (8.0, 11.0, 15.0, 21.0, 29.0, 40.0, 55.0)


@lru_cache(maxsize=4)
def _dictionary(size: tuple[int, int], pitch: PitchTemplate) -> tuple[list[Camera], np.ndarray, np.ndarray]:
    """The views of a frame shape: cameras, flat indices into the score image (V x M, -1 outside)."""
    width, height = size
    small = (SCORE_WIDTH, max(2, round(SCORE_WIDTH * height / width)))
    samples = np.concatenate([p for _, p in pitch.polylines(2.0)])
    cams, rows = [], []
    for pos in POSITIONS:
        for fov in FOVS:
            for pan in np.arange(-60.0, 60.0 + 1e-9, fov / 3):
                for tilt in np.arange(6.0, 36.0 + 1e-9, fov * height / width / 3):
                    cam = _pan_tilt_camera(pos, pan, tilt, fov, small)
                    xy = cam.project(samples)
                    ok = np.isfinite(xy).all(1)
                    xi, yi = np.round(np.nan_to_num(xy)).astype(np.intp).T
                    ok &= (xi >= 0) & (xi < small[0]) & (yi >= 0) & (yi < small[1])
                    if ok.sum() < MIN_SAMPLES:
                        continue
                    cams.append(cam.with_size(size))
                    rows.append(np.where(ok, yi * small[0] + xi, -1))
    return cams, np.array(rows), np.array(small)


def _pan_tilt_camera(position, pan: float, tilt: float, fov: float, size: tuple[int, int]) -> Camera:
    p, t = math.radians(pan), math.radians(tilt)
    forward = np.array([math.sin(p) * math.cos(t), math.cos(p) * math.cos(t), -math.sin(t)])
    return Camera.look_at(position, np.asarray(position) + forward, fov, size)


def first_views(xy: np.ndarray, size: tuple[int, int], pitch: PitchTemplate | None = None,
                count: int = 4) -> list[np.ndarray]:
    """Up to ``count`` plane homographies (pitch ``(x, y, 1)`` -> undistorted pixels of the ``size``
    frame), best first, for white-line points ``xy`` (N x 2 px of the frame)."""
    size = frame_size(size)
    cams, index, small = _dictionary(size, pitch or PitchTemplate())
    if not cams or len(xy) == 0:
        return []
    mask = np.full((small[1], small[0]), 255, np.uint8)
    q = np.round((np.asarray(xy) + 0.5) * small[0] / size[0] - 0.5).astype(np.intp)
    keep = (q[:, 0] >= 0) & (q[:, 0] < small[0]) & (q[:, 1] >= 0) & (q[:, 1] < small[1])
    mask[q[keep, 1], q[keep, 0]] = 0
    dist = np.minimum(cv2.distanceTransform(mask, cv2.DIST_L2, 3), TRUNCATE).ravel()
    d = np.where(index >= 0, dist[np.maximum(index, 0)], np.nan)
    score = np.nanmean(d, axis=1)
    chosen: list[np.ndarray] = []
    for i in np.argsort(score):
        h = cams[i].homography
        if all(np.linalg.norm(h / h[2, 2] - c / c[2, 2]) > 1e-3 * np.linalg.norm(h / h[2, 2]) for c in chosen):
            chosen.append(h)
        if len(chosen) == count:
            break
    return chosen
