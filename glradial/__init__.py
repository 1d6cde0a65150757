"""glradial: radial lens distortion for sports-broadcast video, on the GPU through GLSL.

Coefficients are width-normalised (image width = 1, origin at the image centre); see
:class:`glradial.Lens` and docs/DESIGN.md. Public names are imported lazily so that
``import glradial`` stays light (no GL context is made, torch is never imported); the imports under
``TYPE_CHECKING`` below are the list of them (``glradial.lazy`` reads it), and what type checkers see.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .lazy import attach

__version__ = "0.1.0"

if TYPE_CHECKING:
    from .camera.calibrate import calibrate
    from .camera.estimate import CameraEstimate
    from .camera.estimator import Estimator, estimate
    from .camera.shot_lens import ShotCalibration, ShotCalibrator, ShotLens, calibrate_shot
    from .errors import Error, GLUnavailableError, LensTrackError, ModelLoadError, ShaderCompileError
    from .estimation.lens_estimate import LensEstimate
    from .gl.shaderlib import shader_dir, shader_path
    from .lens.lens import Lens
    from .remapping.remap import Remapper, correct, distort, fit_scale
    from .synthesis.crop_producer import crop_batches
    from .synthesis.crops import CropParams, CropRenderer, render_crops, sample_crop_params
    from .synthesis.stadium import StadiumRenderer, stadium_panorama
    from .tracking.camera_track import CameraTracker, track_cameras
    from .video.live import LiveCorrector, LiveFrame

__getattr__, _dir, _names = attach(__name__, __file__)
__all__ = _names + ["__version__"]


def __dir__() -> list[str]:
    return __all__
