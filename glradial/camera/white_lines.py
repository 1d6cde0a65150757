"""White pitch-line evidence of a broadcast frame, for the camera's first guess: a mask of the painted
lines on the grass, its pixels, the straight lines through them and where pairs of them meet.

Convention: everything here is in pixels of the **work copy**, the frame resized (area
interpolation) to :data:`WORK_WIDTH` pixels wide with its aspect kept; pixel centres at integers,
x right, y down. A line is ``(a, b, c)`` with ``a x + b y + c = 0`` and ``a² + b² = 1``.

The mask: grass is green (hue 30..90 on OpenCV's 0..180 scale, saturated, not dark, once blurred
over a few pixels); a line pixel is brighter than its surroundings by :data:`TOPHAT_MIN` grey levels
(a white top-hat with a disc wider than a painted line at the work scale) and lies where enough of
its neighbourhood is grass (:data:`GRASS_SHARE`), so the stands, ad boards and the sky bring no
evidence; compact blobs (players, the ball) are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..lens.lens import Lens

#: Width (px) of the work copy. The first guess needs lines, not detail: 640 px keeps a 12 cm line at
#: 60 m from a 1280-px wide shot about one pixel wide, and the whole search within its time budget.
WORK_WIDTH = 640
#: Grass: OpenCV HSV hue range (0..180), smallest saturation and value (0..255).
GRASS_HUE, GRASS_MIN_SAT, GRASS_MIN_VAL = (30, 90), 50, 40
#: Grass is judged on a box-blurred copy (side, px): grass is green over an area, noise is not.
GRASS_BLUR = 5
#: Side (px) of the window in which a line pixel needs :data:`GRASS_SHARE` of grass around it.
GRASS_WINDOW, GRASS_SHARE = 15, 0.3
#: White top-hat: disc diameter (px of the work copy) and smallest response (grey levels).
TOPHAT_DISC, TOPHAT_MIN = 9, 15
#: Probabilistic Hough transform on the mask: accumulator threshold, shortest segment, largest gap (px).
HOUGH_VOTES, HOUGH_MIN_LENGTH, HOUGH_MAX_GAP = 25, 25, 10
#: At most this many Hough segments (longest first) are grouped.
MAX_SEGMENTS = 300
#: Segments join one line when they point within MERGE_ANGLE (radians) of it and both their ends
#: lie within MERGE_OFFSET px of it.
MERGE_ANGLE, MERGE_OFFSET = 0.035, 2.5
#: A line is kept when its mask pixels cover at least this length (px).
MIN_LINE_SUPPORT = 30.0
#: Mask pixels this close (px) to a line, and at most SPAN_MARGIN px beyond its Hough segments'
#: ends, are its support in the refit.
SUPPORT_BAND, SPAN_MARGIN = 2.0, 12.0
#: A line found takes the mask pixels this close (px) to it, along its extent, from the later lines.
CLAIM_BAND = 3.5
#: Mask components are dropped when they extend less than BLOB_MIN_EXTENT px, or less than
#: BLOB_COMPACT_EXTENT px with more than BLOB_MAX_THICKNESS px of area per px of extent (players,
#: the ball and specks are compact; lines, alone or joined to a player, are long).
BLOB_MIN_EXTENT, BLOB_COMPACT_EXTENT, BLOB_MAX_THICKNESS = 14, 48, 4.5
#: At most this many lines (longest support first) are kept.
MAX_LINES = 14
#: A vanishing point may lie at most this far (px) inside the convex hull of the line pixels.
HULL_MARGIN = 3.0


@dataclass(frozen=True)
class Line:
    """A straight line of the mask: ``abc`` its normalised equation, ``ends`` (2 x 2) the extreme
    support pixels along it, ``support`` the length (px) its mask pixels cover."""

    abc: np.ndarray
    ends: np.ndarray
    support: float

    @property
    def centre(self) -> np.ndarray:
        return self.ends.mean(axis=0)

    @property
    def half_length(self) -> float:
        return 0.5 * float(np.linalg.norm(self.ends[1] - self.ends[0]))


@dataclass(frozen=True)
class WhiteLines:
    """Line evidence of one frame: ``mask`` (uint8 0/1, work copy), ``field`` (uint8 0/1, where lines
    could be seen: mostly grass around), ``grass`` (the share of the work copy that is grass),
    ``points`` (N x 2 float64, the mask's pixels), ``scale`` (frame px per work px) and ``lines``
    (its straight lines, :class:`Line`, longest support first)."""

    mask: np.ndarray
    field: np.ndarray
    grass: float
    points: np.ndarray
    scale: float
    lines: list[Line]


def work_copy(frame_rgb: np.ndarray) -> tuple[np.ndarray, float]:
    """The frame resized to :data:`WORK_WIDTH` wide (area interpolation; never enlarged) and the
    scale ``frame px / work px``."""
    height, width = frame_rgb.shape[:2]
    if width <= WORK_WIDTH:
        return frame_rgb, 1.0
    scale = width / WORK_WIDTH
    size = (WORK_WIDTH, max(2, int(round(height / scale))))
    return cv2.resize(frame_rgb, size, interpolation=cv2.INTER_AREA), scale


def line_mask(small_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(mask, field, grass share)``: the white-line mask and the field (uint8 0/1: mostly grass
    around) of a work copy (module docstring)."""
    hsv = cv2.cvtColor(cv2.blur(small_rgb, (GRASS_BLUR, GRASS_BLUR)), cv2.COLOR_RGB2HSV)
    hue, sat, val = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    grass = ((hue > GRASS_HUE[0]) & (hue < GRASS_HUE[1]) & (sat > GRASS_MIN_SAT) & (val > GRASS_MIN_VAL)).astype(np.float32)
    around = cv2.blur(grass, (GRASS_WINDOW, GRASS_WINDOW))
    gray = cv2.cvtColor(small_rgb, cv2.COLOR_RGB2GRAY)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (TOPHAT_DISC, TOPHAT_DISC))
    tophat = cv2.morphologyEx(gray, cv2.MORPH_TOPHAT, disc)
    field = (around >= GRASS_SHARE).astype(np.uint8)
    return (tophat >= TOPHAT_MIN).astype(np.uint8) & field, field, float(grass.mean())


def _direction(abc: np.ndarray) -> np.ndarray:
    return np.array([-abc[1], abc[0]])


def _refit(points: np.ndarray, abc: np.ndarray, span: tuple[float, float]) -> Line | None:
    """The total-least-squares line through the mask ``points`` within :data:`SUPPORT_BAND` of
    ``abc`` and within ``span`` (positions along ``abc``'s direction) widened by
    :data:`SPAN_MARGIN` (two passes), its ends and support; ``None`` when the support is too short."""
    along = points @ _direction(abc)
    points = points[(along >= span[0] - SPAN_MARGIN) & (along <= span[1] + SPAN_MARGIN)]
    for _ in range(2):
        near = points[np.abs(points @ abc[:2] + abc[2]) <= SUPPORT_BAND]
        if len(near) < MIN_LINE_SUPPORT:
            return None
        centre = near.mean(axis=0)
        d = near - centre
        _, vecs = np.linalg.eigh(d.T @ d)
        normal = vecs[:, 0]
        abc = np.array([normal[0], normal[1], -normal @ centre])
    s = (near - centre) @ _direction(abc)
    # support: the length covered by occupied 1-px bins along the line (gaps behind players excluded)
    support = float(len(np.unique(np.round(s))))
    if support < MIN_LINE_SUPPORT:
        return None
    ends = centre + np.outer([s.min(), s.max()], _direction(abc))
    return Line(abc, ends, support)


def _merge_segments(segments: np.ndarray) -> list[tuple[np.ndarray, list[float]]]:
    """Hough segments (K x 4: x1, y1, x2, y2), longest first, grouped into lines: the equation of
    each group's longest segment and the span ``[lo, hi]`` of the group's ends along it; groups
    spanning less than :data:`MIN_LINE_SUPPORT` are left out."""
    abc = np.zeros((len(segments), 3))
    spans = np.zeros((len(segments), 2))
    n = 0
    for x1, y1, x2, y2 in segments:
        d = np.array([x2 - x1, y2 - y1]) / max(np.hypot(x2 - x1, y2 - y1), 1e-9)
        off = np.maximum(np.abs(abc[:n, 0] * x1 + abc[:n, 1] * y1 + abc[:n, 2]),
                         np.abs(abc[:n, 0] * x2 + abc[:n, 1] * y2 + abc[:n, 2]))
        same = np.flatnonzero((off <= MERGE_OFFSET) & (np.abs(abc[:n, :2] @ d) <= MERGE_ANGLE))
        k = int(same[0]) if len(same) else n
        if k == n:
            abc[n] = [-d[1], d[0], d[1] * x1 - d[0] * y1]
            spans[n] = [np.inf, -np.inf]
            n += 1
        along = np.array([[x1, y1], [x2, y2]]) @ _direction(abc[k])
        spans[k] = [min(spans[k, 0], along.min()), max(spans[k, 1], along.max())]
    keep = spans[:n, 1] - spans[:n, 0] >= MIN_LINE_SUPPORT
    return [(abc[k], list(spans[k])) for k in np.flatnonzero(keep)]


def thin_components(mask: np.ndarray) -> np.ndarray:
    """``mask`` (uint8 0/1) without its compact components (players, the ball, specks): see
    :data:`BLOB_MIN_EXTENT` and the next constants."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    extent = np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    compact = (extent < BLOB_COMPACT_EXTENT) & (stats[:, cv2.CC_STAT_AREA] > BLOB_MAX_THICKNESS * extent)
    keep = (extent >= BLOB_MIN_EXTENT) & ~compact
    keep[0] = False
    return keep[labels].astype(np.uint8)


def straight_lines(mask: np.ndarray, points: np.ndarray) -> list[Line]:
    """The straight lines of ``mask`` (Hough segments merged, refit to the mask pixels ``points``),
    longest support first. Lines are taken in turn, longest Hough group first, and each takes its
    pixels (within :data:`CLAIM_BAND` px, along its extent) away from the later ones, so a thick
    line or a line beside an ad board's edge does not come back as a fan of near copies."""
    found = cv2.HoughLinesP(mask, 1, np.pi / 180, HOUGH_VOTES, minLineLength=HOUGH_MIN_LENGTH, maxLineGap=HOUGH_MAX_GAP)
    if found is None:
        return []
    segments = found.reshape(-1, 4).astype(np.float64)
    order = np.argsort(-np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1]))[:MAX_SEGMENTS]
    lines: list[Line] = []
    free = points
    for abc, span in _merge_segments(segments[order]):
        line = _refit(free, abc, (span[0], span[1]))
        if line is None:
            continue
        lines.append(line)
        d = _direction(line.abc)
        along = free @ d
        lo, hi = np.sort(line.ends @ d)
        claimed = (np.abs(free @ line.abc[:2] + line.abc[2]) <= CLAIM_BAND) & (along >= lo - 1) & (along <= hi + 1)
        free = free[~claimed]
    return sorted(lines, key=lambda line: -line.support)[:MAX_LINES]


def hull(points: np.ndarray) -> np.ndarray:
    """The convex hull (K x 2 float64, px) of the line pixels ``points``."""
    if len(points) < 3:
        return points.astype(np.float64)
    return cv2.convexHull(points.astype(np.float32))[:, 0, :].astype(np.float64)


def pair_vanishing_points(lines: list[Line], points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(vp, valid)`` of every pair of ``lines`` (in ``np.triu_indices`` order): the homogeneous
    point where the two meet (unit norm) and whether it can be a vanishing point of parallel pitch
    lines: outside the convex hull of the line pixels ``points`` by more than :data:`HULL_MARGIN`
    (parallel lines never meet on the pitch in view, the horizon is beyond it) and not within either
    line's extent."""
    abc = np.array([line.abc for line in lines]).reshape(-1, 3)
    i, j = np.triu_indices(len(lines), 1)
    vp = np.cross(abc[i], abc[j])
    vp /= np.maximum(np.linalg.norm(vp, axis=1, keepdims=True), 1e-300)
    with np.errstate(all="ignore"):
        xy = np.nan_to_num(vp[:, :2] / vp[:, 2:3], nan=1e9, posinf=1e9, neginf=-1e9)
    valid = np.ones(len(vp), bool)
    if len(points) >= 3:
        outline = hull(points).astype(np.float32)[:, None, :]
        near = np.flatnonzero(np.all(np.abs(xy) < 1e6, axis=1))
        for k in near:
            valid[k] = cv2.pointPolygonTest(outline, (float(xy[k, 0]), float(xy[k, 1])), True) < HULL_MARGIN
    ends = np.array([line.ends for line in lines]).reshape(-1, 2, 2)
    for k in (i, j):
        d = np.stack([-abc[k, 1], abc[k, 0]], axis=1)
        a, b = np.sum(ends[k, 0] * d, axis=1), np.sum(ends[k, 1] * d, axis=1)
        along = np.sum(xy * d, axis=1)
        valid &= ~((along > np.minimum(a, b) - SPAN_MARGIN) & (along < np.maximum(a, b) + SPAN_MARGIN))
    return vp, valid


def white_lines(frame_rgb: np.ndarray, lens: Lens | None = None) -> WhiteLines:
    """The line evidence (:class:`WhiteLines`) of a uint8 RGB frame; with ``lens``, of the work
    copy undistorted by it (same size and principal point, scale 1: ``Lens.maps(fit="same")``)."""
    small, scale = work_copy(frame_rgb)
    if lens is not None:
        map_x, map_y = lens.maps((small.shape[1], small.shape[0]), direction="undistort", fit="same")
        small = cv2.remap(small, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    mask, field, grass = line_mask(small)
    mask = thin_components(mask)
    ys, xs = np.nonzero(mask)
    points = np.stack([xs, ys], axis=1).astype(np.float64)
    lines = straight_lines(mask * 255, points) if len(points) else []
    return WhiteLines(mask, field, grass, points, scale, lines)
