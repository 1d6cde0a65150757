"""A lens written for other tools: ST maps (Nuke, Resolve); the place for further exporters."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .stmap import check_stmap_path, lens_stmap, read_stmap, write_stmap

__getattr__, __dir__, __all__ = attach(__name__, __file__)
