"""glradial's own first guess of a frame's camera (a fallback for a dedicated first-guess search): a
dictionary of synthetic main-camera views scored by chamfer distance against the white lines.

The dictionary: cameras at the halfway line, 20, 35 or 55 m behind the near touchline and 12, 20 or 30
m up, pan within ±60 degrees, tilt 5-40 degrees, horizontal field of view 10-70 degrees, pan and tilt
steps a quarter of the field of view. Each view's template samples (every 2 m) are projected once per
frame shape (pinhole, no lens). Per frame, the white-line points are drawn at :data:`SCORE_WIDTH` px;
each view's samples are looked up in the distance transform (the sum of ``1 - d / REACH`` over its
samples: how many markings it puts on lines), and the best :data:`RESCORE` views by that count are
scored by its mean over the view's samples (the share of its drawn markings that lie on lines) times
the share of the evidence its drawn markings explain (the same measure the other way), so neither a
view that puts a few markings on a few lines nor one that draws markings everywhere wins. The best views, as plane homographies to the frame's
undistorted pixels, go to the refinement, which recovers the actual position, focal length and lens.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from ..lens.lens import focal_from_hfov, frame_size
from ..pitch.template import PitchTemplate
from .model import intrinsics

#: Width (px) of the image the dictionary is scored on.
SCORE_WIDTH = 320
#: A sample (or an evidence point) counts as matched by ``1 - d / REACH`` at distance ``d`` (px at
#: :data:`SCORE_WIDTH`), not at all beyond: about the dictionary's step, so a view near the truth scores.
REACH = 10.0
#: A view must put this many template samples (every 2 m) in the frame.
MIN_SAMPLES = 20
#: Camera positions: metres behind the near touchline, heights (metres).
DISTANCES, HEIGHTS = (20.0, 35.0, 55.0), (12.0, 20.0, 30.0)
#: Fields of view (degrees) and the pan and tilt ranges (degrees).
FOVS = (10.0, 14.0, 20.0, 28.0, 40.0, 55.0, 70.0)
PAN, TILT = (-60.0, 60.0), (5.0, 40.0)
#: Pan and tilt steps: the field of view (horizontal, vertical) over this.
STEPS_PER_FOV = 4
#: Views rescored both ways.
RESCORE = 100


def _rotations(pans: np.ndarray, tilts: np.ndarray) -> np.ndarray:
    """World -> camera rotations (V x 3 x 3) of pan/tilt views (no roll; see Camera.pan_tilt_roll)."""
    p, t = np.radians(pans), np.radians(tilts)
    forward = np.stack([np.sin(p) * np.cos(t), np.cos(p) * np.cos(t), -np.sin(t)], -1)
    right = np.stack([np.cos(p), -np.sin(p), np.zeros_like(p)], -1)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], 1)


@lru_cache(maxsize=4)
def _dictionary(size: tuple[int, int], pitch: PitchTemplate):
    """Per view: rotation, position, focal (image widths); flat sample indices into the score image
    (V x M, -1 outside); the score image's size."""
    width, height = size
    small = (SCORE_WIDTH, max(2, round(SCORE_WIDTH * height / width)))
    samples = np.concatenate([p for _, p in pitch.polylines(2.0)])
    world = np.column_stack([samples, np.zeros(len(samples))])
    rot, pos, foc, index = [], [], [], []
    for fov in FOVS:
        pans = np.arange(PAN[0], PAN[1] + 1e-9, fov / STEPS_PER_FOV)
        tilts = np.arange(TILT[0], TILT[1] + 1e-9, fov * height / width / STEPS_PER_FOV)
        r = _rotations(*(a.ravel() for a in np.meshgrid(pans, tilts)))
        f = focal_from_hfov(fov)
        for d in DISTANCES:
            for z in HEIGHTS:
                c = np.array([0.0, -pitch.half_width - d, z])
                cam = np.matmul(world - c, r.transpose(0, 2, 1))  # V x M x 3
                with np.errstate(divide="ignore", invalid="ignore"):
                    u = f * cam[..., 0] / cam[..., 2] * small[0] + small[0] / 2 - 0.5
                    v = f * cam[..., 1] / cam[..., 2] * small[0] + small[1] / 2 - 0.5
                ok = (cam[..., 2] > 1.0) & (u >= 0) & (u <= small[0] - 1) & (v >= 0) & (v <= small[1] - 1)
                good = ok.sum(1) >= MIN_SAMPLES
                flat = np.rint(np.nan_to_num(v)).astype(np.intp) * small[0] + np.rint(np.nan_to_num(u)).astype(np.intp)
                rot.append(r[good])
                pos.append(np.tile(c, (int(good.sum()), 1)))
                foc.append(np.full(int(good.sum()), f))
                index.append(np.where(ok, flat, -1)[good])
    return np.concatenate(rot), np.concatenate(pos), np.concatenate(foc), np.concatenate(index), small


def _homography(rot: np.ndarray, pos: np.ndarray, focal: float, size: tuple[int, int]) -> np.ndarray:
    return intrinsics(focal, size) @ np.column_stack([rot[:, 0], rot[:, 1], -rot @ pos])


def _explained(index_row: np.ndarray, evidence: np.ndarray, small) -> float:
    """How much of the evidence the view's drawn markings explain: the mean of ``1 - d / REACH``
    (0 beyond) over the evidence pixels, ``d`` their distance to the nearest drawn sample."""
    mask = np.full((small[1], small[0]), 255, np.uint8)
    mask.ravel()[index_row[index_row >= 0]] = 0
    mask = cv2.erode(mask, np.ones((3, 3), np.uint8))  # 2 m samples: close the gaps between them
    dist = cv2.distanceTransform(mask, cv2.DIST_L2, 3)
    return float(np.mean(np.maximum(0.0, 1.0 - dist.ravel()[evidence] / REACH)))


def first_views(xy: np.ndarray, size: tuple[int, int], pitch: PitchTemplate | None = None,
                count: int = 10) -> list[np.ndarray]:
    """Up to ``count`` plane homographies (pitch ``(x, y, 1)`` -> undistorted pixels of the ``size``
    frame), best first, for white-line points ``xy`` (N x 2 px of the frame)."""
    size = frame_size(size)
    rot, pos, foc, index, small = _dictionary(size, pitch or PitchTemplate())
    if len(rot) == 0 or len(xy) == 0:
        return []
    mask = np.full((small[1], small[0]), 255, np.uint8)
    q = np.rint((np.asarray(xy) + 0.5) * small[0] / size[0] - 0.5).astype(np.intp)
    keep = (q[:, 0] >= 0) & (q[:, 0] < small[0]) & (q[:, 1] >= 0) & (q[:, 1] < small[1])
    flat = np.unique(q[keep, 1] * small[0] + q[keep, 0])
    mask.ravel()[flat] = 0
    near = np.maximum(0.0, 1.0 - cv2.distanceTransform(mask, cv2.DIST_L2, 3).ravel() / REACH)
    found = np.where(index >= 0, near[np.maximum(index, 0)], 0.0).sum(axis=1)  # markings on lines
    precision = found / np.maximum((index >= 0).sum(axis=1), 1)
    top = np.argsort(-found)[:RESCORE]
    both = [precision[i] * _explained(index[i], flat, small) for i in top]
    return [_homography(rot[i], pos[i], foc[i], size) for i in top[np.argsort(both)[::-1]][:count]]
