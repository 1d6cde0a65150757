"""Automatic lens correction of videos: estimate per frame, detect cuts, smooth per shot, correct.

Pipeline (two passes over the file, so memory does not grow with its length):

1. :func:`track_video` decodes every frame once, feeds each to a :class:`~glradial.smoothing.ShotDetector`
   and runs the estimator on the first frame of every shot and then every ``every``-th frame of
   the shot. The per-shot robust smoother (:func:`~glradial.smoothing.smooth_track`) turns those
   samples into a lens for every frame. A smoothed lens that would fold over on the frame is
   replaced by the nearest accepted raw estimate of the same shot.
2. :func:`correct_video` decodes the file again and corrects each frame with its lens.

The result is also a :class:`LensTrack`, written as a sidecar (:meth:`LensTrack.save`): CSV
(``frame, time_s, shot, k1, k2, k1_raw, k2_raw, weight``; raw columns empty on frames that were not
estimated, ``weight`` = robustness weight of the raw estimate, 0 = rejected as an outlier) or JSON
(the same columns as lists), chosen by the extension.

Convention: frames are ``H x W x 3`` uint8 RGB when they reach the estimator; the lens is
width-normalised ``(k1, k2)`` (DESIGN.md); ``time_s = frame / fps``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .atomic import atomic_write_text
from .lens import Lens, corner_radius
from .progress import Progress
from .smoothing import ShotDetector, smooth_track
from .media_io import VideoReader, VideoWriter

__all__ = ["LensTrack", "track_video", "correct_video", "default_estimator"]

#: estimator: RGB uint8 frame -> (k1, k2)
EstimatorFn = Callable[[np.ndarray], "tuple[float, float] | Lens"]


@dataclass
class LensTrack:
    """Per-frame lenses of one video and how they were obtained (arrays indexed by frame)."""

    fps: float
    size: tuple[int, int]
    shot: np.ndarray  # (n,) int shot id
    lens: np.ndarray  # (n, 2) smoothed (k1, k2) used for the correction
    raw: np.ndarray  # (n, 2) raw estimate, NaN where the frame was not estimated
    weight: np.ndarray  # (n,) robustness weight of the raw estimate, NaN where not estimated

    @property
    def n_frames(self) -> int:
        return len(self.shot)

    def rows(self) -> list[dict]:
        out = []
        for i in range(self.n_frames):
            estimated = not math.isnan(self.raw[i, 0])
            out.append(
                {
                    "frame": i,
                    "time_s": round(i / self.fps, 6),
                    "shot": int(self.shot[i]),
                    "k1": float(self.lens[i, 0]),
                    "k2": float(self.lens[i, 1]),
                    "k1_raw": float(self.raw[i, 0]) if estimated else None,
                    "k2_raw": float(self.raw[i, 1]) if estimated else None,
                    "weight": float(self.weight[i]) if estimated else None,
                }
            )
        return out

    def per_shot(self) -> list[dict]:
        """One row per shot: first/last frame and the median smoothed lens of the shot."""
        shots = []
        for shot in np.unique(self.shot):
            frames = np.flatnonzero(self.shot == shot)
            k = np.median(self.lens[frames], axis=0)
            shots.append(
                {"shot": int(shot), "first_frame": int(frames[0]), "last_frame": int(frames[-1]), "k1": float(k[0]), "k2": float(k[1])}
            )
        return shots

    def save(self, path: str | os.PathLike) -> Path:
        """Write the sidecar atomically: ``.json`` -> JSON, anything else -> CSV."""
        path = Path(path)
        rows = self.rows()
        if path.suffix.lower() == ".json":
            document = {
                "fps": self.fps,
                "size": list(self.size),
                "convention": "width-normalised k1, k2 (image width = 1, centre origin); p_d = p_u (1 + k1 r^2 + k2 r^4)",
                "shots": self.per_shot(),
                "frames": rows,
            }
            return atomic_write_text(path, json.dumps(document, indent=1) + "\n")
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=list(rows[0].keys()) if rows else ["frame"], lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: ("" if value is None else (f"{value:.8g}" if isinstance(value, float) else value)) for key, value in row.items()})
        return atomic_write_text(path, buffer.getvalue())

    @classmethod
    def load_csv(cls, path: str | os.PathLike, fps: float, size: tuple[int, int]) -> "LensTrack":
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))

        def col(name: str) -> np.ndarray:
            return np.array([float(r[name]) if r[name] != "" else np.nan for r in rows])

        return cls(fps, size, col("shot").astype(int), np.stack([col("k1"), col("k2")], 1),
                   np.stack([col("k1_raw"), col("k2_raw")], 1), col("weight"))


def default_estimator(model: str | os.PathLike | None = None) -> EstimatorFn:
    """The bundled CNN (:class:`glradial.Estimator`), as a frame -> lens function."""
    from .estimator import Estimator

    estimator = Estimator(model) if model is not None else Estimator()
    return lambda frame: estimator.estimate(frame)


def _as_pair(value: object) -> tuple[float, float]:
    if isinstance(value, Lens):
        return value.k1, value.k2
    k1, k2 = value  # type: ignore[misc]
    return float(k1), float(k2)


def track_video(
    path: str | os.PathLike,
    estimator: EstimatorFn,
    *,
    every: int = 5,
    window_s: float = 2.0,
    detector: ShotDetector | None = None,
    progress: bool | None = None,
) -> LensTrack:
    """Pass 1: estimate, detect cuts and smooth; see the module docstring.

    ``every`` (frames) is the estimation stride inside a shot; ``window_s`` (seconds) is the
    smoother's half window (longer = steadier, slower to follow a zoom).
    """
    if every < 1:
        raise ValueError(f"every must be >= 1 frame, got {every}")
    if not window_s > 0:
        raise ValueError(f"window must be > 0 seconds, got {window_s}")
    detector = detector or ShotDetector()
    shots: list[int] = []
    times: list[int] = []
    estimates: list[tuple[float, float]] = []
    with VideoReader(path, order="rgb") as reader:
        info = reader.info
        shot, since_start = -1, 0
        with Progress(info.frame_count, "estimate", enabled=progress) as bar:
            for index, frame in enumerate(reader):
                if detector.update(frame):
                    shot, since_start = shot + 1, 0
                if since_start % every == 0:
                    times.append(index)
                    estimates.append(_as_pair(estimator(frame)))
                shots.append(shot)
                since_start += 1
                bar.update()
    n = len(shots)
    shot_array = np.asarray(shots, dtype=np.int64)
    samples = np.asarray(estimates, dtype=np.float64).reshape(-1, 2)
    time_array = np.asarray(times, dtype=np.int64)
    radius = corner_radius(info.size)
    smoothed, weights = smooth_track(time_array, samples, shot_array, half_window=window_s * info.fps, radius=radius)
    # a smoothed lens must not fold over on the frame: fall back to the nearest accepted raw estimate
    for i in range(n):
        lens = Lens(*smoothed[i])
        if lens.fold_radius() <= radius:
            mine = np.flatnonzero((shot_array[time_array] == shot_array[i]) & (weights > 0))
            mine = mine if len(mine) else np.flatnonzero(shot_array[time_array] == shot_array[i])
            smoothed[i] = samples[mine[np.argmin(np.abs(time_array[mine] - i))]]
    raw = np.full((n, 2), np.nan)
    raw[time_array] = samples
    weight = np.full(n, np.nan)
    weight[time_array] = weights
    return LensTrack(info.fps, info.size, shot_array, smoothed, raw, weight)


def correct_video(
    source: str | os.PathLike,
    target: str | os.PathLike,
    lenses: Callable[[int], Lens | tuple[float, float]],
    *,
    fit: str = "same",
    interpolation: str = "linear",
    backend: str = "auto",
    progress: bool | None = None,
    label: str = "correct",
) -> int:
    """Pass 2: correct every frame of ``source`` with ``lenses(frame_index)`` (a :class:`Lens` or
    ``(k1, k2)``) into ``target`` (atomic; fps and size kept). Returns the number of frames written."""
    from .remap import correct

    with VideoReader(source, order="bgr") as reader:
        info = reader.info
        with VideoWriter(target, info.size, info.fps, order="bgr") as writer:
            with Progress(info.frame_count, label, enabled=progress) as bar:
                for index, frame in enumerate(reader):
                    lens = lenses(index)
                    lens = lens if isinstance(lens, Lens) else Lens(*lens)
                    writer.write(correct(frame, lens, fit=fit, interpolation=interpolation, backend=backend))
                    bar.update()
            if 0 < info.frame_count != writer.frames_written:
                sys.stderr.write(
                    f"glradial: warning: {source} reports {info.frame_count} frames in its header; "
                    f"{writer.frames_written} could be decoded and were written\n"
                )
            return writer.frames_written


def estimate_video(
    path: str | os.PathLike,
    *,
    model: str | os.PathLike | None = None,
    every: int = 5,
    window_s: float = 2.0,
    progress: bool | None = None,
) -> LensTrack:
    """Per-frame and per-shot lens of a video with the bundled CNN (or ``model``): the first pass
    of ``glradial correct --auto`` (:func:`track_video`) without the correction. Hook for
    ``glradial estimate VIDEO``."""
    estimate = default_estimator(model)
    return track_video(path, lambda frame: estimate(rgb8_for_estimator(frame)), every=every, window_s=window_s, progress=progress)


def track_report(track: LensTrack, source: str, *, per_frame: bool = False, as_json: bool = False) -> str:
    """Text for ``glradial estimate VIDEO``: one line per shot (or per frame with ``per_frame``),
    or one JSON document (``{"input", "fps", "size", "shots": [...], "frames": [...]}``)."""
    if as_json:
        document = {"input": source, "fps": track.fps, "size": list(track.size), "shots": track.per_shot()}
        if per_frame:
            document["frames"] = track.rows()
        return json.dumps(document)
    lines = []
    if per_frame:
        for row in track.rows():
            lines.append(f"{source}: frame {row['frame']} shot {row['shot']} k1={row['k1']:.6f} k2={row['k2']:.6f}")
    else:
        for shot in track.per_shot():
            lines.append(
                f"{source}: shot {shot['shot']} frames {shot['first_frame']}-{shot['last_frame']} "
                f"k1={shot['k1']:.6f} k2={shot['k2']:.6f}"
            )
    return "\n".join(lines)


def rgb8_for_estimator(frame: np.ndarray) -> np.ndarray:
    """RGB uint8 H×W×3 for the estimator: 16-bit/float scaled, alpha dropped, grey expanded."""
    frame = np.asarray(frame)
    if frame.dtype == np.uint16:
        frame = (frame / 257.0 + 0.5).astype(np.uint8)
    elif frame.dtype in (np.float32, np.float64):
        frame = (np.clip(frame, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    if frame.ndim == 2:
        frame = np.repeat(frame[:, :, None], 3, axis=2)
    return np.ascontiguousarray(frame[:, :, :3])
