"""A frame's camera as glradial reports it: the fitted :class:`Camera` with its confidence.

Convention (as :class:`glradial.LensEstimate`): ``uncertainty_px`` is a 90 % bound on the RMS
reprojection error of the pitch markings in the frame (px of a 1280-wide frame): split-conformal, the
fit's own residual RMS (at least ``floor_px``) times a quantile (``glradial/data/camera_trust.json``).
The quantile and the floor are chosen on the five shared real matches' hand-labelled keypoints
(``bench/doubt_rules.py``, leave one match out: docs/CAMERA.md, "Across matches"); on procedural views
the same calibration gives a quantile of about 1.2 (real lines are wider, blurred, the pitch is not
exactly nominal, and the labels carry ~1-3 px of click noise), so the real matches set it.
``doubtful`` and ``reason`` say whether to use it (one of :data:`REASONS`; ``"ok"`` exactly when not
doubtful). ``markings``: labels of the template elements the fit used
(:meth:`glradial.pitch.PitchTemplate.elements`); ``rms_px`` the fit's RMS distance of the white-line
points on them (px at 1280), ``inliers`` their number, ``support`` the share of the markings drawn in
the frame that the frame shows (:func:`glradial.camera.refine.support`), ``focal_sd`` the relative
standard deviation of the focal length from the fit's Jacobian. A doubtful estimate may carry no camera at all.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .model import Camera

#: Why a camera is doubtful ("ok" when it is not).
REASONS = ("ok", "no_markings", "too_few_markings", "weak_geometry", "poor_fit")
#: The shipped calibration of the bound.
CAMERA_TRUST_FILE = Path(__file__).resolve().parents[1] / "data" / "camera_trust.json"


@lru_cache(maxsize=1)
def camera_trust() -> dict:
    """The bound's calibration and the doubt thresholds (``glradial/data/camera_trust.json``)."""
    return json.loads(CAMERA_TRUST_FILE.read_text(encoding="utf-8"))


def _of_camera(name: str, doc: str) -> property:
    """A read-only attribute of the estimate's camera (``None`` when it has none)."""
    return property(lambda self: None if self.camera is None else getattr(self.camera, name), doc=doc)


@dataclass(frozen=True)
class CameraEstimate:
    """The camera of one frame with its confidence (see the module docstring)."""

    camera: Camera | None
    uncertainty_px: float
    doubtful: bool
    reason: str
    markings: tuple[str, ...] = ()
    rms_px: float = math.inf
    inliers: int = 0
    support: float = 0.0
    focal_sd: float = math.inf

    def __post_init__(self) -> None:
        if self.reason not in REASONS or (self.reason == "ok") == bool(self.doubtful):
            raise ValueError(f"reason must be one of {REASONS} ('ok' exactly when not doubtful), got "
                             f"{self.reason!r} with doubtful={self.doubtful}")
        if self.camera is None and not self.doubtful:
            raise ValueError("an estimate without a camera must be doubtful")
        if not (self.uncertainty_px > 0):
            raise ValueError(f"uncertainty_px must be positive, got {self.uncertainty_px!r}")

    def _need(self) -> Camera:
        if self.camera is None:
            raise ValueError(f"no camera was found in this frame (reason: {self.reason})")
        return self.camera

    lens = _of_camera("lens", "The lens (width-normalised k1, k2), or ``None`` without a camera.")
    focal = _of_camera("focal", "Focal length in image widths.")
    hfov_deg = _of_camera("hfov_deg", "Horizontal field of view (degrees) of the undistorted frame.")
    rotation = _of_camera("rotation", "3 x 3 world (pitch) -> camera rotation (camera x right, y down, z forward).")
    position = _of_camera("position", "Camera centre in pitch metres.")
    pan_tilt_roll = _of_camera("pan_tilt_roll", "Pan, tilt, roll in degrees (glradial.camera.model).")
    homography = _of_camera("homography", "Pitch plane ``(x, y, 1)`` metres -> undistorted frame pixels.")

    @property
    def homography_inverse(self) -> np.ndarray | None:
        """Undistorted frame pixels -> pitch plane ``(x, y, 1)``."""
        return None if self.camera is None else np.linalg.inv(self.camera.homography)

    def project(self, points: object) -> np.ndarray:
        """Pitch points (N x 3, or N x 2 with z = 0; metres) -> N x 2 pixels of the distorted frame,
        lens included (:meth:`glradial.camera.model.Camera.project`). ``ValueError`` without a camera."""
        return self._need().project(points)

    def as_dict(self) -> dict:
        """JSON-ready summary (units in the keys' names)."""
        out: dict = {"doubtful": self.doubtful, "reason": self.reason, "uncertainty_px": self.uncertainty_px,
                     "rms_px": self.rms_px if math.isfinite(self.rms_px) else None, "inliers": self.inliers,
                     "support": self.support,
                     "focal_sd": self.focal_sd if math.isfinite(self.focal_sd) else None, "markings": list(self.markings)}
        cam = self.camera
        if cam is not None:
            pan, tilt, roll = cam.pan_tilt_roll
            out.update({"size": list(cam.size), "k1": cam.lens.k1, "k2": cam.lens.k2, "focal": cam.focal,
                        "focal_px": cam.focal * cam.size[0], "hfov_deg": cam.hfov_deg,
                        "rotation": cam.rotation.tolist(), "position_m": cam.position.tolist(),
                        "pan_deg": pan, "tilt_deg": tilt, "roll_deg": roll,
                        "homography": (cam.homography / cam.homography[2, 2]).tolist()})
        return out
