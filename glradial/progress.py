"""A small text progress bar on stderr for long command-line work (no dependency).

It draws only when enabled (by default: when stderr is a terminal), redraws at most a few times a
second, and prints a final line with the count and the elapsed time when closed.
"""

from __future__ import annotations

import sys
import time
from typing import IO

__all__ = ["Progress"]


class Progress:
    """``Progress(total, label)``; call :meth:`update` per unit of work, :meth:`close` at the end.

    ``total`` may be ``None`` or ``<= 0`` (unknown): the bar then shows a count and a rate only.
    ``enabled=None`` draws when ``stream`` is a terminal.
    """

    def __init__(
        self,
        total: int | None,
        label: str,
        *,
        unit: str = "frames",
        enabled: bool | None = None,
        stream: IO[str] | None = None,
        width: int = 30,
        interval_s: float = 0.2,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = enabled
        self.total = total if total is not None and total > 0 else None
        self.label, self.unit, self.width, self.interval_s = label, unit, width, interval_s
        self.count = 0
        self._start = time.monotonic()
        self._last_draw = 0.0
        self._closed = False

    def update(self, n: int = 1) -> None:
        self.count += n
        now = time.monotonic()
        if self.enabled and now - self._last_draw >= self.interval_s:
            self._last_draw = now
            self._draw(now, end="\r")

    def _draw(self, now: float, end: str) -> None:
        elapsed = max(now - self._start, 1e-9)
        rate = self.count / elapsed
        if self.total:
            done = min(self.count / self.total, 1.0)
            filled = int(round(done * self.width))
            bar = "#" * filled + "-" * (self.width - filled)
            remaining = (self.total - self.count) / rate if rate > 0 else float("inf")
            eta = f" eta {remaining:4.0f}s" if end == "\r" and remaining != float("inf") else ""
            text = f"{self.label} [{bar}] {self.count}/{self.total} {self.unit} {rate:5.1f}/s {elapsed:5.1f}s{eta}"
        else:
            text = f"{self.label} {self.count} {self.unit} {rate:5.1f}/s {elapsed:5.1f}s"
        self.stream.write(text.ljust(79) + end)
        self.stream.flush()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self.enabled:
                self._draw(time.monotonic(), end="\n")

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
