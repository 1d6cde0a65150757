"""OpenGL plumbing: headless EGL contexts (per thread, fork-safe, released explicitly) and the
shader loader (includes, defines, compile errors that name file and line)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import attach

if TYPE_CHECKING:
    from .egl import GLOwner, GLUnavailableError, check_gl_error, create_context, max_texture_size, release_objects, thread_context, thread_resource
    from .shaderlib import ShaderCompileError, TEXTURE_FORMATS, build_program, shader_dir
    from . import egl

__getattr__, __dir__, __all__ = attach(__name__, __file__)
