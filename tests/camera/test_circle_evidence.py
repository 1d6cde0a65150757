"""The centre circle's ellipse among the white-line mask's pixels (glradial.camera.circle_hypotheses)
against analytic answers: ellipses drawn with known centre and axes, flattened as a high, distant main
camera sees the circle, crossed by the halfway line and cut by players; arcs and lines of known
curvature."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from glradial.camera.circle_hypotheses import CURVE_MIN, curved, ellipses
from glradial.camera.white_lines import Line, straight_lines, thin_components

SHAPE = (360, 640)  # the 640-px work copy of a 16:9 frame


def _mask(centre, axes, cuts: int = 6) -> np.ndarray:
    """An ellipse (semi-axes ``axes``, px) drawn 2 px wide on a work-copy mask with the halfway line
    through its centre and a far touchline, cut by ``cuts`` player-sized gaps."""
    mask = np.zeros(SHAPE, np.uint8)
    (cx, cy), (a, b) = centre, axes
    cv2.ellipse(mask, ((cx, cy), (2 * a, 2 * b), 0.0), 1, 2)
    cv2.line(mask, (int(cx), 60), (int(cx), SHAPE[0] - 1), 1, 2)
    cv2.line(mask, (0, 70), (SHAPE[1] - 1, 68), 1, 2)
    for t in np.linspace(0, 2 * np.pi, cuts + 1)[:-1] + 0.4:
        x, y = int(cx + a * np.cos(t)), int(cy + b * np.sin(t))
        mask[y - 6: y + 6, x - 5: x + 5] = 0
    return thin_components(mask)


def _found(mask: np.ndarray):
    ys, xs = np.nonzero(mask)
    points = np.stack([xs, ys], axis=1).astype(np.float64)
    lines = straight_lines(mask * 255, points)
    return ellipses(points, lines, mask.shape), lines


@pytest.mark.parametrize("axes", [(160, 33), (150, 30), (200, 45), (100, 20), (120, 40)])
def test_a_flattened_circle_cut_into_lines_is_found(axes):
    # b / a of 0.2: a main camera some 12 degrees above the circle. Hough cuts its flat sides into
    # straight lines; those are pieces of a curve and go back to the ellipse search.
    mask = _mask((300.0, 170.0), axes)
    found, lines = _found(mask)
    assert len(lines) >= 4, "the flat sides come back as Hough lines: the case under test"
    assert found, "the ellipse must be found"
    (cx, cy), full, _ = found[0][1]
    # drawn 2 px wide on integer pixels: centre within 1 px, each full axis within 2 px
    assert np.hypot(cx - 300.0, cy - 170.0) <= 1.0
    assert np.abs(np.sort(full) - 2 * np.sort(axes)) == pytest.approx([0, 0], abs=2.0)


def test_no_ellipse_among_straight_lines_and_noise():
    rng = np.random.default_rng(3)
    mask = np.zeros(SHAPE, np.uint8)
    for _ in range(6):  # straight lines of every direction, and speckle
        (x0, x1), (y0, y1) = rng.integers(0, 640, 2).tolist(), rng.integers(0, 360, 2).tolist()
        cv2.line(mask, (x0, y0), (x1, y1), 1, 2)
    mask |= (rng.random(SHAPE) < 0.01).astype(np.uint8)
    mask = thin_components(mask)
    assert _found(mask)[0] == []


def _line_through(points: np.ndarray) -> Line:
    """The total-least-squares line of ``points`` (a :class:`Line` as ``straight_lines`` gives)."""
    centre = points.mean(axis=0)
    normal = np.linalg.eigh((points - centre).T @ (points - centre))[1][:, 0]
    abc = np.array([normal[0], normal[1], -normal @ centre])
    along = (points - centre) @ np.array([-abc[1], abc[0]])
    return Line(abc, centre + np.outer([along.min(), along.max()], [-abc[1], abc[0]]), float(np.ptp(along)))


@pytest.mark.parametrize("curvature, bends", [(0.0, False), (3e-5, False), (1e-3, True), (4e-3, True)])
def test_curvature_of_a_line_piece(curvature, bends):
    # 120 px of a parabola y = c x² (curvature c, 1/px), 2 px thick, rasterised to pixel centres: a
    # lens-bent touchline (c ~ 3e-5) is straight, a flattened circle's side (c >= 1e-3) bends
    x = np.arange(-60, 61, dtype=np.float64)
    pts = np.concatenate([np.stack([x, np.round(curvature * x**2 + dy)], axis=1) for dy in (0.0, 1.0)])
    assert curved(pts, _line_through(pts)) is bends
    assert (curvature >= CURVE_MIN) is bends
