"""The camera followed through a shot: each frame's camera carried by the motion between frames and
corrected by the pitch markings, causally (:class:`CameraTracker`, for a live stream) or forward and
backward (:func:`track_cameras`, for a file; ``glradial calibrate VIDEO``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .camera_track import CameraTracker, Motion, carry, motion_of, track_cameras
    from .live_camera import LiveCamera, LiveCameraTracker, camera_tracker

__getattr__, __dir__, __all__ = attach(__name__, __file__)
