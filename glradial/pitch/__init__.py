"""The football pitch's known geometry: configurable dimensions, its markings (lines, circle, arcs,
spots) as labelled elements and sampled polylines, and the 32 labelled keypoints."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .template import KEYPOINT_NAMES, Element, PitchTemplate, default_pitch

__getattr__, __dir__, __all__ = attach(__name__, __file__)
