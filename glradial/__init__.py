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
    "Lens": "lens",
    "GLUnavailableError": "egl",
    "ShaderCompileError": "shaderlib",
    "shader_dir": "shaderlib",
    "shader_path": "shaderlib",
    "correct": "remap",
    "distort": "remap",
    "fit_scale": "remap",
    "Remapper": "remap",
    "CropParams": "crops",
    "sample_crop_params": "crops",
    "render_crops": "crops",
    "CropRenderer": "crops",
    "crop_batches": "crop_producer",
    "stadium_panorama": "stadium",
    "StadiumRenderer": "stadium",
    "estimate": "estimator",
    "Estimator": "estimator",
    "ModelLoadError": "estimator",
    "LensEstimate": "lens_estimate",
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
