"""The Ray runner: ``--ray [ADDRESS]``, one Ray actor per worker, each a
:class:`~glradial.jobs.worker.JobWorker` given one task at a time.

``ADDRESS`` None starts Ray on this machine (no dashboard) and stops it at the end; ``auto`` or
``ray://head:10001`` joins a running cluster, whose nodes need glradial installed (the same
version) and the output folder mounted at the same path. An actor lives for the whole job, so its
process keeps its ONNX session and GL context across the inputs it gets. An actor that dies (its
process killed, its node lost) is seen as ``RayActorError`` on its task: the task is reported as
lost (``None``) and a new actor takes the slot.
"""

from __future__ import annotations

import importlib.util
from typing import Callable

from ..threads import share_of_cores
from .worker import JobWorker, Result, Task

__all__ = ["RayRunner", "INSTALL_HINT", "ray_available"]

INSTALL_HINT = "--ray needs Ray, which is not installed: pip install 'glradial[cluster]' (--workers N runs without it)"


def ray_available() -> bool:
    """Whether ``import ray`` can work."""
    return importlib.util.find_spec("ray") is not None


def _share(ray, workers: int | None) -> int:
    """Each actor's thread budget when none is given: the cluster's CPUs // ``workers`` (1 when
    ``workers`` is None: one actor per CPU), at most the CPUs of its largest node."""
    if workers is None:
        return 1
    largest = max((node["Resources"].get("CPU", 1) for node in ray.nodes() if node.get("Alive")), default=1)
    return max(1, min(int(largest), share_of_cores(workers, int(ray.cluster_resources().get("CPU", 1)))))


class RayRunner:
    """Ray actors running ``work`` (interface of :class:`glradial.jobs.pool.ProcessRunner`).

    ``workers``: actors (default: one per CPU of the cluster, each of 1 thread); ``threads_per_worker``:
    each actor's thread budget (:mod:`glradial.threads`) and the CPUs Ray reserves for it
    (``num_cpus``; default: the cluster's CPUs // ``workers``, at most one node's, at least 1);
    ``gpus_per_worker``: GPUs Ray reserves for each actor (fractions share one). ``init``: more
    ``ray.init`` keywords when Ray is started here.
    """

    label = "Ray actors"

    def __init__(self, work: Callable, address: str | None = None, workers: int | None = None, *,
                 threads_per_worker: int | None = None, gpus_per_worker: float = 0.0, init: dict | None = None) -> None:
        if not ray_available():
            raise ModuleNotFoundError(INSTALL_HINT, name="ray")
        import ray

        self._ray = ray
        self._connected = not ray.is_initialized()  # this runner connects (and disconnects at the end)
        if self._connected:
            local = {"address": "local", "include_dashboard": False, **(init or {})} if address is None else {"address": address}
            ray.init(log_to_driver=False, configure_logging=False, **local)
        self._threads = threads_per_worker or _share(ray, workers)
        if workers is None:
            workers = max(1, int(ray.cluster_resources().get("CPU", 1) // self._threads))
        # num_cpus = the budget: Ray sets the actor's OMP_NUM_THREADS to it, JobWorker sizes the other pools
        self._actor = ray.remote(JobWorker).options(num_cpus=self._threads, num_gpus=gpus_per_worker, max_restarts=0)
        self._work = work
        self.slots: list[list] = [[self._actor.remote(work, self._threads), None, None] for _ in range(workers)]  # actor, task, ref

    def free(self) -> int:
        return sum(slot[1] is None for slot in self.slots)

    def submit(self, task: Task) -> None:
        slot = next(s for s in self.slots if s[1] is None)
        slot[1], slot[2] = task, slot[0].run.remote(task)

    def wait(self, timeout: float) -> list[tuple[Task, Result | None]]:
        """The tasks that ended within ``timeout`` s: ``(task, result)``, ``None`` for an actor that died."""
        ray = self._ray
        refs = [s[2] for s in self.slots if s[1] is not None]
        if not refs:
            return []
        ready, _ = ray.wait(refs, num_returns=1, timeout=timeout)
        if ready:  # and any other that ended meanwhile
            ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
        done = []
        for slot in self.slots:
            if slot[2] is None or slot[2] not in ready:
                continue
            try:
                result = ray.get(slot[2])
            except ray.exceptions.RayActorError:
                result = None
                ray.kill(slot[0], no_restart=True)
                slot[0] = self._actor.remote(self._work, self._threads)
            except ray.exceptions.RayTaskError as err:
                result = Result(slot[1].name, error=" ".join(str(err).split())[-400:])
            done.append((slot[1], result))
            slot[1], slot[2] = None, None
        return done

    def pids(self) -> list[int]:
        return self._ray.get([s[0].pid.remote() for s in self.slots])

    def close(self, kill: bool = False) -> None:
        """End the actors; stop Ray if it was started here, disconnect if this runner joined a cluster."""
        for slot in self.slots:
            try:
                self._ray.kill(slot[0], no_restart=True)
            except Exception:  # an actor already gone
                pass
        running = [slot[2] for slot in self.slots if slot[2] is not None]
        if running:  # ray.kill returns at once: wait until the killed actors' tasks have ended (they error out)
            self._ray.wait(running, num_returns=len(running), timeout=30)
        if self._connected:
            self._ray.shutdown()
