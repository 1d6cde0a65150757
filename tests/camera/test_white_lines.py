"""The white-line detector (glradial.camera.white_lines) against analytic answers: straight lines of
known position, width and contrast drawn on mottled, grainy grass, with and without mowing stripes;
nothing on grass without lines, on stripes alone, on a blank frame or on noise."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from glradial.camera.white_lines import WHITE_CONTRAST, grain, grass_background, line_points, white_lines

SIZE = (1280, 720)
GRASS = np.array([60.0, 120.0, 45.0])  # RGB
#: Three lines (px of the 1280 x 720 frame): a far touchline, a steep box side, a slanted goal line.
LINES = [((100.0, 150.0), (1180.0, 170.0)), ((300.0, 200.0), (420.0, 680.0)), ((700.0, 250.0), (1150.0, 600.0))]


def _frame(contrast: float, width: float, stripes: float = 0.0, noise: float = 3.0, lines=LINES, seed: int = 0) -> np.ndarray:
    """uint8 RGB grass (mottled: blurred noise of about 4 grey levels over 15 px, as a letterbox
    never is; mowing stripes of +-``stripes`` grey levels, 80 px wide, sharp edges) with ``lines`` of
    ``contrast`` grey levels and ``width`` px drawn anti-aliased, plus Gaussian grain of ``noise``."""
    height, width_px = SIZE[1], SIZE[0]
    x = np.arange(width_px)
    rng = np.random.default_rng(seed)
    mottle = cv2.GaussianBlur(rng.normal(0.0, 1.0, (height, width_px)), (0, 0), 15.0)
    img = GRASS + (4.0 / mottle.std()) * mottle[..., None]
    img += stripes * np.sign(np.sin(np.pi * (x + 0.5) / 80.0))[None, :, None]
    paint = np.zeros((height, width_px), np.uint8)
    for a, b in lines:
        cv2.line(paint, (round(a[0] * 16), round(a[1] * 16)), (round(b[0] * 16), round(b[1] * 16)), 255,
                 max(1, round(width)), cv2.LINE_AA, shift=4)
    img += contrast * (paint / 255.0)[..., None]
    img += rng.normal(0.0, noise, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _distance(points: np.ndarray, line) -> np.ndarray:
    (x0, y0), (x1, y1) = line
    d = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
    return np.abs((points - (x0, y0)) @ np.array([-d[1], d[0]]))


def _coverage(points: np.ndarray, line, near: float) -> float:
    """Share of ``line``'s length (1-px bins, 20 px kept off each end) with a point within ``near`` px."""
    (x0, y0), (x1, y1) = line
    length = np.hypot(x1 - x0, y1 - y0)
    d = np.array([x1 - x0, y1 - y0]) / length
    on = points[_distance(points, line) <= near]
    along = (on - (x0, y0)) @ d
    bins = np.unique(np.floor(along[(along >= 20) & (along < length - 20)]))
    return len(bins) / (length - 40)


@pytest.mark.parametrize("contrast, width, stripes", [(60, 3, 0), (20, 2, 0), (25, 3, 0), (20, 2, 8), (40, 4, 8)])
def test_line_points_lie_on_the_drawn_lines(contrast, width, stripes):
    found = line_points(_frame(contrast, width, stripes))
    assert found.size == SIZE
    d = np.min([_distance(found.xy, line) for line in LINES], axis=0)
    ends = np.min([np.linalg.norm(found.xy - end, axis=1) for line in LINES for end in line], axis=0)
    # sub-pixel ridge centres of a symmetric profile: on the line within 1 px of the frame (the
    # 960-px detection copy's pixel is 1.33 frame px), none off the lines (grain, stripe edges); the
    # ridge turns round a line's end, so its last 4 px (width and smoothing) are left out
    on = d[ends > 4.0] <= 1.0
    assert on.mean() >= 0.98, np.percentile(d, [50, 99])
    for line in LINES:
        assert _coverage(found.xy, line, 1.0) >= 0.6, (line, contrast, width, stripes)


def test_lines_under_the_contrast_threshold_are_not_white_lines():
    # painted lines WHITE_CONTRAST grey levels over the grass around them or more; fainter marks
    # (a worn line, a shadow's edge, grain) are not taken
    found = line_points(_frame(0.6 * WHITE_CONTRAST, 3))
    assert max(_coverage(found.xy, line, 1.0) for line in LINES) <= 0.05


@pytest.mark.parametrize("kind", ["grass", "stripes", "blank", "noise"])
def test_nothing_is_found_without_lines(kind):
    if kind == "blank":
        frame = np.zeros((*SIZE[::-1], 3), np.uint8)
    elif kind == "noise":
        frame = np.random.default_rng(1).integers(0, 256, (*SIZE[::-1], 3), dtype=np.uint8)
    else:
        frame = _frame(0, 1, stripes=8.0 if kind == "stripes" else 0.0, noise=4.0, lines=[])
    # mowing stripes' edges are brighter than one side only: no line
    assert len(line_points(frame).xy) <= 20
    assert white_lines(frame).lines == []


@pytest.mark.parametrize("stripes", [0.0, 8.0])
def test_white_lines_finds_each_drawn_line(stripes):
    found = white_lines(_frame(30, 3, stripes))
    s = found.scale
    for (x0, y0), (x1, y1) in LINES:
        # the work copy's line equation: both ends within 1 work px (2 frame px) of the drawn line
        a, b = np.array([(x0 + 0.5) / s - 0.5, (y0 + 0.5) / s - 0.5]), np.array([(x1 + 0.5) / s - 0.5, (y1 + 0.5) / s - 0.5])
        assert any(abs(ln.abc[:2] @ a + ln.abc[2]) <= 1.0 and abs(ln.abc[:2] @ b + ln.abc[2]) <= 1.0 for ln in found.lines)


def test_grain_is_the_sigma_of_white_noise():
    # gray = 0.299 R + 0.587 G + 0.114 B of independent N(0, 10) channels: sigma 6.68 grey levels;
    # white noise minus its 2-px blur keeps 0.98 of it (1 - 2 w0 + sum w², w0 = 1 / (4 pi 2²))
    frame = _frame(0, 1, noise=10.0, lines=[])
    gray = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY).astype(np.float32)
    expected = 10.0 * np.sqrt(0.299**2 + 0.587**2 + 0.114**2) * np.sqrt(1 - 1 / (8 * np.pi))
    assert grain(gray, np.ones(gray.shape, np.uint8)) == pytest.approx(expected, rel=0.05)
    assert grain(gray, np.zeros(gray.shape, np.uint8)) == 0.0


def test_grain_raises_the_bar():
    # grain of 12 grey levels: its speckle clears the fixed WHITE_CONTRAST, not GRAIN_SIGMAS times
    # the frame's grain; the 60-level lines clear both
    found = line_points(_frame(60, 4, noise=12.0))
    d = np.min([_distance(found.xy, line) for line in LINES], axis=0)
    assert np.mean(d <= 1.5) >= 0.9
    assert np.mean([_coverage(found.xy, line, 1.5) for line in LINES]) >= 0.5


def test_a_line_at_the_foot_of_a_bright_board_is_measured_against_the_grass():
    # a far touchline 6-22 px below a bright ad board (grey 230, not green): the box around the line
    # reaches into the board, whose rows raise its mean by about as much as the line's 20 grey levels
    # stand out (the whole box's mean found 41 % of it); the mean of the grass in the box does not rise
    line = ((60.0, 206.0), (1220.0, 222.0))
    frame = _frame(20, 3, lines=[line])
    board = 230 + np.random.default_rng(2).normal(0.0, 12.0, (200, 1280, 1))  # textured: not a letterbox
    frame[:200] = np.clip(np.round(board), 0, 255).astype(np.uint8)
    assert _coverage(line_points(frame).xy, line, 1.5) >= 0.6
    gray = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY).astype(np.float32)
    green = np.repeat((np.arange(720) >= 200)[:, None], 1280, axis=1).astype(np.uint8)
    x = np.arange(100, 1200)
    on_line = grass_background(gray, green)[np.round(206 + 16 * (x - 60) / 1160).astype(int), x]
    # the grass's level within 3 grey levels (mottle and grain), plus what the line itself (3 of the
    # box's 21 rows, 20 levels) adds over its green rows
    assert abs(float(np.median(on_line)) - float(np.median(gray[260:400]))) <= 3.0 + 20 * 3 / 11
