"""Causal lens correction of a live stream: :class:`LiveCorrector`, for one's own capture loop
(``glradial live`` runs one between a live source and an output, :mod:`glradial.video.live_stream`).

Use::

    live = glradial.LiveCorrector(lens, (1280, 720), 50)       # or "auto"
    while capturing:
        live.push(frame, timestamp)                            # never blocks
        for out in live.pull_ready():                          # corrected, in order
            show(out.image); send(out.sample)
    live.finish(); ...; live.close()                         # left open: closed at exit

Conventions:

* ``push(frame, timestamp)``: ``frame`` an ``H x W x 3`` RGB array (uint8, or uint16 full scale),
  or a decoded ``av.VideoFrame`` (planar YUV frames, e.g. yuv420p, are corrected plane by plane in
  their own samples and handed back as ``av.VideoFrame`` with the same ``pts``, :mod:`glradial.remapping.planes`;
  any other pix_fmt is converted to RGB); ``timestamp`` the frame's presentation time in seconds
  on the source's clock (None: the arrival time). A frame's number (``LiveFrame.index``, the
  OpenTrackIO ``sequenceNumber``) is ``round((timestamp - first timestamp) x rate)``: dropped
  frames leave gaps, the numbers stay those of the source.
* Causal and bounded: one worker thread corrects frames in arrival order. A frame whose turn
  comes after it has waited ``max_delay`` frame periods is dropped; so is one that could no longer
  leave in time (its wait plus the median time of the last :data:`COSTS_KEPT` corrections) while a
  newer frame waits behind it (the newest is always tried: the correction keeps going, and keeps
  being measured, however slow it gets); a push finding :data:`MAX_WAITING` frames waiting drops
  the oldest. All are counted in :attr:`LiveStats.dropped` (a frame is dropped rather than the
  delay growing; a burst, e.g. the frames a network source decodes at once after probing, passes
  whole when the worker can take it in time). A frame leaves
  when the caller takes it (:meth:`pull`, or :meth:`left` after the caller's own output); its
  delay (leaving time - push time, in frame periods of ``rate``) is recorded, and one above
  ``max_delay`` counts as late (:attr:`LiveStats.late`). Nothing waits for a shot's end.
* The lens: a :class:`glradial.Lens` (or ``(k1, k2)``) for every frame, or ``"auto"``: the lens of
  each shot read from the frames seen so far (:class:`glradial.video.live_lens.OnlineShotLens`,
  with its doubt policy: a shot not (yet) sure passes through, flagged doubtful; a new lens is
  applied once its maps are built on a helper thread, and ``LiveFrame.state.applied`` says which
  lens a frame got). Its worker is a separate process started with ``spawn``: a script that makes
  an ``"auto"`` corrector needs the ``if __name__ == "__main__":`` guard, or passes
  ``auto={"worker": "thread"}``.
* ``camera`` (:class:`glradial.export.opentrackio.TrackingCamera`): each frame gets its OpenTrackIO sample
  (:func:`glradial.export.opentrackio.frame_sample`), with ``custom.glradial`` k1, k2 (the lens
  reported: the estimate even where it is not applied), uncertainty and doubt as for files.
* ``tracker`` (with ``camera``; :func:`glradial.tracking.live_camera.camera_tracker`): each frame's
  whole camera, ``LiveFrame.tracked``, and a sample with its transform, focal length and lens
  (:func:`glradial.export.opentrackio.camera_frame_sample`). ``lens=None``: frames pass through
  uncorrected (the tracking only). A frame with no sure camera while a fit is in flight waits for
  it while its delay allows (``max_delay`` - 1 periods less its correction: the lock-on reaches
  the frames that arrived just before it).
* :meth:`LiveCorrector.warm_up` starts a given lens's maps on a helper thread: frames before they
  are ready pass through uncorrected, flagged doubtful (``reason`` ``"pending"``).
"""

from __future__ import annotations

import atexit
import threading
import time
import uuid
from collections import OrderedDict, deque
from dataclasses import dataclass, field, replace
from fractions import Fraction
from typing import Callable, NamedTuple

import av
import cv2
import numpy as np

from ..errors import check_count
from ..lens.lens import Lens, as_lens
from ..media.frames import to_rgb8
from ..media.video_io import VideoInfo, frame_planes, yuv_layout
from .live_lens import PENDING, SAMPLE_WIDTH, BundledEstimator, LensState, OnlineShotLens
from .video_pipeline import FrameCorrector

__all__ = ["LiveCorrector", "LiveFrame", "LiveStats", "DEFAULT_MAX_DELAY"]

#: frames a frame may wait from its arrival to its leaving (frame periods)
DEFAULT_MAX_DELAY = 2
#: thumbnails for the cut detector (px): what :class:`glradial.video.cuts.ShotDetector` reads
THUMB_SIZE = (64, 36)
#: frames waiting for the worker at most (memory); a frame is dropped sooner when it would be late
MAX_WAITING = 16
#: corrected frames that wait for the caller at most: one (the worker corrects the next while the
#: caller encodes this one); a slow caller holds the worker back, and the frames behind it are then
#: dropped at the input rather than corrected and left to age
READY_SLOTS = 1
#: corrections whose median time predicts the next one's
COSTS_KEPT = 9
#: OpenTrackIO lens objects kept per lens (a stream changes lens only between shots or on a zoom)
LENS_OBJECTS = 64
#: the lens reported while none is given (tracking only, ``lens=None``)
IDENTITY = Lens(0.0, 0.0)


class _Waiting(NamedTuple):
    """A pushed frame waiting for the worker: the ``frame``, its ``timestamp`` (s, from the stream's
    first), when it ``arrived`` (``time.monotonic()`` s) and its ``index`` on the stream's clock."""

    frame: object
    timestamp: float
    arrived: float
    index: int


@dataclass
class LiveFrame:
    """A corrected frame: ``index`` (its number on the source's clock), ``timestamp`` (s, as
    pushed), ``pts`` (the pushed ``av.VideoFrame``'s, else None), the ``image`` (an array, or an
    ``av.VideoFrame`` for a planar YUV frame), the lens ``state`` (applied, reported, uncertainty,
    doubt, shot), its OpenTrackIO ``sample`` (None without a camera) and when it ``arrived``
    (``time.monotonic()`` s at its push).

    Args:
        index, timestamp, pts, image, state, sample, arrived: above (made by :class:`LiveCorrector`).

    Raises:
        Nothing: a plain record.

    Example:
        >>> import numpy as np, glradial
        >>> with glradial.LiveCorrector((-0.2, 0.0), (64, 36), 25) as live:
        ...     live.push(np.zeros((36, 64, 3), np.uint8), 0.0)
        ...     live.finish()
        ...     frame = live.pull(timeout=None)
        >>> isinstance(frame, glradial.LiveFrame), frame.index, frame.image.shape
        (True, 0, (36, 64, 3))
    """

    index: int
    timestamp: float
    pts: int | None
    image: object
    state: LensState
    sample: dict | None
    arrived: float
    tracked: object | None = None  # the frame's camera (glradial.tracking.live_camera.LiveCamera) with a tracker


@dataclass
class LiveStats:
    """Counts of a live run: frames ``pushed`` and ``corrected``; ``delays`` the delay of every frame
    that left (taken by the caller; frame periods), ``dropped_at`` the numbers of the frames dropped
    before correction (the input outran it; :meth:`dropped_ranges`). The counts ``left``, ``late``
    (left more than ``max_delay`` frame periods after arriving) and ``dropped`` are read from those
    two lists, so that they can never disagree with them."""

    rate: float
    max_delay: int
    pushed: int = 0
    corrected: int = 0
    delays: list[float] = field(default_factory=list)
    dropped_at: list[int] = field(default_factory=list)
    started: float = field(default_factory=time.monotonic)

    dropped = property(lambda self: len(self.dropped_at), doc="Frames dropped before correction (int).")
    left = property(lambda self: len(self.delays), doc="Frames that left, taken by the caller (int).")
    late = property(lambda self: sum(delay > self.max_delay for delay in self.delays),
                    doc="Frames that left more than ``max_delay`` frame periods after arriving (int).")

    def drop(self, index: int) -> None:
        """Count frame ``index`` (its number on the source's clock) as dropped."""
        self.dropped_at.append(index)

    def dropped_ranges(self, most: int = 8) -> str:
        """The dropped frames' numbers as runs (``"0-4, 120"``; at most ``most`` runs, then ``"..."``)."""
        runs: list[list[int]] = []
        for index in sorted(self.dropped_at):
            if runs and index == runs[-1][1] + 1:
                runs[-1][1] = index
            else:
                runs.append([index, index])
        text = [f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:most]]
        return ", ".join(text + (["..."] if len(runs) > most else []))

    def delay_percentile(self, q: float) -> float:
        """The ``q``-th percentile (0-100) of the delays (frame periods; NaN before any frame left)."""
        return float(np.percentile(self.delays, q)) if self.delays else float("nan")

    def fps(self) -> float:
        """Frames left per second since the run started."""
        return self.left / max(time.monotonic() - self.started, 1e-9)

    def line(self) -> str:
        """The status line: frames out, output rate, delay p50/p95 (frames), dropped and late."""
        return (f"{self.left} frames out, {self.fps():.1f} fps (stream {self.rate:.4g}), delay p50 "
                f"{self.delay_percentile(50):.2f} p95 {self.delay_percentile(95):.2f} frames (max {self.max_delay}), "
                f"dropped {self.dropped}, late {self.late}")


class _NewFrames:
    """New frames for the planar path when no writer provides them: ``av.VideoFrame`` in ``pix_fmt``."""

    def __init__(self, size: tuple[int, int], pix_fmt: str) -> None:
        self.size, self.pix_fmt = size, pix_fmt

    def planar_frame(self):
        frame = av.VideoFrame(self.size[0], self.size[1], self.pix_fmt)
        return frame, frame_planes(frame)

    def stamp(self, frame: av.VideoFrame, pts: int | None) -> av.VideoFrame:
        frame.pts = pts
        return frame


class _MapsAhead:
    """Builds the maps of a lens not seen before on a helper thread (a dry run of the correction of a
    frame, which fills the CPU path's map cache, :func:`glradial.remapping.remap.cpu_maps`), so
    that the worker switches to a new ``--auto`` lens only once its maps are there: a new lens then
    costs the stream no frame. ``corrector()`` makes a corrector like the worker's."""

    def __init__(self, corrector: Callable[[], FrameCorrector], size: tuple[int, int]) -> None:
        self._corrector, self.size = corrector, size
        self._built: deque = deque(maxlen=4)
        self._thread: threading.Thread | None = None

    @property
    def started(self) -> bool:
        """Whether a build was ever started."""
        return self._thread is not None

    def ready(self, lens: Lens, frame) -> bool:
        """Whether ``lens``'s maps are built; if not, and no build is running, start one on ``frame``."""
        if lens in self._built:
            return True
        if self._thread is None or not self._thread.is_alive():
            self._thread = threading.Thread(target=self._build, args=(lens, frame), name="glradial-live-maps", daemon=True)
            self._thread.start()
        return False

    def _build(self, lens: Lens, frame) -> None:
        _dry_run(self._corrector(), frame, lens, self.size)
        self._built.append(lens)

    def join(self) -> None:
        """Wait for the build in progress, if any (it runs in native code: not left running at exit)."""
        if self._thread is not None:
            self._thread.join()


def _dry_run(corrector: FrameCorrector, frame, lens: Lens, size: tuple[int, int]) -> None:
    """Correct ``frame`` (an ``av.VideoFrame``, corrected in its planes, or an RGB array) with
    ``lens`` and drop the result: ``corrector`` builds and caches its maps for that lens."""
    if isinstance(frame, av.VideoFrame):
        corrector.planar(frame, lens, _NewFrames(size, frame.format.name), None)
    else:
        corrector(frame, lens)


class LiveCorrector:
    """Correct a live stream frame by frame, causally (module docstring). ``lens``: a Lens,
    ``(k1, k2)`` or ``"auto"``; ``size`` (W, H) px and ``rate`` (frames per second) of the stream;
    ``max_delay`` (frame periods, >= 1); ``camera``: make OpenTrackIO samples (``model`` the
    distortion model, :data:`glradial.export.engines.MODEL_UD` by default); ``fit``,
    ``interpolation``, ``backend`` as :func:`glradial.correct` (``"cpu"`` keeps planar YUV frames
    in YUV); ``codec``: the source's codec (the chroma siting of planar frames); ``frames``: an
    object with ``planar_frame()``/``stamp()`` (a :class:`~glradial.media.video_io.VideoWriter`) to
    make the corrected planar frames, so that they are ready for it; ``estimator`` (default
    :class:`~glradial.video.live_lens.BundledEstimator`) and ``auto`` (keywords of
    :class:`~glradial.video.live_lens.OnlineShotLens`, e.g. ``worker="thread"`` for an estimator
    that cannot be pickled) for ``"auto"``, whose worker is started and waited for here; or an
    OnlineShotLens made beforehand as ``lens`` (closed with this corrector).

    Args:
        lens: above.
        size: the stream's ``(W, H)`` in pixels.
        rate: frames per second (> 0).
        max_delay, camera, model, fit, interpolation, backend, codec, frames, estimator, auto: above.

    Raises:
        ValueError: a bad ``lens``, ``size``, ``rate`` or ``max_delay``, or a lens that folds over
            inside the frame.

    Example:
        >>> import numpy as np, glradial
        >>> live = glradial.LiveCorrector(glradial.Lens(-0.2), (64, 36), 25)
        >>> for i in range(3):
        ...     live.push(np.full((36, 64, 3), 120, np.uint8), i / 25)
        >>> live.finish()
        >>> frames = [live.pull(timeout=None) for _ in range(3)]
        >>> live.close()
        >>> [f.index for f in frames], live.stats.corrected
        ([0, 1, 2], 3)
    """

    def __init__(self, lens: Lens | tuple[float, float] | str | OnlineShotLens | None, size: tuple[int, int],
                 rate: float | Fraction, *, max_delay: int = DEFAULT_MAX_DELAY, camera=None, model: str | None = None,
                 fit: str = "same", interpolation: str = "linear", backend: str = "cpu", codec: str = "", frames=None,
                 estimator: Callable | None = None, auto: dict | None = None, tracker=None) -> None:
        check_count("max_delay", max_delay, unit="frames")
        info = VideoInfo.of(size, rate, codec=codec)
        self.size, self.rate, self.max_delay = info.size, info.rate, int(max_delay)
        self.camera, self.model, self.codec, self.frames = camera, model, codec, frames
        if tracker is not None and camera is None:
            raise ValueError("tracker needs camera (the sensor, rate and timecode of the samples)")
        self.tracker = tracker
        self._corrector = FrameCorrector(backend, fit, interpolation)
        self._online: OnlineShotLens | None = None
        self.passthrough = lens is None
        if lens is None:
            self.lens = None
        elif isinstance(lens, OnlineShotLens):
            self._online, self.lens = lens, None
        elif isinstance(lens, str):
            if lens != "auto":
                raise ValueError(f"lens must be a Lens, (k1, k2), 'auto' or an OnlineShotLens, got {lens!r}")
            self._online, self.lens = OnlineShotLens.started(estimator or BundledEstimator(), **(auto or {})), None
        else:
            self.lens = as_lens(lens)
            self.lens.check_frame(self.size)  # a lens that folds over inside the frame is refused now
        self.stats = LiveStats(float(self.rate), self.max_delay)
        self.source_id = uuid.uuid4().urn
        self._planar: bool | None = None
        self._objects: OrderedDict = OrderedDict()
        self._waiting: deque = deque()
        self._ready: deque = deque()
        self._cond = threading.Condition()
        self._ended = self._stopped = self._done = False
        self._error: BaseException | None = None
        self._first: float | None = None
        self._last_index = -1
        self._costs: deque = deque(maxlen=COSTS_KEPT)  # the last corrections' times (s)
        self._waited = 0.0  # s the last frame waited for a camera fit (not its correction's cost)
        self._applied: Lens | None = None  # --auto: the lens applied now
        self._ahead = _MapsAhead(self._twin, self.size)
        if camera is not None and (self.lens is not None or self.passthrough):
            self._sample(0, 0.0, self._state(0, None))  # the schema validator and the lens object, made now
        self._thread = threading.Thread(target=self._work, name="glradial-live-correct", daemon=True)
        self._thread.start()
        # a script that exits without close(): stopped and joined before the interpreter finalizes
        # (a daemon thread still inside OpenCV then aborts the process: docs/CLI.md, "live")
        atexit.register(self.close)

    # -- the caller's side ---------------------------------------------------------------------------
    def push(self, frame: np.ndarray | av.VideoFrame, timestamp: float | None = None) -> None:
        """Hand over the next frame (module conventions); never blocks: when :data:`MAX_WAITING`
        frames already wait for correction, the oldest of them is dropped here (counted in
        ``stats.dropped``). The worker, not this call, drops a frame that could no longer leave
        within ``max_delay`` frame periods (module docstring)."""
        arrived = time.monotonic()
        if not isinstance(frame, (np.ndarray, av.VideoFrame)):
            raise TypeError(f"frame must be an H x W x 3 array or an av.VideoFrame, got {type(frame).__name__}")
        width, height = (frame.width, frame.height) if isinstance(frame, av.VideoFrame) else (frame.shape[1], frame.shape[0])
        if (width, height) != self.size:
            raise ValueError(f"frame must be {self.size[0]}x{self.size[1]} (the stream's size), got {width}x{height}")
        stamp = (arrived if timestamp is None else float(timestamp))
        with self._cond:
            if self._ended:
                raise ValueError("push after finish(): the stream has ended")
            if self._first is None:
                self._first = stamp
            index = max(round((stamp - self._first) * self.rate), self._last_index + 1)
            self._last_index = index
            self.stats.pushed += 1
            if len(self._waiting) >= MAX_WAITING:
                self.stats.drop(self._waiting.popleft().index)
            self._waiting.append(_Waiting(frame, stamp if timestamp is not None else stamp - self._first, arrived, index))
            self._cond.notify_all()

    def pull(self, timeout: float | None = 0.0, *, leave: bool = True) -> LiveFrame | None:
        """The next corrected frame, waiting up to ``timeout`` s (None: until one is ready or the
        stream is done); None when none is ready. ``leave``: the frame leaves now (its delay is
        recorded); False: the caller calls :meth:`left` once it has sent it on. An error of the
        worker (or of the estimator) is raised here."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            while not self._ready:
                if self._error is not None:
                    raise self._error
                if self._done:
                    return None
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return None
                self._cond.wait(remaining)
            item = self._ready.popleft()
            self._cond.notify_all()
        if leave:
            self.left(item)
        return item

    def pull_ready(self) -> list[LiveFrame]:
        """Every frame corrected so far (none waited for); each leaves now."""
        out = []
        while (item := self.pull(0.0)) is not None:
            out.append(item)
        return out

    def left(self, item: LiveFrame) -> None:
        """Record that ``item`` has left now (its delay, late or not)."""
        delay = (time.monotonic() - item.arrived) * float(self.rate)
        with self._cond:
            self.stats.delays.append(delay)

    @property
    def done(self) -> bool:
        """True once :meth:`finish` was called and every frame has been corrected and pulled."""
        with self._cond:
            return self._done and not self._ready

    def finish(self) -> None:
        """The stream has ended: the frames waiting are still corrected, then :meth:`pull` returns None."""
        with self._cond:
            self._ended = True
            self._cond.notify_all()

    def close(self) -> None:
        """Stop the worker now (frames not yet corrected are dropped, not counted), wait for it and
        for the maps built ahead, and release what they hold (its GL context, on its thread; the
        ``"auto"`` worker). Called at interpreter exit for a corrector not closed by then; again, a no-op."""
        with self._cond:
            self._ended = self._stopped = True
            self._cond.notify_all()
        self._thread.join()
        self._ahead.join()
        if self._online is not None:
            self._online.close()
        if self.tracker is not None:
            self.tracker.close()
        atexit.unregister(self.close)

    def __enter__(self) -> "LiveCorrector":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the worker ----------------------------------------------------------------------------------
    def _next(self):
        """The next frame to correct (dropping those already too late), or None at the end."""
        with self._cond:
            while True:
                while not self._waiting and not self._ended:
                    self._cond.wait()
                if self._stopped or not self._waiting:
                    return None
                item = self._waiting.popleft()
                age = time.monotonic() - item.arrived
                cost = float(np.median(self._costs)) if self._costs else 0.0
                if age * float(self.rate) > self.max_delay or (
                        self._waiting and (age + cost) * float(self.rate) > self.max_delay):
                    self.stats.drop(item.index)
                    continue
                return item

    def _work(self) -> None:
        try:
            while (item := self._next()) is not None:
                started = time.monotonic()
                done = self._correct(*item)
                if self.stats.corrected:  # the first builds maps and opens things: no measure of the rest
                    self._costs.append(time.monotonic() - started - self._waited)
                with self._cond:
                    while len(self._ready) >= READY_SLOTS and not self._stopped:
                        self._cond.wait(0.05)
                    self._ready.append(done)
                    self.stats.corrected += 1
                    self._cond.notify_all()
        except BaseException as err:  # handed to pull()
            self._error = err
        finally:
            self._corrector.release()
            with self._cond:
                self._done = True
                self._cond.notify_all()

    def warm_up(self, frame: np.ndarray | av.VideoFrame, wait: bool = False) -> None:
        """Start building the given lens's maps (and the planar set-up) on ``frame``, one like those
        to come, on a helper thread, so that the stream starts at once: frames that come before the
        maps are ready pass through uncorrected, flagged doubtful (reason ``"pending"``), rather than
        wait and be dropped. ``wait``: build them now instead (every frame corrected, the first ones
        perhaps dropped). Call it before the first :meth:`push`; a no-op for ``"auto"`` (its lenses
        are built ahead as they come), without a lens and for the GL backend."""
        if self.lens is None or self._corrector.backend != "cpu" or self.stats.pushed:
            return
        if isinstance(frame, av.VideoFrame) and not self._takes_planes(frame):
            frame = frame.to_ndarray(format="rgb24")
        if wait:
            _dry_run(self._corrector, frame, self.lens, self.size)
            self._applied = self.lens
        else:
            self._ahead.ready(self.lens, frame)

    def _correct(self, frame, timestamp: float, arrived: float, index: int) -> LiveFrame:
        pts = frame.pts if isinstance(frame, av.VideoFrame) else None
        tracked = self._track(frame, index, arrived) if self.tracker is not None else None
        if self.passthrough:  # tracking only: the frame as it came
            sample = self._sample(index, timestamp, self._state(index, None), tracked) if self.camera is not None else None
            return LiveFrame(index, timestamp, pts, frame, self._state(index, None), sample, arrived, tracked)
        if isinstance(frame, av.VideoFrame) and not self._takes_planes(frame):
            frame = frame.to_ndarray(format="rgb24")
        state = self._state(index, frame)
        if self.lens is not None and self._applied is None and self._ahead.started:  # warm_up's maps not built yet
            if not self._ahead.ready(self.lens, frame):
                state = LensState(0, None, self.lens, None, True, PENDING)
            else:
                self._applied = self.lens
        if self._online is not None and self._corrector.backend == "cpu":  # a new lens: once its maps are built
            wanted = state.applied
            if wanted is None or wanted == self._applied or self._ahead.ready(wanted, frame):
                self._applied = wanted
            state = replace(state, applied=self._applied)
        if isinstance(frame, av.VideoFrame):
            image = self._corrector.planar(frame, state.applied, self.frames, pts)
        else:
            image = frame if state.applied is None else self._corrector(frame, state.applied)
        sample = self._sample(index, timestamp, state, tracked) if self.camera is not None else None
        return LiveFrame(index, timestamp, pts, image, state, sample, arrived, tracked)

    def _track(self, frame, index: int, arrived: float):
        """The frame's camera (the tracker's push), allowed to wait for a fit about to land while no
        frame waits behind it and it can still leave within ``max_delay`` - 1 frame periods (its
        correction's median time kept for it; one period kept for the frames behind it; no wait with
        ``max_delay`` 1); the time waited is kept out of the correction's measured cost."""
        cost = float(np.median(self._costs)) if self._costs else 0.0
        slack = 0.0 if self._waiting else arrived + (self.max_delay - 1) / float(self.rate) - cost - time.monotonic()
        tracked = self.tracker.push(frame, index / float(self.rate), wait=max(0.0, slack))
        self._waited = self.tracker.waited
        return tracked

    def _twin(self) -> FrameCorrector:
        """A corrector like the worker's (same options and planes), for :class:`_MapsAhead`."""
        twin = FrameCorrector(self._corrector.backend, self._corrector.fit, self._corrector.interpolation)
        twin.lattices, twin.black = getattr(self._corrector, "lattices", None), getattr(self._corrector, "black", None)
        return twin

    def _takes_planes(self, frame: av.VideoFrame) -> bool:
        """Whether planar frames are corrected in YUV (decided on the first frame)."""
        if self._planar is None:
            pix_fmt = frame.format.name
            self._planar = (self._corrector.backend == "cpu" and yuv_layout(pix_fmt) is not None
                            and (self.frames is None or self.frames.takes_planes_of(pix_fmt)))
            if self._planar:
                self._corrector.use_planes(VideoInfo.of(self.size, self.rate, codec=self.codec, pix_fmt=pix_fmt),
                                           frame.color_range == 2)
                self.frames = self.frames or _NewFrames(self.size, pix_fmt)
        return self._planar and frame.format.name == self.frames.pix_fmt

    def _state(self, index: int, frame) -> LensState:
        if self._online is None:
            return LensState(shot=0, applied=self.lens, reported=self.lens or IDENTITY, uncertainty_px=None, doubtful=False,
                             reason="")
        return self._online.observe(index, _thumbnail(frame), lambda: _sample_copy(frame))

    def _sample(self, index: int, timestamp: float, state: LensState, tracked=None) -> dict:
        from ..export.engines import MODEL_UD
        from ..export.opentrackio import camera_frame_sample, frame_sample, lens_object

        lens, model = state.reported, self.model or MODEL_UD
        if self.tracker is not None:
            fields = tracked.fields() if tracked is not None else {"doubtful": True, "reason": PENDING}
            while len(self._objects) > LENS_OBJECTS:
                self._objects.popitem(last=False)
            return camera_frame_sample(fields, self.camera, index, self.source_id, model=model,
                                       timestamp_s=timestamp if timestamp >= 0 else None, lens_objects=self._objects)
        objects = self._objects.get(lens)
        if objects is None:
            objects = self._objects[lens] = lens_object(lens, self.camera, model=model)
            while len(self._objects) > LENS_OBJECTS:
                self._objects.popitem(last=False)
        estimated = self._online is not None
        uncertainty = (state.uncertainty_px if state.uncertainty_px is not None else float("nan")) if estimated else None
        return frame_sample(lens, self.camera, index, self.source_id, model=model, uncertainty_px=uncertainty,
                            doubtful=state.doubtful if estimated or state.doubtful else None, shot=state.shot if estimated else None,
                            timestamp_s=timestamp if timestamp >= 0 else None, lens_and_error=objects)


def _thumbnail(frame) -> np.ndarray:
    """The cut detector's uint8 RGB thumbnail of a frame (array or av.VideoFrame)."""
    if isinstance(frame, av.VideoFrame):
        return frame.reformat(width=THUMB_SIZE[0], height=THUMB_SIZE[1], format="rgb24").to_ndarray()
    return cv2.resize(to_rgb8(frame), THUMB_SIZE, interpolation=cv2.INTER_AREA)


def _sample_copy(frame) -> np.ndarray:
    """A uint8 RGB copy of a frame at most :data:`~glradial.video.live_lens.SAMPLE_WIDTH` px wide."""
    width, height = (frame.width, frame.height) if isinstance(frame, av.VideoFrame) else (frame.shape[1], frame.shape[0])
    scale = min(1.0, SAMPLE_WIDTH / width)
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    if isinstance(frame, av.VideoFrame):
        return frame.reformat(width=size[0], height=size[1], format="rgb24", interpolation="AREA").to_ndarray()
    image = to_rgb8(frame)
    return image if scale == 1.0 else cv2.resize(image, size, interpolation=cv2.INTER_AREA)
