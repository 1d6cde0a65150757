"""Line evidence for lens estimation: sub-pixel points on image structures that should be straight.

Convention:
    Input: an RGB (or gray) ``H x W (x C)`` uint8 frame, as :func:`glradial.media.frames.to_rgb8`
    accepts. Detection runs on a gray copy at most :data:`DETECT_WIDTH` pixels wide (area
    interpolation). Output points are in **lens units of the frame** (image width = 1, origin at the
    frame centre, y down; :func:`glradial.lens.lens.pixels_to_lens`), so they do not depend on the
    detection scale; :attr:`LineEvidence.width` is the detection width, the pixel unit that
    residuals and tolerances are stated in (1 px there = ``1 / width`` lens units).

What is detected:
    * **Ridges**: the centre line of thin bright lines (painted pitch lines, goal posts, thin white
      stripes) from the Hessian of the smoothed image: where the most negative eigenvalue dominates,
      the sub-pixel centre is one Newton step along its eigenvector (Steger's ridge point).
    * **Step edges** (ad boards, stand fronts, roofs): Canny pixels away from ridges, moved to the
      sub-pixel maximum of the gradient magnitude along the gradient (parabola through 3 samples).

Grouping: points are binned by orientation (6 bins over 180 degrees), split into connected pieces
(per bin, so a line crossing a circle or another line stays apart from it), and pieces are linked into
chains across gaps (players, nets, shadows) when they are nearly collinear. Masked first: a margin
along the frame border and any letterbox (uniform rows or columns at the border). Chains that are
pixel-straight and exactly horizontal or vertical away from the frame centre are taken for broadcast
graphics (score bugs, clocks, tickers, watermarks) and dropped: a real straight line off the centre
is curved by any lens with ``|k1|`` above a few hundredths, and such overlays would pull the fit to
``k = 0``. Whether a chain is a straight line seen through a lens (and not a circle, an arc or a
curved stand) is decided by :mod:`glradial.estimation.line_fit`, which owns the lens model.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from ..lens.lens import lens_to_pixels, pixels_to_lens
from .corners import split_at_corners

#: Largest width (pixels) of the gray copy lines are detected on (800: as accurate as 960 on validation
#: crops, 2/3 of the pixels; docs/LINES.md).
DETECT_WIDTH = 800
#: Gaussian smoothing (pixels of the detection copy) before the derivatives.
SMOOTH_SIGMA = 1.2
#: Smallest ridge strength: the most negative Hessian eigenvalue, in grey levels (0..255) per px².
RIDGE_MIN_CURVATURE = 1.5
#: Canny hysteresis thresholds on the smoothed 8-bit image (Sobel 3x3 gradient, L2 norm).
CANNY_LOW, CANNY_HIGH = 30, 70
#: Points this close (pixels) to the frame border or a letterbox are ignored.
BORDER_MARGIN = 4
#: Orientation bins over 180 degrees (30 degrees each) for ridges and edges. The two edges of a
#: thick line (opposite polarity) share a bin but do not touch; thin lines are ridges.
ORIENTATION_BINS = 6
#: Pieces with fewer points are dropped before linking.
MIN_PIECE_POINTS = 8
#: Linking: largest gap (px) between two pieces' extents, angle (degrees) between their directions,
#: and perpendicular offset (px, plus a share of the gap) of one piece's ends from the other's line.
LINK_GAP, LINK_ANGLE, LINK_OFFSET, LINK_OFFSET_PER_GAP = 80.0, 6.0, 1.5, 0.02
#: Chains shorter than this (px of the detection copy, along their direction) are dropped.
MIN_CHAIN_LENGTH = 60.0
#: Graphics test: a chain whose points all lie within this many px of one row (or column)...
OVERLAY_FLATNESS = 0.5
#: ...and which lies at least this share of the frame height (width) from the centre row (column).
OVERLAY_OFF_CENTRE = 0.12
#: A uniform border row/column (letterbox): standard deviation below this (grey levels).
LETTERBOX_STD = 4.0


@dataclass(frozen=True)
class Chain:
    """One chain of points that may be the image of a straight line.

    ``points``: float64 ``N x 2`` lens coordinates (see the module docstring), ordered along the
    chain; ``kind``: ``"ridge"`` or ``"edge"``; ``length``: extent along its direction in px of the
    detection copy.
    """

    points: np.ndarray
    kind: str
    length: float


@dataclass(frozen=True)
class LineEvidence:
    """Chains found in one frame: ``size`` is the frame ``(W, H)``, ``width`` the detection width
    (px), ``overlays`` the number of chains dropped as broadcast graphics, ``edge_density`` the
    share of unmasked pixels that are Canny edges (high for noise, near 0 for a blank frame)."""

    chains: list[Chain]
    size: tuple[int, int]
    width: int
    overlays: int = 0
    edge_density: float = 0.0


#: Largest block (input samples) :func:`_area_resize` handles by small matrix products; sizes with no
#: small common ratio go to ``cv2.resize``.
AREA_BLOCK_MAX = 48
#: Rows per matrix product in :func:`_area_resize`: small enough that BLAS stays on one thread.
AREA_CHUNK_ROWS = 4096


def gray_copy(frame: np.ndarray, max_width: int = DETECT_WIDTH) -> np.ndarray:
    """uint8 ``H x W x 3`` RGB (or ``H x W``) -> float32 gray at most ``max_width`` wide (area
    interpolation, rounded to whole grey levels)."""
    gray = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY) if frame.ndim == 3 else frame
    height, width = gray.shape[:2]
    if width > max_width:
        size = (max_width, max(2, int(round(height * max_width / width))))
        if size == (width // 2, height // 2) and width % 2 == height % 2 == 0:
            # halving (1920 -> 960): OpenCV's float area mean of each 2 x 2 block is exact (quarters of
            # integers), the same values as the matrix products below, in a third of the time
            half = cv2.resize(gray.astype(np.float32), size, interpolation=cv2.INTER_AREA)
            return np.rint(half, out=half)
        fast = _area_resize(gray, size)
        if fast is not None:
            return fast
        gray = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    return gray.astype(np.float32)


@lru_cache(maxsize=16)
def _area_weights(n_in: int, n_out: int) -> tuple[int, np.ndarray] | None:
    """Area-interpolation weights of ``n_in`` -> ``n_out`` samples as ``(blocks, W)``: the axis is
    ``blocks`` repeats of ``p`` inputs -> ``q`` outputs, ``W`` the float32 ``q x p`` weights (each
    output's footprint overlap with each input, normalised); ``None`` when ``p`` is too large."""
    blocks = math.gcd(n_in, n_out)
    p, q = n_in // blocks, n_out // blocks
    if p > AREA_BLOCK_MAX:
        return None
    lo = np.arange(q)[:, None] * (p / q)
    i = np.arange(p)[None, :]
    overlap = np.clip(np.minimum(lo + p / q, i + 1) - np.maximum(lo, i), 0.0, None)
    return blocks, (overlap / (p / q)).astype(np.float32)


def _area_resize(gray: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    """``cv2.resize(gray, size, interpolation=cv2.INTER_AREA)`` of a uint8 gray image, as float32
    (the same weights; a sum that rounds to exactly half a grey level may round the other way), by two
    small matrix products (about half the time at 1920 -> 800); ``None`` where the sizes have no
    small common block (:data:`AREA_BLOCK_MAX`)."""
    (height, width), (out_w, out_h) = gray.shape, size
    across, down = _area_weights(width, out_w), _area_weights(height, out_h)
    if across is None or down is None:
        return None
    x = gray.astype(np.float32).reshape(-1, width // across[0])  # rows: blocks of columns
    rows = np.empty((len(x), across[1].shape[0]), np.float32)
    for start in range(0, len(x), AREA_CHUNK_ROWS):
        np.matmul(x[start:start + AREA_CHUNK_ROWS], across[1].T, out=rows[start:start + AREA_CHUNK_ROWS])
    out = down[1] @ rows.reshape(down[0], height // down[0], out_w)  # blocks of rows
    return np.rint(out.reshape(out_h, out_w), out=out.reshape(out_h, out_w))


#: Border rows (columns) :func:`content_box` tests at a time: most frames stop at the first, a
#: letterboxed one after a few blocks instead of one call per row.
CONTENT_BLOCK = 16


def content_box(gray: np.ndarray) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` of the frame without letterbox/pillarbox bands: border rows (columns)
    that are uniform (standard deviation below :data:`LETTERBOX_STD`) are peeled off, at most a
    third of the frame from each side."""
    height, width = gray.shape
    # only the border rows/columns are tested (most frames stop at the first block): no full-frame std
    rows = lambda a, b: gray[a:b]  # noqa: E731
    columns = lambda a, b: np.ascontiguousarray(gray[:, a:b].T)  # noqa: E731 -- each column contiguous, as gray[:, x]
    y0 = _uniform_run(rows, 0, height // 3, 1)
    y1 = height - _uniform_run(rows, height - 1, 2 * height // 3 - 1, -1)
    x0 = _uniform_run(columns, 0, width // 3, 1)
    x1 = width - _uniform_run(columns, width - 1, 2 * width // 3 - 1, -1)
    return x0, y0, x1, y1


def _uniform_run(lines, first: int, stop: int, step: int) -> int:
    """How many of the lines ``first``, ``first + step``, ... (before ``stop``) are uniform (std
    below :data:`LETTERBOX_STD`) before the first that is not; ``lines(a, b)``: the lines ``a`` to
    ``b - 1`` as the rows of an array. :data:`CONTENT_BLOCK` lines are tested at a time."""
    done, todo = 0, abs(stop - first)
    while done < todo:
        n = min(CONTENT_BLOCK, todo - done)
        a = first + step * done
        block = lines(a, a + n) if step > 0 else lines(a - n + 1, a + 1)[::-1]
        busy = np.flatnonzero(block.std(axis=1) >= LETTERBOX_STD)
        if len(busy):
            return done + int(busy[0])
        done += n
    return done


def _derivatives(g: np.ndarray) -> tuple[np.ndarray, ...]:
    d1 = np.array([-0.5, 0.0, 0.5], np.float32)
    d2 = np.array([1.0, -2.0, 1.0], np.float32)
    one = np.array([1.0], np.float32)
    gx = cv2.sepFilter2D(g, -1, d1, one)
    gy = cv2.sepFilter2D(g, -1, one, d1)
    gxx = cv2.sepFilter2D(g, -1, d2, one)
    gyy = cv2.sepFilter2D(g, -1, one, d2)
    gxy = cv2.sepFilter2D(g, -1, d1, d1)
    return gx, gy, gxx, gyy, gxy


def _ridge_points(gx, gy, gxx, gyy, gxy, valid):
    """Sub-pixel centres of bright ridges: ``(x, y, angle, row, column)`` arrays (angle of the line
    in [0, pi); row, column: the integer pixel of each point)."""
    half_trace = cv2.addWeighted(gxx, 0.5, gyy, 0.5, 0.0)
    root = cv2.magnitude(cv2.addWeighted(gxx, 0.5, gyy, -0.5, 0.0), gxy)
    lam = cv2.subtract(half_trace, root)  # most negative eigenvalue
    strong = cv2.compare(lam, -RIDGE_MIN_CURVATURE, cv2.CMP_LT)
    # a ridge, not a blob: the other eigenvalue (half_trace + root) is not as negative
    line_like = cv2.compare(cv2.addWeighted(half_trace, 1.0, root, 1.0, 0.0), cv2.multiply(lam, 0.5), cv2.CMP_GT)
    idx = np.flatnonzero(cv2.bitwise_and(strong, line_like, mask=valid) > 0)  # bool: numpy's fast path
    l1, a, b, c = lam.ravel()[idx], gxx.ravel()[idx], gyy.ravel()[idx], gxy.ravel()[idx]
    # eigenvector of lam: (c, lam - a) or (lam - b, c), whichever is longer (numerically stable)
    v1y, v2x = l1 - a, l1 - b
    use1 = c * c + v1y * v1y >= v2x * v2x + c * c
    nx, ny = np.where(use1, c, v2x), np.where(use1, v1y, c)
    norm2 = nx * nx + ny * ny
    ok = norm2 > 1e-12
    # Newton step along the normal: offset = -(n . grad) n / (n^T H n), n^T H n = lam |n|^2
    step = -(nx * gx.ravel()[idx] + ny * gy.ravel()[idx]) / (l1 * np.where(ok, norm2, 1.0))
    ox, oy = step * nx, step * ny
    keep = np.flatnonzero(ok & (np.abs(ox) <= 0.5) & (np.abs(oy) <= 0.5))
    ys, xs = np.divmod(idx[keep], lam.shape[1])
    nx, ny = nx[keep], ny[keep]
    angle = np.mod(np.arctan2(nx, -ny), np.pi)  # line direction is perpendicular to the normal
    return xs + ox[keep], ys + oy[keep], angle, ys, xs


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    height, width = image.shape
    x = np.clip(x, 0.0, width - 1.001)
    y = np.clip(y, 0.0, height - 1.001)
    x0, y0 = x.astype(np.intp), y.astype(np.intp)
    fx, fy = x - x0, y - y0
    top = image[y0, x0] * (1 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


def _edge_points(g, gx, gy, valid, near_ridge):
    """Sub-pixel step-edge points ``(x, y, direction, row, column, density)``: direction of the
    gradient in [0, 2 pi); ``valid`` (uint8) masks the frame, edges where ``near_ridge`` are
    dropped (the flanks of thin lines); density: share of valid pixels that are edges."""
    edges = cv2.Canny(np.clip(g, 0, 255).astype(np.uint8), CANNY_LOW, CANNY_HIGH, L2gradient=True)
    edges = cv2.bitwise_and(edges, edges, mask=valid)
    density = cv2.countNonZero(edges) / max(cv2.countNonZero(valid), 1)
    idx = np.flatnonzero((edges > 0) & (near_ridge == 0))  # bool: numpy's fast path
    ys, xs = np.divmod(idx, edges.shape[1])
    ex, ey = gx[ys, xs], gy[ys, xs]
    mag = np.hypot(ex, ey)
    ok = mag > 1e-6
    ys, xs, ex, ey, mag = ys[ok], xs[ok], ex[ok], ey[ok], mag[ok]
    dx, dy = ex / mag, ey / mag
    magnitude = cv2.magnitude(gx, gy)
    before = _bilinear(magnitude, xs - dx, ys - dy)
    after = _bilinear(magnitude, xs + dx, ys + dy)
    denom = before - 2.0 * mag + after
    offset = np.where(denom < -1e-6, 0.5 * (before - after) / np.where(denom < -1e-6, denom, -1.0), 0.0)
    offset = np.clip(offset, -0.5, 0.5)
    direction = np.mod(np.arctan2(dy, dx), 2.0 * np.pi)
    return xs + offset * dx, ys + offset * dy, direction, ys, xs, density


@dataclass(frozen=True)
class _Points:
    """Sub-pixel line points of one frame: position (``x``, ``y``, px of the detection copy), orientation ``angle`` (radians in [0, pi)), ``kind`` (0 ridge,
    1 edge) and the integer pixel (``iy``, ``ix``) each was found in."""

    x: np.ndarray
    y: np.ndarray
    angle: np.ndarray
    kind: np.ndarray
    iy: np.ndarray
    ix: np.ndarray


def _piece_keys(points: _Points, bins: int, shape: tuple[int, int]) -> np.ndarray:
    """A key per point, equal for points of the same 8-connected piece of one orientation bin and
    kind (a line crossing a circle stays apart from it); ``shape`` is the frame's (H, W)."""
    b = ((np.floor(points.angle / np.pi * bins + 0.5).astype(np.intp)) % bins).astype(np.uint8)  # radix argsort
    key = np.zeros(len(points.x), np.int64)
    mask = np.zeros(shape, np.uint8)
    by_bin = np.argsort(b, kind="stable")
    bounds = np.searchsorted(b[by_bin], np.arange(bins + 1))
    iy, ix = points.iy, points.ix
    for k in range(bins):
        sel = by_bin[bounds[k]:bounds[k + 1]]
        if len(sel) == 0:
            continue
        y0, y1 = int(iy[sel].min()), int(iy[sel].max()) + 1
        x0, x1 = int(ix[sel].min()), int(ix[sel].max()) + 1
        roi = mask[y0:y1, x0:x1]
        roi[:] = 0
        roi[iy[sel] - y0, ix[sel] - x0] = 1
        _, labels = cv2.connectedComponentsWithAlgorithm(roi, 8, cv2.CV_32S, cv2.CCL_SAUF)
        key[sel] = (labels[iy[sel] - y0, ix[sel] - x0].astype(np.int64) * bins + k) * 2 + points.kind[sel]
    return key


@dataclass(frozen=True)
class _Found:
    """What a gray detection copy shows whatever the lens hint: its line points, their pieces
    (:func:`_grouped`: ``order``, ``group``, ``pieces``), the Canny edge density and the copy's ``(H, W)``."""

    points: _Points
    order: np.ndarray
    group: np.ndarray
    pieces: int
    density: float
    shape: tuple[int, int]


def _grouped(points: _Points, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, int]:
    """The points' connected pieces (:func:`_piece_keys`) of at least :data:`MIN_PIECE_POINTS`:
    ``(order, group, n)``, the indices of their points grouped by piece, each one's piece index and
    the number of pieces."""
    if len(points.x) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp), 0
    key = _piece_keys(points, ORIENTATION_BINS, shape)
    small = key.max() < 1 << 16  # then a 16-bit copy sorts the same, by numpy's radix sort
    order = np.argsort(key.astype(np.uint16) if small else key, kind="stable")
    key_sorted = key[order]
    starts = np.flatnonzero(np.r_[True, key_sorted[1:] != key_sorted[:-1]])
    counts = np.diff(np.r_[starts, len(key_sorted)])
    big = counts >= MIN_PIECE_POINTS
    group = np.repeat(np.cumsum(big) - 1, counts)  # piece index per sorted point (-1..)
    keep = np.repeat(big, counts)
    return order[keep], group[keep], int(big.sum())


class _Pieces:
    """Connected same-orientation, same-kind pieces: per-piece centre, unit axis, extent along it
    (``lo``, ``hi``, px), kind (0 ridge, 1 edge) and the point indices of each piece, from the
    :class:`_Found` of a detection copy.

    Ridge and edge points never touch (edges within 2 px of a ridge were dropped), so each
    orientation bin takes one connected-components pass for both kinds.

    ``lens``: a lens hint ``(k1, k2)``; the pieces are then measured on their points undistorted
    with it, ``x``, ``y`` (px; only the points of kept pieces are undistorted, the others are
    the input's)."""

    def __init__(self, found: _Found, lens: tuple[float, float] | None = None) -> None:
        empty = np.zeros(0)
        points, order, group, n = found.points, found.order, found.group, found.pieces
        self.x, self.y = points.x, points.y
        self.centre, self.axis, self.lo, self.hi = np.zeros((0, 2)), np.zeros((0, 2)), empty, empty
        self.kind = np.zeros(0, np.intp)
        self.members: list[np.ndarray] = []
        if lens is not None and len(order):
            height, width = found.shape
            self.x, self.y = points.x.copy(), points.y.copy()
            self.x[order], self.y[order] = _undistorted(points.x[order], points.y[order], (width, height), lens)
        if n:
            self._measure(points, order, group, n)

    def _measure(self, points: _Points, order: np.ndarray, group: np.ndarray, n: int) -> None:
        """Centre, axis (total least squares), extent and members of the ``n`` pieces; ``order``
        lists the kept points grouped by piece, ``group`` their piece index."""
        x, y = self.x[order], self.y[order]
        cnt = np.bincount(group, minlength=n).astype(np.float64)
        mx, my = np.bincount(group, x, n) / cnt, np.bincount(group, y, n) / cnt
        dx, dy = x - mx[group], y - my[group]
        cxx, cyy = np.bincount(group, dx * dx, n), np.bincount(group, dy * dy, n)
        cxy = np.bincount(group, dx * dy, n)
        theta = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
        self.axis = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        self.centre = np.stack([mx, my], axis=1)
        s = dx * self.axis[group, 0] + dy * self.axis[group, 1]
        bounds = np.r_[0, np.cumsum(cnt.astype(np.intp))[:-1]]
        self.lo, self.hi = np.minimum.reduceat(s, bounds), np.maximum.reduceat(s, bounds)
        self.members = np.split(order, bounds[1:])
        self.kind = points.kind[order[bounds]]

    def __len__(self) -> int:
        return len(self.members)


def _link(p: _Pieces) -> list[list[int]]:
    """Union pieces that continue each other (collinear within tolerance, gap <= LINK_GAP)."""
    n = len(p)
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    if n > 1:
        aligned = np.abs(p.axis @ p.axis.T) >= np.cos(np.radians(LINK_ANGLE))
        i, j = np.nonzero(np.triu(aligned & (p.kind[:, None] == p.kind[None, :]), 1))  # ridges with ridges
        half = 0.5 * (p.hi - p.lo)
        reach = np.hypot(*(p.centre[i] - p.centre[j]).T) <= half[i] + half[j] + LINK_GAP + 2.0
        i, j = i[reach], j[reach]
        ok = np.ones(len(i), bool)
        gap = np.zeros(len(i))
        for a, b, first in ((i, j, True), (j, i, False)):
            ax = p.axis[a]
            normal = np.stack([-ax[:, 1], ax[:, 0]], axis=1)
            ends = p.centre[b][:, None, :] + np.stack([p.lo[b], p.hi[b]], axis=1)[:, :, None] * p.axis[b][:, None, :]
            rel = ends - p.centre[a][:, None, :]
            along = np.einsum("nkc,nc->nk", rel, ax)
            across = np.abs(np.einsum("nkc,nc->nk", rel, normal)).max(axis=1)
            if first:
                gap = np.maximum(0.0, np.maximum(along.min(axis=1) - p.hi[a], p.lo[a] - along.max(axis=1)))
            ok &= across <= LINK_OFFSET + LINK_OFFSET_PER_GAP * gap
        ok &= gap <= LINK_GAP
        for a, b in zip(i[ok].tolist(), j[ok].tolist()):
            parent[find(a)] = find(b)
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(k)
    return list(groups.values())


def _percentiles(a: np.ndarray, quantiles: tuple[float, float]) -> tuple[float, float]:
    """``np.percentile(a, 100 * q)`` (linear interpolation) for two quantiles, by one partial sort."""
    last = len(a) - 1
    h = [last * q for q in quantiles]
    lo = [int(x) for x in h]  # floor: h >= 0
    part = np.partition(a, sorted({i for k in lo for i in (k, min(k + 1, last))}))
    value = [part[k] + (x - k) * (part[min(k + 1, last)] - part[k]) for x, k in zip(h, lo)]
    return float(value[0]), float(value[1])


def _is_overlay(x: np.ndarray, y: np.ndarray, shape: tuple[int, int]) -> bool:
    """Pixel-straight, axis-aligned and off the centre row/column: broadcast graphics. Flatness is
    the 2-98 percentile range across the axis, so a corner or a crossing line at an end does not
    hide a graphics edge."""
    height, width = shape
    for across, centre, extent in ((y, (height - 1) / 2, height), (x, (width - 1) / 2, width)):
        if np.ptp(across) > 0.05 * extent:  # far from axis-aligned: skip the percentiles
            continue
        lo, hi = _percentiles(across, (0.02, 0.98))
        if hi - lo <= 2 * OVERLAY_FLATNESS and abs(np.median(across) - centre) > OVERLAY_OFF_CENTRE * extent:
            return True
    return False


def _undistorted(x: np.ndarray, y: np.ndarray, size: tuple[int, int], lens: tuple[float, float]):
    """Detection-copy pixels undistorted with ``lens`` (exact inverse); pixels with no undistorted
    point (beyond the lens's reach) are kept as they are."""
    from ..lens.lensfuncs import undistort_point_exact

    p_d = pixels_to_lens(np.stack([x, y], axis=1), size)
    p_u, valid = undistort_point_exact(p_d, float(lens[0]), float(lens[1]))
    q = lens_to_pixels(np.where(valid[:, None], p_u, p_d), size)
    return q[:, 0], q[:, 1]


#: Frames whose line points :func:`detect_chains` keeps (:class:`_PointsMemo`): pass 1 of a video
#: detects each sampled frame's chains twice, in the per-frame estimate's line fit (hinted with the
#: CNN's lens) and for the shot's joint fit (hinted with the surest estimate so far), on a worker
#: thread and the caller's, up to ``shot_track.LOOKAHEAD`` samples apart.
POINTS_MEMO_SIZE = 4


def _find_points(gray: np.ndarray) -> _Found:
    """The hint-free part of :func:`detect_chains` on its float32 gray detection copy."""
    height, width = gray.shape
    g = cv2.GaussianBlur(gray, (0, 0), SMOOTH_SIGMA)
    gx, gy, gxx, gyy, gxy = _derivatives(g)
    x0, y0, x1, y1 = content_box(gray)
    valid = np.zeros((height, width), np.uint8)
    m = BORDER_MARGIN
    valid[y0 + m: y1 - m, x0 + m: x1 - m] = 1
    rx, ry, rangle, riy, rix = _ridge_points(gx, gy, gxx, gyy, gxy, valid)
    ridge_mask = np.zeros((height, width), np.uint8)
    ridge_mask[riy, rix] = 1
    near_ridge = cv2.dilate(ridge_mask, np.ones((5, 5), np.uint8))
    ex, ey, edir, eiy, eix, density = _edge_points(g, gx, gy, valid, near_ridge)
    kinds = np.r_[np.zeros(len(rx), np.intp), np.ones(len(ex), np.intp)]
    points = _Points(np.concatenate([rx, ex]), np.concatenate([ry, ey]), np.concatenate([rangle, np.mod(edir, np.pi)]),
                     kinds, np.concatenate([riy, eiy]), np.concatenate([rix, eix]))
    for array in vars(points).values():  # shared by every later detection of this copy
        array.setflags(write=False)
    return _Found(points, *_grouped(points, (height, width)), density, (height, width))


class _PointsMemo:
    """The last :data:`POINTS_MEMO_SIZE` gray copies and their :class:`_Found`: a copy equal to a kept
    one (same shape, same values: detection is a function of the copy alone) gets the kept answer.
    Thread-safe; the detection itself runs outside the lock."""

    def __init__(self, size: int = POINTS_MEMO_SIZE) -> None:
        self._kept: list[tuple[np.ndarray, _Found]] = []
        self._size = size
        self._lock = threading.Lock()

    def find(self, gray: np.ndarray) -> _Found:
        """:func:`_find_points` of ``gray``, kept or found now."""
        with self._lock:
            kept = list(self._kept)
        for copy, found in kept:
            if copy.shape == gray.shape and np.array_equal(copy, gray):
                return found
        found = _find_points(gray)
        with self._lock:
            self._kept = (self._kept + [(gray, found)])[-self._size:]
        return found


_MEMO = _PointsMemo()


def detect_chains(frame: np.ndarray, max_width: int = DETECT_WIDTH,
                  lens_hint: tuple[float, float] | None = None) -> LineEvidence:
    """Find the chains of a uint8 RGB/gray frame (see the module docstring), detecting on a copy at
    most ``max_width`` pixels wide.

    ``lens_hint``: a rough ``(k1, k2)`` (e.g. the CNN's). Pieces are then linked where they continue
    each other once undistorted with it, so strongly curved lines (k1 near -0.7 at the frame edge)
    still form long chains; the chains' points stay those of the frame. The line points of the last
    few frames are kept (:class:`_PointsMemo`): detecting a frame again, with another hint, links them anew."""
    height_full, width_full = frame.shape[:2]
    found = _MEMO.find(gray_copy(frame, max_width))
    (height, width), xs, ys = found.shape, found.points.x, found.points.y
    chains: list[Chain] = []
    overlays = 0
    pieces = _Pieces(found, lens_hint)
    lx, ly = pieces.x, pieces.y
    extent = pieces.hi - pieces.lo
    for group in _link(pieces):  # an edge may change polarity along a line (boards, chessboards)
        if len(group) == 1 and extent[group[0]] < MIN_CHAIN_LENGTH:
            continue
        # extent of the pieces' ends along the longest piece's axis: a cheap bound on the length
        longest = group[int(np.argmax(pieces.hi[group] - pieces.lo[group]))]
        ends = np.concatenate([pieces.centre[group] + pieces.lo[group, None] * pieces.axis[group],
                               pieces.centre[group] + pieces.hi[group, None] * pieces.axis[group]])
        if np.ptp(ends @ pieces.axis[longest]) < MIN_CHAIN_LENGTH:
            continue
        idx = np.concatenate([pieces.members[k] for k in group])
        kind = "edge" if pieces.kind[group[0]] else "ridge"
        for part, axis in _one_line_parts(idx, xs, ys, lx, ly):  # a chain round a corner is cut there
            found_chain = _chain(part, xs, ys, kind, (height, width), (width_full, height_full), axis)
            overlays += found_chain is _OVERLAY
            if isinstance(found_chain, Chain):
                chains.append(found_chain)
    return LineEvidence(chains, (width_full, height_full), width, overlays, found.density)


def bright_ridges(gray: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel centres of the bright thin lines of a float32 gray image (the ridge points chains are
    made of, before grouping): ``(x, y, angle)`` in pixels of ``gray`` (centres at integers) and the
    line direction in [0, pi); ``valid``: uint8 mask of where to look."""
    g = cv2.GaussianBlur(gray, (0, 0), SMOOTH_SIGMA)
    gx, gy, gxx, gyy, gxy = _derivatives(g)
    x, y, angle, _, _ = _ridge_points(gx, gy, gxx, gyy, gxy, valid)
    return x, y, angle


#: Returned by :func:`_chain` for a chain taken for broadcast graphics.
_OVERLAY = object()


def _one_line_parts(idx: np.ndarray, xs, ys, lx, ly) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """The point indices ``idx`` of one linked chain, ordered along it and cut where it turns a
    corner (:func:`glradial.estimation.corners.split_at_corners`, on the points undistorted with
    the hint, ``lx``, ``ly``), each with its axis when known (an uncut chain keeps the chain's)."""
    pts = np.stack([xs[idx], ys[idx]], axis=1)
    centre = pts.mean(axis=0)
    axis = _principal_axis(pts - centre)
    ordered = idx[np.argsort((pts - centre) @ axis)]
    parts = split_at_corners(np.stack([lx[ordered], ly[ordered]], axis=1))
    return [(ordered, axis)] if len(parts) == 1 else [(ordered[s], None) for s in parts]


def _principal_axis(d: np.ndarray) -> np.ndarray:
    """Unit direction of largest spread of the ``N x 2`` points ``d``: the last eigenvector of
    ``np.cov(d.T)``, with np.cov's arithmetic inlined (its argument handling cost more than the sums)."""
    x = d.T - d.T.mean(axis=1)[:, None]
    return np.linalg.eigh(np.dot(x, x.T.conj()) * np.true_divide(1, len(d) - 1))[1][:, 1]


def _chain(idx: np.ndarray, xs, ys, kind: str, shape: tuple[int, int], size_full: tuple[int, int],
           axis: np.ndarray | None = None):
    """A :class:`Chain` of the detection-copy points ``idx`` (along ``axis``, the direction of their
    largest spread, computed when ``None``); ``None`` when shorter than :data:`MIN_CHAIN_LENGTH`,
    :data:`_OVERLAY` when it is broadcast graphics."""
    x, y = xs[idx], ys[idx]
    pts = np.stack([x, y], axis=1)
    centre = pts.mean(axis=0)
    if axis is None:
        axis = _principal_axis(pts - centre)
    s = (pts - centre) @ axis
    length = float(np.ptp(s))
    if length < MIN_CHAIN_LENGTH:
        return None
    if _is_overlay(x, y, shape):
        return _OVERLAY
    order = np.argsort(s)
    # back to full-frame pixel centres, then lens units
    height, width = shape
    full = (pts[order] + 0.5) * np.array([size_full[0] / width, size_full[1] / height]) - 0.5
    return Chain(pixels_to_lens(full, size_full), kind, length)
