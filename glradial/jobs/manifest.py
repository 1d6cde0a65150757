"""The manifest of a job: ``DIR/manifest.json``, what a rerun of the same command reads to skip
complete work.

Format (JSON, version 1): ``{"version", "command", "options", "options_digest", "entries"}``;
``entries`` maps each input's output name (its file name) to ``{"input", "size", "mtime_ns",
"digest" (SHA-256 of the input file), "options_digest", "status" ("pending", "done" or "failed"),
"attempts", "outputs" (file names in DIR), "error", "facts", "seconds", "worker"}``. Only the
job's own process writes it, atomically (:mod:`glradial.media.atomic`), after each input ends, so
it is always one consistent document: an entry is ``done`` only once all its outputs are in place.
An input is complete when its entry is ``done`` with the same digest and options and every output
exists. A file whose size and modification time are those recorded keeps its recorded digest (as
``git`` and ``rsync`` trust them), so a rerun does not read a season's videos again.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..estimation.model_check import file_sha256
from ..media.atomic import atomic_write_text

__all__ = ["MANIFEST_NAME", "Manifest", "options_digest"]

MANIFEST_NAME = "manifest.json"
VERSION = 1
STATUSES = ("pending", "done", "failed")


def options_digest(command: str, options: dict) -> str:
    """SHA-256 of the command and its options (JSON, keys sorted): what makes two runs the same job."""
    text = json.dumps({"command": command, "options": options}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


class Manifest:
    """``DIR/manifest.json`` of ``command`` run with ``options`` (read if it exists)."""

    def __init__(self, out_dir: Path, command: str, options: dict) -> None:
        self.path = Path(out_dir) / MANIFEST_NAME
        self.command = command
        self.options = options
        self.digest = options_digest(command, options)
        self.entries: dict[str, dict] = {}
        self._lines: dict[str, str] = {}  # each entry's line as last saved; entries changed since are re-encoded
        if self.path.exists():
            self._read()

    def _read(self) -> None:
        try:
            document = json.loads(self.path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as err:
            raise ValueError(f"job manifest {str(self.path)!r} is not JSON ({err}): move it away to start afresh") from None
        if not isinstance(document, dict) or document.get("version") != VERSION or not isinstance(document.get("entries"), dict):
            raise ValueError(f"job manifest {str(self.path)!r} is not a glradial job manifest (version {VERSION})")
        if document.get("command") != self.command:
            raise ValueError(f"output folder {str(self.path.parent)!r} holds a '{document.get('command')}' job, not "
                             f"'{self.command}': give another --out-dir")
        self.entries = document["entries"]

    def input_digest(self, name: str, source: Path) -> str:
        """``source``'s SHA-256: the recorded one when its size and modification time are unchanged."""
        stat = source.stat()
        entry = self.entries.get(name, {})
        if entry.get("input") == str(source) and entry.get("size") == stat.st_size and entry.get("mtime_ns") == stat.st_mtime_ns \
                and entry.get("digest"):
            return entry["digest"]
        return file_sha256(source)

    def complete(self, name: str, source: Path, digest: str) -> bool:
        """Whether ``name`` is done for this ``digest`` and these options, its outputs all there."""
        entry = self.entries.get(name)
        if not entry or entry.get("status") != "done" or entry.get("digest") != digest or entry.get("options_digest") != self.digest:
            return False
        return all((self.path.parent / output).exists() for output in entry.get("outputs", []))

    def owns(self, output: str) -> bool:
        """Whether the file ``output`` in DIR was planned or written by a run of this job."""
        return any(output in entry.get("outputs", []) or output in entry.get("planned", []) for entry in self.entries.values())

    def start(self, name: str, source: Path, digest: str, planned: list[str]) -> None:
        """Record ``name`` as pending (before any work on it), its outputs planned."""
        stat = source.stat()
        previous = self.entries.get(name, {})
        self._lines.pop(name, None)
        self.entries[name] = {"input": str(source), "size": stat.st_size, "mtime_ns": stat.st_mtime_ns, "digest": digest,
                              "options_digest": self.digest, "status": "pending", "attempts": 0,
                              "planned": sorted(set(planned) | set(previous.get("outputs", []))), "outputs": [],
                              "error": None, "facts": {}, "seconds": None, "worker": None}

    def finish(self, name: str, status: str, **fields: object) -> None:
        """Set ``name``'s ``status`` (:data:`STATUSES`) and fields (outputs, error, facts, seconds, worker, attempts)."""
        if status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)}, got {status!r}")
        self._lines.pop(name, None)
        self.entries[name].update(status=status, **fields)

    def save(self) -> None:
        """Write the manifest atomically (the previous one stays until the new one is complete): one
        entry a line, only the entries changed since the last save encoded again (it is saved after
        each input: an indented document, re-encoded whole by the json module's pure-Python encoder,
        cost ~0.2 ms x N inputs per input)."""
        head = json.dumps({"version": VERSION, "command": self.command, "options": self.options, "options_digest": self.digest},
                          sort_keys=True, default=str)
        for name in self.entries.keys() - self._lines.keys():
            self._lines[name] = f"{json.dumps(name)}: {json.dumps(self.entries[name], sort_keys=True, default=str)}"
        lines = ",\n".join(self._lines[name] for name in sorted(self.entries))
        atomic_write_text(self.path, f'{head[:-1]}, "entries": {{\n{lines}\n}}}}\n')

    def counts(self) -> dict[str, int]:
        """How many entries have each status."""
        return {status: sum(1 for e in self.entries.values() if e.get("status") == status) for status in STATUSES}
