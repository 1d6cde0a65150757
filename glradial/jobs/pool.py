"""The local runner: ``--workers N`` processes, each a :class:`~glradial.jobs.worker.JobWorker`
given one task at a time over a pipe.

Workers are started with ``spawn`` (a fresh interpreter: no GL context, thread or lock inherited)
and ignore SIGINT: Ctrl-C reaches the job's own process, which ends them. A worker that dies (killed,
out of memory, a crash in native code) is seen by its process sentinel; its task is reported as lost
(``None``) and a new worker takes its place, so one death costs one attempt of one input.
"""

from __future__ import annotations

import multiprocessing
import signal
from multiprocessing.connection import Connection, wait
from typing import Callable

from ..errors import check_count
from ..threads import share_of_cores
from .worker import JobWorker, Result, Task

__all__ = ["ProcessRunner"]


def _serve(work: Callable, threads: int, connection: Connection) -> None:
    """A worker process: tasks in, results out, until the pipe closes."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    worker = JobWorker(work, threads)
    while True:
        try:
            task = connection.recv()
        except EOFError:
            return
        if task is None:
            return
        connection.send(worker.run(task))


class _Slot:
    def __init__(self, context, work: Callable, threads: int) -> None:
        self.connection, child = context.Pipe()
        self.process = context.Process(target=_serve, args=(work, threads, child), daemon=True)
        self.process.start()
        child.close()
        self.task: Task | None = None


class ProcessRunner:
    """``workers`` local processes running ``work`` (see :mod:`glradial.jobs.runner` for the
    interface), each with a thread budget of ``threads`` (:mod:`glradial.threads`; default: its
    share of the cores, ``cores // workers``, at least 1)."""

    label = "processes"

    def __init__(self, work: Callable, workers: int, threads: int | None = None) -> None:
        check_count("workers", workers)
        self._context = multiprocessing.get_context("spawn")
        self._work = work
        check_count("threads", threads, optional=True)
        self._threads = threads or share_of_cores(workers)
        self.slots = [_Slot(self._context, work, self._threads) for _ in range(workers)]

    def free(self) -> int:
        return sum(slot.task is None for slot in self.slots)

    def submit(self, task: Task) -> None:
        index = next(i for i, s in enumerate(self.slots) if s.task is None)
        if not self.slots[index].process.is_alive():  # died while idle: replaced before it is given work
            self._close_slot(self.slots[index], kill=True)
            self.slots[index] = _Slot(self._context, self._work, self._threads)
        slot = self.slots[index]
        slot.task = task
        try:
            slot.connection.send(task)
        except OSError:  # it died just now: wait() sees its sentinel and reports the task as lost
            pass

    def wait(self, timeout: float) -> list[tuple[Task, Result | None]]:
        """The tasks that ended within ``timeout`` s: ``(task, result)``, ``None`` for a worker that died."""
        busy = [s for s in self.slots if s.task is not None]
        ready = set(wait([s.connection for s in busy] + [s.process.sentinel for s in busy], timeout))
        done = []
        for index, slot in enumerate(self.slots):
            if slot.task is None or not ({slot.connection, slot.process.sentinel} & ready):
                continue
            result = None
            try:
                if slot.connection.poll():
                    result = slot.connection.recv()
            except (EOFError, OSError):
                result = None
            done.append((slot.task, result))
            slot.task = None
            if result is None:  # the worker died: a fresh one takes its place
                self._close_slot(slot, kill=True)
                self.slots[index] = _Slot(self._context, self._work, self._threads)
        return done

    def pids(self) -> list[int]:
        return [s.process.pid for s in self.slots]

    @staticmethod
    def _stop_slot(slot: _Slot, kill: bool) -> None:
        """Ask the worker to end (the pipe's end-of-work message), or kill it."""
        if not kill:
            try:
                slot.connection.send(None)
                return
            except OSError:
                pass
        slot.process.kill()

    @staticmethod
    def _reap_slot(slot: _Slot, kill: bool) -> None:
        """Wait for the worker to end (killed after 10 s, 5 s once killed) and close its pipe."""
        slot.process.join(timeout=10 if not kill else 5)
        if slot.process.is_alive():
            slot.process.kill()
            slot.process.join()
        slot.connection.close()

    def _close_slot(self, slot: _Slot, kill: bool) -> None:
        self._stop_slot(slot, kill)
        self._reap_slot(slot, kill)

    def close(self, kill: bool = False) -> None:
        """Stop the workers (``kill``: at once, e.g. on Ctrl-C), all asked first and then waited
        for, so that they wind down together."""
        kills = [kill or slot.task is not None for slot in self.slots]
        for slot, killed in zip(self.slots, kills):
            self._stop_slot(slot, killed)
        for slot, killed in zip(self.slots, kills):
            self._reap_slot(slot, killed)
