"""The camera of a live stream, every frame, causally (``glradial live --camera``).

Two halves, one per speed:

* **the fit** (slow, ~1 s a frame on a shared 2-core machine): a worker (a process by default, as
  :mod:`glradial.video.live_lens`'s) runs :func:`glradial.camera.calibrate.calibrate` on the newest
  frame whenever it is free, tracked from that frame's propagated camera when there is one (the
  existing tracking path: refined from the previous camera, a fresh search where that fit is
  doubtful, e.g. after a cut);
* **the motion** (fast, ~10 ms a frame): corners of a gray copy at most :data:`FLOW_WIDTH` px
  wide are followed from frame to frame by pyramidal Lucas-Kanade (checked backwards, refilled
  when fewer than :data:`REFILL` are left), players dropped by a RANSAC homography of the points
  undistorted with the fit's lens, and the frame-to-frame homographies chained
  (:func:`glradial.video.frame_motion.match_frames` does the same for files, afresh for each
  pair: four times slower). The newest sure fit, of frame ``k``, is
  carried to frame ``t`` by the chained motion ``k -> t`` as a broadcast camera moves: about its
  fixed centre (pan, tilt, roll) and by its zoom (focal length); position and lens stay the fit's
  (:func:`motion_of_homography`, :func:`glradial.tracking.camera_track.carry`).

A frame's camera is sure when the fit it comes from is sure, the motion has not broken since (a
cut or a frame with too little texture breaks it) and that fit is at most ``max_carry`` frames old.
Otherwise it is doubtful, with a reason: calibrate's (:data:`glradial.camera.estimate.REASONS`)
or :data:`PENDING` (no fit yet), :data:`LOST` (the motion broke since the last sure fit) or
:data:`STALE` (the fit is older than ``max_carry`` frames); a doubtful frame carries no camera
unless its fit found one (never a guess presented as sure). Its ``uncertainty_px`` is the fit's
(``calibrate``'s 90 % bound, px at 1280 wide): the drift of the carried motion is measured by
``bench/bench_live_camera.py``, not added to it.

The one place that makes the tracker is :func:`camera_tracker`: a tracker with the same
``for_stream(size, rate)`` and ``push(frame, timestamp) -> LiveCamera`` replaces this one there.
:class:`glradial.tracking.camera_track.CameraTracker` is causal too but measures inside its
``push`` (a full search while it holds no camera: seconds a frame on 2 cores), which a live frame
cannot wait for; this tracker runs the measurement beside the frames instead.
"""

from __future__ import annotations

import atexit
import contextlib
import math
import multiprocessing
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, replace
from fractions import Fraction

import av
import cv2
import numpy as np

from ..camera.estimate import CameraEstimate
from ..camera.model import Camera
from ..camera.white_lines import DETECT_WIDTH
from ..errors import check_count
from ..lens.lens import lens_to_pixels, pixels_to_lens
from ..lens.lensfuncs import undistort_point_exact
from ..lens.options import LIVE_WORKERS, check_choice
from ..video.frame_motion import FB_MAX_PX, MIN_MATCHES, RANSAC_PX, RANSAC_SEED, homography_of
from ..video.live_lens import PENDING, WarmWorker, serve_jobs
from .camera_track import Motion, carry

__all__ = ["LiveCamera", "LiveCameraTracker", "camera_tracker", "motion_of_homography", "PENDING", "LOST", "STALE",
           "LIVE_REASONS"]

#: the frame-to-frame motion broke (a cut, no texture) since the last sure fit (calibrate's own
#: reason for a camera the track lost, :data:`glradial.camera.estimate.REASONS`)
LOST = "track_lost"
#: the last sure fit is older than ``max_carry`` frames
STALE = "stale"
#: a live frame's doubt reasons beyond calibrate's (:data:`glradial.camera.estimate.REASONS`)
LIVE_REASONS = (PENDING, STALE)
#: seconds a fit may be carried by the motion before its frames are doubtful (``max_carry`` = this x rate)
MAX_CARRY_S = 4.0
#: frames whose chained motion is kept (a fit of an older frame can no longer be carried)
MOTION_KEPT = 256
#: the motion's gray copies are at most this wide (px), the frame shrunk by a whole factor (area
#: averaging: a 1280-wide frame by 2, 1920 by 3)
FLOW_WIDTH = 640
#: corners followed at most, and fewer than which new ones are found
FLOW_POINTS, REFILL = 200, 120
#: Lucas-Kanade's window (px of the copy) and pyramid levels
FLOW_WINDOW, FLOW_LEVELS = (15, 15), 2
#: the fit worker process's niceness (added): the frames' motion and samples come first
WORKER_NICENESS = 5


@dataclass(frozen=True)
class LiveCamera:
    """The camera of one frame of a live stream: its ``index``, the ``estimate`` (a
    :class:`~glradial.camera.estimate.CameraEstimate` whose camera is the fit's carried to this frame;
    None while no fit applies), ``doubtful``, ``reason`` ("ok" when sure; calibrate's reasons or
    :data:`LIVE_REASONS`), ``uncertainty_px`` (the fit's bound, px at 1280; NaN without one) and
    ``fit_index`` (the frame the fit was made on; -1 without one)."""

    index: int
    estimate: CameraEstimate | None
    doubtful: bool
    reason: str
    uncertainty_px: float
    fit_index: int

    @property
    def camera(self) -> Camera | None:
        return None if self.estimate is None else self.estimate.camera

    def fields(self) -> dict:
        """The frame's fields as ``glradial calibrate --json`` writes them (homography, k1, k2,
        doubtful, reason, uncertainty_px, focal, position_m, pan/tilt/roll_deg, ...), with this
        frame's doubt and reason, and ``fit_frame`` (the frame the fit was made on)."""
        out = self.estimate.as_dict() if self.estimate is not None else {}
        out.update(doubtful=self.doubtful, reason=self.reason, fit_frame=self.fit_index,
                   uncertainty_px=self.uncertainty_px if math.isfinite(self.uncertainty_px) else None)
        return out


def motion_of_homography(camera: Camera, motion: np.ndarray) -> Motion | None:
    """The :class:`~glradial.tracking.camera_track.Motion` (turn and zoom about the fixed centre) of
    ``camera`` that a homography ``motion`` of its undistorted lens units to a later frame's is,
    ``motion ~ K_t R K_k^-1`` with ``K = diag(f, f, 1)`` (focal in image widths): the new focal
    length balances the rows' norms, the turn is the nearest rotation (SVD); residual 0 (unknown
    here). None where the homography is no camera turn (degenerate)."""
    a = np.asarray(motion, np.float64) @ np.diag([camera.focal, camera.focal, 1.0])
    norms = np.linalg.norm(a, axis=1)
    if not np.all(np.isfinite(a)) or norms[2] <= 0:
        return None
    focal = float((norms[0] + norms[1]) / (2.0 * norms[2]))
    if not focal > 0:
        return None
    u, _, vt = np.linalg.svd(np.diag([1.0 / focal, 1.0 / focal, 1.0]) @ a)
    turn = u @ vt
    if np.linalg.det(turn) < 0:
        turn = -turn
    return Motion(turn, focal / camera.focal, 0.0)


class _Flow:
    """Corners followed from frame to frame (module docstring): :meth:`step` gives the homography
    of the previous frame's undistorted lens units to this one's, or None where the motion breaks."""

    def __init__(self) -> None:
        self.gray: np.ndarray | None = None
        self.points: np.ndarray | None = None

    def step(self, gray: np.ndarray, hint: tuple[float, float]) -> np.ndarray | None:
        previous, self.gray = self.gray, gray
        if previous is None or previous.shape != gray.shape:
            self.points = None
            return None
        if self.points is None or len(self.points) < REFILL:
            self.points = _corners(previous)
            if self.points is None:
                return None
        start = self.points
        params = dict(winSize=FLOW_WINDOW, maxLevel=FLOW_LEVELS, criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 0.03))
        end, ok, _ = cv2.calcOpticalFlowPyrLK(previous, gray, start, None, **params)
        back, ok_back, _ = cv2.calcOpticalFlowPyrLK(gray, previous, end, start.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **params)
        height, width = gray.shape
        q = end.reshape(-1, 2)
        keep = ((ok.ravel() == 1) & (ok_back.ravel() == 1) & (np.linalg.norm((back - start).reshape(-1, 2), axis=1) <= FB_MAX_PX)
                & (q[:, 0] >= 0) & (q[:, 0] < width) & (q[:, 1] >= 0) & (q[:, 1] < height))
        self.points = None
        if keep.sum() < MIN_MATCHES:
            return None
        size = (width, height)
        ua, va = undistort_point_exact(pixels_to_lens(start.reshape(-1, 2)[keep].astype(np.float64), size), *hint)
        ub, vb = undistort_point_exact(pixels_to_lens(q[keep].astype(np.float64), size), *hint)
        cv2.setRNGSeed(RANSAC_SEED)
        _, inliers = cv2.findHomography(lens_to_pixels(ua, size), lens_to_pixels(ub, size), cv2.RANSAC, RANSAC_PX,
                                        maxIters=300, confidence=0.99)
        good = None if inliers is None else (inliers.ravel() == 1) & va & vb
        if good is None or good.sum() < MIN_MATCHES:
            return None
        self.points = end[keep][good]
        return homography_of(ua[good], ub[good])


def _corners(gray: np.ndarray) -> np.ndarray | None:
    """Corners of a gray copy to follow (float32 N x 1 x 2), away from the border (overlays)."""
    mask = np.zeros_like(gray)
    mask[8:-8, 8:-8] = 255
    corners = cv2.goodFeaturesToTrack(gray, FLOW_POINTS, 0.01, 8, mask=mask, blockSize=7)
    return None if corners is None or len(corners) < MIN_MATCHES else corners.astype(np.float32)


def _luma(frame) -> np.ndarray:
    """The gray copy the motion is matched on: the luma plane of a YUV ``av.VideoFrame`` (no
    conversion), else the RGB frame's gray."""
    if isinstance(frame, av.VideoFrame):
        if frame.format.name.startswith(("yuv", "yuvj", "nv12")):
            plane = frame.planes[0]
            rows = np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)
            return _shrunk(rows[:, :plane.width])
        frame = frame.to_ndarray(format="rgb24")
    return _shrunk(cv2.cvtColor(np.asarray(frame), cv2.COLOR_RGB2GRAY))


def _shrunk(gray: np.ndarray) -> np.ndarray:
    """A uint8 gray frame shrunk by the whole factor that brings it to at most :data:`FLOW_WIDTH` px."""
    factor = -(-gray.shape[1] // FLOW_WIDTH)
    if factor == 1:
        return np.ascontiguousarray(gray)
    size = (gray.shape[1] // factor, gray.shape[0] // factor)
    return cv2.resize(gray[: size[1] * factor, : size[0] * factor], size, interpolation=cv2.INTER_AREA)


def _fit_copy(frame) -> np.ndarray:
    """The RGB copy of a frame that the fit is made on: at most :data:`~glradial.camera.white_lines.DETECT_WIDTH`
    px wide (area interpolation; the white lines are found on such a copy whatever the frame's size,
    so nothing is lost), converted and shrunk in one pass for an ``av.VideoFrame``: less to convert
    on the frame thread and to send to the worker (1.5 MB instead of 2.8 MB at 720p, 6.2 MB at 1080p)."""
    width, height = (frame.width, frame.height) if isinstance(frame, av.VideoFrame) else (frame.shape[1], frame.shape[0])
    size = (width, height) if width <= DETECT_WIDTH else (DETECT_WIDTH, max(2, round(height * DETECT_WIDTH / width)))
    if isinstance(frame, av.VideoFrame):
        return frame.reformat(width=size[0], height=size[1], format="rgb24", interpolation="AREA").to_ndarray()
    rgb = np.asarray(frame)
    return rgb if size == (width, height) else cv2.resize(rgb, size, interpolation=cv2.INTER_AREA)


def _serve(connection, duty: float, niceness: int = 0, size: tuple[int, int] = (1280, 720)) -> None:
    """The fit worker: warms up on a procedural view (imports, first-call set-up), says ``("ready",)``,
    then answers each job ``(index, rgb, previous)`` with ``("fit", index, CameraEstimate, rest_s)``
    (:func:`glradial.video.live_lens.serve_jobs`: ``rest_s`` keeps it to ``duty`` of a core) until None."""
    from ..camera.calibrate import calibrate
    from ..camera.views import random_camera, render_view

    if niceness:
        with contextlib.suppress(OSError):
            os.nice(niceness)  # the frames come first: the fit takes what the correction leaves
    def warm_up() -> None:
        view = render_view(random_camera(np.random.default_rng(0), size), seed=0, players=0)
        calibrate(view.frame, previous=calibrate(view.frame))

    def answer(job: tuple) -> tuple:
        index, rgb, previous = job
        return index, calibrate(rgb, previous=previous)

    serve_jobs(connection, warm_up, answer, duty)


class LiveCameraTracker(WarmWorker):
    """The camera of every frame of a live stream (module docstring). ``size`` (W, H) and ``rate``
    (frames per second) of the stream, or given later to :meth:`for_stream` (a tracker warmed up
    before the stream is opened); ``worker``: ``"process"`` (default), ``"thread"``, or
    ``"inline"`` (the fit runs inside :meth:`push` every ``every`` frames: deterministic, for tests
    and files, not live); ``max_carry``: frames a fit is carried (default :data:`MAX_CARRY_S` s);
    ``duty``: the worker's share of one core at most (it rests between fits; default 1: it fits
    again at once, a process at :data:`WORKER_NICENESS`, so that the frames come first).
    Call :meth:`push` for every frame in order from one thread; :meth:`close` stops the worker."""

    worker_name = "camera"

    def __init__(self, size: tuple[int, int] | None = None, rate: float | Fraction | None = None, *,
                 worker: str = "process", every: int = 1, max_carry: int | None = None, duty: float = 1.0) -> None:
        self.worker = check_choice("worker", worker, LIVE_WORKERS + ("inline",))
        check_count("every", every, unit="frames")
        check_count("max_carry", max_carry, unit="frames", optional=True)
        if not 0 < duty <= 1:
            raise ValueError(f"duty must lie in (0, 1] (a share of one core), got {duty!r}")
        self.every, self._max_carry, self.duty = every, max_carry, float(duty)
        self.size: tuple[int, int] | None = None
        self.rate, self.max_carry, self._index = 0.0, 0, -1
        if size is not None or rate is not None:
            self.for_stream(size, rate)
        self.fits, self.waited = 0, 0.0  # fits taken; seconds the last push waited for one
        self._flow = _Flow()
        self._chain, self._motion = 0, np.eye(3)
        self._history: OrderedDict[int, tuple[int, np.ndarray]] = OrderedDict()
        self._base: tuple[int, CameraEstimate] | None = None  # the newest sure fit
        self._last: tuple[int, CameraEstimate] | None = None  # the newest fit, sure or not
        self._latest: Camera | None = None  # the newest frame's camera (the next fit starts there)
        self._first: float | None = None
        self._ready, self._busy, self._rest_until = worker == "inline", False, 0.0
        self._connection = self._process = None
        if worker != "inline":
            self._start(worker)

    def _start(self, worker: str) -> None:
        if worker == "process":
            context = multiprocessing.get_context("spawn")
            self._connection, theirs = context.Pipe()
            self._process = context.Process(target=_serve, args=(theirs, self.duty, WORKER_NICENESS), name="glradial-live-camera",
                                            daemon=True)
        else:
            self._connection, theirs = multiprocessing.Pipe()
            self._process = threading.Thread(target=_serve, args=(theirs, self.duty), name="glradial-live-camera", daemon=True)
        self._process.start()
        atexit.register(self.close)

    def for_stream(self, size: tuple[int, int], rate: float | Fraction) -> "LiveCameraTracker":
        """Set the stream's ``size`` (W, H px) and ``rate`` (frames per second) before the first
        :meth:`push`; returns the tracker."""
        from ..lens.lens import frame_size

        if not (isinstance(rate, (int, float, Fraction)) and not isinstance(rate, bool) and rate > 0):
            raise ValueError(f"rate must be > 0 frames per second, got {rate!r}")
        if self._index >= 0:
            raise ValueError("for_stream after the first push: a tracker follows one stream")
        self.size, self.rate = frame_size(size), float(rate)
        self.max_carry = self._max_carry or max(1, round(MAX_CARRY_S * self.rate))
        return self

    # -- the frame thread ----------------------------------------------------------------------------
    def push(self, frame: np.ndarray | av.VideoFrame, timestamp: float | None = None, wait: float = 0.0) -> LiveCamera:
        """The camera of the next frame (``H x W x 3`` uint8 RGB, or an ``av.VideoFrame``) whose
        presentation time is ``timestamp`` s (None: one frame period after the previous one).
        ``wait`` (s): where no sure camera reaches this frame and a fit is in flight (the first
        lock-on, or after a cut), wait that long at most for it (the caller's slack within its
        ``max_delay``): a fit that lands meanwhile makes this frame sure too; :attr:`waited` says
        how long this push waited (s)."""
        if self.size is None:
            raise ValueError("push before for_stream(size, rate): the tracker does not know the stream yet")
        self._check_size(frame)
        index = self._number(timestamp)
        while self._connection is not None and self._connection.poll():
            self._receive()
        self._follow(index, _luma(frame))
        self._latest = self._carried(index)
        self.waited = 0.0
        if wait > 0 and self._busy and self._latest is None:
            started = time.monotonic()
            if self._connection.poll(wait):
                self._receive()
                self._latest = self._carried(index)
            self.waited = time.monotonic() - started
        if self.worker == "inline":
            if index % self.every == 0 or self._base is None:
                from ..camera.calibrate import calibrate

                self._answer(index, calibrate(_fit_copy(frame), previous=self._latest))
                self._latest = self._carried(index)
        elif self._ready and not self._busy and time.monotonic() >= self._rest_until:
            self._connection.send((index, np.ascontiguousarray(_fit_copy(frame)), self._latest))
            self._busy = True
        return self._state(index)

    def start_on(self, frame: np.ndarray | av.VideoFrame, timestamp: float = 0.0) -> None:
        """Start the first fit on the stream's first frame now, as soon as it is decoded (before the
        frame thread pushes it: the lock-on comes that much sooner); ``timestamp``: its presentation
        time (s) on the clock :meth:`push` is given (:class:`~glradial.video.live.LiveCorrector`'s:
        0 for the first frame), so that the fit is attributed to that frame even where the frame
        itself is never pushed (dropped: the fit then reaches no frame, which stay doubtful until
        the next). After :meth:`for_stream`, before the first push; the fit is skipped (not the
        clock) for an ``"inline"`` tracker or a worker not ready yet."""
        if self.size is None:
            raise ValueError("start_on before for_stream(size, rate): the tracker does not know the stream yet")
        if self._index >= 0:
            raise ValueError("start_on after the first push: it starts the fit on the first frame")
        self._check_size(frame)
        self._first = float(timestamp)
        if self.worker != "inline" and self._ready and not self._busy:
            self._connection.send((0, np.ascontiguousarray(_fit_copy(frame)), None))
            self._busy = True

    def _check_size(self, frame: np.ndarray | av.VideoFrame) -> None:
        width, height = (frame.width, frame.height) if isinstance(frame, av.VideoFrame) else (frame.shape[1], frame.shape[0])
        if (width, height) != self.size:
            raise ValueError(f"frame must be {self.size[0]}x{self.size[1]} (the stream's size), got {width}x{height}")

    def _number(self, timestamp: float | None) -> int:
        if timestamp is None:
            index = self._index + 1
        else:
            self._first = float(timestamp) if self._first is None else self._first
            index = max(round((float(timestamp) - self._first) * self.rate), self._index + 1)
        self._index = index
        return index

    def _follow(self, index: int, gray: np.ndarray) -> None:
        """Chain the motion from the previous frame to this one (a new chain where it breaks)."""
        lens = self._base[1].camera.lens if self._base is not None else None
        step = self._flow.step(gray, (lens.k1, lens.k2) if lens is not None else (0.0, 0.0))
        if step is None:
            self._chain, self._motion = self._chain + 1, np.eye(3)
        else:
            self._motion = step @ self._motion
            self._motion /= self._motion[2, 2]
        self._history[index] = (self._chain, self._motion.copy())
        while len(self._history) > MOTION_KEPT:
            self._history.popitem(last=False)

    def _carried(self, index: int) -> Camera | None:
        """The newest sure fit carried to frame ``index`` (None when it cannot be)."""
        if self._base is None:
            return None
        fit_index, estimate = self._base
        then, now = self._history.get(fit_index), self._history.get(index)
        if then is None or now is None or then[0] != now[0]:
            return None
        motion = motion_of_homography(estimate.camera, now[1] @ np.linalg.inv(then[1]))
        return None if motion is None else carry(estimate.camera, motion)

    def _receive(self) -> None:
        message = self._reply()
        if message is None:
            return
        _, index, estimate, rest = message
        sure = not estimate.doubtful  # resting after a doubtful fit would only delay the lock-on
        self._busy, self._rest_until = False, time.monotonic() + (rest if sure else 0.0)
        self._answer(index, estimate)

    def _answer(self, index: int, estimate: CameraEstimate) -> None:
        """Take the fit of frame ``index`` (made on :func:`_fit_copy`: its camera seeing the stream's size)."""
        if estimate.camera is not None:
            estimate = replace(estimate, camera=estimate.camera.with_size(self.size))
        self.fits += 1
        self._last = (index, estimate)
        if not estimate.doubtful and estimate.camera is not None:
            self._base = (index, estimate)

    def _state(self, index: int) -> LiveCamera:
        if self._base is None:
            if self._last is None:
                return LiveCamera(index, None, True, PENDING, math.nan, -1)
            fit_index, estimate = self._last
            return LiveCamera(index, None, True, estimate.reason, estimate.uncertainty_px, fit_index)
        fit_index, estimate = self._base
        camera = self._latest
        if camera is None:
            return LiveCamera(index, None, True, LOST, estimate.uncertainty_px, fit_index)
        carried = replace(estimate, camera=camera, carried=index - fit_index)
        stale = index - fit_index > self.max_carry
        return LiveCamera(index, carried, stale, STALE if stale else "ok", estimate.uncertainty_px, fit_index)

    def close(self) -> None:
        """Stop the worker (a process abandons its fit, terminated after 5 s; a thread finishes it).
        Called at exit for a tracker not closed by then; again, a no-op."""
        atexit.unregister(self.close)
        if self._connection is None or self._connection.closed:
            return
        try:
            self._connection.send(None)
        except OSError:
            pass
        self._process.join(timeout=None if isinstance(self._process, threading.Thread) else 5.0)
        if not isinstance(self._process, threading.Thread) and self._process.is_alive():
            self._process.terminate()
            self._process.join()
        self._connection.close()


def camera_tracker(**options: object) -> LiveCameraTracker:
    """The live camera tracker of ``glradial live --camera``, its worker warmed up (the stream is
    given later, :meth:`LiveCameraTracker.for_stream`): the one place that chooses it (a causal tracker
    with ``for_stream(size, rate)``, ``start_on(first_frame)`` and ``push(frame, timestamp, wait=) -> LiveCamera``
    swaps in here)."""
    return LiveCameraTracker.started(**options)
