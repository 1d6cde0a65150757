"""The lens of a live stream, shot by shot, from the frames seen so far (``glradial live --auto``).

Causal counterpart of :mod:`glradial.video.shot_track`: every frame's 64 px thumbnail goes to the
cut detector (:class:`glradial.video.cuts.ShotDetector`, causal by design); a cut opens a new shot.
Within a shot, a frame every ``every`` frames (the stride doubling each
:data:`~glradial.video.shot_track.SAMPLES_PER_STRIDE` samples, as for files) is handed, at most
:data:`SAMPLE_WIDTH` px wide, to a worker thread that adds it to the shot's
:class:`~glradial.video.shot_evidence.ShotCollector` (line chains, frame-to-frame matches, the
per-frame estimate on every ``estimate_every``-th sample) and refits the shot
(:func:`glradial.video.shot_fit.fit_shot`) on all its evidence so far: the shot's lens is refined as
it goes on. Nothing waits for it: a sampled frame finds the worker busy, it is skipped (the next
frame is offered instead), and the worker rests between samples so that it takes at most ``duty``
of one core (the correction of every frame comes first). Its answer for the shot reaches the
frames that follow it; the lens at the latest sample's zoom (a zooming shot's lens follows the zoom
as the shot fit models it).

Doubt policy, that of files (:mod:`glradial.video.shot_track`): a shot whose fit states a bound
above ``doubtful_px`` (px at 1920 wide) is doubtful and its lens is not applied unless
``apply_doubtful`` (a ``fold_over`` lens never is). A new shot has no lens until its first sample
is fitted: its first frames, and a doubtful shot's, pass through uncorrected and flagged doubtful
(``until_sure="pass"``, the default) or keep the last sure lens of an earlier shot
(``until_sure="last"``: still flagged doubtful: it is not this shot's own).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..lens.lens import Lens, corner_radius
from ..lens.options import check_choice
from .cuts import ShotDetector
from .lens_track import DOUBTFUL_PX
from .shot_evidence import ShotCollector
from .shot_fit import fit_shot
from .shot_track import ESTIMATE_EVERY, EVERY, SAMPLES_PER_STRIDE

__all__ = ["LensState", "OnlineShotLens", "UNTIL_SURE", "SAMPLE_WIDTH", "DUTY"]

#: what a shot's frames get until its lens is sure: "pass" (uncorrected) or "last" (the last sure lens)
UNTIL_SURE = ("pass", "last")
#: sampled frames are handed to the shot evidence at most this wide (px): the per-frame estimator
#: reads 384 px and the line detector up to 960 px; 640 px halves the cost of 960 px for a live
#: stream (measured: 25-50 ms a sample for chains and matches at 640 px on this machine)
SAMPLE_WIDTH = 640
#: the worker's share of one core at most (it rests ``(1/duty - 1)`` times each sample's cost)
DUTY = 0.5
#: reason of a shot whose first sample is not fitted yet
PENDING = "pending"


@dataclass(frozen=True)
class LensState:
    """The lens of one frame of a live stream: its ``shot`` (0 = the first), the lens ``applied``
    (None: passed through uncorrected), the lens ``reported`` (the shot's latest estimate; the last
    sure lens, or 0 0, while none), its ``uncertainty_px`` (~p90 bound, px at 1920 wide; None while
    the shot has no estimate), ``doubtful`` and ``reason`` (machine-readable: ``uncertain``,
    ``no_geometry``, ``fold_over``, ``pending`` or "")."""

    shot: int
    applied: Lens | None
    reported: Lens
    uncertainty_px: float | None
    doubtful: bool
    reason: str


@dataclass(frozen=True)
class _Fit:
    lens: Lens
    uncertainty_px: float
    doubtful: bool
    reason: str


class OnlineShotLens:
    """Per-frame lens of a live stream (module docstring). Call :meth:`observe` for every frame in
    order, from one thread; :meth:`close` stops the worker. ``estimator``: uint8 RGB frame -> lens
    (:func:`glradial.video.video_pipeline.default_estimator`); ``size``: the stream's frame (W, H) px."""

    def __init__(self, estimator: Callable[[np.ndarray], Lens], size: tuple[int, int], *, every: int = EVERY,
                 estimate_every: int = ESTIMATE_EVERY, doubtful_px: float = DOUBTFUL_PX, apply_doubtful: bool = False,
                 until_sure: str = "pass", duty: float = DUTY, detector: ShotDetector | None = None) -> None:
        for name, value in (("every", every), ("estimate_every", estimate_every)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if not doubtful_px > 0:
            raise ValueError(f"doubtful_px must be > 0 (px at 1920), got {doubtful_px!r}")
        if not 0 < duty <= 1:
            raise ValueError(f"duty must lie in (0, 1] (a share of one core), got {duty!r}")
        self.until_sure = check_choice("until_sure", until_sure, UNTIL_SURE)
        self.estimator, self.every, self.estimate_every = estimator, int(every), int(estimate_every)
        self.doubtful_px, self.apply_doubtful, self.duty = float(doubtful_px), bool(apply_doubtful), float(duty)
        self.radius = corner_radius(size)
        self.detector = detector or ShotDetector()
        self.shot = -1
        self.samples_taken = self.samples_skipped = 0
        self._sampled = self._seen = -1
        self._in_shot = 0  # samples handed over in the current shot
        self._last_sure: Lens | None = None
        self._fits: dict[int, _Fit] = {}
        self._job: tuple[int, int, np.ndarray] | None = None
        self._error: BaseException | None = None
        self._rest_until = 0.0
        self._lock = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._work, name="glradial-live-lens", daemon=True)
        self._thread.start()

    # -- the frame thread ----------------------------------------------------------------------------
    def observe(self, index: int, thumbnail: np.ndarray, sample: Callable[[], np.ndarray]) -> LensState:
        """The lens of frame ``index`` (increasing; gaps allowed: dropped frames): ``thumbnail`` its
        small uint8 RGB copy for the cut detector (64 px wide is enough), ``sample()`` its uint8 RGB
        copy at most :data:`SAMPLE_WIDTH` px wide, asked for only when the frame is sampled."""
        if self._error is not None:
            raise self._error
        advance, self._seen = (index - self._seen if self._seen >= 0 else 1), index
        if self.detector.update(thumbnail, max(1, advance)):
            self.shot += 1
            self._sampled, self._in_shot = -1, 0
        stride = self.every * 2 ** (self._in_shot // SAMPLES_PER_STRIDE)
        if self._sampled < 0 or index - self._sampled >= stride:
            with self._lock:
                idle = self._job is None and time.monotonic() >= self._rest_until
                if idle:
                    self._job = (self.shot, index, sample())
                    self._lock.notify()
            if idle:
                self._sampled, self._in_shot = index, self._in_shot + 1
                self.samples_taken += 1
            else:
                self.samples_skipped += 1
        return self._state(self.shot)

    def _state(self, shot: int) -> LensState:
        with self._lock:
            fit = self._fits.get(shot)
            last_sure = self._last_sure
        held = last_sure if self.until_sure == "last" else None
        if fit is None:
            return LensState(shot, held, last_sure or Lens(0.0, 0.0), None, True, PENDING)
        if not fit.doubtful:
            return LensState(shot, fit.lens, fit.lens, fit.uncertainty_px, False, "")
        applied = fit.lens if self.apply_doubtful and fit.reason != "fold_over" else held
        return LensState(shot, applied, fit.lens, fit.uncertainty_px, True, fit.reason)

    # -- the worker ----------------------------------------------------------------------------------
    def _work(self) -> None:
        collector, collected_shot = None, -1
        while True:
            with self._lock:
                while self._job is None and not self._stop:
                    self._lock.wait()
                if self._stop:
                    return
                shot, index, frame = self._job
            started = time.monotonic()
            try:
                if shot != collected_shot:
                    collector, collected_shot = ShotCollector(self.estimator, self.estimate_every), shot
                collector.add(index, frame)
                result = fit_shot(collector.evidence, doubtful_px=self.doubtful_px, radius=self.radius)
                k1, k2 = (float(v) for v in result.lens_at(collector.evidence.zoom[-1]))
                fit = _Fit(Lens(k1, k2), float(result.uncertainty_px), bool(result.doubtful), result.reason)
            except BaseException as err:  # handed to the frame thread
                self._error = err
                return
            with self._lock:
                self._fits = {s: f for s, f in self._fits.items() if s >= shot - 1}
                self._fits[shot] = fit
                if not fit.doubtful and math.isfinite(fit.uncertainty_px):
                    self._last_sure = fit.lens
                self._job = None
                self._rest_until = time.monotonic() + (time.monotonic() - started) * (1.0 / self.duty - 1.0)

    def close(self) -> None:
        """Stop the worker (a sample in progress finishes first)."""
        with self._lock:
            self._stop = True
            self._lock.notify()
        self._thread.join()
