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
standard deviation of the focal length from the fit's Jacobian. A doubtful estimate may carry no camera at all;
a degenerate one (:func:`degenerate`: e.g. a focal length of 1e-8 image widths or a camera 2e9 m away)
never carries it.
``carried``: frames since the last sure measurement when the camera was carried there by the frame-to-frame
motion (:mod:`glradial.tracking.camera_track`; 0: measured on this frame); ``"track_lost"``: carried too far.
:attr:`CameraEstimate.why` says what the doubt rests on in numbers (e.g. ``"support 0.73 < 0.83"``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Mapping

import numpy as np

from .model import Camera

#: Why a camera is doubtful ("ok" when it is not).
REASONS = ("ok", "no_markings", "too_few_markings", "weak_geometry", "poor_fit", "track_lost")
#: The shipped calibration of the bound.
CAMERA_TRUST_FILE = Path(__file__).resolve().parents[1] / "data" / "camera_trust.json"


@lru_cache(maxsize=1)
def camera_trust() -> dict:
    """The bound's calibration and the doubt thresholds (``glradial/data/camera_trust.json``)."""
    return json.loads(CAMERA_TRUST_FILE.read_text(encoding="utf-8"))


def ship_camera_trust(changes: Mapping[str, object], path: Path = CAMERA_TRUST_FILE) -> Path:
    """Write the shipped calibration with ``changes`` (settings chosen by a bench and the notes that say
    how, keys ending in ``source``) to ``path``, atomically, and drop the cached :func:`camera_trust`;
    returns ``path``. A setting the file does not have is a ``ValueError`` naming it (a misspelt key
    would otherwise be shipped and never read)."""
    from ..media.atomic import atomic_write_text

    trust = camera_trust()
    unknown = sorted(k for k in changes if k not in trust and not k.endswith("source"))
    if unknown:
        raise ValueError(f"changes name settings that {CAMERA_TRUST_FILE.name} does not have: {unknown}")
    atomic_write_text(Path(path), json.dumps({**trust, **changes}, indent=2) + "\n")
    camera_trust.cache_clear()
    return Path(path)


#: A fitted camera outside these is degenerate and never reported (the estimate keeps no camera):
#: focal length (image widths; 0.05-50 is a field of view of 170 down to 1.1 degrees) and the
#: distance of the camera from the centre spot (m).
FOCAL_RANGE, MAX_DISTANCE_M = (0.05, 50.0), 1000.0


def degenerate(camera: Camera) -> bool:
    """Whether ``camera`` is no camera that could film a pitch: a focal length outside
    :data:`FOCAL_RANGE`, farther than :data:`MAX_DISTANCE_M` from the centre spot, or not above it."""
    return not (FOCAL_RANGE[0] <= camera.focal <= FOCAL_RANGE[1]
                and float(np.linalg.norm(camera.position)) <= MAX_DISTANCE_M and camera.position[2] > 0)


def _of_camera(name: str, doc: str) -> property:
    """A read-only attribute of the estimate's camera (``None`` when it has none)."""
    return property(lambda self: None if self.camera is None else getattr(self.camera, name), doc=doc)


@dataclass(frozen=True)
class CameraEstimate:
    """The camera of one frame with its confidence (see the module docstring).

    Args:
        camera: the fitted :class:`glradial.camera.model.Camera` (``None``: none found).
        uncertainty_px: 90 % bound on the markings' RMS reprojection error, px at 1280 wide (> 0).
        doubtful: True when the camera should not be used as if sure.
        reason: one of :data:`REASONS`, ``"ok"`` exactly when not doubtful.
        markings, rms_px, inliers, support, focal_sd: the fit's evidence (module docstring).
        carried: frames since the last sure measurement (0: measured on this frame).
        detail: the doubt rule's failed checks in numbers
            (:func:`glradial.camera.calibrate.doubt_checks`; ``""`` when sure).

    Raises:
        ValueError: an unknown ``reason``, one not matching ``doubtful``, a sure estimate without
            a camera, or ``uncertainty_px <= 0``.

    Example:
        >>> import math, glradial
        >>> none = glradial.CameraEstimate(None, math.inf, True, "no_markings")
        >>> none.lens is None, none.as_dict()["reason"]
        (True, 'no_markings')
        >>> none.project([[0.0, 0.0]])
        Traceback (most recent call last):
        ...
        ValueError: no camera was found in this frame (reason: no_markings)
    """

    camera: Camera | None
    uncertainty_px: float
    doubtful: bool
    reason: str
    markings: tuple[str, ...] = ()
    rms_px: float = math.inf
    inliers: int = 0
    support: float = 0.0
    focal_sd: float = math.inf
    carried: int = 0
    detail: str = ""

    def __post_init__(self) -> None:
        if self.camera is not None and degenerate(self.camera):  # no impossible numbers leave glradial
            object.__setattr__(self, "camera", None)
            object.__setattr__(self, "doubtful", True)
            object.__setattr__(self, "reason", "poor_fit" if self.reason == "ok" else self.reason)
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

    @property
    def why(self) -> str:
        """The doubt in numbers: each check of the doubt rule the fit fails (:attr:`detail`, thresholds
        of ``camera_trust.json``), e.g. ``"support 0.70 < 0.725; rms 3.10 px > 2.5 px"`` (px at 1280);
        ``""`` when it is sure, the reason alone where no figure says more."""
        if not self.doubtful:
            return ""
        if self.camera is None:
            if self.inliers:
                return "the fit is degenerate (no camera kept)"
            return "no camera found"
        failed = [self.detail] if self.detail else []
        if self.reason == "track_lost":
            failed.insert(0, f"carried {self.carried} frames, bound {self.uncertainty_px:.1f} px")
        return "; ".join(failed) or self.reason

    def to_pitch(self, pixels: object) -> np.ndarray:
        """Pixels of the distorted frame (N x 2) -> N x 2 pitch metres (z = 0), the exact inverse of
        :meth:`project` on the pitch plane, lens included (:meth:`glradial.camera.model.Camera.to_pitch`;
        NaN above the horizon). ``ValueError`` without a camera; a doubtful estimate's positions are
        as doubtful as its camera."""
        return self._need().to_pitch(pixels)

    def as_dict(self) -> dict:
        """JSON-ready summary (units in the keys' names)."""
        out: dict = {"doubtful": self.doubtful, "reason": self.reason, "uncertainty_px": self.uncertainty_px,
                     "rms_px": self.rms_px if math.isfinite(self.rms_px) else None, "inliers": self.inliers,
                     "support": self.support,
                     "focal_sd": self.focal_sd if math.isfinite(self.focal_sd) else None, "markings": list(self.markings),
                     "why": self.why, "carried": self.carried}
        cam = self.camera
        if cam is not None:
            pan, tilt, roll = cam.pan_tilt_roll
            out.update({"size": list(cam.size), "k1": cam.lens.k1, "k2": cam.lens.k2, "focal": cam.focal,
                        "focal_px": cam.focal * cam.size[0], "hfov_deg": cam.hfov_deg,
                        "rotation": cam.rotation.tolist(), "position_m": cam.position.tolist(),
                        "pan_deg": pan, "tilt_deg": tilt, "roll_deg": roll,
                        "homography": (cam.homography / cam.homography[2, 2]).tolist()})
        return out
