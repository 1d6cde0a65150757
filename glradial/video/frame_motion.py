"""Frame-to-frame evidence of a video shot: matched points of two frames and their homography.

A broadcast camera pans, tilts and zooms about a fixed centre, so two frames of one shot are
related by a plane homography once both are undistorted with the right lens (a rotation about the
camera centre, and a change of focal length, move every ray, not only those of one plane). The
matches found here feed :mod:`glradial.video.shot_fit`, which finds the lens under which one homography
fits them.

Matching: Shi-Tomasi corners of a gray copy at most :data:`MOTION_WIDTH` px wide, tracked with
pyramidal Lucas-Kanade optical flow and checked backwards (forward-backward error at most
:data:`FB_MAX_PX`); points that move against the camera (players, the ball) are dropped by a RANSAC
homography on the points undistorted with a rough lens (:data:`RANSAC_PX`).

Convention: points are in lens units of the frame (image width = 1, origin at the frame centre,
:func:`glradial.lens.lens.pixels_to_lens`); ``hint`` lenses are width-normalised ``(k1, k2)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..lens.lens import lens_to_pixels, pixels_to_lens
from ..lens.lensfuncs import undistort_point_exact

__all__ = ["MOTION_WIDTH", "Matches", "motion_gray", "track_corners", "match_frames",
           "zoom_of", "homography_of", "homographies_of"]

#: gray copies for matching are at most this wide (px): corners are located to ~0.1 px there, i.e.
#: ~0.3 px of a 1920-wide frame, below the displacement errors the lens fit aims at
MOTION_WIDTH = 640
#: corners tracked per pair of frames
MAX_CORNERS = 400
#: Lucas-Kanade window (px of the gray copy, square)
LK_WINDOW = 21
#: matches kept per pair (evenly thinned): the lens fit weighs a pair as at most
#: :data:`glradial.video.shot_fit.MATCH_CAP` points anyway, and evaluates every kept one at each step
MAX_MATCHES = 150
#: corners closer than this to each other (px of the gray copy) are not both taken
MIN_CORNER_DISTANCE = 10
#: a track whose backward track misses its start by more than this (px of the gray copy) is dropped
FB_MAX_PX = 0.4
#: RANSAC inlier threshold (px of the gray copy) on points undistorted with the hint lens: wide
#: enough to keep the points near the frame edge when the hint is far off (a wrong hint leaves a
#: misfit there that grows with the rotation between the frames; at 1.5 px, pairs 0.4 frame widths
#: apart under a hint of k1 ~0 against a true -0.25 lost exactly those points, the ones that show the
#: lens, and the fit leaned 11 px towards the hint: docs/eval/shots.md), narrow enough to drop a
#: running player (some 20 px of a 640 px copy between samples 0.4 s apart)
RANSAC_PX = 4.0
#: seed of OpenCV's generator before each RANSAC, so that a video gives the same lens every run
RANSAC_SEED = 25
#: fewer inliers than this: the pair gives no evidence (too little texture, or no overlap)
MIN_MATCHES = 30
#: corners this close to the border (px of the gray copy) are not used (overlays, letterbox edges)
BORDER_PX = 8


@dataclass(frozen=True)
class Matches:
    """Points of frame ``a`` and where they lie in frame ``b`` (lens units, ``N x 2`` each, N >=
    :data:`MIN_MATCHES`), found on copies ``width`` px wide (the scale of their localisation noise);
    ``homography`` the least-squares homography (:func:`homography_of`, ``H[2, 2] = 1``) of the points
    undistorted with the hint lens the matches were checked with (``None``: none fits)."""

    a: np.ndarray
    b: np.ndarray
    width: int
    homography: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.a)


def motion_gray(frame: np.ndarray, max_width: int = MOTION_WIDTH) -> np.ndarray:
    """uint8 ``H x W x 3`` RGB (or ``H x W`` gray) -> uint8 gray at most ``max_width`` px wide (area)."""
    frame = np.asarray(frame)
    if frame.dtype != np.uint8 or frame.ndim not in (2, 3):
        raise ValueError(f"frame must be a uint8 H x W (x 3) array, got {frame.dtype} {frame.shape}")
    gray = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY) if frame.ndim == 3 else frame
    height, width = gray.shape
    if width > max_width:
        gray = cv2.resize(gray, (max_width, max(2, round(height * max_width / width))), interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(gray)


def track_corners(gray: np.ndarray) -> np.ndarray | None:
    """The corners :func:`match_frames` tracks from a gray copy (:func:`motion_gray`): float32 ``N x
    1 x 2`` sub-pixel positions (px of the copy), strongest first, :data:`MAX_CORNERS` at most; ``None``
    when it has none. A frame matched with several others (a shot's anchors) is given them once."""
    mask = np.zeros_like(gray)
    mask[BORDER_PX:-BORDER_PX, BORDER_PX:-BORDER_PX] = 255
    corners = cv2.goodFeaturesToTrack(gray, MAX_CORNERS, 0.005, MIN_CORNER_DISTANCE, mask=mask, blockSize=7)
    if corners is None:
        return None
    return cv2.cornerSubPix(gray, corners.astype(np.float32), (4, 4), (-1, -1),
                            (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 0.01))


#: pyramidal Lucas-Kanade levels and stopping rule of :func:`match_frames` (both directions)
LK_LEVELS, LK_CRITERIA = 4, (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.01)


def match_frames(a: np.ndarray, b: np.ndarray, hint: tuple[float, float] = (0.0, 0.0),
                 guess: np.ndarray | None = None, corners: np.ndarray | None = None) -> Matches | None:
    """Matched points of two gray copies (:func:`motion_gray`, same size) of frames of one shot;
    ``None`` when fewer than :data:`MIN_MATCHES` survive (no texture, no overlap, a cut). ``hint``
    is a rough lens, used only to reject points that move against the camera. ``guess``: a
    homography (lens units, of points undistorted with ``hint``) predicting where the points of
    ``a`` lie in ``b``: the tracker then starts there, so frames far apart in a pan or zoom match.
    ``corners``: :func:`track_corners` of ``a``, where already found."""
    if a.shape != b.shape:
        raise ValueError(f"frames to match must have one size, got {a.shape[::-1]} and {b.shape[::-1]}")
    start = track_corners(a) if corners is None else corners
    if start is None or len(start) < MIN_MATCHES:
        return None
    p, q = _tracked(a, b, start, hint, guess)
    if len(p) < MIN_MATCHES:
        return None
    height, width = a.shape
    size = (width, height)
    pa, pb = pixels_to_lens(p, size), pixels_to_lens(q, size)
    ua, va = undistort_point_exact(pa, float(hint[0]), float(hint[1]))
    ub, vb = undistort_point_exact(pb, float(hint[0]), float(hint[1]))
    cv2.setRNGSeed(RANSAC_SEED)  # this thread's OpenCV generator: the same frames give the same matches
    _, inliers = cv2.findHomography(lens_to_pixels(ua, size), lens_to_pixels(ub, size), cv2.RANSAC, RANSAC_PX,
                                    maxIters=500, confidence=0.995)
    if inliers is None:
        return None
    good = np.flatnonzero((inliers.ravel() == 1) & va & vb)
    if len(good) < MIN_MATCHES:
        return None
    good = good[np.linspace(0, len(good) - 1, min(len(good), MAX_MATCHES)).astype(np.intp)]
    return Matches(pa[good], pb[good], width, homography_of(ua[good], ub[good]))


def _tracked(a: np.ndarray, b: np.ndarray, start: np.ndarray, hint: tuple[float, float],
             guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The corners ``start`` of ``a`` tracked into ``b`` and back (pixels of the copies, float64 ``N
    x 2`` each, in ``start``'s order): those found both ways, back within :data:`FB_MAX_PX` of where
    they started and inside the border of ``b``. Only the points found forwards are tracked back (each
    point is tracked on its own: the same answer as tracking them all)."""
    height, width = a.shape
    lk = dict(winSize=(LK_WINDOW, LK_WINDOW), maxLevel=LK_LEVELS, criteria=LK_CRITERIA)
    if guess is None:
        end, ok, _ = cv2.calcOpticalFlowPyrLK(a, b, start, None, **lk)
    else:
        predicted = _predict(start.reshape(-1, 2), (width, height), hint, guess).reshape(-1, 1, 2).astype(np.float32)
        end, ok, _ = cv2.calcOpticalFlowPyrLK(a, b, start, predicted, flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
    p, q = start.reshape(-1, 2).astype(np.float64), end.reshape(-1, 2).astype(np.float64)
    inside = (q[:, 0] >= BORDER_PX) & (q[:, 0] < width - BORDER_PX) & (q[:, 1] >= BORDER_PX) & (q[:, 1] < height - BORDER_PX)
    found = np.flatnonzero((ok.ravel() == 1) & inside)
    if len(found) < MIN_MATCHES:
        return p[:0], q[:0]
    back, ok_back, _ = cv2.calcOpticalFlowPyrLK(b, a, end[found], start[found].copy(),
                                                flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
    fb = np.linalg.norm((back - start[found]).reshape(-1, 2), axis=1)
    keep = found[(ok_back.ravel() == 1) & (fb <= FB_MAX_PX)]
    return p[keep], q[keep]


def _predict(pixels: np.ndarray, size: tuple[int, int], hint: tuple[float, float], guess: np.ndarray) -> np.ndarray:
    """Pixels of one frame -> where ``guess`` (a homography of hint-undistorted lens units) puts them."""
    from ..lens.lensfuncs import distort_point

    p_u, _ = undistort_point_exact(pixels_to_lens(pixels, size), float(hint[0]), float(hint[1]))
    q = np.c_[p_u, np.ones(len(p_u))] @ np.asarray(guess, np.float64).T
    return lens_to_pixels(distort_point(q[:, :2] / q[:, 2:3], float(hint[0]), float(hint[1])), size)


def homography_of(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Least-squares homography (3 x 3, ``H[2, 2] = 1``) taking points ``a`` to ``b`` (``N x 2``, N
    >= 4, lens units): normalised direct linear transform, no outlier rejection; ``None`` when the
    points fix none (degenerate)."""
    h = cv2.findHomography(a, b, 0)[0]
    return None if h is None else h / h[2, 2]


def zoom_of(homography: np.ndarray) -> float:
    """Scale change at the frame centre of ``homography`` (lens units to lens units): the square
    root of the determinant of its Jacobian at the origin; > 1 when the second frame is zoomed in."""
    h = np.asarray(homography, np.float64) / homography[2, 2]
    jacobian = h[:2, :2] - np.outer(h[:2, 2], h[2, :2])
    det = float(np.linalg.det(jacobian))
    return math.sqrt(det) if det > 0 else math.nan


#: Gauss-Newton steps :func:`homographies_of` takes from the normalised DLT on the transfer error
HOMOGRAPHY_REFINE_STEPS = 2


def homographies_of(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None,
                    start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`homography_of` for many point sets at once: ``a``, ``b`` ``(..., N, 2)`` (lens units),
    ``mask`` ``(..., N)`` the points that count (``None``: all). Returns ``(H, ok)``: ``H``
    ``(..., 3, 3)`` with ``H[2, 2] = 1`` and ``ok`` ``(...)``, False where the points fix no
    homography (fewer than 4, or degenerate; ``H`` is then meaningless).

    As OpenCV's ``findHomography(a, b, 0)``: a normalised direct linear transform (each set's points
    centred and scaled to unit RMS distance, the smallest eigenvector of ``A^T A``), then refined on
    the transfer error ``|H a - b|^2`` (:data:`HOMOGRAPHY_REFINE_STEPS` Gauss-Newton steps where
    OpenCV takes Levenberg-Marquardt ones: the same minimum), every set in one vectorised solve
    whose sums over the points are matrix products. ``start`` (``(..., 3, 3)``, ``H[2, 2] = 1``):
    homographies of nearly the same points (a finite-difference neighbour), refined by one step
    instead (its error, quadratic in theirs, is far below such a difference's)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    w = np.ones(a.shape[:-1]) if mask is None else np.asarray(mask, np.float64)
    x, y, u, v = (np.ascontiguousarray(c) for c in (a[..., 0], a[..., 1], b[..., 0], b[..., 1]))
    count = w.sum(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        h = _dlt(x, y, u, v, w, np.maximum(count, 1.0)) if start is None else np.broadcast_to(start, x.shape[:-1] + (3, 3))
        for _ in range(HOMOGRAPHY_REFINE_STEPS if start is None else 1):
            h = _refine(h, x, y, u, v, w)
    ok = (count >= 4) & np.all(np.isfinite(h), axis=(-2, -1))
    return h, ok


def _normaliser(x: np.ndarray, y: np.ndarray, w: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, ...]:
    """Centre and scale (``(...)`` each) taking the weighted points to centroid 0, RMS distance 1."""
    cx, cy = np.sum(w * x, axis=-1) / count, np.sum(w * y, axis=-1) / count
    spread = np.sum(w * (x * x + y * y), axis=-1) / count - cx * cx - cy * cy
    return cx, cy, 1.0 / np.sqrt(np.maximum(spread, 1e-24))


def _similarity(cx: np.ndarray, cy: np.ndarray, s: np.ndarray, inverse: bool = False) -> np.ndarray:
    t = np.zeros(np.shape(s) + (3, 3))
    t[..., 2, 2] = 1.0
    if inverse:
        t[..., 0, 0] = t[..., 1, 1] = 1.0 / s
        t[..., 0, 2], t[..., 1, 2] = cx, cy
    else:
        t[..., 0, 0] = t[..., 1, 1] = s
        t[..., 0, 2], t[..., 1, 2] = -s * cx, -s * cy
    return t


def _dlt(x: np.ndarray, y: np.ndarray, u: np.ndarray, v: np.ndarray, w: np.ndarray, count: np.ndarray) -> np.ndarray:
    """The normalised DLT of :func:`homographies_of` (``H[2, 2] = 1``): on the normalised points,
    the smallest eigenvector of ``A^T A``, whose 3x3 blocks are the moments ``sum w c X X^T`` (``X =
    (x, y, 1)``, ``c`` one of ``1, u, v, u^2 + v^2``), taken as one matrix product."""
    ax, ay, sa = _normaliser(x, y, w, count)
    bx, by, sb = _normaliser(u, v, w, count)
    px, py = (x - ax[..., None]) * sa[..., None], (y - ay[..., None]) * sa[..., None]
    qx, qy = (u - bx[..., None]) * sb[..., None], (v - by[..., None]) * sb[..., None]
    one = np.ones_like(px)
    big = np.stack([px, py, one], axis=-2)  # (..., 3, N)
    c = [w, qx * w, qy * w, (qx * qx + qy * qy) * w]
    m = big @ np.swapaxes(np.concatenate([big * k[..., None, :] for k in c], axis=-2), -1, -2)  # (..., 3, 12)
    xx, ux, vx, rr = m[..., 0:3], m[..., 3:6], m[..., 6:9], m[..., 9:12]
    zero = np.zeros_like(xx)
    ata = np.concatenate([np.concatenate([xx, zero, -ux], axis=-1), np.concatenate([zero, xx, -vx], axis=-1),
                          np.concatenate([-ux, -vx, rr], axis=-1)], axis=-2)
    _, vectors = np.linalg.eigh(np.nan_to_num(ata))
    hn = vectors[..., :, 0].reshape(vectors.shape[:-2] + (3, 3))
    h = _similarity(bx, by, sb, inverse=True) @ hn @ _similarity(ax, ay, sa)
    return h / h[..., 2:3, 2:3]


def _refine(h: np.ndarray, x: np.ndarray, y: np.ndarray, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """One Gauss-Newton step of the 8 free entries of ``h`` (``H[2, 2] = 1``) on the weighted
    transfer error ``r = (u, v) - p`` (``p`` the projection of ``(x, y)``). With ``Y = d (x, y, 1)``
    (``d`` the inverse depth) a point's rows of the Jacobian are ``[Y, 0, -p_x Y2]`` and ``[0, Y,
    -p_y Y2]`` (``Y2`` its first two entries), so the normal equations' blocks are sums of ``Y Y^T``
    times ``1``, ``p_x``, ``p_y``, ``|p|^2`` and the gradient sums of ``Y`` times ``r``: one product."""
    e = h[..., None]
    d = 1.0 / (e[..., 2, 0, :] * x + e[..., 2, 1, :] * y + 1.0)
    px = (e[..., 0, 0, :] * x + e[..., 0, 1, :] * y + e[..., 0, 2, :]) * d
    py = (e[..., 1, 0, :] * x + e[..., 1, 1, :] * y + e[..., 1, 2, :]) * d
    rx, ry = u - px, v - py
    xd, yd, wd = x * d, y * d, w * d
    left = np.stack([xd, yd, d], axis=-2)  # (..., 3, N)
    pp = px * px + py * py
    right = np.empty(x.shape[:-1] + (12,) + x.shape[-1:])
    xw, yw = np.multiply(xd, w, out=right[..., 0, :]), np.multiply(yd, w, out=right[..., 1, :])
    right[..., 2, :] = wd
    for k, (f, g) in enumerate(((px, xw), (px, yw), (py, xw), (py, yw), (pp, xw), (pp, yw)), start=3):
        np.multiply(f, g, out=right[..., k, :])
    np.multiply(rx, w, out=right[..., 9, :])
    np.multiply(ry, w, out=right[..., 10, :])
    right[..., 11, :] = (rx * px + ry * py) * w
    m = left @ np.swapaxes(right, -1, -2)  # (..., 3, 12)
    yy, sx, sy, spp = m[..., 0:3], m[..., 3:5], m[..., 5:7], m[..., :2, 7:9]
    zero = np.zeros_like(yy)
    normal = np.concatenate([np.concatenate([yy, zero, -sx], axis=-1), np.concatenate([zero, yy, -sy], axis=-1),
                             np.concatenate([-np.swapaxes(sx, -1, -2), -np.swapaxes(sy, -1, -2), spp], axis=-1)], axis=-2)
    gradient = np.concatenate([m[..., :, 9], m[..., :, 10], -m[..., :2, 11]], axis=-1)
    normal += np.eye(8) * (1e-12 * np.trace(normal, axis1=-2, axis2=-1)[..., None, None] + 1e-300)
    step = np.linalg.solve(np.nan_to_num(normal), np.nan_to_num(gradient)[..., None])[..., 0]
    out = h.copy()
    out[..., :2, :] += step[..., :6].reshape(step.shape[:-1] + (2, 3))
    out[..., 2, :2] += step[..., 6:]
    return out
