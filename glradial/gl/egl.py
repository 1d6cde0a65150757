"""Headless OpenGL contexts through EGL (Mesa llvmpipe when there is no GPU), and who owns them.

A moderngl context belongs to the thread (and process) that created it; moderngl issues every call
to whatever context is current on the calling thread. Rules this module implements:

* :func:`thread_context` keeps one lazily created context per thread and per process. Objects that
  live on it (the module-level functions' :class:`~glradial.Remapper`, the stadium renderer) are
  kept beside it by :func:`thread_resource`. When the thread ends, CPython clears its thread-local
  data on that thread, and the holder unbinds the context there (EGL frees or hands over a context
  only once it is current nowhere; without it each short-lived thread leaked ~4 MB) and puts it,
  with its resources, in a small pool that new threads adopt (:data:`THREAD_CONTEXT_POOL`); beyond
  that, it releases the resources and destroys the context.
* Fork: a forked child inherits the parent's EGL display, whose driver threads (llvmpipe's
  rasterizer) did not survive the fork, so any context on it, old or new, hangs at the first
  readback. A child therefore never touches the parent's contexts and makes its own on a display
  the parent never initialised: the parent uses the EGL device platform (what moderngl uses), a
  child the Mesa surfaceless platform. A further generation (a child of a child that used GL) has
  no fresh display left and gets :class:`GLUnavailableError` (``backend="auto"`` then uses the CPU);
  the ``spawn`` and ``forkserver`` start methods always work.
* :class:`GLOwner` records the thread and process that made a GL-owning object; :meth:`GLOwner.enter`
  raises ``RuntimeError`` naming both threads when another one uses it, and makes the owner's
  context current (another context made later on the same thread would otherwise receive the calls).
"""

from __future__ import annotations

import ctypes
import os
import threading
from typing import Callable, TypeVar

import moderngl

from ..errors import GLUnavailableError
from .llvm_guard import guard_bundled_llvm

#: The Debian packages that provide headless EGL with Mesa's software rasteriser.
EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"

_SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "lavapipe")


def _unavailable(wanted: str, reason: object) -> GLUnavailableError:
    return GLUnavailableError(
        f"cannot create a headless OpenGL 3.3 context through EGL ({wanted}): {reason}. "
        f"Install the EGL library and Mesa's drivers (Debian/Ubuntu: apt-get install "
        f"{EGL_PACKAGES}); backend='cpu' works without them."
    )


# -- displays and fork ------------------------------------------------------------------------------
#: EGL display kind -> pid of the process that initialised it (copied into forked children, which
#: is how a child knows the display is its parent's).
_display_pid: dict[str, int] = {}
_display_lock = threading.Lock()
#: contexts and holders inherited from a parent process: kept referenced, never released here
_inherited: list[object] = []

_EGL_PLATFORM_SURFACELESS_MESA = 0x31DD
_EGL_NONE = 0x3038


class _SurfacelessContext:
    """An EGL context on the Mesa surfaceless platform, created through ctypes; moderngl drives it
    through the loader protocol (``load_opengl_function``, ``__enter__``, ``__exit__``,
    ``release``). Used only in forked children (see the module docstring)."""

    def __init__(self, libegl: str) -> None:
        vp = ctypes.c_void_p
        try:
            egl = ctypes.CDLL(libegl)
        except OSError as err:
            raise _unavailable(libegl, err) from None
        egl.eglGetProcAddress.restype = vp
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        egl.eglInitialize.argtypes = [vp, vp, vp]
        egl.eglChooseConfig.argtypes = [vp, vp, vp, ctypes.c_int, vp]
        egl.eglCreateContext.restype = vp
        egl.eglCreateContext.argtypes = [vp, vp, vp, vp]
        egl.eglMakeCurrent.argtypes = [vp, vp, vp, vp]
        egl.eglDestroyContext.argtypes = [vp, vp]
        egl.eglGetError.restype = ctypes.c_int
        self._egl = egl
        address = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
        if not address:
            raise _unavailable(libegl, "eglGetPlatformDisplayEXT is missing")
        get_display = ctypes.CFUNCTYPE(vp, ctypes.c_uint, vp, vp)(address)
        self._display = get_display(_EGL_PLATFORM_SURFACELESS_MESA, None, None)
        if not self._display or not egl.eglInitialize(self._display, None, None):
            raise _unavailable(libegl, f"no surfaceless EGL display (error 0x{egl.eglGetError():x})")
        ints = lambda *values: (ctypes.c_int * len(values))(*values)  # noqa: E731
        config, count = vp(), ctypes.c_int()
        # EGL_SURFACE_TYPE = PBUFFER, EGL_RENDERABLE_TYPE = OPENGL
        if not egl.eglChooseConfig(self._display, ints(0x3033, 0x1, 0x3040, 0x8, _EGL_NONE), ctypes.byref(config), 1, ctypes.byref(count)) or not count.value:
            raise _unavailable(libegl, f"no OpenGL config on the surfaceless display (error 0x{egl.eglGetError():x})")
        egl.eglBindAPI(0x30A2)  # EGL_OPENGL_API
        # OpenGL 3.3 core profile
        self._context = egl.eglCreateContext(self._display, config, None, ints(0x3098, 3, 0x30FB, 3, 0x30FD, 1, _EGL_NONE))
        if not self._context:
            raise _unavailable(libegl, f"eglCreateContext failed (error 0x{egl.eglGetError():x})")
        self.__enter__()

    def load_opengl_function(self, name: str) -> int:
        return self._egl.eglGetProcAddress(name.encode()) or 0

    load = load_opengl_function

    def __enter__(self) -> None:
        self._egl.eglMakeCurrent(self._display, None, None, self._context)

    def __exit__(self, *exc: object) -> None:
        self._egl.eglMakeCurrent(self._display, None, None, None)

    def release(self) -> None:
        if self._context:
            self.__exit__()
            self._egl.eglDestroyContext(self._display, self._context)
            self._context = None


def _claim_display() -> str:
    """The EGL display kind this process may use: ``"device"`` unless an ancestor initialised it,
    then ``"surfaceless"``; raises :class:`GLUnavailableError` when both are an ancestor's."""
    pid = os.getpid()
    with _display_lock:
        for kind in ("device", "surfaceless"):
            owner = _display_pid.get(kind)
            if owner is None or owner == pid:
                _display_pid[kind] = pid
                return kind
    raise GLUnavailableError(
        f"process {pid} descends through fork from two processes that had used OpenGL (its EGL device "
        f"and surfaceless displays were both initialised by ancestors, and inherited displays hang): no "
        f"OpenGL context can be made here. Use multiprocessing's 'spawn' or 'forkserver' start method, "
        f"or backend='cpu'."
    )


def create_context(*, libegl: str | None = None, device_index: int | None = None) -> moderngl.Context:
    """Create a standalone, headless OpenGL >= 3.3 core context through EGL, current on the calling
    thread.

    ``libegl`` names the EGL library to load (default: the system's ``libEGL.so.1``);
    ``device_index`` picks an EGL device (GPU) where several exist. In a process forked from one
    that used GL the context is made on the surfaceless platform instead (module docstring;
    ``device_index`` is then ignored). Before the process's first context, libraries that carry their
    own LLVM (triton) are preloaded so that they keep it (:mod:`.llvm_guard`). Raises :class:`GLUnavailableError` naming the missing
    library and the packages that provide it.
    """
    wanted = libegl or "libEGL.so.1"
    guard_bundled_llvm()  # before Mesa's LLVM becomes global (llvm_guard's docstring)
    kind = _claim_display()
    if kind == "surfaceless":
        loader = _SurfacelessContext(wanted)
        try:
            return moderngl.create_context(require=330, standalone=True, context=loader)
        except Exception as err:
            loader.release()
            raise _unavailable(wanted, err) from None
    kwargs: dict[str, object] = {"backend": "egl", "require": 330}
    if libegl is not None:
        kwargs["libegl"] = libegl
    if device_index is not None:
        kwargs["device_index"] = device_index
    try:
        return moderngl.create_standalone_context(**kwargs)
    except Exception as err:  # glcontext raises a bare Exception
        raise _unavailable(wanted, err) from None


def destroy_context(ctx: moderngl.Context) -> None:
    """Unbind ``ctx`` from the calling thread (where it must be current or not current anywhere)
    and destroy it: EGL only frees a context that is current on no thread."""
    try:
        ctx.__exit__(None, None, None)
    except AttributeError:  # already released (moderngl swapped in an InvalidObject)
        return
    ctx.release()


def make_current(ctx: moderngl.Context) -> None:
    """Make ``ctx`` current on the calling thread (cheap when it already is)."""
    ctx.__enter__()


# -- per-thread contexts ------------------------------------------------------------------------------
R = TypeVar("R")


#: contexts (with their resources) of ended threads, unbound, kept for new threads to adopt:
#: creating and destroying an EGL context leaks ~40 kB inside Mesa 22.3 (measured over 400 cycles on
#: one thread), reusing one leaks nothing and saves the set-up
THREAD_CONTEXT_POOL = 4
_pool: list[tuple[moderngl.Context, dict[str, object]]] = []
_pool_lock = threading.Lock()


class _ThreadGL:
    """One thread's context and the objects kept on it; handed back when the thread ends."""

    def __init__(self, ctx: moderngl.Context | None = None, resources: dict[str, object] | None = None) -> None:
        self.pid = os.getpid()
        self.thread_id = threading.get_ident()
        self.ctx = ctx if ctx is not None else create_context()
        self.resources: dict[str, object] = resources if resources is not None else {}

    def close(self) -> None:
        """Runs on the ending thread (its context is current there): unbind the context and pool
        it with its resources, or release them and destroy it when the pool is full."""
        if os.getpid() != self.pid or threading.get_ident() != self.thread_id or self.ctx is None:
            return  # a parent's context (never touched in a child), or another thread's (at exit)
        ctx, resources = self.ctx, self.resources
        self.ctx, self.resources = None, {}
        make_current(ctx)
        with _pool_lock:
            if len(_pool) < THREAD_CONTEXT_POOL:
                ctx.__exit__(None, None, None)  # current nowhere now: another thread may take it
                _pool.append((ctx, resources))
                return
        for resource in reversed(list(resources.values())):
            resource.release()  # type: ignore[attr-defined]
        destroy_context(ctx)

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:  # noqa: BLE001 - a destructor must not raise; the thread is ending
            pass


_local = threading.local()


def _adopt_pooled() -> _ThreadGL | None:
    """A pooled context (all of this process's: a forked child moves the parent's aside,
    :func:`_after_fork_in_child`), made current on the calling thread with its resources' owners
    moved here; None if the pool is empty."""
    with _pool_lock:
        if not _pool:
            return None
        ctx, resources = _pool.pop()
    make_current(ctx)
    for resource in resources.values():
        owner = getattr(resource, "_owner", None)
        if isinstance(owner, GLOwner):
            owner.adopt()
    return _ThreadGL(ctx, resources)


def _thread_gl() -> _ThreadGL:
    """The calling thread's holder, adopted from the pool or made on first use (a forked child's
    inherited holder was already moved aside by :func:`_after_fork_in_child`)."""
    holder = getattr(_local, "holder", None)
    if holder is None:
        _local.holder = holder = _adopt_pooled() or _ThreadGL()
    return holder


def thread_context() -> moderngl.Context:
    """The calling thread's context, created on first use (one per thread and per process),
    current on return; released when the thread ends."""
    holder = _thread_gl()
    make_current(holder.ctx)
    return holder.ctx


def thread_resource(key: str, factory: Callable[[moderngl.Context], R]) -> R:
    """The calling thread's object ``key``, made by ``factory(thread_context())`` on first use and
    released (``.release()``) with the thread's context when the thread ends."""
    ctx = thread_context()
    resources = _local.holder.resources
    resource = resources.get(key)
    if resource is None:
        resource = resources[key] = factory(ctx)
    return resource  # type: ignore[return-value]


def _after_fork_in_child() -> None:
    global _display_lock, _pool_lock
    _display_lock, _pool_lock = threading.Lock(), threading.Lock()  # another thread may have held them
    holder = getattr(_local, "holder", None)
    if holder is not None:
        _inherited.append(holder)
        _local.holder = None
    _inherited.extend(_pool)  # the parent's pooled contexts: never used in the child
    _pool.clear()


os.register_at_fork(after_in_child=_after_fork_in_child)


# -- ownership ------------------------------------------------------------------------------------
def _thread_label(thread: threading.Thread | None, ident: int) -> str:
    name = thread.name if thread is not None else "?"
    return f"thread {name!r} (id {ident})"


class GLOwner:
    """The thread and process that made a GL-owning object (``what``, e.g. ``"Remapper"``).

    :meth:`enter` is called at the top of every method that touches GL: it raises ``RuntimeError``
    naming the object and both threads (or processes) when called from another one, and makes
    ``ctx`` current, since moderngl sends calls to whatever context is current.
    """

    def __init__(self, what: str, ctx: moderngl.Context) -> None:
        self.what = what
        self.ctx = ctx
        self.pid = os.getpid()
        self.thread_id = threading.get_ident()
        self.thread = threading.current_thread()

    def adopt(self) -> None:
        """Make the calling thread the owner (the thread-context pool hands a context and its
        objects to a new thread once their old thread has ended and unbound it)."""
        self.pid = os.getpid()
        self.thread_id = threading.get_ident()
        self.thread = threading.current_thread()

    def check(self) -> None:
        """Raise ``RuntimeError`` unless called on the owning thread of the owning process."""
        pid, ident = os.getpid(), threading.get_ident()
        if pid != self.pid:
            raise RuntimeError(
                f"this {self.what} was made in process {self.pid} and cannot be used in process {pid} "
                f"(a forked child): its GL context belongs to the parent. Make a new {self.what} in the child."
            )
        # a dead thread's id can be reused by a new thread; the owner is still alive while its
        # thread-local data is being released at its end
        if ident != self.thread_id or not self.thread.is_alive():
            raise RuntimeError(
                f"this {self.what} was made on {_thread_label(self.thread, self.thread_id)} and cannot be "
                f"used from {_thread_label(threading.current_thread(), ident)}: a GL context belongs to the "
                f"thread that made it. Make one {self.what} per thread (glradial.correct, distort, "
                f"render_crops and stadium_panorama keep one per thread for you)."
            )

    def enter(self) -> None:
        """:meth:`check`, then make the context current."""
        self.check()
        make_current(self.ctx)


# -- queries --------------------------------------------------------------------------------------
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
