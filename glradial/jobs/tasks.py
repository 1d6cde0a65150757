"""What one input of each job command is: the command's own ``run`` on that one file, its outputs
written into the worker's staging folder, and the facts the report keeps.

``correct``/``distort`` write ``NAME`` (the input's file name; ``correct --auto`` on a video also
``NAME.lens.csv``, its sidecar); ``estimate`` and ``calibrate`` write ``NAME.json``: what the
one-file command prints with ``--json`` for that input (estimate: the image's object or the video's
document; calibrate: the list of per-frame objects). The command runs exactly as it does alone, so
a job's outputs are the one-file command's.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

from ..media.atomic import atomic_write_text

__all__ = ["JOB_COMMANDS", "CommandWork", "planned_outputs"]

#: the commands that run as jobs over many inputs (``crops`` shards separately: glradial.jobs.crop_shards)
JOB_COMMANDS = ("correct", "distort", "estimate", "calibrate")


def planned_outputs(command: str, options: dict, source: Path) -> list[str]:
    """The file names ``command`` writes in DIR for ``source``."""
    from ..media.image_io import media_kind

    name = source.name
    if command in ("estimate", "calibrate"):
        return [f"{name}.json"]
    if command == "correct" and options.get("auto") and media_kind(source) == "video":
        return [name, f"{name}.lens.csv"]
    return [name]


def _module(command: str):
    from ..commands import calibrate, correct, distort, estimate

    return {"correct": correct, "distort": distort, "estimate": estimate, "calibrate": calibrate}[command]


@dataclass(frozen=True)
class CommandWork:
    """``work(source, staging) -> facts`` of :mod:`glradial.jobs.worker` for ``command`` with
    ``options`` (the parsed options, without paths and job options). Picklable: it travels to pool
    processes and Ray actors."""

    command: str
    options: dict

    def __call__(self, source: str, staging: Path) -> dict:
        facts: dict = {}
        args = argparse.Namespace(**self.options, quiet=True, overwrite=True, job_facts=facts)
        out, err = io.StringIO(), io.StringIO()
        if self.command in ("correct", "distort"):
            args.input, args.output = source, str(staging / Path(source).name)
        elif self.command == "estimate":
            args.inputs, args.json = [source], True
        else:
            args.input, args.json = source, True
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = _module(self.command).run(args)
        if status:
            raise RuntimeError(f"'{self.command}' ended with status {status}: {' '.join(err.getvalue().split())[-300:]}")
        warnings = [line for line in err.getvalue().splitlines() if "warning" in line]
        if warnings:
            facts["warnings"] = warnings
        if self.command in ("estimate", "calibrate"):
            records = [json.loads(line) for line in out.getvalue().splitlines() if line.strip()]
            document = records if self.command == "calibrate" else records[0]
            atomic_write_text(staging / f"{Path(source).name}.json", json.dumps(document, indent=1) + "\n")
            facts.update(_record_facts(self.command, document))
        return facts


def _record_facts(command: str, document) -> dict:
    """The report's facts of an estimate (an image's object or a video's document) or of a calibration (frames)."""
    if command == "estimate":
        if "shots" in document:
            shots = document["shots"]
            return {"shot_list": shots, "frames": sum(s["last_frame"] - s["first_frame"] + 1 for s in shots)}
        return {"frames": 1, **{k: document.get(k) for k in ("k1", "k2", "method", "uncertainty_px", "doubtful", "reason")}}
    frames = document
    facts: dict = {"frames": len(frames), "doubtful_frames": sum(bool(f.get("doubtful")) for f in frames)}
    if any("shot" in f for f in frames):
        facts["shots"] = len({f["shot"] for f in frames})
    sure = [f for f in frames if not f.get("doubtful") and f.get("focal") is not None]
    if sure:
        facts["camera"] = {key: sure[len(sure) // 2].get(key) for key in ("k1", "k2", "focal", "hfov_deg", "position_m",
                                                                         "pan_deg", "tilt_deg", "roll_deg", "uncertainty_px")}
    return facts
