"""OpenGL plumbing: headless EGL contexts (per thread, fork-safe, released explicitly) and the
shader loader (includes, defines, compile errors that name file and line)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from . import egl
    from .egl import GLOwner, GLUnavailableError, check_gl_error, create_context, max_texture_size, release_objects, thread_context, thread_resource
    from .llvm_guard import guard_bundled_llvm
    from .shaderlib import TEXTURE_FORMATS, ShaderCompileError, build_program, shader_dir

__getattr__, __dir__, __all__ = attach(__name__, __file__)
