"""Silence what native libraries (FFmpeg, libpng, libjpeg, OpenCV's logger) print on stderr.

Those libraries write straight to file descriptor 2, beside glradial's own one-line errors: a
corrupt PNG gives ``libpng error: ...`` and then glradial's ``ValueError`` says the same. Around a
native decode or encode, :func:`silenced` points descriptor 2 at ``/dev/null`` and restores it
after; glradial reports the failure itself (the caller checks the library's return value). It is
process-wide while active (another thread's stderr output in that window is dropped too), so it
wraps single library calls only, never a long computation. Nested and concurrent uses share one
redirection (a counter under a lock). ``GLRADIAL_DEBUG=1`` leaves stderr alone.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from typing import Iterator

_lock = threading.Lock()
_depth = 0
_saved_fd: int | None = None


@contextlib.contextmanager
def silenced() -> Iterator[None]:
    """Descriptor 2 goes to ``/dev/null`` inside the block (see the module docstring)."""
    global _depth, _saved_fd
    if os.environ.get("GLRADIAL_DEBUG"):
        yield
        return
    with _lock:
        if _depth == 0:
            try:
                sys.stderr.flush()
            except (AttributeError, OSError, ValueError):
                pass
            saved = os.dup(2)
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 2)
            os.close(null)
            _saved_fd = saved
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _saved_fd is not None:
                os.dup2(_saved_fd, 2)
                os.close(_saved_fd)
                _saved_fd = None


def _after_fork_in_child() -> None:
    """A fork while another thread had descriptor 2 silenced: give the child its stderr back."""
    global _lock, _depth, _saved_fd
    _lock = threading.Lock()
    if _saved_fd is not None:
        os.dup2(_saved_fd, 2)
        os.close(_saved_fd)
    _depth, _saved_fd = 0, None


os.register_at_fork(after_in_child=_after_fork_in_child)
