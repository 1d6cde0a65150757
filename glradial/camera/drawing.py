"""Pictures of a fitted camera: the projected template drawn on the (distorted) frame, and the frame
warped onto the pitch plane (a top view)."""

from __future__ import annotations

import cv2
import numpy as np

from ..pitch.template import PitchTemplate
from .model import Camera

#: Overlay colour (RGB) and width (px of a 1280-wide frame).
OVERLAY_RGB = (255, 40, 200)
OVERLAY_WIDTH = 2.0


def overlay(frame: np.ndarray, camera: Camera, pitch: PitchTemplate | None = None) -> np.ndarray:
    """A copy of the uint8 RGB ``frame`` with ``pitch``'s markings (every 0.25 m, lens included)
    drawn where ``camera`` projects them; the keypoints as small circles."""
    out = np.ascontiguousarray(frame[..., :3]).copy()
    height, width = out.shape[:2]
    cam = camera.with_size((width, height))
    thick = max(1, int(round(OVERLAY_WIDTH * width / 1280)))
    pitch = pitch or PitchTemplate()
    for _, line in pitch.polylines(0.25):
        xy = cam.project(line)
        ok = np.isfinite(xy).all(1) & (np.abs(xy[:, 0] - width / 2) < 2 * width) & (np.abs(xy[:, 1] - height / 2) < 2 * height)
        for run in np.split(np.arange(len(xy)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1):
            if ok[run[0]] and len(run) >= 2:
                cv2.polylines(out, [np.round(xy[run] * 16).astype(np.int32)], False, OVERLAY_RGB, thick, cv2.LINE_AA, 4)
    for q in cam.project(pitch.keypoints()):
        if np.isfinite(q).all() and 0 <= q[0] < width and 0 <= q[1] < height:
            cv2.circle(out, (int(round(q[0])), int(round(q[1]))), 3 * thick, OVERLAY_RGB, thick, cv2.LINE_AA)
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


