"""Correction and distortion of frames by a lens: `correct`, `distort`, `fit_scale`, `Remapper`,
on the GL backend (GLSL shaders) or the CPU backend (cv2.remap), with one numeric policy."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .remap import Remapper, auto_backend, correct, distort, fit_scale

__getattr__, __dir__, __all__ = attach(__name__, __file__)
