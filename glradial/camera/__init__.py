"""The whole camera of one frame from the pitch's known geometry: the pinhole-plus-lens camera model
(projection, plane-homography decomposition), the joint refinement of pose, focal length and lens
against the pitch markings, and :func:`calibrate` with its judged :class:`CameraEstimate`; per shot
of a video, one lens as a function of the zoom (:func:`calibrate_shot`).

The first guess on a frame is ``glradial.camera.first_guess.first_guess`` (imported from its module:
the module of that name is what ``glradial.camera.first_guess`` names)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .calibrate import calibrate
    from .estimate import REASONS, CameraEstimate
    from .estimator import Estimator, lens_bound_px, pitch_lens
    from .first_guess import Candidate
    from .model import Camera, decompose_homography
    from .shot_lens import ShotCalibration, ShotCalibrator, ShotLens, calibrate_shot, fit_shot_lens
    from .views import random_camera, render_view

__getattr__, __dir__, __all__ = attach(__name__, __file__)
