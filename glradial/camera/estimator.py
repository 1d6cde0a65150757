"""The lens of a frame from both kinds of evidence: the joint camera fit to the pitch template
(:func:`glradial.camera.calibrate.calibrate`) where the template fits, combined with the estimation
layer's reading (the CNN and the line fit, :mod:`glradial.estimation.net_lines`); the estimation
layer's reading alone where it does not.

``method="auto"`` of :func:`estimate` and :class:`Estimator` (what ``glradial.estimate`` and
``glradial.Estimator`` are; a subclass of the estimation layer's ``Estimator``) runs both by default
(``pitch=True``; ``glradial estimate IMG``, ``correct IMG --auto``). When the camera is not doubtful,
the answer is a :class:`glradial.LensEstimate` with ``method="pitch"``:
``k = w k_p + (1 - w) k_a`` (width-normalised ``(k1, k2)``), ``k_p`` the camera's lens
(:func:`camera_lens`, bound ``b_p``: :func:`lens_bound_px`), ``k_a`` the estimation layer's reading
(bound ``b_a``, doubtful or not: its doubt is by benefit and its bound stays calibrated), stating
``w b_p + (1 - w) b_a``, ``w`` = ``lens_weight`` (``glradial/data/camera_trust.json``). Both
bounds are 90 % bounds on the maximum displacement error over the 16:9 frame (px of a 1920-wide frame,
:func:`glradial.lens.metrics.max_displacement_px`; not the camera's bound on the markings'
reprojection, another quantity). The radial map is linear in ``(k1, k2)`` and that error is a norm,
so the combination's error is at most ``w e_p + (1 - w) e_a``, and its stated bound holds whenever
both bounds do. It is doubtful by benefit as the estimation layer's answers are
(``"weak_geometry"`` where the stated bound reaches the identity lens:
:func:`glradial.estimation.trust.shift_px`). ``chains`` is the number of template markings the camera
fit used. When the camera is doubtful, or the estimation layer found no pitch evidence at all (blank,
noise, no grass: the camera fit is then not run), the estimation layer's answer is returned
unchanged; ``pitch=False`` gives it always, bit for bit. ``"net"`` and ``"lines"`` never run the camera fit.

**The camera fit starts from the estimation layer's reading** (:func:`fit_camera`: ``calibrate(frame,
lens=...)``): its search undistorts the white lines with that lens, so a barrel lens no longer hides the
straight lines it looks for (docs/CAMERA.md has the figures).

**The camera's lens** is the fit's ``(k1, k2)`` pulled part of the way (``lens_manifold_pull``) toward the
Lopez-Antequera manifold lens nearest it over the radii to the 16:9 corner (:func:`manifold_lens`,
:func:`camera_lens`): the markings a broadcast frame shows rarely reach its corners, so the fit's ``k2``
trades against ``k1`` along a ridge, which the manifold steadies; the whole way to the manifold throws
away what the fit read off it. Its bound is split-conformal:
``lens_quantile`` times the fit's marking RMS (px at 1280, at least ``lens_floor_px``), in quadrature
with ``lens_shift_weight`` times :func:`centre_shift_px` (how far the lens moves when a principal point
off centre is fitted with it: large where the markings do not pin the lens down), all in
``camera_trust.json`` with the calibration they come from (``bench/pitch_lens_choice.py``).

**Why a fixed weight and not the bounds' inverse variance**: per-frame weights make the answer jump
between two readings that disagree by a frame-wide offset (the line fit reads a larger ``k2`` on the
Bundesliga frames), which costs more than the bounds' per-frame information gains (measured
self-consistently, docs/CAMERA.md, "The lens fed back"). ``lens_weight``, ``lens_manifold_pull``,
``lens_quantile``, ``lens_shift_weight`` (the bound's :func:`centre_shift_px` term), ``lens_agreement``
(:func:`combine`: a reading outside it times the camera lens's bound is dropped) and ``lens_max_hfov_deg`` are chosen on the five shared
matches, leave one match out, under the constraint that the procedural test crops (exact truth) get no
worse (``bench/pitch_lens_choice.py``; docs/CAMERA.md, "The lens fed back across matches").

This lives in the camera layer because it needs both layers: ``estimation`` sits below ``camera`` and
must not import it, so the estimation layer's :class:`~glradial.estimation.net_lines.NetLinesEstimator` stays
the CNN-plus-lines estimator and this module composes the two.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..estimation import decentring
from ..estimation.lens_estimate import LensEstimate, check_method
from ..estimation.net_lines import NetLinesEstimator, default_net_lines_estimator, square_pixels
from ..estimation.trust import NO_EVIDENCE_REASONS, shift_px
from ..lens.lens import Lens, pixels_to_lens
from ..lens.metrics import manifold_k2, max_displacement, max_displacement_px
from ..lens.options import Method
from ..media.frames import to_rgb8
from ..pitch.template import PitchTemplate
from .calibrate import calibrate
from .estimate import CameraEstimate, camera_trust
from .refine import K2_PRIOR, MIN_ELEMENT_POINTS, assign, template_samples
from .white_lines import line_points


def manifold_lens(lens: Lens) -> Lens:
    """The lens on the Lopez-Antequera manifold (``k2 = manifold_k2(k1)``) nearest ``lens`` in max
    displacement over the radii to the 16:9 corner (:func:`glradial.lens.metrics.max_displacement`),
    ``k1`` to 1e-4 (a coarse then a fine grid: the max of ``|d1 r^3 + d2 r^5|`` is not smooth in ``k1``)."""
    k1 = float(lens.k1)
    for half, n in ((1.0, 801), (0.0025, 101)):
        k = np.linspace(k1 - half, k1 + half, n)
        k1 = float(k[np.argmin(max_displacement(np.column_stack([k, manifold_k2(k)]), np.array([lens.k1, lens.k2])))])
    return Lens(k1, float(manifold_k2(k1)))


def pulled_lens(fit: Lens, pull: float) -> Lens:
    """``fit`` pulled toward the manifold lens nearest it (:func:`manifold_lens`) by the share ``pull``:
    ``p m + (1 - p) k``."""
    nearest = manifold_lens(fit)
    return Lens(pull * nearest.k1 + (1 - pull) * fit.k1, pull * nearest.k2 + (1 - pull) * fit.k2)


def camera_lens(camera: CameraEstimate) -> Lens:
    """The lens ``camera``'s fit contributes (see the module docstring, "The camera's lens"): the fit's
    ``(k1, k2)`` pulled toward the manifold lens nearest it by the share ``lens_manifold_pull``
    (``camera_trust.json``; :func:`pulled_lens`)."""
    return pulled_lens(camera.lens, float(camera_trust()["lens_manifold_pull"]))


def pitch_bound_px(rms_px: float, centre_px: float, t: dict) -> float:
    """90 % bound (px at 1920) on the max-displacement error of the camera lens of a fit whose marking
    RMS is ``rms_px`` (px at 1280) and whose lens moves by ``centre_px`` (px at 1920, :func:`centre_shift_px`;
    NaN: not measured, no term) when a principal point off centre is fitted with it: ``lens_quantile``
    times the RMS (at least ``lens_floor_px``) in quadrature with ``lens_shift_weight`` times the shift
    (thresholds ``t``: ``camera_trust.json``)."""
    base = t["lens_quantile"] * max(rms_px, t["lens_floor_px"])
    return float(np.hypot(base, t["lens_shift_weight"] * centre_px) if np.isfinite(centre_px) else base)


def lens_bound_px(camera: CameraEstimate, centre_px: float = float("nan")) -> float:
    """90 % bound (px at 1920) on the max-displacement error of :func:`camera_lens`
    (:func:`pitch_bound_px` of ``camera``'s marking RMS and the lens's ``centre_px``, :func:`centre_shift_px`
    of the frame, under ``glradial/data/camera_trust.json``); ``inf`` for a camera wider than
    ``lens_max_hfov_deg``, the widest sure camera the bound was calibrated on: beyond it no bound is
    known (the real wide camera, 72.4 degrees with its principal point off centre, had its lens 13-16 px
    off against a bound of 7.6 px, docs/CAMERA.md)."""
    t = camera_trust()
    if camera.camera is not None and camera.hfov_deg > float(t["lens_max_hfov_deg"]):
        return float("inf")
    return pitch_bound_px(camera.rms_px, centre_px, t)


#: Gate (px at 1280) within which a white-line point counts as on its marking for :func:`centre_shift_px`.
SHIFT_GATE_PX = 3.0


def centre_shift_px(rgb: np.ndarray, camera: CameraEstimate) -> float:
    """How far ``camera``'s fitted lens moves when decentring terms (a principal point off centre) are
    fitted with it on the straight markings it explains: the white-line points of ``rgb`` within
    :data:`SHIFT_GATE_PX` of each straight marking with at least ``MIN_ELEMENT_POINTS`` of them form
    one chain, read by :func:`glradial.estimation.decentring.centre_shift_px` (px at 1920; NaN with
    fewer than its ``MIN_CHAINS`` chains or no camera). Large where the markings seen cannot tell the
    fitted centred lens from a decentred one: the lens is not pinned down by the pitch."""
    cam = camera.camera
    if cam is None:
        return float("nan")
    pitch = PitchTemplate()
    lines = line_points(rgb)
    samples = template_samples(pitch)
    got = assign(cam.with_size(lines.size), samples, lines.xy, lines.angle, SHIFT_GATE_PX)
    if got is None:
        return float("nan")
    element, on = samples.element[got[0]], got[3]
    straight = [i for i, e in enumerate(pitch.elements()) if e.kind != "arc"]
    chains = [i for i in straight if np.sum(on & (element == i)) >= MIN_ELEMENT_POINTS]
    if not chains:
        return float("nan")
    masks = [on & (element == i) for i in chains]
    points = np.concatenate([pixels_to_lens(lines.xy[m], lines.size) for m in masks])
    chain = np.concatenate([np.full(m.sum(), j) for j, m in enumerate(masks)])
    weight = np.array([1.0 / m.sum() for m in masks])  # each chain weighs alike (1 / px^2 over its points)
    return decentring.centre_shift_px(points, chain, weight, float(lines.size[0]), cam.lens.k1, cam.lens.k2, K2_PRIOR)


def combine(pitch: tuple[float, float], pitch_bound: float, reading: tuple[float, float], reading_bound: float,
            t: dict, hfov_deg: float = 0.0) -> tuple[tuple[float, float], float, bool]:
    """The lens fed back from a sure camera's lens ``pitch`` (bound ``pitch_bound``) and the estimation
    layer's ``reading`` (bound ``reading_bound``): ``(k, stated bound, from the pitch)``; bounds px at
    1920, ``t`` the thresholds (``camera_trust.json``). Where the reading lies within ``lens_agreement``
    times the camera lens's bound of it (max-displacement distance ``D``), ``k = w k_p + (1 - w) k_a``,
    ``w`` = ``lens_weight`` (with ``lens_weight_floor_by_bounds``, at least ``b_a² / (b_a² + b_p²)``),
    stating ``w b_p + (1 - w) b_a`` (the radial map is linear in ``(k1, k2)`` and the error a norm).
    Beyond, the reading contradicts the camera's calibrated bound and is dropped: the camera's lens
    alone, stating ``max(b_p, D + b_a)`` (its error when either bound holds). The test leaves the
    reading's own bound out: on 121364 the line fit reads curved stand fronts and roof fascias as
    straight lines and its bound does not know it (docs/CAMERA.md). A camera wider than
    ``lens_max_hfov_deg`` (``hfov_deg``, the undistorted frame's field of view) lies outside the views
    the camera lens's bound was calibrated on: the reading is kept as it is."""
    if hfov_deg > t["lens_max_hfov_deg"]:
        return tuple(reading), reading_bound, False  # type: ignore[return-value]
    apart = float(max_displacement_px(np.array(pitch), np.array(reading)))
    if apart > float(t["lens_agreement"]) * pitch_bound:  # the reading outside the sure camera's bound: dropped
        return tuple(pitch), max(pitch_bound, apart + reading_bound), True  # type: ignore[return-value]
    w = float(t["lens_weight"])
    if t["lens_weight_floor_by_bounds"]:  # at least the camera's inverse-variance share: a reading far less sure weighs less
        w = max(w, reading_bound**2 / (reading_bound**2 + pitch_bound**2))
    k = (w * pitch[0] + (1 - w) * reading[0], w * pitch[1] + (1 - w) * reading[1])
    return k, w * pitch_bound + (1 - w) * reading_bound, True


def pitch_lens(camera: CameraEstimate, fallback: LensEstimate, centre_px: float = float("nan")) -> LensEstimate:
    """The camera fit's lens (:func:`camera_lens`) combined with ``fallback`` (the estimation layer's
    reading of the same frame), as a :class:`LensEstimate` with ``method="pitch"`` and ``fallback``'s pixel
    aspect, when ``camera`` is not doubtful (see the module docstring); else ``fallback`` unchanged.
    The camera weighs ``lens_weight`` (``camera_trust.json``); the answer is doubtful
    (``"weak_geometry"``) where its stated bound reaches the identity lens, as the estimation layer's."""
    if not isinstance(camera, CameraEstimate):
        raise TypeError(f"camera must be a glradial.CameraEstimate, got {type(camera).__name__}")
    if not isinstance(fallback, LensEstimate):
        raise TypeError(f"fallback must be a glradial.LensEstimate, got {type(fallback).__name__}")
    if camera.doubtful or camera.camera is None or not _may_be_a_pitch(fallback):
        return fallback
    lens = camera_lens(camera)
    k, stated, from_pitch = combine((lens.k1, lens.k2), lens_bound_px(camera, centre_px), (fallback.k1, fallback.k2),
                                    fallback.uncertainty_px, camera_trust(), camera.hfov_deg)
    if not from_pitch:  # a camera wider than the lens bound knows: the reading as it is
        return fallback
    sure = stated < shift_px(k)  # doubt by benefit, as the estimation layer's: the identity lens within the bound
    return LensEstimate(*k, pixel_aspect=fallback.pixel_aspect, uncertainty_px=stated, method="pitch",
                        chains=len(camera.markings), doubtful=not sure, reason="ok" if sure else "weak_geometry")


def fit_camera(rgb: np.ndarray, reading: LensEstimate) -> CameraEstimate:
    """The camera fit of a square-pixel frame ``rgb`` that :func:`pitch_lens` combines with ``reading``
    (the estimation layer's answer for it): :func:`glradial.camera.calibrate.calibrate` started from
    that reading's lens (the search undistorts the white lines with it and the coarse stage holds it;
    a strong barrel no longer hides the straight lines the search looks for)."""
    return calibrate(rgb, lens=Lens(reading.k1, reading.k2))


def _may_be_a_pitch(reading: LensEstimate) -> bool:
    """False where the estimation layer found no pitch evidence at all (a blank or noise frame, no
    grass: :data:`glradial.estimation.trust.NO_EVIDENCE_REASONS`): the camera fit is not run there."""
    return reading.reason not in NO_EVIDENCE_REASONS


def with_pitch(frame: np.ndarray, reading: LensEstimate) -> tuple[LensEstimate, CameraEstimate | None]:
    """What ``method="auto"`` answers for ``frame`` given the estimation layer's ``reading`` of it, and
    the camera fit behind it: ``(pitch_lens(camera, reading), camera)``, the camera fitted to the frame
    restored to square pixels (``reading.pixel_aspect``) as the estimator did; ``(reading, None)``
    where the estimation layer found no pitch evidence (the fit is not run). The one path of
    :func:`estimate` and :class:`Estimator` (and of the benches that score them)."""
    if not _may_be_a_pitch(reading):
        return reading, None
    rgb = to_rgb8(frame, clip=False)
    if reading.pixel_aspect != 1.0:
        rgb = square_pixels(rgb, reading.pixel_aspect)
    camera = fit_camera(rgb, reading)
    measure = camera_trust()["lens_shift_weight"] > 0 and not camera.doubtful  # the term costs a white-line pass
    return pitch_lens(camera, reading, centre_shift_px(rgb, camera) if measure else float("nan")), camera


def _with_pitch(frames: list, found: list[LensEstimate]) -> list[LensEstimate]:
    """Each estimate replaced by its frame's camera-fit lens where the template fits
    (:func:`with_pitch`); frames with no pitch evidence skip the fit."""
    return [with_pitch(frame, est)[0] for frame, est in zip(frames, found)]


def _as_list(frames: object) -> object:
    """A materialised sequence of frames (a generator is read once), anything else as given for the
    estimator's own checks."""
    if isinstance(frames, np.ndarray) and frames.ndim == 4:
        return list(frames)
    if isinstance(frames, (str, bytes, np.ndarray)) or not hasattr(frames, "__iter__"):
        return frames
    return list(frames)  # type: ignore[call-overload]


class Estimator(NetLinesEstimator):
    """:class:`glradial.estimation.net_lines.NetLinesEstimator` (same arguments) whose ``method="auto"`` adds the
    pitch camera fit's lens where the template fits (``pitch=True``, the default; see the module
    docstring). ``pitch=False`` is the estimation layer's ``auto``, unchanged (what video uses: the
    camera fit costs 0.2-0.4 s a frame).

    Args:
        model_path: an ``.onnx`` model (default: the bundled one).
        threads: onnxruntime intra-op threads (default: onnxruntime's choice).
        mirror_average: average each frame's reading with its mirror's (default True).

    Raises:
        FileNotFoundError: ``model_path`` does not exist.
        glradial.ModelLoadError: the file is not a usable glradial model.
        ValueError, TypeError: a bad ``threads`` or ``mirror_average``.

    Example:
        >>> import numpy as np, glradial
        >>> estimator = glradial.Estimator(threads=1)
        >>> found = estimator(np.zeros((72, 128, 3), np.uint8))  # a blank frame: no evidence
        >>> found.doubtful, found.reason
        (True, 'blank_frame')
    """

    def estimate_batch(self, frames: Sequence[np.ndarray], method: Method = "auto", pixel_aspect: float = 1.0,
                       *, pitch: bool = True) -> list[LensEstimate]:
        """:meth:`glradial.estimation.net_lines.NetLinesEstimator.estimate_batch`, then, for ``method="auto"`` and ``pitch``, the camera fit."""
        frames = _as_list(frames)
        found = super().estimate_batch(frames, method, pixel_aspect)  # type: ignore[arg-type]
        if method != "auto" or not pitch:
            return found
        return _with_pitch(list(frames), found)  # type: ignore[call-overload]

    def estimate(self, frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0,
                 *, pitch: bool = True) -> LensEstimate:
        """Estimate one frame's lens (as :meth:`estimate_batch`)."""
        return self.estimate_batch([frame], method, pixel_aspect, pitch=pitch)[0]

    __call__ = estimate


def estimate(frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0, *, pitch: bool = True) -> LensEstimate:
    """Estimate the radial lens of one RGB frame (``glradial.estimate``): ``"auto"`` (default) is the
    estimation layer's reading combined with the pitch camera fit's lens where the template fits (the
    CNN/line-fit answer alone elsewhere, and always with ``pitch=False``); ``"net"`` and
    ``"lines"`` as :func:`glradial.estimation.net_lines.estimate_net_lines`. ``pixel_aspect`` for frames stored
    with non-square pixels. Uses the shared bundled estimator.

    Args:
        frame: H×W×3 RGB array (uint8, uint16 or float).
        method: ``"auto"``, ``"net"`` or ``"lines"``.
        pixel_aspect: the frame's stored pixel aspect (``fy / fx``, 1 = square).
        pitch: with ``"auto"``, add the pitch camera fit's lens where the template fits.

    Returns:
        A :class:`glradial.LensEstimate` (width-normalised ``k1``, ``k2``, its bound in px at 1920
        wide, and its doubt).

    Raises:
        ValueError: an unknown ``method``, a bad frame shape or ``pixel_aspect``.
        TypeError: ``frame`` is not an array.

    Example:
        >>> import numpy as np, glradial
        >>> noise = np.random.default_rng(0).integers(0, 255, (72, 128, 3), np.uint8)
        >>> found = glradial.estimate(noise)
        >>> found.doubtful, found.reason  # said to be doubtful, so correct() leaves the frame alone
        (True, 'noise_frame')
    """
    check_method(method)
    found = default_net_lines_estimator().estimate(frame, method, pixel_aspect)
    return _with_pitch([frame], [found])[0] if method == "auto" and pitch else found
