"""The lens of one frame: the CNN (ONNX) estimator, pitch-line evidence and its robust fit,
the `LensEstimate` with its uncertainty, method and doubt (the calibrated trust model), model
validation at load."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .lens_estimate import LensEstimate, frame_evidence, judge
    from .model_check import ModelLoadError
    from .net_lines import NetLinesEstimator, default_model_path, estimate_net_lines, view_box, view_to_frame
    from .trust import REASONS, FrameEvidence, TrustModel, load_trust

__getattr__, __dir__, __all__ = attach(__name__, __file__)
