"""Test clips with a known lens on every frame: shots of a virtual broadcast camera that pans, tilts
and zooms about its centre over a real still (a rotation homography of the picture) or over an
equirectangular panorama (a moving perspective crop), seen through a radial lens that may follow
the zoom, cut together. For tests, the shot evaluation (``scripts/make_clips.py``,
docs/eval/shots.md) and benches; real pictures are validation only.

Rendering is independent of glradial's correctors: every output pixel (distorted) is mapped by the
exact inverse of the lens (:func:`glradial.lens.lensfuncs.undistort_point_exact`) to the pinhole image,
then to a ray of the camera, rotated, and looked up in the source (``cv2.remap``, bilinear).

Conventions: a still is treated as a pinhole picture whose horizontal field of view is
``hfov_deg``, seen through its own radial lens ``source_lens`` (width-normalised ``(k1, k2)`` about
the picture's centre; default none): a real camera's frame with a calibrated lens (e.g. the
checkerboard lens of ``../shared/data/real_wide_camera``) is then used as the pinhole picture it
shows, its own lens removed exactly (:func:`glradial.lens.lensfuncs.distort_point` maps the pinhole
point to the picture's pixel), so the clip's truth is its whole lens; the virtual camera's field of view is that divided by ``zoom`` (times a margin
chosen so that the frame never leaves the picture). Angles in degrees; pan to the right and tilt
up are positive (:func:`glradial.synthesis.crops.camera_rotation`). The lens is width-normalised ``(k1, k2)`` (DESIGN.md).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..lens.lens import focal_from_hfov, hfov_deg, pixels_to_lens
from ..lens.lensfuncs import distort_point, fold_radius, undistort_point_exact
from ..lens.metrics import manifold_k2
from ..synthesis.crops import camera_rotation, ray_to_lonlat

__all__ = ["ShotSpec", "ClipTruth", "render_shot", "render_clip", "write_clip", "read_truth"]


@dataclass(frozen=True)
class ShotSpec:
    """One shot: ``frames`` long over ``source`` (uint8 RGB still or equirectangular panorama,
    ``panorama=True``), the camera moving linearly from ``start`` to ``end`` ``(pan_deg, tilt_deg,
    zoom)``, the lens ``k1`` going from ``k1[0]`` to ``k1[1]`` linearly in log zoom, ``k2`` the manifold
    value plus ``k2_offset``; or, ``cropped``, one lens (``k1[0]``, its ``k2``) cropped by the zoom:
    ``(k1 / s^2, k2 / s^4)`` at ``s`` = zoom / start zoom (a fixed lens and a digital zoom; ``k1[1]``
    unused). For a still, ``hfov_deg`` is the picture's assumed field of view (it
    only matters for pans and tilts: a zoom about the centre is a scale), ``source_lens`` its own
    lens (width-normalised ``(k1, k2)``, removed exactly while rendering) and ``source_centre`` that
    lens's centre, the camera's principal point (widths from the picture's centre, y down); for a
    panorama, the camera's field of view at zoom 1."""

    source: np.ndarray
    frames: int
    start: tuple[float, float, float] = (0.0, 0.0, 1.0)
    end: tuple[float, float, float] = (0.0, 0.0, 1.0)
    k1: tuple[float, float] = (-0.2, -0.2)
    k2_offset: float = 0.0
    hfov_deg: float = 60.0
    panorama: bool = False
    source_lens: tuple[float, float] = (0.0, 0.0)
    source_centre: tuple[float, float] = (0.0, 0.0)
    cropped: bool = False

    def camera(self, i: int) -> tuple[float, float, float]:
        """``(pan_deg, tilt_deg, zoom)`` of frame ``i`` (zoom interpolated geometrically)."""
        t = i / max(self.frames - 1, 1)
        pan, tilt = (a + (b - a) * t for a, b in zip(self.start[:2], self.end[:2]))
        zoom = self.start[2] * (self.end[2] / self.start[2]) ** t
        return pan, tilt, zoom

    def lens(self, i: int) -> tuple[float, float]:
        """The lens of frame ``i``: k1 linear in log zoom between the shot's ends (``cropped``: the
        first lens scaled by the zoom, see the class docstring)."""
        if self.cropped:
            s2 = (self.camera(i)[2] / self.start[2]) ** 2
            return self.k1[0] / s2, (float(manifold_k2(self.k1[0])) + self.k2_offset) / (s2 * s2)
        lo, hi = math.log(self.start[2]), math.log(self.end[2])
        t = (math.log(self.camera(i)[2]) - lo) / (hi - lo) if hi != lo else i / max(self.frames - 1, 1)
        k1 = self.k1[0] + (self.k1[1] - self.k1[0]) * t
        return k1, float(manifold_k2(k1)) + self.k2_offset


@dataclass
class ClipTruth:
    """Per-frame ground truth of a clip: ``shot`` ids, ``lens`` (N x 2), ``zoom`` (N)."""

    shot: np.ndarray
    lens: np.ndarray
    zoom: np.ndarray

    def rows(self) -> list[dict]:
        return [{"frame": i, "shot": int(s), "k1": float(k[0]), "k2": float(k[1]), "zoom": float(z)}
                for i, (s, k, z) in enumerate(zip(self.shot, self.lens, self.zoom))]


def _rays(size: tuple[int, int], lens: tuple[float, float], hfov: float, rotation: np.ndarray) -> np.ndarray:
    """World rays (H x W x 3) of the distorted output pixels of a camera with ``rotation``."""
    width, height = size
    x, y = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    p_d = pixels_to_lens(np.stack([x, y], axis=-1).reshape(-1, 2), size)
    p_u, _ = undistort_point_exact(p_d, *lens)
    focal = focal_from_hfov(hfov)  # lens units (width = 1)
    rays = np.concatenate([p_u, np.full((len(p_u), 1), focal)], axis=1) @ rotation.T
    return rays.reshape(height, width, 3)


def _source_pixels(spec: ShotSpec, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h, w = spec.source.shape[:2]
    if spec.panorama:
        lon, lat = ray_to_lonlat(rays)
        return ((lon / (2 * math.pi) + 0.5) * w - 0.5) % w, (0.5 - lat / math.pi) * h - 0.5
    focal = focal_from_hfov(spec.hfov_deg) * w
    z = np.maximum(rays[..., 2], 1e-9)
    x, y = rays[..., 0] / z * focal, rays[..., 1] / z * focal  # px from the picture's centre, pinhole
    if any(spec.source_lens) or any(spec.source_centre):  # the picture's own lens about its principal point
        pinhole = np.stack([x, y], axis=-1) / w
        fold = fold_radius(*spec.source_lens)
        if np.max(np.hypot(pinhole[..., 0], pinhole[..., 1])) >= fold:
            raise ValueError(f"source_lens {spec.source_lens!r} folds over at radius {fold:.3f} (widths) inside the "
                             "view: the picture cannot show it; zoom in or tilt towards its centre")
        p_d = (distort_point(pinhole, *spec.source_lens) + np.asarray(spec.source_centre)) * w
        x, y = p_d[..., 0], p_d[..., 1]
    return x + w / 2 - 0.5, y + h / 2 - 0.5


def _margin(spec: ShotSpec, size: tuple[int, int]) -> float:
    """Extra zoom that keeps every frame of a shot over a still inside the picture."""
    if spec.panorama:
        return 1.0
    h, w = spec.source.shape[:2]
    margin = 1.0
    small = (64, max(2, round(64 * size[1] / size[0])))
    for _ in range(4):
        worst = 1.0
        for i in (0, spec.frames // 2, spec.frames - 1):
            pan, tilt, zoom = spec.camera(i)
            hfov = hfov_deg(focal_from_hfov(spec.hfov_deg) * zoom * margin)
            x, y = _source_pixels(spec, _rays(small, spec.lens(i), hfov, camera_rotation(pan, tilt, 0.0)))
            worst = max(worst, float(np.max(np.abs(x - (w - 1) / 2)) / ((w - 1) / 2 - 1)),
                        float(np.max(np.abs(y - (h - 1) / 2)) / ((h - 1) / 2 - 1)))
        if worst <= 1.0:
            break
        margin *= worst * 1.01
    return margin


def render_shot(spec: ShotSpec, size: tuple[int, int]):
    """Yield ``(frame, (k1, k2), zoom)`` for every frame of the shot (uint8 RGB ``size`` = (W, H))."""
    if spec.frames < 1:
        raise ValueError(f"a shot needs at least one frame, got frames={spec.frames}")
    for name in ("source_lens", "source_centre"):
        value = getattr(spec, name)
        if len(value) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in value):
            raise ValueError(f"{name} must be two finite numbers, got {value!r}")
    margin = _margin(spec, size)
    for i in range(spec.frames):
        pan, tilt, zoom = spec.camera(i)
        hfov = hfov_deg(focal_from_hfov(spec.hfov_deg) * zoom * margin)
        lens = spec.lens(i)
        x, y = _source_pixels(spec, _rays(size, lens, hfov, camera_rotation(pan, tilt, 0.0)))
        border = cv2.BORDER_WRAP if spec.panorama else cv2.BORDER_REPLICATE
        frame = cv2.remap(spec.source, x.astype(np.float32), y.astype(np.float32), cv2.INTER_LINEAR, borderMode=border)
        yield frame, lens, zoom * margin


def render_clip(shots: list[ShotSpec], size: tuple[int, int]):
    """All frames of ``shots`` cut together: ``(frames (N x H x W x 3 uint8), ClipTruth)``."""
    frames, shot_ids, lenses, zooms = [], [], [], []
    for s, spec in enumerate(shots):
        for frame, lens, zoom in render_shot(spec, size):
            frames.append(frame)
            shot_ids.append(s)
            lenses.append(lens)
            zooms.append(zoom)
    return np.stack(frames), ClipTruth(np.asarray(shot_ids), np.asarray(lenses, np.float64), np.asarray(zooms))


def write_clip(path: str | os.PathLike, frames: np.ndarray, truth: ClipTruth, fps: float = 25.0, crf: float = 18) -> Path:
    """Write a rendered clip (H.264 at ``crf``, or FFV1 for ``.mkv``: lossless) and its ground truth
    beside it (``PATH.truth.csv``: frame, shot, k1, k2, zoom). Returns the truth file's path."""
    from ..media.atomic import atomic_write_text
    from ..media.video_io import EncodeOptions, VideoInfo, VideoWriter

    path = Path(path)
    size = (frames.shape[2], frames.shape[1])
    lossless = path.suffix.lower() == ".mkv"
    info = VideoInfo.of(size, fps, **(dict(codec="ffv1", pix_fmt="gbrp") if lossless else dict(codec="libx264")))
    options = EncodeOptions() if lossless else EncodeOptions(crf=crf)
    with VideoWriter(path, info, options=options, overwrite=True) as writer:
        for frame in frames:
            writer.write(frame)
    lines = ["frame,shot,k1,k2,zoom"] + [f"{r['frame']},{r['shot']},{r['k1']:.8g},{r['k2']:.8g},{r['zoom']:.6g}" for r in truth.rows()]
    return atomic_write_text(Path(f"{path}.truth.csv"), "\n".join(lines) + "\n")


def read_truth(path: str | os.PathLike) -> ClipTruth:
    """The ground truth written by :func:`write_clip` (``PATH.truth.csv``)."""
    rows = np.genfromtxt(path, delimiter=",", names=True, ndmin=1)
    return ClipTruth(rows["shot"].astype(np.int64), np.stack([rows["k1"], rows["k2"]], 1), rows["zoom"])
