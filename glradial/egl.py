"""Headless OpenGL contexts through EGL (Mesa llvmpipe when there is no GPU).

A moderngl context belongs to the thread (and process) that created it. :func:`thread_context`
keeps one lazily created context per thread and per process: a worker process forked from a parent
that already had a context gets a fresh one, never the parent's. Objects made on a context are
released explicitly by their owner (``gc_mode`` stays ``None``), never by the garbage collector from
another thread.
"""

from __future__ import annotations

import os
import threading

import moderngl

#: The Debian packages that provide headless EGL with Mesa's software rasteriser.
EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"

_SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "lavapipe")


class GLUnavailableError(RuntimeError, ValueError):
    """No OpenGL 3.3 context could be created (EGL library or driver missing).

    A ``RuntimeError`` (the environment is at fault) that is also a ``ValueError``, so callers that
    catch bad-input errors at the API boundary catch it too; the message names the library and the
    packages that provide it.
    """


def create_context(*, libegl: str | None = None, device_index: int | None = None) -> moderngl.Context:
    """Create a standalone, headless OpenGL >= 3.3 core context through EGL.

    ``libegl`` names the EGL library to load (default: the system's ``libEGL.so.1``);
    ``device_index`` picks an EGL device (GPU) where several exist. Raises
    :class:`GLUnavailableError` naming the missing library and the packages that provide it.
    """
    kwargs: dict[str, object] = {"backend": "egl", "require": 330}
    if libegl is not None:
        kwargs["libegl"] = libegl
    if device_index is not None:
        kwargs["device_index"] = device_index
    try:
        return moderngl.create_standalone_context(**kwargs)
    except Exception as err:  # glcontext raises a bare Exception
        wanted = libegl or "libEGL.so.1"
        raise GLUnavailableError(
            f"cannot create a headless OpenGL 3.3 context through EGL ({wanted}): {err}. "
            f"Install the EGL library and Mesa's drivers (Debian/Ubuntu: apt-get install "
            f"{EGL_PACKAGES}); backend='cpu' works without them."
        ) from None


_local = threading.local()


def thread_context() -> moderngl.Context:
    """The calling thread's context, created on first use (one per thread and per process)."""
    pid = os.getpid()
    ctx = getattr(_local, "ctx", None)
    if ctx is None or getattr(_local, "pid", None) != pid:
        _local.ctx = create_context()
        _local.pid = pid
    return _local.ctx


def max_texture_size(ctx: moderngl.Context) -> int:
    """``GL_MAX_TEXTURE_SIZE``: the largest width or height of a 2-D texture on ``ctx``."""
    return int(ctx.info["GL_MAX_TEXTURE_SIZE"])


def renderer_name(ctx: moderngl.Context) -> str:
    """The driver's ``GL_RENDERER`` string, e.g. ``"llvmpipe (LLVM 15.0.6, 256 bits)"``."""
    return str(ctx.info["GL_RENDERER"])


def is_software_renderer(ctx: moderngl.Context) -> bool:
    """True when ``ctx`` renders on the CPU (llvmpipe, softpipe, swrast, lavapipe)."""
    name = renderer_name(ctx).lower()
    return any(tag in name for tag in _SOFTWARE_RENDERERS)


def check_gl_error(ctx: moderngl.Context, where: str) -> None:
    """Raise ``RuntimeError`` if the GL error flag is set, naming ``where`` it was found."""
    error = ctx.error
    if error != "GL_NO_ERROR":
        raise RuntimeError(f"OpenGL error {error} after {where}")


def release_objects(ctx: moderngl.Context, *objects: object) -> None:
    """Release GL objects in order, skipping ``None``.

    If the framebuffer bound on ``ctx`` is among them, framebuffer 0 is bound first: moderngl
    re-binds the last bound framebuffer after creating a new one, which is an error once it is gone.
    """
    bound = ctx.fbo
    if bound is not None and any(obj is bound for obj in objects):
        ctx.detect_framebuffer(0).use()
    for obj in objects:
        if obj is not None:
            obj.release()  # type: ignore[attr-defined]
