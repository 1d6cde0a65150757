"""Pictures of the pitch through a camera.

Procedural pitch views with an exact camera: the template's markings drawn through a known camera
and lens onto textured grass (mowing stripes, grain, players as occluding blobs, a stand band above the
far touchline), for tests, the conformal calibration of the bound and ``bench/camera_procedural.py``.

The markings are drawn in an **undistorted** frame (anti-aliased polylines through the camera's
homography, line width in metres projected) and the lens is then applied with the exact inverse maps
(:meth:`glradial.Lens.maps`, ``direction="distort"``, ``fit="crop"``). ``fit="crop"`` samples the
undistorted lens point ``p_u`` at ``p_u / s`` (``s``: :meth:`glradial.Lens.fit_scale`), so the
undistorted frame is drawn with focal length ``focal / s``: every output pixel then has a source and
the distorted frame is exactly ``camera``'s view, up to resampling.

Pictures of a fitted camera on a real frame: the projected template drawn on the (distorted) frame
(:func:`overlay`), and the frame warped onto the pitch plane (:func:`top_view`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..lens.lens import Lens, focal_from_hfov, hfov_deg
from ..lens.metrics import manifold_k2
from ..pitch.template import PitchTemplate
from .model import Camera

#: Overlay colour (RGB) and width (px of a 1280-wide frame).
OVERLAY_RGB = (255, 40, 200)
OVERLAY_WIDTH = 2.0
#: The colour of a doubtful camera's overlay (RGB): the markings dashed, under a DOUBTFUL banner.
DOUBT_RGB = (255, 160, 0)


def overlay(frame: np.ndarray, camera: Camera, pitch: PitchTemplate | None = None, doubt: str = "") -> np.ndarray:
    """A copy of the uint8 RGB ``frame`` with ``pitch``'s markings (every 0.25 m, lens included)
    drawn where ``camera`` projects them; the keypoints as small circles. ``doubt``: why the camera is
    doubtful (:attr:`glradial.CameraEstimate.why`); given, the markings are drawn dashed in
    :data:`DOUBT_RGB` under a banner ``DOUBTFUL: <doubt>``, so a picture never passes for a sure one."""
    out = np.ascontiguousarray(frame[..., :3]).copy()
    height, width = out.shape[:2]
    cam = camera.with_size((width, height))
    thick = max(1, int(round(OVERLAY_WIDTH * width / 1280)))
    colour = DOUBT_RGB if doubt else OVERLAY_RGB
    pitch = pitch or PitchTemplate()
    for _, line in pitch.polylines(0.25):
        xy = cam.project(line)
        ok = np.isfinite(xy).all(1) & (np.abs(xy[:, 0] - width / 2) < 2 * width) & (np.abs(xy[:, 1] - height / 2) < 2 * height)
        if doubt:  # dashed: every other metre
            ok &= (np.arange(len(xy)) // 4) % 2 == 0
        for run in np.split(np.arange(len(xy)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1):
            if ok[run[0]] and len(run) >= 2:
                cv2.polylines(out, [np.round(xy[run] * 16).astype(np.int32)], False, colour, thick, cv2.LINE_AA, 4)
    for q in cam.project(pitch.keypoints()):
        if np.isfinite(q).all() and 0 <= q[0] < width and 0 <= q[1] < height:
            cv2.circle(out, (int(round(q[0])), int(round(q[1]))), 3 * thick, colour, thick, cv2.LINE_AA)
    if doubt:
        scale = 0.6 * width / 1280
        cv2.rectangle(out, (0, 0), (width, int(36 * scale) + 8), (0, 0, 0), -1)
        cv2.putText(out, f"DOUBTFUL: {doubt}", (8, int(26 * scale) + 4), cv2.FONT_HERSHEY_SIMPLEX, scale, DOUBT_RGB,
                    max(1, thick // 2), cv2.LINE_AA)
    return out


def top_view(frame: np.ndarray, camera: Camera, pitch: PitchTemplate | None = None,
             px_per_m: float = 8.0, margin_m: float = 5.0) -> np.ndarray:
    """The frame warped onto the pitch plane: a north-up image (x right, far touchline at the top)
    of the pitch plus ``margin_m``, ``px_per_m`` pixels per metre; black where the frame does not
    see. Pixel ``(i, j)`` shows pitch point ``(x0 + i / s, y1 - j / s)``."""
    pitch = pitch or PitchTemplate()
    height, width = frame.shape[:2]
    cam = camera.with_size((width, height))
    hl, hw = pitch.half_length + margin_m, pitch.half_width + margin_m
    cols, rows = int(round(2 * hl * px_per_m)), int(round(2 * hw * px_per_m))
    gx, gy = np.meshgrid(-hl + (np.arange(cols) + 0.5) / px_per_m, hw - (np.arange(rows) + 0.5) / px_per_m)
    xy = cam.project(np.column_stack([gx.ravel(), gy.ravel()]))
    xy = np.where(np.isfinite(xy), xy, -1e4).astype(np.float32)
    mx, my = xy[:, 0].reshape(rows, cols), xy[:, 1].reshape(rows, cols)
    return cv2.remap(np.ascontiguousarray(frame[..., :3]), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

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
    return Camera.look_at(position, target, hfov, size, Lens(k1, float(manifold_k2(k1))), roll=rng.uniform(-1, 1))


#: Horizontal fields of view (degrees) of :func:`zoom_cameras`' lens at its wide and tele ends.
ZOOM_LENS_HFOV = (56.0, 20.0)


def zoom_cameras(rng: np.random.Generator, frames: int, size: tuple[int, int] = (1280, 720),
                 zoom: float = 2.0) -> list[Camera]:
    """``frames`` cameras of one main-camera zoom shot with a lens that follows the zoom: a fixed
    position (as :func:`random_camera`), the aim drifting between two pitch points, the horizontal
    field of view narrowing from 40-56 degrees by ``zoom`` times in focal length (geometric steps), and
    the lens's ``k1`` going from barrel at the wide end (-0.30..-0.15 at :data:`ZOOM_LENS_HFOV` [0])
    toward pincushion at the tele end (-0.02..0.06 at ``ZOOM_LENS_HFOV[1]``) linearly in the field of
    view (degrees), ``k2`` on the Lopez-Antequera manifold."""
    position = np.array([rng.uniform(-10, 10), -34.0 - rng.uniform(20, 45), rng.uniform(12, 28)])
    centre = np.array([(-1.0, 0.0, 1.0)[rng.integers(3)] * rng.uniform(30, 40), rng.uniform(-6, 6)])
    start, end = centre + rng.uniform(-8, 8, 2), centre + rng.uniform(-8, 8, 2)
    hfov_wide = rng.uniform(40, 56)
    focal = np.geomspace(focal_from_hfov(hfov_wide), zoom * focal_from_hfov(hfov_wide), frames)
    hfov = hfov_deg(focal)
    k1_wide, k1_tele = rng.uniform(-0.30, -0.15), rng.uniform(-0.02, 0.06)
    out = []
    for i, h in enumerate(hfov):
        t = i / max(frames - 1, 1)
        k1 = k1_tele + (k1_wide - k1_tele) * (h - ZOOM_LENS_HFOV[1]) / (ZOOM_LENS_HFOV[0] - ZOOM_LENS_HFOV[1])
        out.append(Camera.look_at(position, (1 - t) * start + t * end, float(h), size,
                                  Lens(float(k1), float(manifold_k2(k1)))))
    return out
