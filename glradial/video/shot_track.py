"""Pass 1 of ``correct --auto`` and ``estimate VIDEO``: one lens per shot, read while decoding.

Every frame is decoded once and reduced to a 64 px thumbnail for the cut detector
(:class:`glradial.video.smoothing.ShotDetector`). A cheap subsample of each shot -- its first frame, then
every ``every``-th (the stride doubles each :data:`SAMPLES_PER_STRIDE` samples, so a long shot
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

import os
from fractions import Fraction
from typing import Callable

import numpy as np

from ..lens.lens import Lens, corner_radius
from ..media.frames import to_rgb8
from ..media.progress import Progress
from ..media.video_io import VideoReader
from .lens_track import DOUBTFUL_PX, LensTrack
from .shot_evidence import ShotCollector
from .shot_fit import ShotLens, fit_shot
from .smoothing import ShotDetector

__all__ = ["track_shots", "SAMPLES_PER_STRIDE", "EVERY", "ESTIMATE_EVERY"]

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
) -> LensTrack:
    """Pass 1 (module docstring): the :class:`LensTrack` of the video at ``path``. ``estimator``
    maps a uint8 RGB frame to a lens; ``every`` (frames) is the sampling stride, ``estimate_every``
    (samples) how often the estimator runs; ``doubtful_px`` (px at 1920) the bound above which a
    shot is doubtful; ``apply_doubtful`` applies doubtful shots' lenses anyway; ``rate`` the frame
    rate of an image-sequence input (default 25)."""
    from .video_pipeline import ESTIMATE_WIDTH, Pipelined

    for name, value in (("every", every), ("estimate_every", estimate_every)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if not doubtful_px > 0:
        raise ValueError(f"doubtful_px must be > 0 (px at 1920), got {doubtful_px!r}")
    detector = detector or ShotDetector()
    stamps: list[float] = []
    with VideoReader(path, order="rgb", max_width=DETECT_WIDTH, keep_decoded=True, rate=rate) as reader:
        info = reader.info
        shots = _Shots(estimator, estimate_every, doubtful_px, corner_radius(info.size))
        since = 0
        with Progress(info.frame_count, "estimate", enabled=progress) as bar, Pipelined(reader.items()) as frames:
            for item in frames:
                stamps.append(float(item.pts * info.time_base) if item.pts is not None else item.index / info.fps)
                if detector.update(item.image):
                    shots.open(item.index)
                    since = 0
                stride = every * 2 ** (len(shots.collector.evidence.samples) // SAMPLES_PER_STRIDE)
                if since % stride == 0:
                    shots.collector.add(item.index, to_rgb8(reader.convert(item.decoded, ESTIMATE_WIDTH)))
                    since = 0
                since += 1
                bar.update()
        shots.close()
    return _track(info, np.asarray(stamps), shots, apply_doubtful, doubtful_px)


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
