"""One lens per shot as a function of the zoom: the frames of a shot share one broadcast zoom lens
whose width-normalised ``(k1, k2)`` is a smooth function of the focal length each frame measures.

Model (:class:`ShotLens`): each of ``k1``, ``k2`` a polynomial in ``u = ln(f / f_ref)`` (the zoom
position: a zoom ring is roughly logarithmic in the focal length), ``f`` the focal length in image
widths and ``f_ref`` the shot's median sure focal length, of degree 0 (a constant lens: a zoom range
below :data:`ZOOM_RANGES` [0] or fewer than :data:`MIN_FRAMES` [1] sure frames), 1, or 2 (a zoom
range of at least :data:`ZOOM_RANGES` [1] and :data:`MIN_FRAMES` [2] sure frames). Zoom lenses go
from barrel at the wide end toward pincushion at the tele end, faster at the wide end: a slope and a
bend are what a shot's few-to-few-hundred noisy frames can fix.

Fit (:func:`fit_shot_lens`): over the shot's sure frames (not doubtful), a robust weighted least
squares of the lens's radial map (:func:`glradial.lens.metrics.radial_map`) at radii up to the 16:9
corner, in px of a 1920-wide frame (the unit of :func:`glradial.lens.metrics.max_displacement_px`),
each frame weighted by the inverse of its lens bound (:func:`glradial.camera.estimator.lens_bound_px`,
relative to the shot's median; an unknown bound, a camera wider than calibrated, as the largest known,
all alike when none is known), plain least squares first, then under a Huber loss at the scale of
the residuals' spread (:data:`HUBER_SPREAD`, at least :data:`ROBUST_PX` px): a frame whose own
lens is far off (a bad fit that was still judged sure) barely moves the shot's. At least
``MIN_FRAMES[0]`` sure frames, else no shot model.

Per frame (:class:`ShotCalibrator`, :func:`calibrate_shot`): every frame is calibrated as
:func:`glradial.calibrate` does, tracking from the previous sure frame; at the shot's end, each sure
frame's pose and focal length are refit with the lens fixed at the shot model's lens at its focal
length (:data:`REFIT_PASSES` times, the lens updated to the new focal length each time), then judged
again. A frame whose refit is doubtful keeps its own estimate; a doubtful frame stays doubtful.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from ..lens.lens import Lens
from ..lens.metrics import CORNER_RADIUS_16_9, REPORT_WIDTH, radial_map
from ..media.frames import to_rgb8
from ..pitch.template import PitchTemplate
from .calibrate import FINE_POINTS, calibrate_points, check_pitch, judge_fit
from .estimate import CameraEstimate
from .estimator import lens_bound_px
from .model import Camera
from .refine import refine
from .white_lines import LinePoints, line_points

#: Sure frames a shot needs for a shot model of degree 0 (constant), 1 and 2 in ``ln(f / f_ref)``.
MIN_FRAMES = (3, 4, 8)
#: Zoom range (largest sure focal length over the smallest) a shot needs for degree 1 and for degree
#: 2. Low: at the wide end a broadcast zoom's distortion moves a 1920-wide frame's corner by several px
#: over a 5 % zoom; and within the range the frames span, a slope or a bend fitted to noise costs
#: little (the model is only read at the frames' own focal lengths).
ZOOM_RANGES = (1.02, 1.2)
#: Radii (lens units) at which the shot model's radial map is compared with each frame's.
FIT_RADII = np.linspace(0.0, CORNER_RADIUS_16_9, 7)[1:]
#: The robust fit's Huber scale: ``HUBER_SPREAD`` times the median frame's RMS residual after a plain
#: fit, at least ``ROBUST_PX`` (px at 1920). Frames within it count fully (noise: as efficient as plain
#: least squares), frames beyond it in proportion to the inverse of their distance (a wrong frame).
ROBUST_PX, HUBER_SPREAD = 0.5, 1.5
#: Gates (px at 1280) of the refit with the shot lens, and how many times it runs.
REFIT_GATES = (6.0, 3.0)
REFIT_PASSES = 2


@dataclass(frozen=True)
class ShotLens:
    """A shot's lens as a function of the focal length: ``k1(f) = sum_j k1_poly[j] u^j`` and
    likewise ``k2``, with ``u = ln(f / focal_ref)`` (width-normalised ``k1``, ``k2``; ``f`` and
    ``focal_ref`` in image widths). ``frames`` sure frames made it, their focal lengths spanning
    ``focal_range`` (image widths).

    Args:
        k1_poly, k2_poly: the polynomials' coefficients, constant first.
        focal_ref: the reference focal length (image widths).
        focal_range: the sure frames' smallest and largest focal length (image widths).
        frames: how many sure frames the fit used.

    Raises:
        ValueError: from :meth:`lens_at`, a focal length that is not a positive number.

    Example:
        >>> import math, glradial
        >>> shot = glradial.ShotLens((-0.2, 0.05), (0.03, 0.0), 1.5, (1.2, 1.9), 40)
        >>> shot.degree, shot.lens_at(1.5).k1, round(shot.lens_at(1.5 * math.e).k1, 6)
        (1, -0.2, -0.15)
    """

    k1_poly: tuple[float, ...]
    k2_poly: tuple[float, ...]
    focal_ref: float
    focal_range: tuple[float, float]
    frames: int

    @property
    def degree(self) -> int:
        """0: one lens for the whole shot; 1, 2: a lens that follows the zoom."""
        return len(self.k1_poly) - 1

    def lens_at(self, focal: float) -> Lens:
        """The lens at focal length ``focal`` (image widths, > 0)."""
        if isinstance(focal, bool) or not (isinstance(focal, (int, float, np.number)) and math.isfinite(focal) and focal > 0):
            raise ValueError(f"focal must be a positive number of image widths, got {focal!r}")
        u = math.log(float(focal) / self.focal_ref)
        return Lens(float(np.polyval(self.k1_poly[::-1], u)), float(np.polyval(self.k2_poly[::-1], u)))

    def as_dict(self) -> dict:
        """JSON-ready summary (``k = sum_j poly[j] ln(focal / focal_ref)^j``, focal in image widths)."""
        return {"degree": self.degree, "k1_poly": list(self.k1_poly), "k2_poly": list(self.k2_poly),
                "focal_ref": self.focal_ref, "focal_range": list(self.focal_range), "frames": self.frames}


def _radial_px(k: np.ndarray) -> np.ndarray:
    """The radial map of lenses ``k`` (N x 2) at :data:`FIT_RADII`, px at 1920 (N x R)."""
    return REPORT_WIDTH * radial_map(FIT_RADII, k)


def _degree(frames: int, zoom: float) -> int:
    """The model's degree for ``frames`` sure frames over a zoom range ``zoom`` (module constants)."""
    degree = 0
    for d, (need, reach) in enumerate(zip(MIN_FRAMES[1:], ZOOM_RANGES), start=1):
        if frames >= need and zoom >= reach:
            degree = d
    return degree


def fit_shot_lens(estimates: Iterable[CameraEstimate]) -> ShotLens | None:
    """The shot's lens model from its frames' estimates (module docstring); ``None`` with fewer than
    ``MIN_FRAMES[0]`` sure frames."""
    estimates = list(estimates)
    for i, e in enumerate(estimates):
        if not isinstance(e, CameraEstimate):
            raise TypeError(f"estimates[{i}] must be a glradial.CameraEstimate, got {e!r}")
    sure = [e for e in estimates if not e.doubtful and e.camera is not None]
    if len(sure) < MIN_FRAMES[0]:
        return None
    focal = np.array([e.focal for e in sure])
    k = np.array([[e.lens.k1, e.lens.k2] for e in sure])
    bound = np.array([lens_bound_px(e) for e in sure])
    known = bound[np.isfinite(bound)]  # inf: wider than the views the bound knows; weighs as the least sure known
    bound = np.where(np.isfinite(bound), bound, known.max() if len(known) else 1.0)
    weight = np.median(bound) / bound
    f_ref = float(np.median(focal))
    powers = np.log(focal / f_ref)[:, None] ** np.arange(_degree(len(sure), float(focal.max() / focal.min())) + 1)
    target = _radial_px(k)

    def residuals(p: np.ndarray) -> np.ndarray:
        model = powers @ p.reshape(2, -1).T
        return ((_radial_px(model) - target) * weight[:, None]).ravel()

    start = np.zeros((2, powers.shape[1]))
    start[:, 0] = np.median(k, axis=0)
    # plain least squares first (a robust loss from a far start would call the frames it cannot yet
    # explain outliers), then the robust loss at the scale of the residuals' spread
    p = least_squares(residuals, start.ravel(), x_scale="jac").x
    spread = np.median(np.sqrt(np.mean(residuals(p).reshape(len(sure), -1) ** 2, axis=1)))
    p = least_squares(residuals, p, loss="huber", f_scale=max(ROBUST_PX, HUBER_SPREAD * spread),
                      x_scale="jac").x.reshape(2, -1)
    return ShotLens(tuple(float(c) for c in p[0]), tuple(float(c) for c in p[1]), f_ref,
                    (float(focal.min()), float(focal.max())), len(sure))


def refit_with_lens(estimate: CameraEstimate, lines: LinePoints, shot: ShotLens,
                    pitch: PitchTemplate | None = None) -> CameraEstimate:
    """``estimate``'s frame refit (pose and focal length) with the lens fixed at ``shot``'s lens at
    its focal length, on the frame's white-line points ``lines`` (module docstring); ``estimate``
    itself when it is doubtful or the refit is."""
    if estimate.doubtful or estimate.camera is None:
        return estimate
    cam, fine, fit = estimate.camera, lines.thinned(FINE_POINTS), None
    for _ in range(REFIT_PASSES):
        start = Camera(cam.rotation, cam.position, cam.focal, lines.size, shot.lens_at(cam.focal))
        fit = refine(start, fine.xy, fine.angle, pitch, fit_lens=False, gates=REFIT_GATES, support_xy=lines.xy)
        if fit is None:
            return estimate
        cam = fit.camera
    refit = judge_fit(fit, len(lines.xy))
    if refit.doubtful:
        return estimate
    # the lens at the focal length the last pass ended on (it moved by a small fraction of a percent)
    return replace(refit, camera=Camera(cam.rotation, cam.position, cam.focal, cam.size, shot.lens_at(cam.focal)))


@dataclass
class ShotCalibrator:
    """Calibrates the frames of one shot, one at a time (:meth:`add`), and at its end (:meth:`finish`)
    refits them with the shot's lens model (module docstring). Keeps each frame's white-line points
    (a few thousand per frame), not the frames.

    Args:
        pitch: the pitch's markings (default FIFA's 105 × 68 m).

    Raises:
        ValueError: a bad ``pitch``; :meth:`add` raises ``TypeError`` for a frame that is not an array.

    Example:
        >>> import numpy as np, glradial
        >>> calibrator = glradial.ShotCalibrator()
        >>> calibrator.add(np.zeros((90, 160, 3), np.uint8)).reason
        'no_markings'
        >>> calibrator.finish().lens_model is None  # too few sure frames for a shot lens
        True
    """

    pitch: PitchTemplate | None = None
    _estimates: list[CameraEstimate] = field(default_factory=list, repr=False)
    _lines: list[LinePoints] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        self.pitch = check_pitch(self.pitch)

    def add(self, frame: np.ndarray) -> CameraEstimate:
        """The frame's own estimate (as :func:`glradial.calibrate`, tracking from the shot's previous
        sure frame): before the shot model."""
        if not isinstance(frame, np.ndarray):
            raise TypeError(f"frame must be a numpy image array, got {type(frame).__name__}")
        rgb = to_rgb8(frame)
        lines = line_points(rgb)
        previous = next((e for e in reversed(self._estimates) if not e.doubtful), None)
        est = calibrate_points(rgb, lines, self.pitch, None, previous)
        self._estimates.append(est)
        self._lines.append(lines)
        return est

    def finish(self) -> "ShotCalibration":
        """The shot's calibration (:class:`ShotCalibration`); the calibrator is then empty, ready
        for the next shot."""
        frames, lines = self._estimates, self._lines
        self._estimates, self._lines = [], []
        shot = fit_shot_lens(frames)
        if shot is None:
            return ShotCalibration(frames, frames, None, [False] * len(frames))
        refit = [refit_with_lens(e, w, shot, self.pitch) for e, w in zip(frames, lines)]
        return ShotCalibration(refit, frames, shot, [r is not e for r, e in zip(refit, frames)])


@dataclass(frozen=True)
class ShotCalibration:
    """One shot's cameras: ``estimates`` (per frame, with the shot's lens where ``from_shot``),
    ``frame_estimates`` (each frame's own, before the shot model) and ``lens_model`` (the
    :class:`ShotLens`, ``None`` when the shot had too few sure frames).

    Args:
        estimates, frame_estimates, lens_model, from_shot: above (one entry per frame).

    Raises:
        Nothing: a plain record made by :meth:`ShotCalibrator.finish`.

    Example:
        >>> import numpy as np, glradial
        >>> shot = glradial.calibrate_shot([np.zeros((90, 160, 3), np.uint8)] * 2)
        >>> isinstance(shot, glradial.ShotCalibration), shot.from_shot
        (True, [False, False])
    """

    estimates: list[CameraEstimate]
    frame_estimates: list[CameraEstimate]
    lens_model: ShotLens | None
    from_shot: list[bool]


def calibrate_shot(frames: Iterable[np.ndarray], *, pitch: PitchTemplate | None = None) -> ShotCalibration:
    """The cameras of the frames of **one shot** (no cut inside: split a video at its cuts first,
    e.g. with :func:`glradial.video.cuts.detect_cuts`) with one lens
    per shot as a function of the measured focal length (module docstring). ``frames``: uint8/uint16/
    float RGB or gray arrays of one size, consumed one at a time.

    Args:
        frames: the shot's frames (a list, a generator or an N×H×W×C array).
        pitch: the pitch's markings (default FIFA's 105 × 68 m).

    Returns:
        A :class:`glradial.ShotCalibration`.

    Raises:
        TypeError: ``frames`` is not an iterable of frames (e.g. one frame).

    Example:
        >>> import numpy as np, glradial
        >>> glradial.calibrate_shot(np.zeros((90, 160, 3), np.uint8))
        Traceback (most recent call last):
        ...
        TypeError: frames must be an iterable of frames (a list, a generator, an N x H x W x C array), got ndarray of shape (90, 160, 3)
        >>> [e.reason for e in glradial.calibrate_shot(np.zeros((2, 90, 160, 3), np.uint8)).estimates]
        ['no_markings', 'no_markings']
    """
    if isinstance(frames, np.ndarray) and frames.ndim < 4 or not isinstance(frames, Iterable):
        raise TypeError(f"frames must be an iterable of frames (a list, a generator, an N x H x W x C array), got {type(frames).__name__}"
                        f"{' of shape ' + str(frames.shape) if isinstance(frames, np.ndarray) else ''}")
    calibrator = ShotCalibrator(pitch)
    for frame in frames:
        calibrator.add(frame)
    return calibrator.finish()
