"""Pass 1 of ``correct --auto`` and ``estimate VIDEO``: one lens per shot, read while decoding.

The decoder hands over a subsample: where the packets' timestamps number the frames
(:func:`glradial.media.video_io.frame_timestamps`: H.264, HEVC, MPEG-1/2/4 in a container with
timestamps, progressive), it skips the frames no other frame refers to
(:meth:`~glradial.media.video_io.VideoReader.skip_nonreference`: about half of an x264 stream, which
it then never decodes) and each decoded frame is numbered by its timestamp; anything else is decoded
whole (``sparse=False`` forces that). Each decoded frame is reduced to a 64 px thumbnail for the cut
detector (:class:`glradial.video.cuts.ShotDetector`). On a sparse decode the detector only
proposes candidates (at :data:`CANDIDATE_RATIO` of its ratio: frames 1-3 apart differ more than
consecutive ones); :class:`CutCheck` then decodes every frame of the stretch before each candidate
(from the key frame before it: its cost is bounded by the stream's key-frame interval) and applies
the detector's own test frame by frame, so that the cuts found, and where they are placed, are
those of a decode of every frame. A cheap subsample of each shot -- its first decoded frame, then one every
``every`` frames (:func:`stride`: after :data:`FIRST_SAMPLES` samples the stride doubles each
:data:`SAMPLES_PER_STRIDE` samples, up to :data:`MAX_STRIDE` ``every``) -- is converted at most
:data:`ESTIMATE_WIDTH` px wide and handed to a
:class:`~glradial.video.shot_evidence.ShotCollector` (line chains, frame-to-frame matches, the per-frame
estimate on every ``estimate_every``-th sample). When a cut (or the end) closes the shot, its
evidence is fitted jointly (:func:`glradial.video.shot_fit.fit_shot`) and dropped: memory holds one
shot's evidence, never its frames. Every frame then gets its shot's lens at its zoom (the log zoom
of the samples, interpolated linearly between them).

Doubt policy: a doubtful shot (:class:`~glradial.video.shot_fit.FittedShotLens` ``doubtful``/``reason``) is
marked in the track and, unless ``apply_doubtful``, not applied (its frames pass through
uncorrected); a lens that folds over inside the frame (``fold_over``) is never applied.
"""

from __future__ import annotations

import copy
import os
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from fractions import Fraction
from typing import Callable

import numpy as np

from ..errors import check_count, check_flag
from ..lens import doubt
from ..lens.lens import Lens, corner_radius
from ..media.frames import to_rgb8
from ..media.progress import Progress
from ..media.video_io import VideoReader, frame_timestamps
from ..threads import thread_budget
from .cuts import ShotDetector
from .lens_track import DOUBTFUL_PX, LensTrack
from .pipelined import Pipelined
from .shot_evidence import ShotCollector
from .shot_fit import FittedShotLens, fit_shot, load_solver

__all__ = ["track_shots", "CutCheck", "stride", "FIRST_SAMPLES", "SAMPLES_PER_STRIDE", "MAX_STRIDE", "EVERY", "ESTIMATE_EVERY", "CANDIDATE_RATIO",
           "ESTIMATE_WIDTH"]

#: pass 1 converts the estimated frames at most this wide (px): the CNN looks at 384 px, the line
#: detector at <= 960 px, so a full-size conversion would be wasted
ESTIMATE_WIDTH = 960

#: default stride of the sampled frames (frames): 0.4 s at 25 fps
EVERY = 10
#: the per-frame estimator runs on every this-many-th sample (its answer is the fit's weak prior
#: and the fallback of a shot without geometry): a 2-s shot's samples 0 and 4, a 6-s shot's 0 and
#: 4 of 7 (with 3: 0, 3, 6, the last one's estimate then delaying the shot's fit); accuracy as with
#: 3 on the sets it was chosen on and on four of five held out (figure sweep_estimate_every)
ESTIMATE_EVERY = 4
#: a shot's first this many samples lie ``every`` frames apart (its first 2 s at 25 fps)
FIRST_SAMPLES = 5
#: after :data:`FIRST_SAMPLES`, a shot's sampling stride doubles after each this many samples, up
#: to :data:`MAX_STRIDE` ``every``: a 6-s shot is sampled 7 times (0, 10, ... 40, 60, 100), not 9
#: with 4 (pass 1's CPU 15 % less on scripts/make_clips.py's main set of 6-s shots, where it was
#: chosen; the same accuracy there and held out on --set check, static and 20-s shots; figure
#: sweep_stride_cap)
SAMPLES_PER_STRIDE = 1
#: the longest stride, in ``every``: a long shot is sampled every 320 frames (12.8 s at 25 fps) once
#: its stride reaches it (after about 40 s), so its zoom is still followed however long it lasts, at
#: a cost that grows with its length (a 45-min continuous camera: ~220 samples; with no cap, 16); not
#: reached on the validation sets' 20-s shots (figure sweep_estimate_every)
MAX_STRIDE = 32
#: frames of the decoded stream converted for the cut detector (px wide)
DETECT_WIDTH = 64
#: the sparse decode flags a candidate cut at this fraction of the detector's ratio (its frames lie
#: 1-3 apart, so a camera's own motion scores higher than from frame to frame: 1.3x on a panning
#: held-out clip, proc_5 of scripts/make_clips.py --set check), then :class:`CutCheck` decides
CANDIDATE_RATIO = 0.5
#: samples at most waiting for an estimate that runs ahead on a worker thread before their chains
#: and matches are found (:class:`_Shots`): the estimator of one sample overlaps the line detection
#: and matching of the ones before it; a sample is taken up as soon as the samples before it are
#: and its estimate (if due) is in, not held until this many more are sampled (when the stride
#: grows, that held a sample's evidence until the decode had gone 2 strides further)
LOOKAHEAD = 2


class _Shots:
    """The shots closed so far: their first frame, lens, and the frames and zooms sampled.

    With ``ahead``, pass 1's work runs on three worker threads beside the caller's (which decodes,
    detects cuts and finds each sample's line chains): the estimator (every call of it, so one
    thread uses it), started on a sample due for an estimate (:meth:`ShotCollector.due`) as soon
    as it is sampled and read once it is in (at most :data:`LOOKAHEAD` samples later); each
    sample's matches and zoom, found with the hint of the moment its chains were found; each closed
    shot's joint fit, while the next shot is scanned. Every step gets the inputs it gets in turn
    (the estimator and the fit are functions of their input), so the track is the same; only the
    estimator's calls may come in another order (a sample's own estimate, when it has few chains,
    after the next due one)."""

    def __init__(self, estimator: Callable, estimate_every: int, doubtful_px: float, radius: float,
                 ahead: bool = True) -> None:
        self.estimate_every = estimate_every
        self.doubtful_px, self.radius = doubtful_px, radius
        self._workers = tuple(ThreadPoolExecutor(1, thread_name_prefix=f"glradial-{job}")
                              for job in ("estimate", "fit", "motion")) if ahead else None
        if ahead:
            self._workers[1].submit(load_solver)  # while the first frames decode
        self._run = estimator
        self.estimator = estimator if not ahead else lambda frame: self._workers[0].submit(estimator, frame).result()
        self.starts: list[int] = []
        self.fits: list[Future | FittedShotLens] = []
        self.sampled: list[tuple[np.ndarray, np.ndarray]] = []
        self.estimates: list[tuple[int, Lens]] = []
        self.collector: ShotCollector | None = None
        self._pending: deque = deque()
        self._queued = 0

    def open(self, index: int) -> None:
        self.close()
        self.starts.append(index)
        self.collector = ShotCollector(self.estimator, self.estimate_every)
        self._queued = 0

    def add(self, index: int, frame: np.ndarray) -> None:
        """Sample frame ``index`` of the open shot (its evidence found now, or once its estimate is in)."""
        self._queued += 1
        if self._workers is None:
            self.collector.add(index, frame)
            return
        due = self.collector.due(self._queued - 1)
        self._pending.append((index, frame, self._workers[0].submit(self._run, frame) if due else None))
        while self._pending and (len(self._pending) > LOOKAHEAD or self._pending[0][2] is None or self._pending[0][2].done()):
            self._collect()

    def _collect(self) -> None:
        """Find the evidence of the first pending sample (its estimate read, waited for if it runs)."""
        index, frame, estimate = self._pending.popleft()
        self.collector.add(index, frame, None if estimate is None else estimate.result, motion=self._workers[2])

    def close(self) -> None:
        if self.collector is None:
            return
        while self._pending:
            self._collect()
        evidence = self.collector.finish()
        fit = dict(doubtful_px=self.doubtful_px, radius=self.radius)
        self.fits.append(fit_shot(evidence, **fit) if self._workers is None else self._workers[1].submit(fit_shot, evidence, **fit))
        self.sampled.append((np.array([s.frame for s in evidence.samples]), np.asarray(evidence.zoom, np.float64)))
        self.estimates.extend(self.collector.estimates)
        self.collector = None

    @property
    def sampled_in_shot(self) -> int:
        """Samples taken of the open shot so far (their evidence found or pending)."""
        return self._queued

    def wait_for_fits(self) -> None:
        """Wait for the fits still running on the fit worker: :attr:`fits` then holds each shot's."""
        self.fits = [fit.result() if isinstance(fit, Future) else fit for fit in self.fits]

    def stop(self) -> None:
        """End the workers (what is queued and not started is dropped)."""
        if self._workers is not None:
            for worker in self._workers:
                worker.shutdown(wait=True, cancel_futures=True)


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
    ahead: bool = True,
) -> LensTrack:
    """Pass 1 (module docstring): the :class:`LensTrack` of the video at ``path``. ``estimator``
    maps a uint8 RGB frame to a lens; ``every`` (frames) is the sampling stride, ``estimate_every``
    (samples) how often the estimator runs; ``doubtful_px`` (px at 1920) the bound above which a
    shot is doubtful; ``apply_doubtful`` applies doubtful shots' lenses anyway; ``rate`` the frame
    rate of an image-sequence input (default 25); ``sparse=False`` decodes every frame even where
    the stream allows the sparse decode; ``ahead=False`` calls ``estimator`` on this thread, one
    sample after the other (``True``: on a worker thread, ahead of the samples' other evidence,
    and the shots' fits on another: :class:`_Shots`; the same track; not where the process's
    thread budget is one core, :func:`glradial.threads.thread_budget`: a job's worker)."""
    for name, value in (("every", every), ("estimate_every", estimate_every)):
        check_count(name, value)
    if not doubtful_px > 0:
        raise ValueError(f"doubtful_px must be > 0 (px at 1920), got {doubtful_px!r}")
    for name, value in (("sparse", sparse), ("ahead", ahead)):
        check_flag(name, value)
    ahead = bool(ahead) and thread_budget() != 1  # one core: the workers would only take turns
    detector = detector or ShotDetector()
    fresh = copy.deepcopy(detector)
    with VideoReader(path, order="rgb", max_width=DETECT_WIDTH, keep_decoded=True, rate=rate) as reader:
        info = reader.info
        order = frame_timestamps(path) if sparse and info.fields == "progressive" else None
        shots = _Shots(estimator, estimate_every, doubtful_px, corner_radius(info.size), ahead)
        check = CutCheck(path, order, detector, rate=rate) if order is not None else None
        try:
            stamps = _scan(reader, order, detector, shots, every, progress, check)
            shots.wait_for_fits()  # before the workers end
        except _Unnumbered:  # the decoder's timestamps do not match the packets': decode every frame
            return track_shots(path, estimator, every=every, estimate_every=estimate_every, detector=fresh,
                               progress=progress, doubtful_px=doubtful_px, apply_doubtful=apply_doubtful, rate=rate,
                               sparse=False, ahead=ahead)
        finally:
            shots.stop()
            if check is not None:
                check.close()
    return _track(info, stamps, shots, apply_doubtful, doubtful_px)


class _Unnumbered(Exception):
    """A decoded frame's timestamp is not one of the packets' (pass 1 then decodes every frame)."""


def _scan(reader: VideoReader, order: np.ndarray | None, detector: ShotDetector, shots: _Shots, every: int,
          progress: bool | None, check: "CutCheck | None") -> np.ndarray:
    """Decode (every frame, or with ``order`` the frames other frames refer to, numbered by
    ``order``), detect cuts (with ``order``: candidates, confirmed and placed by ``check``), sample
    each shot; returns the frames' times (s)."""

    info = reader.info
    candidates = detector if check is None else replace(copy.deepcopy(detector), ratio=detector.ratio * CANDIDATE_RATIO)
    if order is not None:
        reader.skip_nonreference()
    stamps: list[float] = []
    previous = sampled = -1
    total = len(order) if order is not None else info.frame_count
    with Progress(total, "estimate", enabled=progress) as bar, Pipelined(reader.items()) as frames:
        for item in frames:
            index = item.index if order is None else _number(order, item.pts)
            if order is None:
                stamps.append(float(item.pts * info.time_base) if item.pts is not None else item.index / info.fps)
            if candidates.update(item.image, index - previous if previous >= 0 else 1):
                start = index if check is None or previous < 0 else check.confirm(previous, index, shots.starts[-1])
                if start is not None:
                    shots.open(start)
                    sampled = -1
            if sampled < 0 or index - sampled >= stride(every, shots.sampled_in_shot):
                shots.add(index, to_rgb8(reader.convert(item.decoded, ESTIMATE_WIDTH)))
                sampled = index
                if order is not None and _last_sample(sampled, every, shots.sampled_in_shot, len(order)):
                    shots.close()  # its fit runs while the frames after it decode (a later cut opens the next shot)
            bar.update(index - previous)
            previous = index
    shots.close()
    if shots.starts:
        shots.starts[0] = 0  # frames shown before the first decoded one (skipped leading B-frames) open the video
    if order is not None:
        stamps = [float(pts * info.time_base) for pts in order]
    return np.asarray(stamps, np.float64)


def stride(every: int, taken: int) -> int:
    """Frames from a shot's sample to its next once ``taken`` samples are taken: ``every`` for the
    first :data:`FIRST_SAMPLES`, then doubling after each :data:`SAMPLES_PER_STRIDE`, up to
    :data:`MAX_STRIDE` ``every``."""
    if taken < FIRST_SAMPLES:
        return every
    return every * min(2 ** (1 + (taken - FIRST_SAMPLES) // SAMPLES_PER_STRIDE), MAX_STRIDE)


def _last_sample(index: int, every: int, taken: int, frames: int) -> bool:
    """Whether the shot just sampled at frame ``index`` (``taken`` samples so far) takes no more: no
    frame of the video's ``frames`` lies a :func:`stride` on (the numbering is known: the sparse
    decode's timestamps)."""
    return index + stride(every, taken) >= frames


def _number(order: np.ndarray, pts: int | None) -> int:
    """The frame number of a decoded frame's ``pts`` among all frames' timestamps ``order``."""
    index = int(np.searchsorted(order, pts)) if pts is not None else len(order)
    if index >= len(order) or order[index] != pts:
        raise _Unnumbered(pts)
    return index


class CutCheck:
    """The full decode's cut test for a candidate cut of the sparse decode: :meth:`confirm` decodes
    every frame of the stretch before it (from the key frame at or before the first frame it needs)
    and runs ``detector``'s test frame by frame, as a decode of every frame would."""

    def __init__(self, path: str | os.PathLike, order: np.ndarray, detector: ShotDetector, *,
                 rate: Fraction | None = None) -> None:
        self.path, self.order, self.detector, self.rate = path, order, copy.deepcopy(detector), rate
        self._reader: VideoReader | None = None

    def confirm(self, a: int, b: int, start: int) -> int | None:
        """The first frame of a new shot in ``a + 1 .. b`` (``a``, ``b``: consecutive decoded frames
        whose difference was a candidate cut; ``start``: the first frame of the current shot), or
        None when a decode of every frame finds no cut there (the test: :meth:`ShotDetector.is_cut`)."""
        test = self.detector
        first = max(start, a - test.window)
        thumbs = self._thumbnails(first, b)
        if sorted(thumbs) != list(range(first, b + 1)):
            return b  # the stretch could not be read whole: the sparse decode's answer
        scores = [test.pair_score(thumbs[j - 1], thumbs[j]) for j in range(first + 1, b + 1)]  # frame j: scores[j - first - 1]
        for j in range(a + 1, b + 1):
            if test.is_cut(scores[j - first - 1], scores[: j - first - 1], j - start):
                return j
        return None

    def _thumbnails(self, first: int, last: int) -> dict[int, np.ndarray]:
        if self._reader is None:
            self._reader = VideoReader(self.path, order="rgb", max_width=DETECT_WIDTH, rate=self.rate)
        order = self.order
        self._reader.seek(int(order[first]))
        thumbs: dict[int, np.ndarray] = {}
        for item in self._reader.items():
            if item.pts is None or item.pts > order[last]:
                break
            if item.pts >= order[first]:
                thumbs[int(np.searchsorted(order, item.pts))] = item.image
        return thumbs

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None


def _log_zoom_at(here: np.ndarray, frames, zooms) -> np.ndarray:
    """The log zoom of frames ``here`` from the sampled ``frames``' ``zooms``: linear between samples
    and, past the last sample (up to a stride of frames before the shot ends), continued at the last
    two samples' rate: a zoom does not stop at the last sample (held there, a zoom-in's last frames
    kept the lens of up to a stride before, 19 px off on issue 35's two-shot clip). Likewise before
    the first sample, at the first two samples' rate: the frames between a cut and the shot's first
    decoded frame (a cut placed on frames the sparse decode skips, :class:`CutCheck`) are the first
    frames of the new shot, and a zoom was already under way there."""
    frames, zooms = np.asarray(frames, np.float64), np.asarray(zooms, np.float64)
    z = np.interp(here, frames, zooms)
    if len(frames) >= 2 and frames[-1] > frames[-2]:
        after = here > frames[-1]
        z[after] = zooms[-1] + (zooms[-1] - zooms[-2]) / (frames[-1] - frames[-2]) * (here[after] - frames[-1])
    if len(frames) >= 2 and frames[1] > frames[0]:
        before = here < frames[0]
        z[before] = zooms[0] - (zooms[1] - zooms[0]) / (frames[1] - frames[0]) * (frames[0] - here[before])
    return z


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
        lens[here] = fit.lens_at(_log_zoom_at(here, frames, zooms))
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
    applied = np.array([doubt.applies(bool(d), r, bool(apply_doubtful)) for d, r in zip(doubtful, reason)], bool)
    return LensTrack(info.rate, info.size, shot, lens, raw, weight, time_s=stamps, uncertainty_px=sure,
                     raw_uncertainty_px=raw_sure, method=method, doubtful_px=doubtful_px, doubtful=doubtful,
                     reason=reason, applied=applied)
