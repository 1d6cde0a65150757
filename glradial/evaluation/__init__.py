"""How well lenses are estimated: held-out procedural crops, real frames with applied lenses,
metrics, breakdowns and reports (`glradial evaluate`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .evaluation import EvaluationSettings, OnnxPredictor, evaluate
    from .real_eval import evaluate_folder, self_consistent_truth
    from .trust_calibration import conformal_quantile

__getattr__, __dir__, __all__ = attach(__name__, __file__)
