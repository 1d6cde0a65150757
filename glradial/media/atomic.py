"""Atomic file writing: an output either appears complete or not at all.

Convention: the data is written to a temporary file in the *same folder* as the target (so that the
final ``os.replace`` is a rename on one file system, atomic on POSIX and Windows), whose name keeps
the target's extension (encoders such as OpenCV's choose the format from it). The temporary file is
removed on any exception, ``KeyboardInterrupt`` included, so an error or Ctrl-C leaves neither a
half-written output nor a stray temporary file. An existing target is only replaced on success.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text", "check_output_folder", "check_overwrite",
           "temporary_folder"]


def check_output_folder(path: str | os.PathLike) -> Path:
    """Return ``path`` as a ``Path`` after checking that its folder exists and it is not a folder.

    Raises ``FileNotFoundError`` (no such folder), ``NotADirectoryError`` (the folder's name is a
    file) or ``IsADirectoryError`` (``path`` is a folder), naming the path.
    """
    target = Path(path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        if folder.exists():
            raise NotADirectoryError(f"output folder {str(folder)!r} is a file, not a folder (for {str(target)!r})")
        raise FileNotFoundError(f"output folder {str(folder)!r} does not exist (for {str(target)!r})")
    if target.is_dir():
        raise IsADirectoryError(f"output {str(target)!r} is a folder, expected a file name")
    return target


def check_overwrite(path: str | os.PathLike, overwrite: bool) -> None:
    """``FileExistsError`` naming ``path`` when it exists and ``overwrite`` is false."""
    if not overwrite and os.path.lexists(path):
        raise FileExistsError(f"output {str(path)!r} already exists (overwrite it with -y/--overwrite)")


def _final_mode(target: Path) -> int:
    """Permissions for the finished file: those of the file it replaces, else ``0o666 & ~umask``
    (what ``open(path, "w")`` would give; ``mkstemp`` makes its files ``0o600``)."""
    try:
        return target.stat().st_mode & 0o7777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed to ``path``.

    The temporary name is ``.<name>.<random>.tmp<suffix>`` (hidden, same suffix as ``path``). The
    body writes the file at the yielded path (with any library); if the body raises, or writes
    nothing, the temporary file is removed and ``path`` is left untouched.
    """
    target = check_output_folder(path)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=f".{target.stem}.", suffix=f".tmp{target.suffix}", dir=target.parent if str(target.parent) else "."
        )
    except OSError as err:  # an unwritable folder (permissions, read-only or pseudo file system)
        raise _naming(err, target, "cannot create a file in its folder: ") from err
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise OSError(f"nothing was written for {str(target)!r}")
        os.chmod(tmp, _final_mode(target))
        os.replace(tmp, target)
    except OSError as err:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if err.errno is None:
            raise
        raise _naming(err, target) from err
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _naming(err: OSError, target: Path, context: str = "") -> OSError:
    """``err`` (an ``OSError`` with an errno) restated for the output ``target`` with its errno
    symbol (e.g. ENOSPC on a full disk), never the temporary file's name; same class and errno."""
    if err.errno is None:
        return err
    symbol = errno.errorcode.get(err.errno, str(err.errno))
    message = f"cannot write {str(target)!r}: {context}{os.strerror(err.errno)} ({symbol})"
    try:
        named = type(err)(message)
    except TypeError:
        named = OSError(message)
    named.errno = err.errno  # without strerror, str() is the message alone (no "[Errno 2]" prefix)
    return named


def temporary_folder(target: str | os.PathLike, prefix: str) -> Path:
    """A new hidden folder ``.<prefix><random>.tmp`` beside ``target`` (for outputs made of many
    files, moved into place by the caller); an unwritable folder raises ``OSError`` naming
    ``target`` and the errno symbol, not the temporary name."""
    target = Path(target)
    folder = target.parent if str(target.parent) else Path(".")
    try:
        return Path(tempfile.mkdtemp(prefix=f".{prefix}", suffix=".tmp", dir=folder))
    except OSError as err:
        raise _naming(err, target, "cannot create a folder in its folder: ") from err


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (fsync before the rename) and return the path."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically and return the path."""
    return atomic_write_bytes(path, text.encode(encoding))
