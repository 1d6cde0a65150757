"""The lens of a live stream, shot by shot, from the frames seen so far (``glradial live --auto``).

Causal counterpart of :mod:`glradial.video.shot_track`: every frame's 64 px thumbnail goes to the
cut detector (:class:`glradial.video.cuts.ShotDetector`, causal by design); a cut opens a new shot.
Within a shot, a frame every ``every`` frames (later ones further apart:
:func:`~glradial.video.shot_track.stride`, as for files) is handed, at most
:data:`SAMPLE_WIDTH` px wide, to a worker thread that adds it to the shot's
:class:`~glradial.video.shot_evidence.ShotCollector` (line chains, frame-to-frame matches, the
per-frame estimate on every ``estimate_every``-th sample) and refits the shot
(:func:`glradial.video.shot_fit.fit_shot`) on all its evidence so far: the shot's lens is refined as
it goes on. The worker is a separate process by default (``worker="process"``: the line detector
and the fit are mostly Python, and on a thread they would hold the interpreter's lock against the
correction and the encoder; its estimator must then be picklable, e.g. :class:`BundledEstimator`),
or a thread (``worker="thread"``, any callable); either way it talks over a pipe. Nothing waits for
it: a sampled frame that finds the worker busy is skipped (the next frame is offered instead), and
the worker rests between samples so that it takes at most ``duty`` of one core (the correction of
every frame comes first). :meth:`OnlineShotLens.wait_ready` waits until the worker has loaded its
estimator (a live run does so before opening its input). Its answer for the shot reaches the
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

import atexit
import math
import multiprocessing
import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import check_count
from ..lens import doubt
from ..lens.lens import Lens, corner_radius
from ..lens.options import LIVE_WORKERS, UNTIL_SURE, check_choice
from .cuts import ShotDetector
from .lens_track import DOUBTFUL_PX
from .shot_evidence import ShotCollector
from .shot_fit import fit_shot, load_solver
from .shot_track import ESTIMATE_EVERY, EVERY, stride

__all__ = ["LensState", "OnlineShotLens", "BundledEstimator", "SAMPLE_WIDTH", "DUTY", "worker_reply", "serve_jobs",
           "WarmWorker", "READY_TIMEOUT_S"]

#: seconds :meth:`WarmWorker.wait_ready` waits for a live worker to warm up by default
READY_TIMEOUT_S = 120.0
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


class BundledEstimator:
    """A picklable frame -> lens function (for a worker process): the bundled estimator (or the ONNX
    ``model``; ``method`` as :meth:`glradial.Estimator.estimate`), loaded on first use in the process
    that calls it (:func:`glradial.video.video_pipeline.default_estimator`)."""

    def __init__(self, model: str | None = None, method: str | None = None) -> None:
        self.model, self.method = model, method
        self._estimate: Callable | None = None

    def __call__(self, frame: np.ndarray) -> Lens:
        if self._estimate is None:
            from .video_pipeline import default_estimator

            self._estimate = default_estimator(self.model, self.method)
        return self._estimate(frame)

    def __getstate__(self) -> dict:
        return {"model": self.model, "method": self.method, "_estimate": None}


def worker_reply(connection, name: str) -> tuple | None:
    """The next message of a live worker process on ``connection`` (a :mod:`multiprocessing` pipe end):
    ``None`` for its ``("ready",)``, else the message tuple. ``RuntimeError`` naming the ``name``
    worker when it ended (the pipe closed) or sent ``("error", text)``."""
    try:
        message = connection.recv()
    except (EOFError, OSError):
        raise RuntimeError(f"the {name} worker ended unexpectedly") from None
    if message[0] == "error":
        raise RuntimeError(f"the {name} worker failed: {message[1]}")
    return None if message[0] == "ready" else message


def serve_jobs(connection, warm_up: Callable[[], object], answer: Callable[[tuple], tuple], duty: float) -> None:
    """A live worker's loop (a process or a thread): runs ``warm_up()``, says ``("ready",)``, then
    answers each job with ``("fit", *answer(job), rest_s)`` (``rest_s``: how long it asks to rest so
    that it takes at most ``duty`` of a core) until it gets None; an error is sent as ``("error",
    text)`` (read by :func:`worker_reply`); a closed pipe or Ctrl-C ends it quietly."""
    try:
        warm_up()
        connection.send(("ready",))
        while (job := connection.recv()) is not None:
            started = time.monotonic()
            reply = answer(job)
            connection.send(("fit", *reply, (time.monotonic() - started) * (1.0 / duty - 1.0)))
    except (EOFError, OSError, KeyboardInterrupt):  # the other end went away, or Ctrl-C reached the process group
        return
    except Exception as err:  # handed to the frame thread
        try:
            connection.send(("error", f"{type(err).__name__}: {err}"))
        except OSError:
            pass


def _serve(connection, estimator: Callable, estimate_every: int, doubtful_px: float, duty: float) -> None:
    """The lens worker (:func:`serve_jobs`): loads ``estimator`` on a blank frame, then answers each
    job ``(shot, index, frame)`` with ``("fit", shot, _Fit, rest_s)``."""
    shots: dict = {}  # the shot being collected: {shot number: ShotCollector}

    def answer(job: tuple) -> tuple:
        shot, index, frame = job
        if shot not in shots:
            shots.clear()
            shots[shot] = ShotCollector(estimator, estimate_every)
        collector = shots[shot]
        collector.add(index, frame)
        result = fit_shot(collector.evidence, doubtful_px=doubtful_px, radius=corner_radius((frame.shape[1], frame.shape[0])))
        k1, k2 = (float(v) for v in result.lens_at(collector.evidence.zoom[-1]))
        return shot, _Fit(Lens(k1, k2), float(result.uncertainty_px), bool(result.doubtful), result.reason)

    def warm_up():  # the solver's import and the estimator's first run, before the worker says it is ready
        load_solver()
        return estimator(np.full((SAMPLE_WIDTH * 9 // 16, SAMPLE_WIDTH, 3), 96, np.uint8))

    serve_jobs(connection, warm_up, answer, duty)


class WarmWorker:
    """What a live worker's owner shares (:class:`OnlineShotLens`, and the live camera tracker):
    made and waited for until its worker has warmed up. A subclass holds ``_ready``, ``_connection``
    (its end of the worker's pipe), ``_receive()`` (one message in) and ``close()``, and names its
    worker in :attr:`worker_name` (for the errors)."""

    worker_name = "live"

    @classmethod
    def started(cls, *args: object, **options: object):
        """A new one (the constructor's arguments) whose worker has warmed up (:meth:`wait_ready`);
        closed again if that fails."""
        made = cls(*args, **options)
        try:
            made.wait_ready()
        except BaseException:
            made.close()
            raise
        return made

    def _reply(self) -> tuple | None:
        """The worker's next message (:func:`worker_reply`); ``None`` for its "ready", noted."""
        message = worker_reply(self._connection, self.worker_name)
        if message is None:
            self._ready = True
        return message

    def wait_ready(self, timeout: float = READY_TIMEOUT_S) -> None:
        """Wait until the worker has warmed up (``TimeoutError`` after ``timeout`` s; its error, as
        ``RuntimeError``, if it failed)."""
        end = time.monotonic() + timeout
        while not self._ready:
            if not self._connection.poll(max(0.0, end - time.monotonic())):
                raise TimeoutError(f"the {self.worker_name} worker was not ready within {timeout:g} s")
            self._receive()


class OnlineShotLens(WarmWorker):
    """Per-frame lens of a live stream (module docstring). Call :meth:`observe` for every frame in
    order, from one thread; :meth:`close` stops the worker. ``estimator``: uint8 RGB frame -> lens
    (:class:`BundledEstimator`; picklable for ``worker="process"``); ``every``, ``estimate_every``,
    ``doubtful_px``, ``apply_doubtful`` as for files (:func:`glradial.video.shot_track.track_shots`);
    ``until_sure`` and ``duty`` as the module docstring says."""

    worker_name = "lens"

    def __init__(self, estimator: Callable[[np.ndarray], Lens], *, every: int = EVERY,
                 estimate_every: int = ESTIMATE_EVERY, doubtful_px: float = DOUBTFUL_PX, apply_doubtful: bool = False,
                 until_sure: str = "pass", duty: float = DUTY, worker: str = "process",
                 detector: ShotDetector | None = None) -> None:
        for name, value in (("every", every), ("estimate_every", estimate_every)):
            check_count(name, value)
        if not doubtful_px > 0:
            raise ValueError(f"doubtful_px must be > 0 (px at 1920), got {doubtful_px!r}")
        if not 0 < duty <= 1:
            raise ValueError(f"duty must lie in (0, 1] (a share of one core), got {duty!r}")
        self.until_sure = check_choice("until_sure", until_sure, UNTIL_SURE)
        self.every, self.apply_doubtful = int(every), bool(apply_doubtful)
        self.detector = detector or ShotDetector()
        self.shot = -1
        self.samples_taken = self.samples_skipped = 0
        self._sampled = self._seen = -1
        self._in_shot = 0  # samples handed over in the current shot
        self._last_sure: Lens | None = None
        self._fits: dict[int, _Fit] = {}
        self._ready = self._busy = False
        self._rest_until = 0.0
        args = (estimator, int(estimate_every), float(doubtful_px), float(duty))
        if check_choice("worker", worker, LIVE_WORKERS) == "process":
            context = multiprocessing.get_context("spawn")  # no fork of a process with threads
            self._connection, theirs = context.Pipe()
            self._worker = context.Process(target=_serve, args=(theirs, *args), name="glradial-live-lens", daemon=True)
        else:
            self._connection, theirs = multiprocessing.Pipe()
            self._worker = threading.Thread(target=_serve, args=(theirs, *args), name="glradial-live-lens", daemon=True)
        self._worker.start()
        atexit.register(self.close)  # not closed by the script: stopped before the interpreter finalizes

    # -- the frame thread ----------------------------------------------------------------------------
    def observe(self, index: int, thumbnail: np.ndarray, sample: Callable[[], np.ndarray]) -> LensState:
        """The lens of frame ``index`` (increasing; gaps allowed: dropped frames): ``thumbnail`` its
        small uint8 RGB copy for the cut detector (64 px wide is enough), ``sample()`` its uint8 RGB
        copy at most :data:`SAMPLE_WIDTH` px wide, asked for only when the frame is sampled."""
        while self._connection.poll():
            self._receive()
        advance, self._seen = (index - self._seen if self._seen >= 0 else 1), index
        if self.detector.update(thumbnail, max(1, advance)):
            self.shot += 1
            self._sampled, self._in_shot = -1, 0
        if self._sampled < 0 or index - self._sampled >= stride(self.every, self._in_shot):
            if self._ready and not self._busy and time.monotonic() >= self._rest_until:
                self._connection.send((self.shot, index, sample()))
                self._busy = True
                self._sampled, self._in_shot = index, self._in_shot + 1
                self.samples_taken += 1
            else:
                self.samples_skipped += 1
        return self._state(self.shot)

    def _receive(self) -> None:
        """Take one message of the worker."""
        message = self._reply()
        if message is None:
            return
        _, shot, fit, rest = message
        self._fits = {s: f for s, f in self._fits.items() if s >= shot - 1}
        self._fits[shot] = fit
        if not fit.doubtful and math.isfinite(fit.uncertainty_px):
            self._last_sure = fit.lens
        self._busy, self._rest_until = False, time.monotonic() + rest

    def _state(self, shot: int) -> LensState:
        fit, last_sure = self._fits.get(shot), self._last_sure
        held = last_sure if self.until_sure == "last" else None
        if fit is None:
            return LensState(shot=shot, applied=held, reported=last_sure or Lens(0.0, 0.0), uncertainty_px=None,
                             doubtful=True, reason=PENDING)
        if not fit.doubtful:
            return LensState(shot=shot, applied=fit.lens, reported=fit.lens, uncertainty_px=fit.uncertainty_px,
                             doubtful=False, reason="")
        applied = fit.lens if doubt.applies(True, fit.reason, self.apply_doubtful) else held
        return LensState(shot=shot, applied=applied, reported=fit.lens, uncertainty_px=fit.uncertainty_px,
                         doubtful=True, reason=fit.reason)

    def close(self) -> None:
        """Stop the worker: a process abandons the sample in progress (terminated after 5 s); a thread,
        which cannot be stopped, finishes it and is waited for (left running inside OpenCV or
        onnxruntime, it would abort the process at interpreter exit). Called at exit for an online
        lens not closed by then; again, a no-op."""
        atexit.unregister(self.close)
        if self._connection.closed:
            return
        try:
            self._connection.send(None)
        except OSError:
            pass
        if isinstance(self._worker, threading.Thread):
            self._worker.join()
            self._connection.close()
            return
        self._worker.join(timeout=5.0)
        if self._worker.is_alive():
            self._worker.terminate()
            self._worker.join()
        self._connection.close()
