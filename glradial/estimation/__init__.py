"""The lens of one frame: the CNN (ONNX) estimator, pitch-line evidence and its robust fit,
the `LensEstimate` with its uncertainty and method, model validation at load."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .estimator import Estimator, default_model_path, estimate
    from .lens_estimate import LINES_UNCERTAINTY_FLOOR_PX, NET_UNCERTAINTY_PX, LensEstimate, choose, fit_frame, line_candidates
    from .model_check import ModelLoadError

__getattr__, __dir__, __all__ = attach(__name__, __file__)
