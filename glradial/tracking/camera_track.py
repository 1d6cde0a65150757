"""The camera followed through a shot: a frame that alone would be declined takes the camera carried
from its sure neighbours by frame-to-frame motion, and the camera is smooth where it moves smoothly.

Model: a broadcast (or fixed) camera turns and zooms about a fixed centre, so two frames of one shot
are related by the plane homography ``H = K_b R K_a⁻¹`` of their undistorted lens points
(:mod:`glradial.video.frame_motion`: corners tracked by Lucas-Kanade on a 640-px gray copy, players
dropped by RANSAC). :func:`carry` reads the new focal length and rotation from ``H``, the position
kept. Each frame:

1. **predict**: the previous frame's camera carried by the motion (the same camera when there was
   no previous frame or the motion was not found);
2. **measure**: the white-line points refit from the prediction (the short tracking gates of
   :func:`glradial.calibrate`, lens free), judged by
   :func:`glradial.camera.calibrate.judge_fit` (the doubt rule is calibrate's, untouched). Without any
   camera yet, glradial's full search runs instead, at most every :data:`SEARCH_EVERY` frames. A still
   camera pools the white-line points of up to :data:`POOL` earlier frames :data:`POOL_SPACING` apart
   (players cover other parts of the lines in each), so its measurement sees more of the markings
   than any one frame. Once the
   track holds a sure camera, this step runs on every :data:`MEASURE_EVERY` th frame only, and on
   each frame that zooms (:data:`ZOOMING`: the lens changes with the focal length);
3. **correct**: a sure measurement pulls the prediction toward it by :data:`GAIN` (rotation on the
   sphere, focal length in log, position and lens linearly): the motion carries what changes fast,
   the markings correct drift (a complementary filter, no lag on a pan). A sure measurement farther
   from the prediction than its own bound plus the prediction's takes over outright (the track had
   drifted); on a zooming frame the lens is the measured one (it changes with the focal length). A
   doubtful measurement leaves the prediction alone.

The bound: a measured frame states the bound of its measurement (px at 1280, as
:class:`glradial.CameraEstimate`); a carried frame the bound of the last sure frame grown by the
motion's standard error and :data:`DRIFT_PX` per frame, ``carried`` counting the frames since it. A carried
camera is sure while the motion is found, its bound stays under :data:`MAX_BOUND_PX` and the frames
since the last sure one under :data:`MAX_CARRIED`; past either, or without a sure frame yet, doubtful (``track_lost``, or the
measurement's own reason).

:class:`CameraTracker` is causal (``push(frame, time)``, one frame in, its camera out: ``glradial
live``); :func:`track_cameras` runs it forward and a second filter backward over the same motions
for a file, each frame taking the surer of the two (the two averaged where both are sure: a
smoother with no lag either way; where the forward pass had no camera yet, the backward one reads
the motion from the same matched points with its own camera), in blocks, ``lag`` to ``2 lag``
frames behind the newest frame read.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..camera.calibrate import FINE_POINTS, TRACK_GATES, calibrate_points, check_pitch, judge_fit
from ..camera.estimate import CameraEstimate
from ..camera.model import Camera
from ..camera.refine import refine
from ..camera.white_lines import LinePoints, line_points
from ..lens.lens import Lens
from ..lens.lensfuncs import undistort_point_exact
from ..media.frames import to_rgb8
from ..pitch.template import PitchTemplate
from ..video.frame_motion import match_frames, motion_gray

__all__ = ["CameraTracker", "Motion", "TrackStep", "carry", "motion_between", "motion_of", "track_cameras"]

#: Share of the way a sure measurement pulls the carried camera (per measured frame).
GAIN = 0.3
#: Growth of a carried camera's bound per frame (px at 1280) on top of the motion's residual.
DRIFT_PX = 0.1
#: A carried camera is doubtful past this bound (px at 1280) or this many frames since a sure one.
MAX_BOUND_PX, MAX_CARRIED = 20.0, 250
#: Once the track holds a sure camera, the markings are measured on every this many frames (the
#: white-line points and their refit cost some 5 times the motion; the motion carries the others).
MEASURE_EVERY = 5
#: A frame that zooms by more than this (|ln f_b / f_a|) is measured too: a zoom lens's distortion
#: changes with its focal length, which the motion does not carry.
ZOOMING = 0.002
#: Without any camera, glradial's full search (seconds a frame) runs at most every this many frames.
SEARCH_EVERY = 10
#: A still camera (its motion since the oldest pooled frame under :data:`STILL_PX` px at 1280 at
#: the frame's corners) measures on its own white-line points and those of up to :data:`POOL` earlier
#: frames at least :data:`POOL_SPACING` frames apart (players move some metres in 0.2 s: each frame
#: hides other parts of the lines).
POOL, POOL_SPACING, STILL_PX = 8, 5, 1.0
#: Report width of bounds and residuals (px).
_WIDTH = 1280.0


@dataclass(frozen=True)
class Motion:
    """How the camera moved between two frames of a shot about its fixed centre: ``turn`` (3 x 3, the
    first frame's camera axes to the second's: ``R_b = turn @ R_a``), ``zoom`` (``f_b / f_a``) and
    ``residual_px`` (the matched points' RMS misfit times ``sqrt(4 / N)``: the standard error of the
    fitted motion, px at 1280)."""

    turn: np.ndarray
    zoom: float
    residual_px: float

    def inverse(self) -> "Motion":
        """The motion from the second frame back to the first."""
        return Motion(self.turn.T, 1.0 / self.zoom, self.residual_px)

    def shift_px(self, focal: float) -> float:
        """The largest shift (px at 1280) this motion gives a point at the frame's corner, for a
        camera of focal length ``focal`` (image widths): the turn's angle and the zoom, to first order."""
        angle = float(np.linalg.norm(Rotation.from_matrix(self.turn).as_rotvec()))
        return _WIDTH * (focal * angle * (1 + 0.34 / focal ** 2) + 0.58 * abs(math.log(self.zoom)))


def motion_of(camera: Camera, a: np.ndarray, b: np.ndarray) -> Motion | None:
    """The turn and zoom of ``camera`` to the next frame of its shot from matched points ``a`` of its
    frame and ``b`` of the next (N x 2, N >= 4, lens units: image width 1, centred; undistorted with
    ``camera``'s lens): the rotation ``R`` and zoom that best take ``a`` to ``b`` as
    ``K_b R K_a⁻¹`` (``K = diag(f, f, 1)``), a robust least squares of four parameters (a turn and a
    zoom fix the motion of a camera about its centre far better than the eight of a free homography,
    whose perspective terms the points of one frame pin down poorly). ``None`` when the fit fails."""
    fa = camera.focal
    ra = np.c_[a / fa, np.ones(len(a))]

    def residuals(x: np.ndarray) -> np.ndarray:
        q = ra @ Rotation.from_rotvec(x[:3]).as_matrix().T
        with np.errstate(divide="ignore", invalid="ignore"):
            return (fa * math.exp(x[3]) * q[:, :2] / q[:, 2:3] - b).ravel()

    fit = least_squares(residuals, np.zeros(4), loss="soft_l1", f_scale=2.0 / _WIDTH, x_scale=1e-3)
    if not fit.success or not np.all(np.isfinite(fit.fun)):
        return None
    # the residual of one point over the square root of the points per parameter: how far the fitted
    # motion itself may be off (px at 1280), what a carried camera's bound grows by
    rms = float(np.sqrt(np.mean(fit.fun ** 2) * 2)) * _WIDTH
    return Motion(Rotation.from_rotvec(fit.x[:3]).as_matrix(), math.exp(fit.x[3]), rms * math.sqrt(4.0 / len(a)))


def carry(camera: Camera, motion: Motion) -> Camera:
    """``camera`` moved by ``motion``: the same centre and lens, turned and zoomed."""
    return Camera(motion.turn @ camera.rotation, camera.position, camera.focal * motion.zoom, camera.size, camera.lens)


def blend(a: Camera, b: Camera, weight: float, lens_weight: float | None = None) -> Camera:
    """The camera ``weight`` of the way from ``a`` to ``b`` (rotation on the sphere, focal length in
    log, position linearly) and its lens ``lens_weight`` of the way (default ``weight``; linearly)."""
    lw = weight if lens_weight is None else lens_weight
    turn = Rotation.from_matrix(b.rotation @ a.rotation.T).as_rotvec() * weight
    focal = math.exp((1 - weight) * math.log(a.focal) + weight * math.log(b.focal))
    lens = Lens((1 - lw) * a.lens.k1 + lw * b.lens.k1, (1 - lw) * a.lens.k2 + lw * b.lens.k2)
    return Camera(Rotation.from_rotvec(turn).as_matrix() @ a.rotation, (1 - weight) * a.position + weight * b.position,
                  focal, a.size, lens)


def camera_gap_px(a: Camera, b: Camera, pitch: PitchTemplate) -> float:
    """RMS distance (px at 1280) between where ``a`` and ``b`` put the pitch.keypoints() in the frame."""
    pa, pb = a.project(pitch.keypoints()), b.project(pitch.keypoints())
    d = np.linalg.norm(pa - pb, axis=1)
    d = d[np.isfinite(d)]
    return math.inf if len(d) == 0 else float(np.sqrt(np.mean(d ** 2)) * _WIDTH / a.size[0])


@dataclass(frozen=True)
class TrackStep:
    """One frame's record: ``motion`` (from the previous frame, ``None``: not found, first frame, or
    no camera to read it with), ``measured`` (the frame's own measurement, sure or not; ``None``: none
    ran), ``matches`` (the matched points of the previous frame and this one, distorted lens units,
    for a backward pass to read the motion with its own camera where the forward pass had no sure
    one) and ``read_sure`` (whether ``motion`` was read with a sure camera's focal length and lens)."""

    motion: Motion | None
    measured: CameraEstimate | None
    matches: tuple[np.ndarray, np.ndarray] | None = None
    read_sure: bool = False


def motion_between(camera: Camera, a: np.ndarray, b: np.ndarray) -> Motion | None:
    """:func:`motion_of` for matched points ``a``, ``b`` in distorted lens units, undistorted with
    ``camera``'s lens first; ``None`` with fewer than 4 points both ends of which undistort."""
    lens = camera.lens
    (ua, va), (ub, vb) = undistort_point_exact(a, lens.k1, lens.k2), undistort_point_exact(b, lens.k1, lens.k2)
    ok = va & vb
    return motion_of(camera, ua[ok], ub[ok]) if ok.sum() >= 4 else None


class _Filter:
    """The predict-correct filter over :class:`TrackStep`\\ s (module docstring), in either direction."""

    def __init__(self, pitch: PitchTemplate) -> None:
        self.pitch = pitch
        self.state: CameraEstimate | None = None
        self.carried = 0
        self.anchored = False

    def predict(self, motion: Motion | None) -> Camera | None:
        if self.state is None or self.state.camera is None:
            return None
        return self.state.camera if motion is None else carry(self.state.camera, motion)

    def update(self, predicted: Camera | None, step: TrackStep) -> CameraEstimate:
        measured = step.measured
        sure = measured is not None and not measured.doubtful
        if sure and predicted is not None and self.anchored:
            gap = camera_gap_px(predicted, measured.camera, self.pitch)
            weight = 1.0 if gap > measured.uncertainty_px + self.state.uncertainty_px else GAIN
            zooming = step.motion is not None and abs(math.log(step.motion.zoom)) > ZOOMING
            # a zoom lens's distortion follows its focal length: the measured lens, not a lagging blend
            self.state = replace(measured, camera=blend(predicted, measured.camera, weight, 1.0 if zooming else weight))
        elif sure:
            self.state = measured
        if sure:
            self.carried, self.anchored = 0, True
            return self.state
        return self._carried(predicted, measured, math.nan if step.motion is None else step.motion.residual_px)

    def _carried(self, predicted: Camera | None, measured: CameraEstimate | None, residual_px: float) -> CameraEstimate:
        if not self.anchored and measured is not None and measured.camera is not None and (
                self.state is None or measured.support * measured.inliers > self.state.support * self.state.inliers):
            self.state = measured  # no sure camera yet: the best-supported doubtful one is carried
            return measured
        if predicted is None:  # nothing to carry
            return measured if measured is not None else CameraEstimate(None, 1280.0, True, "no_markings")
        self.carried += 1
        moved = math.isfinite(residual_px)  # the motion was found (else the camera was only kept)
        bound = self.state.uncertainty_px + (residual_px if moved else 0.0) + DRIFT_PX
        lost = not (self.anchored and moved) or bound > MAX_BOUND_PX or self.carried > MAX_CARRIED
        reason = "ok" if not lost else (self.state.reason if not self.anchored else "track_lost")
        self.state = replace(self.state, camera=predicted, uncertainty_px=bound, doubtful=lost, reason=reason,
                             carried=self.carried)
        return self.state


class CameraTracker:
    """The camera of each frame of a shot, causally (module docstring): ``push(frame, time)`` returns
    the frame's :class:`glradial.CameraEstimate` at once, from this frame and the ones before it.

    ``frame``: a uint8/uint16/float RGB or gray array, one size through the tracker; ``time``: its
    time in seconds (optional; kept as :attr:`time`). The estimate's ``carried`` counts the frames since
    the last sure measurement (0: measured on this frame), its ``uncertainty_px`` grows with it
    (px at 1280), and ``doubtful`` says whether to use it (module docstring). :meth:`cut` starts a new
    shot (forgets the camera and the pooled points). :attr:`steps` keeps each frame's
    :class:`TrackStep` (a few hundred bytes) for :func:`track_cameras`' backward pass when
    ``keep_steps``. ``measure_every``: once a sure camera is held, the markings are measured on every
    this many frames (1: every frame; the motion carries the others), on any frame that zooms and on
    any frame whose motion was not found. Not thread-safe: one tracker per stream, used from one thread.

    Args:
        pitch: the pitch template (default: the standard 105 x 68 m pitch).
        measure_every: above (frames, >= 1).
        keep_steps: keep each frame's :class:`TrackStep` for a backward pass.

    Raises:
        ValueError: ``measure_every`` is not a whole number >= 1; ``push`` with a ``time`` that is not
            a finite number.
        TypeError: ``push`` with a ``frame`` that is not a numpy array.

    Example:
        >>> import numpy as np, glradial
        >>> tracker = glradial.CameraTracker()
        >>> grass = np.full((72, 128, 3), (40, 120, 40), np.uint8)  # no markings: no camera, said so
        >>> est = tracker.push(grass, 0.0)
        >>> est.doubtful, est.reason, est.camera is None
        (True, 'no_markings', True)
    """

    def __init__(self, pitch: PitchTemplate | None = None, *, measure_every: int = MEASURE_EVERY,
                 keep_steps: bool = False) -> None:
        if isinstance(measure_every, bool) or not isinstance(measure_every, int) or measure_every < 1:
            raise ValueError(f"measure_every must be a whole number of frames >= 1, got {measure_every!r}")
        self.pitch = check_pitch(pitch)
        self.measure_every = measure_every
        self.keep_steps = keep_steps
        self.steps: list[TrackStep] = []
        self.time: float | None = None
        self.cut()

    def cut(self) -> None:
        """A new shot: the next frame starts without a camera."""
        self._filter = _Filter(self.pitch)
        self._gray: np.ndarray | None = None
        self._pool: deque[LinePoints] = deque(maxlen=POOL)
        self._since_search = SEARCH_EVERY
        self._since_measure = 0
        self._drift = 0.0  # px at 1280 the camera moved since the oldest pooled frame
        self._since_pooled = 0

    def push(self, frame: np.ndarray, time: float | None = None) -> CameraEstimate:
        """The camera of the next frame of the shot (class docstring)."""
        if not isinstance(frame, np.ndarray):
            raise TypeError(f"frame must be a numpy image array, got {type(frame).__name__}")
        if time is not None and not (isinstance(time, (int, float)) and math.isfinite(time)):
            raise ValueError(f"time must be a finite number of seconds or None, got {time!r}")
        rgb = to_rgb8(frame)
        gray = motion_gray(rgb)
        if self._gray is not None and self._gray.shape != gray.shape:
            raise ValueError(f"frame size changed within a shot: {self._gray.shape[::-1]} -> {gray.shape[::-1]} "
                             "(call cut() between shots)")
        motion, matches = self._motion(gray)
        self._gray, self.time = gray, time
        predicted = self._filter.predict(motion)
        self._drift += math.inf if motion is None or predicted is None else motion.shift_px(predicted.focal)
        if self._drift > STILL_PX:  # moved since the oldest pooled frame: its points no longer lie here
            self._pool.clear()
            self._drift = 0.0
        self._since_measure += 1
        self._since_pooled += 1
        measured = None
        zooming = motion is not None and abs(math.log(motion.zoom)) > ZOOMING
        if not self._filter.anchored or motion is None or zooming or self._since_measure >= self.measure_every:
            lines = line_points(rgb)
            measured, self._since_measure = self._measure(rgb, lines, predicted), 0
            if not self._pool or self._since_pooled >= POOL_SPACING:
                self._pool.append(lines)
                self._since_pooled = 0
        step = TrackStep(motion, measured, matches if self.keep_steps else None, self._filter.anchored)
        if self.keep_steps:
            self.steps.append(step)
        return self._filter.update(predicted, step)

    def _motion(self, gray: np.ndarray) -> tuple[Motion | None, tuple[np.ndarray, np.ndarray] | None]:
        """The motion from the previous frame (with the camera held, if any) and the matches it comes from."""
        if self._gray is None:
            return None, None
        state = self._filter.state
        camera = None if state is None else state.camera
        lens = (0.0, 0.0) if camera is None else (camera.lens.k1, camera.lens.k2)
        m = match_frames(self._gray, gray, lens)
        if m is None:
            return None, None
        return (None if camera is None else motion_between(camera, m.a, m.b)), (m.a, m.b)

    def _measure(self, rgb: np.ndarray, lines: LinePoints, predicted: Camera | None) -> CameraEstimate | None:
        """The frame's own measurement (module docstring, step 2); ``None`` when none ran."""
        if not self._filter.anchored:
            self._since_search += 1
            if self._since_search >= SEARCH_EVERY:  # no sure camera yet: glradial's own search now and then
                self._since_search = 0
                return calibrate_points(rgb, lines, self.pitch, None, None)
            if predicted is None:
                return None
        pooled = _pooled([*self._pool, lines])
        if len(pooled.xy) < 12:
            return judge_fit(None, len(pooled.xy))
        fine = pooled.thinned(FINE_POINTS)
        fit = refine(predicted, fine.xy, fine.angle, self.pitch, gates=TRACK_GATES, lens_from=1, support_xy=pooled.xy)
        return judge_fit(fit, len(pooled.xy))


def _pooled(pool: Iterable[LinePoints]) -> LinePoints:
    pool = list(pool)
    if len(pool) == 1:
        return pool[0]
    return LinePoints(np.concatenate([p.xy for p in pool]), np.concatenate([p.angle for p in pool]), pool[-1].size)


def _backward(steps: list[TrackStep], pitch: PitchTemplate, start: int) -> list[CameraEstimate | None]:
    """The backward filter's estimates of frames ``start ..`` of ``steps``, run from the newest."""
    back, out = _Filter(pitch), [None] * (len(steps) - start)
    for i in range(len(steps) - 1, start - 1, -1):
        following = steps[i + 1] if i + 1 < len(steps) else None
        inverse = None
        if following is not None and following.motion is not None and following.read_sure:
            inverse = following.motion.inverse()
        elif following is not None and following.matches is not None and back.state is not None \
                and back.state.camera is not None:  # the forward pass had no sure camera here: read it with ours
            inverse = motion_between(back.state.camera, following.matches[1], following.matches[0])
        out[i - start] = back.update(back.predict(inverse), TrackStep(inverse, steps[i].measured))
    return out


def combine(forward: CameraEstimate, backward: CameraEstimate | None, pitch: PitchTemplate) -> CameraEstimate:
    """The forward and backward estimates of one frame: the sure one, both averaged (weights the
    inverse squared bounds) where both are sure, the forward one otherwise."""
    if backward is None or backward.camera is None or backward.doubtful:
        return forward
    if forward.camera is None or forward.doubtful:
        return backward
    wf, wb = forward.uncertainty_px ** -2, backward.uncertainty_px ** -2
    cam = blend(forward.camera, backward.camera, wb / (wf + wb))
    bound = min(forward.uncertainty_px, backward.uncertainty_px)
    return replace(forward if forward.carried <= backward.carried else backward, camera=cam, uncertainty_px=bound,
                   carried=min(forward.carried, backward.carried))


def track_cameras(frames: Iterable[np.ndarray], *, pitch: PitchTemplate | None = None, lag: int = 25,
                  is_cut: Callable[[np.ndarray], bool] | None = None) -> Iterator[tuple[int, CameraEstimate]]:
    """Each frame's camera of a video, forward and backward (module docstring): yields ``(index,
    estimate)`` in order, in blocks of ``lag`` frames (>= 0; 0: forward only, each frame at once), each
    frame once ``lag`` to ``2 lag`` later frames are read (the backward pass runs once per block over
    them), each shot's last frames at its end. ``is_cut(frame)``: whether a frame starts a new shot
    (e.g. :meth:`glradial.video.cuts.ShotDetector.update`; default: one shot). Keeps the undecided
    frames' records only, not the frames.

    Args:
        frames: the video's frames (RGB or gray arrays, one size), in order.
        pitch: the pitch template (default: the standard pitch).
        lag: above (frames, >= 0).
        is_cut: above.

    Returns:
        An iterator of ``(index, CameraEstimate)``, every frame once, in order.

    Raises:
        ValueError: ``lag`` is not a whole number >= 0 (when iteration starts).

    Example:
        >>> import numpy as np, glradial
        >>> grass = np.full((72, 128, 3), (40, 120, 40), np.uint8)
        >>> [(i, est.doubtful) for i, est in glradial.track_cameras([grass, grass], lag=0)]
        [(0, True), (1, True)]
    """
    if isinstance(lag, bool) or not isinstance(lag, int) or lag < 0:
        raise ValueError(f"lag must be a whole number of frames >= 0, got {lag!r}")
    pitch = check_pitch(pitch)
    tracker = CameraTracker(pitch, keep_steps=True)
    forward: list[CameraEstimate] = []
    base = 0  # the index of forward[0] and tracker.steps[0]
    for index, frame in enumerate(frames):
        if is_cut is not None and is_cut(frame) and index > 0:
            yield from _flush(tracker.steps, forward, pitch, base, index)
            tracker.cut()
            tracker.steps, forward, base = [], [], index
        forward.append(tracker.push(frame))
        if len(forward) > 2 * lag:
            end = index + 1 - lag
            yield from _flush(tracker.steps, forward, pitch, base, end)
            del tracker.steps[: end - base], forward[: end - base]
            base = end
    yield from _flush(tracker.steps, forward, pitch, base, base + len(forward))


def _flush(steps: list[TrackStep], forward: list[CameraEstimate], pitch: PitchTemplate, base: int,
           end: int) -> Iterator[tuple[int, CameraEstimate]]:
    """Frames ``base .. end - 1`` (``forward[0]`` is frame ``base``), the backward pass over every step held."""
    back = _backward(steps, pitch, 0)
    for index in range(base, end):
        yield index, combine(forward[index - base], back[index - base], pitch)
