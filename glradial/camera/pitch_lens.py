"""The lens of a frame from both kinds of evidence: the joint camera fit to the pitch template
(:func:`glradial.camera.calibrate.calibrate`) where the template fits, combined with today's estimator
(the CNN and the line fit, :mod:`glradial.estimation.estimator`); today's estimator alone where it does not.

``method="auto"`` of :func:`estimate` and :class:`Estimator` (what ``glradial.estimate`` and
``glradial.Estimator`` are; a subclass of the estimation layer's ``Estimator``) with ``pitch=True``
(``glradial estimate IMG --pitch``) runs both. When the
camera is not doubtful, the answer is a :class:`glradial.LensEstimate` with ``method="pitch"``: the
camera fit's lens ``k_p`` (bound ``b_p``, :func:`lens_bound_px`) and the estimation layer's reading
``k_a`` (its own bound ``b_a``) weighted by the inverse squares of their bounds,
``k = (k_p / b_p^2 + k_a / b_a^2) / (1 / b_p^2 + 1 / b_a^2)`` (width-normalised ``(k1, k2)``), stating
the same weights' mean of the two bounds. Both bounds are 90 % bounds on the maximum displacement
error over the 16:9 frame (px of a 1920-wide frame, :func:`glradial.lens.metrics.max_displacement_px`;
not the camera's bound on the markings' reprojection, another quantity). The radial map is linear in
``(k1, k2)`` and that error is a norm, so the combination's error is at most the weighted mean of the
two errors, and its stated bound holds whenever both bounds do. ``chains`` is the number of template
markings the camera fit used. When the camera is doubtful, the estimation layer's answer is returned
unchanged. ``"net"`` and ``"lines"`` never run the camera fit.

Why combined and not the camera's lens alone: on real frames the camera fit's lens is not the
stronger evidence everywhere (docs/CAMERA.md, "The lens fed back": better on one Bundesliga clip, worse
on the other and on a real_football frame); its bound, calibrated on real frames, says so, and the
weights follow the bounds.

Why opt-in (``pitch=False`` by default): measured, it moves the Bundesliga clips' self-consistent
median from 3.75 to 3.40 px (goal 3) and leaves real_football and procedural crops where they were,
but it costs 200-400 ms a frame (7-10x today's ``auto``), reads worse where a pincushion lens was
applied (k1 > 0.1: 5.6 -> 6.6 px), and the camera fit is fooled by line drawings that are not a pitch
(seven random lines on grass, two parallel template lines: the combined bound failed on the latter).
Until the camera's doubt check rejects those, the default stays the estimation layer's ``auto``.

The camera's lens bound is split-conformal: ``lens_quantile`` times the fit's marking RMS (px at 1280,
at least ``lens_floor_px``), both in ``glradial/data/camera_trust.json`` with the calibration they
come from (``bench/pitch_lens_bound.py``).

This lives in the camera layer because it needs both layers: ``estimation`` sits below ``camera`` and
must not import it, so the estimation layer's :class:`~glradial.estimation.estimator.Estimator` stays
the CNN-plus-lines estimator and this module composes the two.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..estimation.estimator import Estimator as LinesEstimator
from ..estimation.estimator import default_estimator, square_pixels
from ..estimation.lens_estimate import LensEstimate, check_method
from ..lens.options import Method
from ..media.frames import to_rgb8
from .calibrate import calibrate
from .estimate import CameraEstimate, camera_trust


def lens_bound_px(camera: CameraEstimate) -> float:
    """90 % bound (px at 1920) on the max-displacement error of ``camera``'s lens: ``lens_quantile``
    times its marking RMS (px at 1280, at least ``lens_floor_px``; ``glradial/data/camera_trust.json``)."""
    t = camera_trust()
    return float(t["lens_quantile"] * max(camera.rms_px, t["lens_floor_px"]))


def pitch_lens(camera: CameraEstimate, fallback: LensEstimate) -> LensEstimate:
    """The camera fit's lens combined with ``fallback`` (the estimation layer's reading of the same
    frame) by inverse-variance weights from their bounds, as a :class:`LensEstimate` with
    ``method="pitch"`` and ``fallback``'s pixel aspect (see the module docstring), when ``camera`` is
    not doubtful; else ``fallback`` unchanged."""
    if not isinstance(camera, CameraEstimate):
        raise TypeError(f"camera must be a glradial.CameraEstimate, got {type(camera).__name__}")
    if not isinstance(fallback, LensEstimate):
        raise TypeError(f"fallback must be a glradial.LensEstimate, got {type(fallback).__name__}")
    if camera.doubtful or camera.camera is None:
        return fallback
    lens, bound = camera.lens, lens_bound_px(camera)
    w_pitch, w_other = bound ** -2, fallback.uncertainty_px ** -2
    total = w_pitch + w_other
    k1 = (w_pitch * lens.k1 + w_other * fallback.k1) / total
    k2 = (w_pitch * lens.k2 + w_other * fallback.k2) / total
    return LensEstimate(k1, k2, pixel_aspect=fallback.pixel_aspect,
                        uncertainty_px=(w_pitch * bound + w_other * fallback.uncertainty_px) / total,
                        method="pitch", chains=len(camera.markings), doubtful=False, reason="ok")


def _with_pitch(frames: list, found: list[LensEstimate]) -> list[LensEstimate]:
    """Each estimate replaced by its frame's camera-fit lens where the template fits (the frame
    restored to square pixels as the estimator did)."""
    out = []
    for frame, est in zip(frames, found):
        rgb = to_rgb8(frame, clip=False)
        if est.pixel_aspect != 1.0:
            rgb = square_pixels(rgb, est.pixel_aspect)
        out.append(pitch_lens(calibrate(rgb), est))
    return out


def _as_list(frames: object) -> object:
    """A materialised sequence of frames (a generator is read once), anything else as given for the
    estimator's own checks."""
    if isinstance(frames, np.ndarray) and frames.ndim == 4:
        return list(frames)
    if isinstance(frames, (str, bytes, np.ndarray)) or not hasattr(frames, "__iter__"):
        return frames
    return list(frames)  # type: ignore[call-overload]


class Estimator(LinesEstimator):
    """:class:`glradial.estimation.estimator.Estimator` (same arguments) whose ``method="auto"`` with
    ``pitch=True`` adds the pitch camera fit's lens where the template fits (see the module docstring).
    ``pitch=False`` (the default) is the estimation layer's ``auto``, unchanged: the camera fit costs
    200-400 ms a frame and is opt-in (module docstring, "Why opt-in")."""

    def estimate_batch(self, frames: Sequence[np.ndarray], method: Method = "auto", pixel_aspect: float = 1.0,
                       *, pitch: bool = False) -> list[LensEstimate]:
        """:meth:`glradial.estimation.estimator.Estimator.estimate_batch`, then, for ``method="auto"`` and ``pitch``, the camera fit."""
        frames = _as_list(frames)
        found = super().estimate_batch(frames, method, pixel_aspect)  # type: ignore[arg-type]
        if method != "auto" or not pitch:
            return found
        return _with_pitch(list(frames), found)  # type: ignore[call-overload]

    def estimate(self, frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0,
                 *, pitch: bool = False) -> LensEstimate:
        """Estimate one frame's lens (as :meth:`estimate_batch`)."""
        return self.estimate_batch([frame], method, pixel_aspect, pitch=pitch)[0]

    __call__ = estimate


def estimate(frame: np.ndarray, method: Method = "auto", pixel_aspect: float = 1.0, *, pitch: bool = False) -> LensEstimate:
    """Estimate the radial lens of one RGB frame (``glradial.estimate``): ``"auto"`` (default) as the
    estimation layer's, and with ``pitch=True`` combined with the pitch camera fit's lens where the
    template fits (the CNN/line-fit answer alone elsewhere); ``"net"`` and
    ``"lines"`` as :func:`glradial.estimation.estimator.estimate`. ``pixel_aspect`` for frames stored
    with non-square pixels. Uses the shared bundled estimator."""
    check_method(method)
    found = default_estimator().estimate(frame, method, pixel_aspect)
    return _with_pitch([frame], [found])[0] if method == "auto" and pitch else found
