"""The one place benches keep their measured figures: ``docs/figures/NAME.json``.

Every bench that measures something a document quotes calls :func:`write_figure` once at its end.
The file records what was measured (``results``: any JSON-serialisable value, units in the key names,
e.g. ``median_px``, ``ms_per_frame``) and how (the machine, the UTC date, the commit and whether the
tree had uncommitted changes, the exact command). Documents point to a figure by its file name (or to
the table ``scripts/render_figures.py`` renders from all of them) instead of quoting it by hand, so a
new measurement changes one generated file, not prose in several.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import io
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any, Iterator

ROOT = Path(__file__).resolve().parents[1]
#: Where the figures live (one JSON file per bench and variant).
FIGURES_DIR = ROOT / "docs" / "figures"


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def machine() -> dict[str, Any]:
    """What the figures were measured on: CPU model, logical CPUs, OS and Python."""
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "logical_cpus": os.cpu_count(), "system": platform.platform(),
            "python": platform.python_version()}


def write_figure(name: str, results: Any, argv: list[str] | None = None,
                 directory: Path | None = None) -> Path:
    """Write ``results`` as ``docs/figures/<name>.json`` (atomically) with how they were measured.

    Args:
        name: the figure's file stem: the bench's name, plus a variant where one bench writes several
            (``"calibrate_matches"``, ``"bench_video_1920x1080"``); letters, digits, ``_`` and ``-``.
        results: the measured values (JSON-serialisable; NaN is written as ``null``).
        argv: the bench's arguments (default ``sys.argv[1:]``), recorded in ``command``.
        directory: where to write (default: the environment's ``GLRADIAL_FIGURES_DIR``, else
            :data:`FIGURES_DIR`; tests that run a bench set it to a temporary folder).

    Returns:
        The path written.

    Raises:
        ValueError: ``name`` is empty or holds other characters than letters, digits, ``_``, ``-``.
    """
    if not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ValueError(f"name must be letters, digits, '_' or '-', got {name!r}")
    argv = sys.argv[1:] if argv is None else list(argv)
    script = Path(sys.argv[0]).resolve()
    try:
        script_name = str(script.relative_to(ROOT))
    except ValueError:
        script_name = script.name
    record = {
        "name": name,
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "commit": _git("rev-parse", "--short", "HEAD"),
        "dirty": bool(_git("status", "--porcelain", "--untracked-files=no")),
        "command": " ".join(["python", script_name, *argv]),
        "machine": machine(),
        "results": _finite(results),
    }
    if directory is None:
        directory = Path(os.environ.get("GLRADIAL_FIGURES_DIR") or FIGURES_DIR)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=1, allow_nan=False) + "\n")
    os.replace(tmp, path)
    return path


def _finite(value: Any) -> Any:
    """``value`` with NaN and infinities replaced by ``None`` (strict JSON) and numpy scalars as Python."""
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if hasattr(value, "item") and callable(value.item) and getattr(value, "ndim", 1) == 0:
        value = value.item()
    if isinstance(value, float) and (value != value or value in (float("inf"), float("-inf"))):
        return None
    return value


@contextlib.contextmanager
def printed_report() -> Iterator[list[str]]:
    """Collect what a bench prints (its report table) while still printing it: the yielded list
    holds the printed lines once the block ends. For benches whose figures are a printed table,
    written as ``write_figure(name, {"report": lines})`` (rendered verbatim in docs/BENCH.md)."""
    lines: list[str] = []
    buffer = io.StringIO()

    real = sys.stdout

    class _Both(io.TextIOBase):
        def write(self, text: str) -> int:
            real.write(text)
            buffer.write(text)
            return len(text)

        def flush(self) -> None:
            real.flush()

    with contextlib.redirect_stdout(_Both()):
        yield lines
    lines.extend(buffer.getvalue().splitlines())
