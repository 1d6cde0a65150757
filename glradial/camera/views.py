"""Procedural pitch views with an exact camera: the template's markings drawn through a known camera
and lens onto textured grass (mowing stripes, grain, players as occluding blobs, a stand band above the
far touchline), for tests, the conformal calibration of the bound and ``bench/camera_procedural.py``.

The markings are drawn in an **undistorted** frame (anti-aliased polylines through the camera's
homography, line width in metres projected) and the lens is then applied with the exact inverse maps
(:meth:`glradial.Lens.maps`, ``direction="distort"``, ``fit="crop"``). ``fit="crop"`` samples the
undistorted lens point ``p_u`` at ``p_u / s`` (``s``: :meth:`glradial.Lens.fit_scale`), so the
undistorted frame is drawn with focal length ``focal / s``: every output pixel then has a source and
the distorted frame is exactly ``camera``'s view, up to resampling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..lens.lens import Lens
from ..pitch.template import PitchTemplate
from .model import Camera

#: Supersampling of the drawn markings (cv2 polylines with 4 bits of sub-pixel shift).
SHIFT = 4


@dataclass(frozen=True)
class View:
    """A rendered frame (uint8 RGB) and the camera that saw it."""

    frame: np.ndarray
    camera: Camera


def _grass(rng: np.random.Generator, camera: Camera) -> np.ndarray:
    """Grass of the undistorted frame: mowing stripes 5 m wide along x on the pitch plane, grain."""
    width, height = camera.size
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    hinv = np.linalg.inv(camera.homography)
    p = np.stack([xs, ys, np.ones_like(xs)], -1) @ hinv.T
    with np.errstate(divide="ignore", invalid="ignore"):
        gx, gy = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
    below = (p[..., 2] > 0) & (np.abs(gx) < 62) & (np.abs(gy) < 42)  # grass to 9.5 / 8 m beyond the lines
    stripe = np.where(below, (np.floor(np.nan_to_num(gx) / 5.5) % 2) * 2 - 1, 0.0)
    base = np.array(rng.uniform([25, 85, 25], [60, 140, 55]))
    img = base[None, None] * (1.0 + rng.uniform(0.04, 0.12) * stripe[..., None])
    img += rng.normal(0.0, rng.uniform(2, 6), img.shape)
    img[~below] = rng.uniform(40, 120, 3)  # beyond the grass: the stands
    return img


def _markings(img: np.ndarray, camera: Camera, pitch: PitchTemplate, line_m: float, brightness: float) -> None:
    for _, line in pitch.polylines(0.25):
        uv, z = camera.undistorted_lens_points(line)
        front = z > 0.5
        if front.sum() < 2:
            continue
        xy = (uv[front] * camera.size[0] + np.array(camera.size) / 2.0 - 0.5)
        inside = np.all(np.abs(xy - np.array(camera.size) / 2) < 3 * np.array(camera.size), axis=1)
        if inside.sum() < 2:
            continue
        xy, depth = xy[inside], z[front][inside]
        thick = max(1, int(round(camera.focal * camera.size[0] * line_m / float(np.median(depth)))))
        colour = tuple(float(brightness) for _ in range(3))
        cv2.polylines(img, [np.round(xy * (1 << SHIFT)).astype(np.int32)], False, colour, thick, cv2.LINE_AA, SHIFT)


def render_view(camera: Camera, seed: int = 0, pitch: PitchTemplate | None = None, players: int = 12) -> View:
    """The pitch seen by ``camera`` (its size, lens and pose), textured with ``seed``."""
    rng = np.random.default_rng(seed)
    pitch = pitch or PitchTemplate()
    width, height = camera.size
    distorted = bool(camera.lens.k1 or camera.lens.k2)
    s = camera.lens.fit_scale((width, height), "crop", "distort") if distorted else 1.0
    canvas = Camera(camera.rotation, camera.position, camera.focal / s, camera.size)
    img = _grass(rng, canvas)
    _markings(img, canvas, pitch, line_m=rng.uniform(0.10, 0.14), brightness=rng.uniform(200, 250))
    for _ in range(players):  # upright blobs standing on random pitch points: occlusions, clutter
        foot = canvas.project(rng.uniform([-50, -32], [50, 32])[None])[0]
        if not np.all(np.isfinite(foot)):
            continue
        size = camera.focal * width * 1.8 / max(1.0, float(np.linalg.norm(camera.position)))
        colour = tuple(float(c) for c in rng.uniform(0, 255, 3))
        cv2.ellipse(img, (int(foot[0]), int(foot[1] - size / 2)), (max(1, int(size / 5)), max(1, int(size / 2))),
                    0, 0, 360, colour, -1)
    img = np.clip(img, 0, 255).astype(np.uint8)
    if distorted:
        mx, my = camera.lens.maps((width, height), direction="distort", fit="crop")
        img = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return View(img, camera)


def random_camera(rng: np.random.Generator, size: tuple[int, int] = (1280, 720), lens: bool = True) -> Camera:
    """A main-camera view: on the near side (15-60 m behind the touchline, 10-32 m up, within 15 m of
    the halfway line), aimed at a random point of the pitch, horizontal field of view 16-64 degrees
    (log-uniform in the focal length), roll within 1 degree, and a lens on the Lopez-Antequera
    manifold (k1 in [-0.35, 0.05])."""
    position = np.array([rng.uniform(-15, 15), -34.0 - rng.uniform(15, 60), rng.uniform(10, 32)])
    target = np.array([rng.uniform(-50, 50), rng.uniform(-28, 28), 0.0])
    hfov = math.degrees(2 * math.atan(math.exp(rng.uniform(math.log(math.tan(math.radians(8))),
                                                              math.log(math.tan(math.radians(32)))))))
    k1 = rng.uniform(-0.35, 0.05) if lens else 0.0
    k2 = 0.019 * k1 + 0.805 * k1 * k1
    return Camera.look_at(position, target, hfov, size, Lens(k1, k2), roll=rng.uniform(-1, 1))
