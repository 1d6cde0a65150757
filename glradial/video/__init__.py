"""The lens of a video: cut detection, one lens per shot (its frames' lines and frame-to-frame
motion in one joint fit, following the zoom, with a doubt policy), the per-frame `LensTrack` and its
sidecar, and `--auto`'s two passes (track, correct) on a decode/correct/encode pipeline; the causal
correction of a live stream (`LiveCorrector`, ``glradial live``) with each shot's lens from its frames so far."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .lens_track import DOUBTFUL_PX, LensTrack, load_lens_track
    from .live import LiveCorrector, LiveFrame, LiveStats
    from .video_pipeline import correct_video, default_estimator, doubtful_warnings, track_report, track_video

__getattr__, __dir__, __all__ = attach(__name__, __file__)
