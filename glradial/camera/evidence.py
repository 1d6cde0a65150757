"""The white-line evidence a camera is fitted to: sub-pixel centres of bright thin lines on the grass.

Convention:
    Input: a uint8 RGB ``H x W x 3`` frame (or gray ``H x W``). Detection runs on a copy at most
    :data:`DETECT_WIDTH` pixels wide (:func:`glradial.estimation.lines.gray_copy`), with the ridge
    detector of the line evidence (:func:`glradial.estimation.lines.bright_ridges`). Points are
    returned in pixels of the **distorted frame at its own resolution** (centres at integers), with
    their line direction (radians in [0, pi)). Letterboxes and a border margin are masked, and where
    the frame has pitch green, points off the pitch region (the largest green area: stands, boards, sky)
    are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..estimation.lines import BORDER_MARGIN, bright_ridges, content_box, gray_copy
from ..estimation.trust import pitch_green

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
#: A white line is this many grey levels (0..255) brighter than the mean of a :data:`BACKGROUND_BOX` px
#: box around it (detection copy): mowing stripes and grain are not.
WHITE_CONTRAST = 14.0
BACKGROUND_BOX = 21


@dataclass(frozen=True)
class WhiteLines:
    """White-line points of one frame: ``xy`` (N x 2 pixels of the ``size = (W, H)`` frame), ``angle``
    (N, line direction in radians, [0, pi)), ``green`` (share of pitch-green pixels)."""

    xy: np.ndarray
    angle: np.ndarray
    size: tuple[int, int]
    green: float

    def thinned(self, count: int) -> "WhiteLines":
        """At most ``count`` of the points, evenly spread over the list (a bounded fitting cost)."""
        if len(self.xy) <= count:
            return self
        keep = np.linspace(0, len(self.xy) - 1, count).round().astype(np.intp)
        return WhiteLines(self.xy[keep], self.angle[keep], self.size, self.green)


def _grass_mask(frame: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, float]:
    """uint8 mask (detection size) of the pitch: the largest connected region of pitch green, closed
    over its lines and players (:data:`GRASS_CLOSE` px) and grown by :data:`GRASS_GROW` px so the
    lines at its edge count; and the green share of the frame. All ones when the frame is not green
    enough to tell."""
    if frame.ndim != 3:
        return np.ones(shape, np.uint8), 0.0
    small = cv2.resize(frame, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    band, own = pitch_green(small, 2 * HUE_HALF_WINDOW + 1)
    share = float(np.count_nonzero(band)) / band.size
    if share < GREEN_FRAME_SHARE:
        return np.ones(shape, np.uint8), share
    green = own.astype(np.uint8)  # this pitch's own green (stands and boards are other hues)
    green = cv2.morphologyEx(green, cv2.MORPH_OPEN, np.ones((GRASS_OPEN, GRASS_OPEN), np.uint8))
    closed = cv2.morphologyEx(green, cv2.MORPH_CLOSE, np.ones((GRASS_CLOSE, GRASS_CLOSE), np.uint8))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    if count < 2:
        return np.ones(shape, np.uint8), share
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    pitch = (labels == largest).astype(np.uint8)
    return cv2.dilate(pitch, np.ones((GRASS_GROW, GRASS_GROW), np.uint8)), share


def white_lines(frame: np.ndarray) -> WhiteLines:
    """The white-line points of a uint8 frame (see the module docstring)."""
    if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim not in (2, 3):
        raise TypeError(f"frame must be a uint8 H×W or H×W×3 array, got {type(frame).__name__} "
                        f"{getattr(frame, 'dtype', '')} {getattr(frame, 'shape', '')}")
    height_full, width_full = frame.shape[:2]
    gray = gray_copy(frame if frame.ndim == 2 else frame[..., :3], DETECT_WIDTH)
    height, width = gray.shape
    x0, y0, x1, y1 = content_box(gray)
    grass, share = _grass_mask(frame[..., :3] if frame.ndim == 3 else frame, (height, width))
    valid = np.zeros((height, width), np.uint8)
    m = BORDER_MARGIN
    valid[y0 + m: y1 - m, x0 + m: x1 - m] = 1
    x, y, angle = bright_ridges(gray, valid & grass)
    background = cv2.blur(gray, (BACKGROUND_BOX, BACKGROUND_BOX))
    r, c = np.clip(np.rint(y).astype(np.intp), 0, height - 1), np.clip(np.rint(x).astype(np.intp), 0, width - 1)
    white = gray[r, c] - background[r, c] > WHITE_CONTRAST
    x, y, angle = x[white], y[white], angle[white]
    s = width_full / width
    xy = np.stack([(x + 0.5) * s - 0.5, (y + 0.5) * s - 0.5], axis=1)
    return WhiteLines(xy, angle, (width_full, height_full), share)
