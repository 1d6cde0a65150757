"""The whole camera from one frame: the pitch template, the first guess of the pitch-to-image
homography on a broadcast frame, and the joint refinement of pose, focal length and lens.

The first guess is ``glradial.camera.first_guess.first_guess`` (the module of the same name is what
``glradial.camera.first_guess`` names, so the function is imported from it)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .first_guess import Candidate

__getattr__, __dir__, __all__ = attach(__name__, __file__)
