"""SRT through the system's FFmpeg where PyAV's own FFmpeg lacks libsrt (PyAV's wheels do).

An ``srt://`` URL (caller by default; ``?mode=listener`` waits for a caller; FFmpeg's SRT options,
e.g. ``latency``, ``passphrase``, pass through in the query) is read or written by a relay: the
``ffmpeg`` command (:data:`FFMPEG`) copies the stream, without re-encoding, between SRT and a pipe
of MPEG-TS that PyAV reads or writes (``pipe:FD``), so the causal rules of ``glradial live`` are
unchanged: the relay adds no buffering beyond FFmpeg's probe (kept as short as
:mod:`glradial.media.stream_io`'s) and SRT's own ``latency``.

:func:`srt_route` says which FFmpeg carries SRT: ``"pyav"`` (PyAV's build has libsrt), ``"ffmpeg"``
(the relay), or ``ValueError`` naming what to install when neither does.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
from functools import lru_cache

import av

__all__ = ["FFMPEG", "srt_route", "SrtRelay", "is_srt"]

#: the system FFmpeg command the relay runs (Debian's ffmpeg is built with libsrt)
FFMPEG = "ffmpeg"
#: the relay's probe of an SRT input: as short as stream_io's (microseconds, bytes)
RELAY_PROBE = ("-probesize", "500000", "-analyzeduration", "100000")
#: seconds an SRT output waits at its end for the peer to take what it has not yet acknowledged
LINGER_S = 2
#: the output relay's probe of glradial's own MPEG-TS: the first packets only (its parameters lead the
#: first key frame), so that frames go on as they come rather than in a burst after the probe
OUT_PROBE = ("-probesize", "32768", "-analyzeduration", "0")


def is_srt(url: str) -> bool:
    """Whether ``url`` is an ``srt://`` URL."""
    return url.lower().startswith("srt://")


@lru_cache(maxsize=1)
def _pyav_has_srt() -> bool:
    """Whether PyAV's FFmpeg knows the srt protocol (an unknown protocol fails before any network)."""
    try:
        av.open("srt://127.0.0.1:9?mode=caller&connect_timeout=1", "r", timeout=0.05).close()
    except av.ProtocolNotFoundError:
        return False
    except Exception:  # a connection error: the protocol exists
        return True
    return True


def _ffmpeg_has_srt(command: str) -> bool:
    path = shutil.which(command)
    if path is None:
        return False
    try:
        listing = subprocess.run([path, "-hide_banner", "-protocols"], capture_output=True, text=True, timeout=20).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return "srt" in {line.strip() for line in listing.splitlines()}


def srt_route() -> str:
    """``"pyav"`` or ``"ffmpeg"`` (module docstring); ``ValueError`` when neither has SRT."""
    if _pyav_has_srt():
        return "pyav"
    if _ffmpeg_has_srt(FFMPEG):
        return "ffmpeg"
    raise ValueError(f"srt:// needs FFmpeg with libsrt: PyAV's build has none, and the system's {FFMPEG!r} "
                     f"{'has no srt protocol' if shutil.which(FFMPEG) else 'was not found'}; install FFmpeg with SRT "
                     "(Debian/Ubuntu: apt-get install ffmpeg; scripts/install_system_deps.sh does it)")


class SrtRelay:
    """An ``ffmpeg`` process copying MPEG-TS between the SRT ``url`` and a pipe: ``direction``
    ``"in"`` (SRT -> :attr:`url`, a ``pipe:FD`` PyAV reads) or ``"out"`` (a ``pipe:FD`` PyAV
    writes -> SRT). ``idle_timeout`` (s, input): the SRT read gives up after so long without data
    (the relay then ends, which ends the input). :meth:`close` ends it (the output flushed first)."""

    def __init__(self, url: str, direction: str, *, idle_timeout: float | None = None) -> None:
        if direction not in ("in", "out"):
            raise ValueError(f"direction must be 'in' or 'out', got {direction!r}")
        if not is_srt(url):
            raise ValueError(f"url must be an srt:// URL, got {url!r}")
        self.source, self.direction = url, direction
        command = [shutil.which(FFMPEG) or FFMPEG, "-hide_banner", "-nostdin", "-loglevel", "error"]
        if direction == "in":
            srt = url if idle_timeout is None else _with_option(url, "timeout", int(idle_timeout * 1e6))
            command += [*RELAY_PROBE, "-i", srt, "-map", "0", "-c", "copy", "-f", "mpegts", "pipe:1"]
            self.process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            self.url = f"pipe:{self.process.stdout.fileno()}"
        else:
            srt = _with_option(url, "linger", LINGER_S)  # the last frames still reach the peer when the stream ends
            command += ["-f", "mpegts", *OUT_PROBE, "-i", "pipe:0", "-map", "0", "-c", "copy", "-f", "mpegts", srt]
            self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
            self.url = f"pipe:{self.process.stdin.fileno()}"

    def error(self) -> str:
        """The relay's complaint once it has ended ("" while it runs or when it said nothing)."""
        if self.process.poll() is None:
            return ""
        with contextlib.suppress(Exception):
            return self.process.stderr.read().decode("utf-8", "replace").strip()
        return ""

    def close(self, wait: float = 5.0) -> None:
        """End the relay: an output's pipe is closed (FFmpeg flushes to SRT and exits), an input's
        process is stopped; killed after ``wait`` s. Again, a no-op."""
        pipe = self.process.stdin if self.direction == "out" else self.process.stdout
        with contextlib.suppress(OSError):
            pipe.close()
        if self.direction == "in" and self.process.poll() is None:
            self.process.terminate()
        try:
            self.process.wait(timeout=wait)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()


def _with_option(url: str, name: str, value: object) -> str:
    """``url`` with ``name=value`` added to its query unless it sets ``name`` already."""
    query = url.partition("?")[2]
    if any(part.partition("=")[0] == name for part in query.split("&") if part):
        return url
    return url + ("&" if "?" in url else "?") + f"{name}={value}"
