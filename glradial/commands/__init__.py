"""Subcommands of the ``glradial`` command, one module each.

Contract (read by :mod:`glradial.cli`): a module ``glradial/commands/<name>.py`` exposes

* ``add_parser(subparsers) -> argparse.ArgumentParser``: adds its subparser (named ``<name>``) with a
  help text that documents every option and its units, and
* ``run(args) -> int``: does the work, returns the exit status (0 on success).

Modules import heavy libraries (moderngl, onnxruntime, torch) inside ``run``, never at import time,
so that ``glradial --help`` stays fast. ``run`` reports bad input by raising :class:`UsageError`
(wrong combination of options: exit 2), :class:`CliError`, ``ValueError``, ``TypeError`` or ``OSError``
(exit 1); the CLI prints one line ``glradial: error: <message>`` and no traceback. Outputs are written
atomically (:mod:`glradial.atomic`, :mod:`glradial.media_io`).

Shared helpers for command modules live here: :func:`parse_size`, :func:`positive_int`,
:func:`show_progress`.
"""

from __future__ import annotations

import argparse
import re

__all__ = ["CliError", "UsageError", "parse_size", "positive_int", "positive_float", "show_progress"]

_SIZE = re.compile(r"^\s*(\d+)\s*[xX×,]\s*(\d+)\s*$")


class CliError(Exception):
    """A user-facing error: the CLI prints its message on one line and exits with status 1."""


class UsageError(CliError):
    """A wrong combination of options: printed with a pointer to ``--help``, exit status 2."""


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for ``WxH`` (pixels), e.g. ``1920x1080`` -> ``(1920, 1080)``."""
    match = _SIZE.match(text)
    if not match:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT in pixels, e.g. 1920x1080, got {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    if width <= 0 or height <= 0:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return width, height


def _int_at_least(text: str, minimum: int, kind: str) -> int:
    """Parse ``text`` as an integer ``>= minimum``; the error names ``kind`` (e.g. "positive")."""
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < minimum:
        raise argparse.ArgumentTypeError(f"expected a {kind} integer, got {text!r}") from None
    return value


def positive_int(text: str) -> int:
    """argparse type for an integer >= 1."""
    return _int_at_least(text, 1, "positive")


def non_negative_int(text: str) -> int:
    """argparse type for an integer >= 0 (seeds)."""
    return _int_at_least(text, 0, "non-negative")


def positive_float(text: str) -> float:
    """argparse type for a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """argparse type for a finite number (rejects nan/inf)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def show_progress(args: argparse.Namespace) -> bool | None:
    """Whether to draw progress bars: ``None`` (auto: when stderr is a terminal) unless ``--quiet``."""
    return False if getattr(args, "quiet", False) else None
