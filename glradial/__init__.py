"""glradial: radial lens distortion for sports-broadcast video, on the GPU through GLSL.

Coefficients are width-normalised (image width = 1, origin at the image centre); see
:class:`glradial.Lens` and DESIGN.md. Public names are imported lazily so that ``import glradial``
stays light (no GL context is made, torch is never imported).
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: public name -> module (relative to the package) that defines it
_EXPORTS = {
    "Lens": "lens.lens",
    "GLUnavailableError": "gl.egl",
    "ShaderCompileError": "gl.shaderlib",
    "correct": "remapping.remap",
    "distort": "remapping.remap",
    "fit_scale": "remapping.remap",
    "Remapper": "remapping.remap",
    "CropParams": "synthesis.crops",
    "sample_crop_params": "synthesis.crops",
    "render_crops": "synthesis.crops",
    "CropRenderer": "synthesis.crops",
    "crop_batches": "synthesis.crop_producer",
    "stadium_panorama": "synthesis.stadium",
    "StadiumRenderer": "synthesis.stadium",
    "estimate": "estimation.estimator",
    "Estimator": "estimation.estimator",
    "ModelLoadError": "estimation.estimator",
    "LensEstimate": "estimation.lens_estimate",
}

__all__ = sorted(_EXPORTS) + ["__version__"]


def __getattr__(name: str) -> Any:
    module_name = _EXPORTS.get(name)
    if module_name is None:
        raise AttributeError(f"module 'glradial' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module_name}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
