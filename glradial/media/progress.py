"""Progress bars on stderr for long command-line work, drawn by tqdm.

:class:`Progress` is the one interface the commands use: ``with Progress(total, label) as bar:``
then ``bar.update(n)`` per unit of work. It draws only when enabled (by default: when stderr is a
terminal; ``glradial -q`` disables it), so piped or logged output stays clean.
"""

from __future__ import annotations

import sys
from contextlib import AbstractContextManager
from typing import IO

from tqdm import tqdm

__all__ = ["Progress"]


class Progress(AbstractContextManager):
    """``Progress(total, label)``; call :meth:`update` per unit of work, :meth:`close` at the end.

    ``total`` may be ``None`` or ``<= 0`` (unknown): the bar then shows a count and a rate only.
    ``enabled=None`` draws when ``stream`` (default stderr) is a terminal.
    """

    def __init__(
        self,
        total: int | None,
        label: str,
        *,
        unit: str = "frames",
        enabled: bool | None = None,
        stream: IO[str] | None = None,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.enabled = bool(enabled)
        self.total = total if total is not None and total > 0 else None
        self.count = 0
        self._bar = tqdm(total=self.total, desc=label, unit=f" {unit}", file=self.stream, disable=not self.enabled,
                         dynamic_ncols=True, mininterval=0.2, leave=True)

    def update(self, n: int = 1) -> None:
        self.count += n
        self._bar.update(n)

    def describe(self, **postfix: object) -> None:
        """Show ``name=value`` pairs after the bar (e.g. a job's frames and failures)."""
        self._bar.set_postfix(postfix, refresh=False)

    def close(self) -> None:
        self._bar.close()

    def __exit__(self, *exc: object) -> None:
        self.close()
