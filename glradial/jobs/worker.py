"""One input of a job, run where a worker is (a pool process or a Ray actor).

The worker writes the input's outputs into a staging folder of its own inside the output folder
(``DIR/.staging/NAME.XXXX/``), then moves each into place with ``os.replace`` (atomic on one file
system) and removes the staging folder: a final name never holds a half-written file, whatever
happens to the worker; what a killed worker leaves under ``DIR/.staging`` is removed by the job.
A :class:`JobWorker` lives as long as its process or actor, so the caches of the process (the
ONNX session of an estimator, the GL context of its thread) serve every input it is given.
"""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

__all__ = ["STAGING", "Task", "Result", "JobWorker", "run_task", "worker_name"]

#: the staging folder's name inside the output folder
STAGING = ".staging"


@dataclass(frozen=True)
class Task:
    """One unit of work: the input ``source`` whose outputs go into ``out_dir`` under ``name``."""

    name: str
    source: str
    out_dir: str


@dataclass
class Result:
    """What a task gave: output file names in DIR, facts for the report, seconds, the worker
    (``host:pid``) and, when it failed, the error (one line)."""

    name: str
    outputs: list[str] = field(default_factory=list)
    facts: dict = field(default_factory=dict)
    seconds: float = 0.0
    worker: str = ""
    error: str | None = None


def worker_name() -> str:
    """``host:pid`` of this process."""
    return f"{socket.gethostname()}:{os.getpid()}"


def run_task(work: Callable[[str, Path], dict], task: Task) -> Result:
    """Run ``work(source, staging) -> facts`` for ``task`` and move what it wrote into place. An
    exception becomes the result's ``error``; ``KeyboardInterrupt`` and ``SystemExit`` propagate."""
    start = time.perf_counter()
    root = Path(task.out_dir) / STAGING
    root.mkdir(exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f"{task.name}.", dir=root))
    try:
        facts = work(task.source, staging) or {}
        written = sorted(p.name for p in staging.iterdir() if not p.name.startswith("."))
        if not written:
            raise RuntimeError("the command wrote no output")
        for name in written:  # a file, or a folder (a crops shard) moved whole
            os.replace(staging / name, Path(task.out_dir) / name)
        return Result(task.name, written, facts, time.perf_counter() - start, worker_name())
    except Exception as err:  # the job records it and goes on with the other inputs
        message = " ".join(str(err).split()) or type(err).__name__
        if not isinstance(err, (ValueError, TypeError, OSError)) and type(err).__name__ not in message:
            message = f"{type(err).__name__}: {message}"
        return Result(task.name, seconds=time.perf_counter() - start, worker=worker_name(), error=message)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


class JobWorker:
    """A worker's state across inputs: ``work`` (a picklable callable) run on each task, this
    process's native thread pools sized to ``threads`` (:func:`glradial.threads.set_thread_budget`;
    None leaves the libraries' defaults)."""

    def __init__(self, work: Callable[[str, Path], dict], threads: int | None = None) -> None:
        from ..threads import set_thread_budget

        if threads is not None:  # first: before NumPy (BLAS) is imported and any GL context made
            set_thread_budget(threads)
        from ..commands import keep_estimators

        keep_estimators()
        self.work = work

    def run(self, task: Task) -> Result:
        return run_task(self.work, task)

    def pid(self) -> int:
        return os.getpid()

    def threads(self) -> dict:
        """This worker's thread budget as each pool sees it: glradial's, OpenMP's variable (Ray sets
        it to the actor's ``num_cpus``), llvmpipe's variable and OpenCV's."""
        import cv2

        from ..threads import thread_budget

        return {"budget": thread_budget(), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS"),
                "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"), "cv2": cv2.getNumThreads()}
