"""Keep Mesa's LLVM and a Python package's own LLVM apart in one process.

Mesa's software rasteriser (llvmpipe) links the system's ``libLLVM``, and the driver is loaded into
the process's global symbol scope: before the first EGL context, ``dlsym(RTLD_DEFAULT,
"LLVMContextCreate")`` finds nothing; after it, the system's LLVM (Debian 12: ``libLLVM-15``). From
then on every LLVM symbol name in the process resolves there first. A library loaded *after* that which carries a different LLVM
inside itself and exports its symbols (triton's ``libtriton.so``, which the registry's default,
CUDA-enabled torch installs and imports lazily from its optimisers and ``torch.compile``) then has
its own LLVM calls bound to the system's LLVM of another version, and the interpreter dies with a
segmentation fault at ``import triton``.

Loaded *before* Mesa, such a library binds its LLVM calls to its own copy (``RTLD_LOCAL``: nothing
of it becomes visible to Mesa or anyone else), and both work side by side. :func:`guard_bundled_llvm`
does that, once per process, before glradial makes its first EGL context: it only maps the library
(about 20 ms for triton; no Python import, no torch), and does nothing where the package is not
installed. Where the library is there but cannot be loaded, a warning says what to do instead.
"""

from __future__ import annotations

import glob
import importlib.util
import logging
import os
import threading
import warnings

logger = logging.getLogger(__name__)

#: Packages known to ship a shared library with their own LLVM's symbols exported, and the glob
#: (relative to the package's folder) of that library.
BUNDLED_LLVM_LIBRARIES: tuple[tuple[str, str], ...] = (("triton", os.path.join("_C", "libtriton*.so")),)

_guarded = False
_lock = threading.Lock()


def _library_paths(package: str, pattern: str) -> list[str]:
    """The files matching ``pattern`` in the installed ``package``'s folder (none if it is absent)."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return []
    if spec is None or not spec.submodule_search_locations:
        return []
    return sorted(p for folder in spec.submodule_search_locations for p in glob.glob(os.path.join(folder, pattern)))


def guard_bundled_llvm() -> list[str]:
    """Load, with ``RTLD_LOCAL``, every installed library of :data:`BUNDLED_LLVM_LIBRARIES`, once per
    process and before Mesa's LLVM is global (the module docstring says why). Returns the paths it
    loaded on this call (empty on later calls or when none is installed)."""
    global _guarded
    import ctypes

    with _lock:
        if _guarded:
            return []
        _guarded = True
        loaded = []
        for package, pattern in BUNDLED_LLVM_LIBRARIES:
            for path in _library_paths(package, pattern):
                try:
                    ctypes.CDLL(path, mode=os.RTLD_NOW | os.RTLD_LOCAL)
                except OSError as err:
                    warnings.warn(
                        f"glradial could not preload {path} ({err}); importing {package!r} after an OpenGL "
                        f"context exists may crash the interpreter (two LLVMs in one process): import "
                        f"{package} before using glradial's GL backend, or use backend='cpu'",
                        RuntimeWarning, stacklevel=3)
                    continue
                logger.debug("preloaded %s before Mesa's LLVM", path)
                loaded.append(path)
        return loaded
