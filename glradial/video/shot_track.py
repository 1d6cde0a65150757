"""Pass 1 of ``correct --auto`` and ``estimate VIDEO``: one lens per shot, read while decoding.

The decoder hands over a subsample: where the packets' timestamps number the frames
(:func:`glradial.media.video_io.frame_timestamps`: H.264, HEVC, MPEG-1/2/4 in a container with
timestamps, progressive), it skips the frames no other frame refers to
(:meth:`~glradial.media.video_io.VideoReader.skip_nonreference`: about half of an x264 stream, which
it then never decodes) and each decoded frame is numbered by its timestamp; anything else is decoded
whole (``sparse=False`` forces that). Each decoded frame is reduced to a 64 px thumbnail for the cut
detector (:class:`glradial.video.smoothing.ShotDetector`). A cut seen between two decoded frames
``a`` and ``b`` with skipped frames between them is placed exactly afterwards
(:func:`place_cuts`): the stretch ``a .. b`` alone is decoded again (from the key frame before
``a``) and the cut goes before the frame that differs most from its predecessor -- the same test on
the same thumbnails. A cheap subsample of each shot -- its first decoded frame, then one every
``every`` frames (the stride doubles each :data:`SAMPLES_PER_STRIDE` samples, so a long shot
costs no more than a log factor) -- is converted at most
:data:`glradial.video.video_pipeline.ESTIMATE_WIDTH` px wide and handed to a
:class:`~glradial.video.shot_evidence.ShotCollector` (line chains, frame-to-frame matches, the per-frame
estimate on every ``estimate_every``-th sample). When a cut (or the end) closes the shot, its
evidence is fitted jointly (:func:`glradial.video.shot_fit.fit_shot`) and dropped: memory holds one
shot's evidence, never its frames. Every frame then gets its shot's lens at its zoom (the log zoom
of the samples, interpolated linearly between them).

Doubt policy: a doubtful shot (:class:`~glradial.video.shot_fit.ShotLens` ``doubtful``/``reason``) is
marked in the track and, unless ``apply_doubtful``, not applied (its frames pass through
uncorrected); a lens that folds over inside the frame (``fold_over``) is never applied.
"""

from __future__ import annotations

import copy
import os
from fractions import Fraction
from typing import Callable

import numpy as np

from ..lens.lens import Lens, corner_radius
from ..media.frames import to_rgb8
from ..media.progress import Progress
from ..media.video_io import VideoReader, frame_timestamps
from .lens_track import DOUBTFUL_PX, LensTrack
from .shot_evidence import ShotCollector
from .shot_fit import ShotLens, fit_shot
from .smoothing import ShotDetector

__all__ = ["track_shots", "place_cuts", "SAMPLES_PER_STRIDE", "EVERY", "ESTIMATE_EVERY"]

#: default stride of the sampled frames (frames): 0.4 s at 25 fps
EVERY = 10
#: the per-frame estimator runs on every this-many-th sample (its answer is the fit's weak prior
#: and the fallback of a shot without geometry)
ESTIMATE_EVERY = 3
#: a shot's sampling stride doubles after each this many samples
SAMPLES_PER_STRIDE = 32
#: frames of the decoded stream converted for the cut detector (px wide)
DETECT_WIDTH = 64


class _Shots:
    """The shots closed so far: their first frame, lens, and the frames and zooms sampled."""

    def __init__(self, estimator: Callable, estimate_every: int, doubtful_px: float, radius: float) -> None:
        self.estimator, self.estimate_every = estimator, estimate_every
        self.doubtful_px, self.radius = doubtful_px, radius
        self.starts: list[int] = []
        self.fits: list[ShotLens] = []
        self.sampled: list[tuple[np.ndarray, np.ndarray]] = []
        self.estimates: list[tuple[int, Lens]] = []
        self.collector: ShotCollector | None = None

    def open(self, index: int) -> None:
        self.close()
        self.starts.append(index)
        self.collector = ShotCollector(self.estimator, self.estimate_every)

    def close(self) -> None:
        if self.collector is None:
            return
        evidence = self.collector.evidence
        self.fits.append(fit_shot(evidence, doubtful_px=self.doubtful_px, radius=self.radius))
        self.sampled.append((np.array([s.frame for s in evidence.samples]), np.asarray(evidence.zoom, np.float64)))
        self.estimates.extend(self.collector.estimates)
        self.collector = None


def track_shots(
    path: str | os.PathLike,
    estimator: Callable[[np.ndarray], Lens],
    *,
    every: int = EVERY,
    estimate_every: int = ESTIMATE_EVERY,
    detector: ShotDetector | None = None,
    progress: bool | None = None,
    doubtful_px: float = DOUBTFUL_PX,
    apply_doubtful: bool = False,
    rate: Fraction | None = None,
    sparse: bool = True,
) -> LensTrack:
    """Pass 1 (module docstring): the :class:`LensTrack` of the video at ``path``. ``estimator``
    maps a uint8 RGB frame to a lens; ``every`` (frames) is the sampling stride, ``estimate_every``
    (samples) how often the estimator runs; ``doubtful_px`` (px at 1920) the bound above which a
    shot is doubtful; ``apply_doubtful`` applies doubtful shots' lenses anyway; ``rate`` the frame
    rate of an image-sequence input (default 25); ``sparse=False`` decodes every frame even where
    the stream allows the sparse decode."""
    for name, value in (("every", every), ("estimate_every", estimate_every)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if not doubtful_px > 0:
        raise ValueError(f"doubtful_px must be > 0 (px at 1920), got {doubtful_px!r}")
    if not isinstance(sparse, (bool, np.bool_)):
        raise TypeError(f"sparse must be a bool, got {sparse!r}")
    detector = detector or ShotDetector()
    fresh = copy.deepcopy(detector)
    with VideoReader(path, order="rgb", max_width=DETECT_WIDTH, keep_decoded=True, rate=rate) as reader:
        info = reader.info
        order = frame_timestamps(path) if sparse and info.fields == "progressive" else None
        shots = _Shots(estimator, estimate_every, doubtful_px, corner_radius(info.size))
        try:
            stamps, windows = _scan(reader, order, detector, shots, every, progress)
        except _Unnumbered:  # the decoder's timestamps do not match the packets': decode every frame
            return track_shots(path, estimator, every=every, estimate_every=estimate_every, detector=fresh,
                               progress=progress, doubtful_px=doubtful_px, apply_doubtful=apply_doubtful, rate=rate,
                               sparse=False)
    if windows:
        placed = place_cuts(path, order, windows, fresh, rate=rate)
        shots.starts = [placed.get(start, start) for start in shots.starts]
    return _track(info, stamps, shots, apply_doubtful, doubtful_px)


class _Unnumbered(Exception):
    """A decoded frame's timestamp is not one of the packets' (pass 1 then decodes every frame)."""


def _scan(reader: VideoReader, order: np.ndarray | None, detector: ShotDetector, shots: _Shots, every: int,
          progress: bool | None) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Decode (every frame, or with ``order`` the frames other frames refer to, numbered by
    ``order``), detect cuts, sample each shot; returns the frames' times (s) and the windows
    ``(a, b)`` of the cuts seen between two decoded frames ``a`` and ``b > a + 1``."""
    from .video_pipeline import ESTIMATE_WIDTH, Pipelined

    info = reader.info
    if order is not None:
        reader.skip_nonreference()
    stamps: list[float] = []
    windows: list[tuple[int, int]] = []
    previous = sampled = -1
    total = len(order) if order is not None else info.frame_count
    with Progress(total, "estimate", enabled=progress) as bar, Pipelined(reader.items()) as frames:
        for item in frames:
            index = item.index if order is None else _number(order, item.pts)
            if order is None:
                stamps.append(float(item.pts * info.time_base) if item.pts is not None else item.index / info.fps)
            if detector.update(item.image, index - previous if previous >= 0 else 1):
                shots.open(index)
                sampled = -1
                if previous >= 0 and index > previous + 1:
                    windows.append((previous, index))
            stride = every * 2 ** (len(shots.collector.evidence.samples) // SAMPLES_PER_STRIDE)
            if sampled < 0 or index - sampled >= stride:
                shots.collector.add(index, to_rgb8(reader.convert(item.decoded, ESTIMATE_WIDTH)))
                sampled = index
            bar.update(index - previous)
            previous = index
    shots.close()
    if shots.starts:
        shots.starts[0] = 0  # frames shown before the first decoded one (skipped leading B-frames) open the video
    if order is not None:
        stamps = [float(pts * info.time_base) for pts in order]
    return np.asarray(stamps, np.float64), windows


def _number(order: np.ndarray, pts: int | None) -> int:
    """The frame number of a decoded frame's ``pts`` among all frames' timestamps ``order``."""
    index = int(np.searchsorted(order, pts)) if pts is not None else len(order)
    if index >= len(order) or order[index] != pts:
        raise _Unnumbered(pts)
    return index


def place_cuts(path: str | os.PathLike, order: np.ndarray, windows: list[tuple[int, int]], detector: ShotDetector,
               *, rate: Fraction | None = None) -> dict[int, int]:
    """The first frame of each shot whose cut pass 1 saw between decoded frames ``a`` and ``b``
    (``windows``; frames numbered by their timestamps ``order``): every frame of ``a .. b`` is
    decoded (from the key frame before ``a``) and the cut placed before the frame that differs most
    from its predecessor (``detector``'s score, on the thumbnails pass 1 uses). Returns ``{b:
    first frame}``; a window whose frames cannot all be read keeps ``b``."""
    placed: dict[int, int] = {}
    with VideoReader(path, order="rgb", max_width=DETECT_WIDTH, rate=rate) as reader:
        for a, b in windows:
            reader.seek(int(order[a]))
            thumbs: dict[int, np.ndarray] = {}
            for item in reader.items():
                if item.pts is None or item.pts > order[b]:
                    break
                if item.pts >= order[a]:
                    thumbs[int(np.searchsorted(order, item.pts))] = item.image
            scores = {j: detector.pair_score(thumbs[j - 1], thumbs[j]) for j in range(a + 1, b + 1)
                      if j - 1 in thumbs and j in thumbs}
            placed[b] = max(scores, key=scores.get) if len(scores) == b - a else b
    return placed


def _track(info, stamps: np.ndarray, shots: _Shots, apply_doubtful: bool, doubtful_px: float) -> LensTrack:
    """The per-frame lens track of the closed shots."""
    n = len(stamps)
    bounds = shots.starts[1:] + [n]
    shot = np.zeros(n, np.int64)
    lens = np.empty((n, 2))
    sure = np.empty(n)
    doubtful = np.zeros(n, bool)
    reason = [""] * n
    for s, (first, end, fit, (frames, zooms)) in enumerate(zip(shots.starts, bounds, shots.fits, shots.sampled)):
        here = np.arange(first, end)
        shot[here] = s
        lens[here] = fit.lens_at(np.interp(here, frames, zooms))
        sure[here] = fit.uncertainty_px
        doubtful[here] = fit.doubtful
        reason[first:end] = [fit.reason] * len(here)
    raw = np.full((n, 2), np.nan)
    raw_sure = np.full(n, np.nan)
    weight = np.full(n, np.nan)
    method = [""] * n
    for index, estimate in shots.estimates:
        raw[index] = (estimate.k1, estimate.k2)
        raw_sure[index] = float(getattr(estimate, "uncertainty_px", np.nan))
        method[index] = str(getattr(estimate, "method", "") or "")
        weight[index] = 1.0
    applied = ~doubtful | (bool(apply_doubtful) & np.array([r != "fold_over" for r in reason], bool))
    return LensTrack(info.rate, info.size, shot, lens, raw, weight, time_s=stamps, uncertainty_px=sure,
                     raw_uncertainty_px=raw_sure, method=method, doubtful_px=doubtful_px, doubtful=doubtful,
                     reason=reason, applied=applied)
