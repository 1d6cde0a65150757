"""A job over many inputs: what is complete is skipped, the rest is run on a runner
(:class:`~glradial.jobs.pool.ProcessRunner` or :class:`~glradial.jobs.ray_runner.RayRunner`) with
bounded retries, the manifest saved after each input, one progress bar, and the report at the end.

Rules: every input of a job is checked (digest, output names, outputs in the way) before any work;
an input that is not complete has no output in DIR (a stale one from an earlier run with other
options or another file is removed when its work starts); a failure (an error, or the worker's
death) is retried up to ``retries`` more times, then recorded as failed while the rest completes;
Ctrl-C stops the workers, leaves in-flight inputs ``pending`` in the manifest (which is saved, as
always, atomically) and removes the staging folder.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..media.progress import Progress
from .manifest import Manifest
from .report import report_rows, write_report
from .worker import STAGING, Task

__all__ = ["JobSummary", "run_job"]


@dataclass
class JobSummary:
    """How a job ended: input names done (this run), skipped (complete before), failed, pending
    (interrupted); the frames written; the report's paths."""

    done: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    frames: int = 0
    seconds: float = 0.0
    report: tuple[Path, Path] | None = None


def _plan(manifest: Manifest, inputs: list[Path], planned: Callable[[Path], list[str]], overwrite: bool):
    """(tasks to run, names skipped); refuses outputs in the way before any work."""
    out_dir = manifest.path.parent
    tasks, skipped = [], []
    for source in inputs:
        digest = manifest.input_digest(source.name, source)
        if manifest.complete(source.name, source, digest):
            skipped.append(source.name)
            continue
        outputs = planned(source)
        for output in outputs:
            if (out_dir / output).exists() and not overwrite and not manifest.owns(output):
                raise FileExistsError(f"output {str(out_dir / output)!r} already exists and is not this job's "
                                      "(overwrite it with -y/--overwrite)")
        tasks.append((Task(source.name, str(source), str(out_dir)), source, digest, outputs))
    return tasks, skipped


def _clear_stale(manifest: Manifest, name: str) -> None:
    """Remove the outputs an earlier run left for ``name`` (redone now) and its staging leftovers."""
    out_dir = manifest.path.parent
    for output in manifest.entries.get(name, {}).get("outputs", []) + manifest.entries.get(name, {}).get("planned", []):
        if (out_dir / output).is_dir():
            shutil.rmtree(out_dir / output)
        else:
            (out_dir / output).unlink(missing_ok=True)
    for left in (out_dir / STAGING).glob(f"{name}.*"):
        shutil.rmtree(left, ignore_errors=True)


def _settle(manifest: Manifest, task: Task, result, attempts: dict, retries: int, queue: deque, summary: JobSummary) -> bool:
    """Record one ended attempt; returns whether ``task`` is finished (done or failed for good)."""
    error = "the worker died (killed or crashed)" if result is None else result.error
    common = dict(attempts=attempts[task.name], seconds=None if result is None else round(result.seconds, 3),
                  worker=None if result is None else result.worker)
    if error is None:
        manifest.finish(task.name, "done", outputs=result.outputs, facts=result.facts, error=None, **common)
        summary.done.append(task.name)
        summary.frames += int(result.facts.get("frames") or 0)
        return True
    _clear_stale(manifest, task.name)
    if attempts[task.name] <= retries:
        print(f"glradial: warning: {task.source}: {error}; retrying (attempt {attempts[task.name] + 1} of {retries + 1})",
              file=sys.stderr, flush=True)
        queue.append(task)
        return False
    manifest.finish(task.name, "failed", error=error, outputs=[], **common)
    summary.failed.append(task.name)
    return True


def _drive(runner, manifest: Manifest, tasks: list[Task], retries: int, bar: Progress, summary: JobSummary) -> None:
    queue, attempts = deque(tasks), {t.name: 0 for t in tasks}
    busy = 0
    while queue or busy:
        while queue and runner.free():
            task = queue.popleft()
            attempts[task.name] += 1
            runner.submit(task)
            busy += 1
        for task, result in runner.wait(0.5):
            busy -= 1
            if _settle(manifest, task, result, attempts, retries, queue, summary):
                manifest.save()
                bar.update(1)
                bar.describe(frames=summary.frames, failed=len(summary.failed))


def run_job(command: str, inputs: list[Path], out_dir: str | Path, make_runner: Callable[[], object], options: dict,
            planned: Callable[[Path], list[str]], *, retries: int = 1, overwrite: bool = False,
            progress: bool | None = None) -> JobSummary:
    """Run ``command`` (its ``options``) over ``inputs`` into ``out_dir``: ``make_runner()`` gives the
    runner (called only when there is work); ``planned(source)`` the output names of an input.
    Prints "nothing to do" and writes nothing when every input is complete."""
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ValueError(f"retries must be an integer >= 0, got {retries!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"--out-dir {str(out)!r} is a file, not a folder")
    out.mkdir(parents=True, exist_ok=True)
    manifest = Manifest(out, command, options)
    plan, skipped = _plan(manifest, inputs, planned, overwrite)
    summary = JobSummary(skipped=skipped)
    if not plan:
        print(f"nothing to do: all {len(skipped)} input(s) already complete in {out} (its manifest.json); "
              "outputs and report unchanged", flush=True)
        return summary
    start = time.perf_counter()
    for task, source, digest, outputs in plan:
        _clear_stale(manifest, task.name)
        manifest.start(task.name, source, digest, outputs)
    manifest.save()
    try:
        with Progress(len(inputs), command, unit="files", enabled=progress) as bar:
            bar.update(len(skipped))
            runner = make_runner()
            try:
                _drive(runner, manifest, [p[0] for p in plan], retries, bar, summary)
            except BaseException:  # Ctrl-C, SIGTERM: the workers are ended at once, then what they left is removed
                runner.close(kill=True)
                for task, *_ in plan:
                    if manifest.entries[task.name]["status"] == "pending":
                        _clear_stale(manifest, task.name)
                raise
            runner.close()
    finally:
        manifest.save()
        shutil.rmtree(out / STAGING, ignore_errors=True)
        names = {source.name for source in inputs}
        summary.seconds = time.perf_counter() - start
        summary.report = write_report(out, report_rows({k: v for k, v in manifest.entries.items() if k in names}, set(skipped)))
    return summary
