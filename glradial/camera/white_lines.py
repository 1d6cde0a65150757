"""The white pitch lines of a broadcast frame, the one extraction the camera uses, in two forms:

* :func:`line_points` (:class:`LinePoints`), what the camera is **fitted** to: sub-pixel centres of
  bright thin ridges (the line detector's Hessian ridges,
  :func:`glradial.estimation.lines.bright_ridges`) on a copy at most :data:`DETECT_WIDTH` px wide,
  brighter than their neighbourhood by :data:`WHITE_CONTRAST` grey levels (more on a grainy frame:
  :data:`GRAIN_SIGMAS` times its :func:`grain`), kept on the pitch region
  (:func:`pitch_region`: the largest area of the pitch's own green, closed over its lines and
  players); letterboxes and a border margin are masked. Points are returned in pixels of the
  **distorted frame at its own resolution** (centres at integers), with their line direction
  (radians in [0, pi)).
* :func:`white_lines` (:class:`WhiteLines`), what the first guess **searches**: a mask of the painted
  lines on the grass of the **work copy**, the frame resized (area interpolation) to
  :data:`WORK_WIDTH` px wide with its aspect kept, its pixels, the straight lines through them and
  where pairs of them meet. A line pixel is brighter than its surroundings by :data:`TOPHAT_MIN` grey
  levels (a white top-hat with a disc wider than a painted line at the work scale) and lies where
  enough of its neighbourhood is grass (:data:`GRASS_SHARE`), so the stands, ad boards and the sky
  bring no evidence; compact blobs (players, the ball) are dropped. Pixels of the work copy, x right,
  y down; a line is ``(a, b, c)`` with ``a x + b y + c = 0`` and ``a² + b² = 1``.

Grass is the pitch's own green of :func:`glradial.estimation.trust.pitch_green` (defined once there):
the dominant hue window, :data:`HUE_HALF_WINDOW` either side, of its pitch-green band, so stands and
boards of other greens and yellows are not grass; for the work copy's mask judged once box-blurred over
:data:`GRASS_BLUR` px (grass is green over an area, noise is not).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..estimation.lines import BORDER_MARGIN, bright_ridges, content_box, gray_copy
from ..estimation.trust import pitch_green
from ..lens.lens import Lens

#: Largest width (px) of the copy the white lines are detected on.
DETECT_WIDTH = 960
#: The pitch region: green closed over this many px (detection copy), then grown by this many...
GRASS_CLOSE, GRASS_GROW = 15, 7
#: Speckle (px, detection copy) removed before: greenish crowd pixels.
GRASS_OPEN = 5
#: Half width (OpenCV hue units, 2 degrees each) of the pitch's own green around the hue peak.
HUE_HALF_WINDOW = 7
#: ...required only of frames where at least this share of the pixels is green.
GREEN_FRAME_SHARE = 0.15
#: A white line is this many grey levels (0..255) brighter than the mean of the grass in a
#: :data:`BACKGROUND_BOX` px box around it (detection copy): mowing stripes and grain are not.
WHITE_CONTRAST = 14.0
BACKGROUND_BOX = 21
#: The box's mean is taken over its pitch-green pixels when at least this share of it is green
#: (:func:`grass_background`): the grass beside a line, not an ad board or a graphic over it.
BACKGROUND_GRASS_SHARE = 0.2
#: ...and at least GRAIN_SIGMAS times the frame's grain (:func:`grain`: the robust sigma of the
#: detection copy minus its GRAIN_BLUR-sigma blur, where lines are looked for): a grainy, noisy or
#: blocky frame raises the bar so its speckle is not taken for lines (a noise peak clears 4 sigmas with
#: odds under 1e-4); broadcast frames have a grain of 1-3 grey levels, under WHITE_CONTRAST / 4.
GRAIN_SIGMAS, GRAIN_BLUR = 4.0, 2.0
#: The grain's medians are taken over every GRAIN_STRIDE-th pixel (tens of thousands remain: the
#: robust sigma within a percent).
GRAIN_STRIDE = 7


#: Width (px) of the work copy. The first guess needs lines, not detail: 640 px keeps a 12 cm line at
#: 60 m from a 1280-px wide shot about one pixel wide, and the whole search within its time budget.
WORK_WIDTH = 640
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
class LinePoints:
    """White-line points of one frame, what the camera is fitted to: ``xy`` (N x 2 pixels of the ``size = (W, H)`` frame), ``angle``
    (N, line direction in radians, [0, pi))."""

    xy: np.ndarray
    angle: np.ndarray
    size: tuple[int, int]

    @cached_property
    def tree(self) -> cKDTree:
        """A k-d tree of :attr:`xy`, built once for every fit of this frame that measures support on it."""
        return cKDTree(self.xy)

    def thinned(self, count: int) -> "LinePoints":
        """At most ``count`` of the points, evenly spread over the list (a bounded fitting cost)."""
        if len(self.xy) <= count:
            return self
        keep = np.linspace(0, len(self.xy) - 1, count).round().astype(np.intp)
        return LinePoints(self.xy[keep], self.angle[keep], self.size)


def grass_pixels(frame: np.ndarray, shape: tuple[int, int]) -> np.ndarray | None:
    """uint8 mask (``shape``, the detection size) of the pixels of the pitch's own green (the frame
    area-resized; :func:`glradial.estimation.trust.pitch_green`, :data:`HUE_HALF_WINDOW`); ``None``
    for a gray frame or one not green enough to tell (under :data:`GREEN_FRAME_SHARE` pitch green)."""
    if frame.ndim != 3:
        return None
    small = cv2.resize(frame, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    band, own = pitch_green(small, 2 * HUE_HALF_WINDOW + 1)
    if float(np.count_nonzero(band)) / band.size < GREEN_FRAME_SHARE:
        return None
    return own.astype(np.uint8)  # this pitch's own green (stands and boards are other hues)


def pitch_region(frame: np.ndarray, shape: tuple[int, int], green: np.ndarray | None = None) -> np.ndarray:
    """uint8 mask (detection size) of the pitch: the largest connected region of pitch green
    (``green``, or :func:`grass_pixels` of ``frame``), closed over its lines and players
    (:data:`GRASS_CLOSE` px) and grown by :data:`GRASS_GROW` px so the lines at its edge count. All
    ones when the frame is not green enough to tell."""
    green = grass_pixels(frame, shape) if green is None else green
    if green is None:
        return np.ones(shape, np.uint8)
    green = cv2.morphologyEx(green, cv2.MORPH_OPEN, np.ones((GRASS_OPEN, GRASS_OPEN), np.uint8))
    closed = cv2.morphologyEx(green, cv2.MORPH_CLOSE, np.ones((GRASS_CLOSE, GRASS_CLOSE), np.uint8))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    if count < 2:
        return np.ones(shape, np.uint8)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    pitch = (labels == largest).astype(np.uint8)
    return cv2.dilate(pitch, np.ones((GRASS_GROW, GRASS_GROW), np.uint8))


def grass_background(gray: np.ndarray, green: np.ndarray | None) -> np.ndarray:
    """The grey level (float32, ``gray``'s shape) a line is measured against: the mean of the
    :data:`BACKGROUND_BOX` px box around each pixel over its pitch-green pixels (``green``, uint8)
    where that is darker than the whole box's mean, so a line at the foot of a bright ad board or
    beside a white graphic is measured against the grass beside it, not the board (and a line in a
    shadow, whose grass is not the sunlit pitch green, as before: against the whole box); the plain
    box mean where under :data:`BACKGROUND_GRASS_SHARE` of the box is green (or no ``green``)."""
    plain = cv2.blur(gray, (BACKGROUND_BOX, BACKGROUND_BOX))
    if green is None:
        return plain
    weight = green.astype(np.float32)
    share = cv2.blur(weight, (BACKGROUND_BOX, BACKGROUND_BOX))
    on_grass = cv2.blur(gray * weight, (BACKGROUND_BOX, BACKGROUND_BOX)) / np.maximum(share, 1e-6)
    return np.where(share >= BACKGROUND_GRASS_SHARE, np.minimum(on_grass, plain), plain)


def line_points(frame: np.ndarray) -> LinePoints:
    """The white-line points (:class:`LinePoints`) of a uint8 frame: sub-pixel ridge centres on the
    pitch region of a copy at most :data:`DETECT_WIDTH` px wide, in pixels of the frame itself (module
    docstring)."""
    if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim not in (2, 3):
        raise TypeError(f"frame must be a uint8 H×W or H×W×3 array, got {type(frame).__name__} "
                        f"{getattr(frame, 'dtype', '')} {getattr(frame, 'shape', '')}")
    height_full, width_full = frame.shape[:2]
    gray = gray_copy(frame if frame.ndim == 2 else frame[..., :3], DETECT_WIDTH)
    height, width = gray.shape
    x0, y0, x1, y1 = content_box(gray)
    green = grass_pixels(frame[..., :3] if frame.ndim == 3 else frame, (height, width))
    grass = pitch_region(frame, (height, width), green)
    valid = np.zeros((height, width), np.uint8)
    m = BORDER_MARGIN
    valid[y0 + m: y1 - m, x0 + m: x1 - m] = 1
    where = valid & grass
    x, y, angle = bright_ridges(gray, where)
    background = grass_background(gray, green)
    r, c = np.clip(np.rint(y).astype(np.intp), 0, height - 1), np.clip(np.rint(x).astype(np.intp), 0, width - 1)
    white = gray[r, c] - background[r, c] > max(WHITE_CONTRAST, GRAIN_SIGMAS * grain(gray, where))
    x, y, angle = x[white], y[white], angle[white]
    s = width_full / width
    xy = np.stack([(x + 0.5) * s - 0.5, (y + 0.5) * s - 0.5], axis=1)
    return LinePoints(xy, angle, (width_full, height_full))


def grain(gray: np.ndarray, where: np.ndarray) -> float:
    """The grain (grey levels) of the float32 ``gray`` over the uint8 mask ``where``: 1.4826 times the
    median absolute deviation of ``gray`` minus its :data:`GRAIN_BLUR`-sigma Gaussian blur (every
    :data:`GRAIN_STRIDE`-th pixel; noise,
    film grain and compression; lines are too few and stripes or shade too smooth to move it); 0
    where fewer than 100 pixels are given."""
    idx = np.flatnonzero(where)[::GRAIN_STRIDE]  # the sampled pixels only: the residual of no other is read
    residual = gray.ravel()[idx] - cv2.GaussianBlur(gray, (0, 0), GRAIN_BLUR).ravel()[idx]
    if len(residual) < 100:
        return 0.0
    return 1.4826 * float(np.median(np.abs(residual - np.median(residual))))


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
    """Line evidence of one frame for the first guess: ``mask`` (uint8 0/1, work copy), ``field`` (uint8 0/1, where lines
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
    grass = pitch_green(cv2.blur(small_rgb, (GRASS_BLUR, GRASS_BLUR)), 2 * HUE_HALF_WINDOW + 1)[1].astype(np.float32)
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
