"""A standard football pitch (105 x 68 m, IFAB markings) drawn through a pinhole camera with a known
pose, for tests of the line fit: the image is exactly a plane seen through a homography, so lines
of one direction meet in a vanishing point and circles are ellipses, as on a real pitch."""

from __future__ import annotations

import cv2
import numpy as np

import glradial
from glradial.pitch import PitchTemplate

PITCH = PitchTemplate()  # the one home of the markings' dimensions
LENGTH, WIDTH = PITCH.length, PITCH.width
GRASS, WHITE = (40, 110, 40), (235, 235, 235)


def _segment(a, b, n: int = 200) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return np.asarray(a, float) * (1 - t) + np.asarray(b, float) * t


def _arc(centre, radius: float, start: float, stop: float, n: int = 240) -> np.ndarray:
    t = np.radians(np.linspace(start, stop, n))
    return np.stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)], axis=1)


def markings(parts: tuple[str, ...] = ("lines", "circle", "arcs")) -> list[np.ndarray]:
    """Polylines (metres on the pitch plane, x along the length, y across, origin at a corner: the
    centred coordinates of :class:`glradial.pitch.PitchTemplate` shifted by half its size) of the chosen parts:
    ``"lines"`` (touchlines, goal lines, halfway line, both penalty areas and goal areas),
    ``"circle"`` (the centre circle), ``"arcs"`` (the penalty arcs outside the areas), or any of
    ``"touchline"``, ``"box_sides"`` for the single elements the degenerate tests need."""
    out: list[np.ndarray] = []
    cy = WIDTH / 2
    if "lines" in parts:
        out += [_segment((0, 0), (LENGTH, 0)), _segment((0, WIDTH), (LENGTH, WIDTH)),
                _segment((0, 0), (0, WIDTH)), _segment((LENGTH, 0), (LENGTH, WIDTH)),
                _segment((LENGTH / 2, 0), (LENGTH / 2, WIDTH))]
        for x0, s in ((0.0, 1.0), (LENGTH, -1.0)):
            for depth, half in ((PITCH.box_depth, PITCH.box_width / 2), (PITCH.goal_area_depth, PITCH.goal_area_width / 2)):
                out += [np.concatenate([_segment((x0, cy - half), (x0 + s * depth, cy - half)),
                                        _segment((x0 + s * depth, cy - half), (x0 + s * depth, cy + half)),
                                        _segment((x0 + s * depth, cy + half), (x0, cy + half))])]
    if "touchline" in parts:
        out.append(_segment((20.0, 0.0), (45.0, 0.0)))
    if "box_sides" in parts:
        half, depth = PITCH.box_width / 2, PITCH.box_depth
        out += [_segment((0, cy - half), (depth, cy - half)), _segment((0, cy + half), (depth, cy + half))]
    if "circle" in parts:
        out.append(_arc((LENGTH / 2, cy), PITCH.circle_radius, 0, 360, 480))
    if "arcs" in parts:
        half_angle, r, spot = PITCH.arc_half_angle(), PITCH.circle_radius, PITCH.penalty_spot  # the arc outside the area
        out.append(_arc((spot, cy), r, -half_angle, half_angle))
        out.append(_arc((LENGTH - spot, cy), r, 180 - half_angle, 180 + half_angle))
    return out


def homography(camera, target, hfov_deg: float, size: tuple[int, int]) -> np.ndarray:
    """3 x 3 map from the pitch plane (x, y, 1; metres, z up = 0) to pixels of a pinhole camera at
    ``camera`` (x, y, height) looking at ``target`` (x, y) on the pitch, horizontal field of view
    ``hfov_deg``, no roll, principal point at the frame centre."""
    width, height = size
    c = np.asarray(camera, float)
    forward = np.array([target[0], target[1], 0.0]) - c
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    rotation = np.stack([right, down, forward])  # world -> camera (x right, y down, z forward)
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
    k = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    t = -rotation @ c
    return k @ np.column_stack([rotation[:, 0], rotation[:, 1], t])


def render(h: np.ndarray, size: tuple[int, int], parts=("lines", "circle", "arcs"), thickness: int = 3) -> np.ndarray:
    """The pitch markings of ``parts`` drawn through homography ``h`` (anti-aliased, sub-pixel)."""
    width, height = size
    image = np.full((height, width, 3), GRASS, np.uint8)
    for line in markings(parts):
        p = np.column_stack([line, np.ones(len(line))]) @ h.T
        front = p[:, 2] > 1e-3
        if front.sum() < 2:
            continue
        xy = p[front, :2] / p[front, 2:3]
        inside = (np.abs(xy[:, 0] - width / 2) < 4 * width) & (np.abs(xy[:, 1] - height / 2) < 4 * height)
        xy = xy[inside]
        if len(xy) >= 2:
            cv2.polylines(image, [np.round(xy * 16).astype(np.int32)], False, WHITE, thickness, cv2.LINE_AA, shift=4)
    return image


def distorted(image: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """``image`` seen through the lens ``(k1, k2)``: exact inverse maps at ``fit='crop'`` (a full
    frame; the lens refers to it), applied with cv2.remap, independent of the GL path."""
    height, width = image.shape[:2]
    map_x, map_y = glradial.Lens(k1, k2).maps((width, height), direction="distort", fit="crop")
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


#: Views used by the tests: main camera at the halfway line looking at a penalty area (goal-area and
#: penalty-area corners in view), and a wider view of the centre.
BOX_VIEW = dict(camera=(40.0, -35.0, 18.0), target=(14.0, 30.0), hfov_deg=50.0)
CENTRE_VIEW = dict(camera=(52.5, -40.0, 20.0), target=(52.5, 30.0), hfov_deg=60.0)
