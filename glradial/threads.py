"""The process's thread budget: how many threads each native pool of this process may use.

A job's worker is given its share of the cores (``cores // workers``, at least 1), as Ray gives an
actor of ``num_cpus=N`` N threads (it sets ``OMP_NUM_THREADS``) and ``make -j``/GNU parallel run one
job per core: N workers then run about N x budget threads, not N x cores. :func:`set_thread_budget`
applies it to every pool glradial drives: OpenMP and BLAS (their environment variables, read when
the library loads), llvmpipe (``LP_NUM_THREADS``, read when a GL context is made), OpenCV
(``cv2.setNumThreads``), onnxruntime (a session's intra-op threads, :class:`glradial.Estimator`),
FFmpeg's codec threads and swscale's slice threads (:mod:`glradial.media.video_io`). Without a
budget (a one-file command) each library keeps its own default (about one thread per core).
A video pass still overlaps decoding, correcting and encoding on its own threads (a pipeline's
stages, not a pool), so a worker of budget 1 keeps somewhat more than one core busy.
"""

from __future__ import annotations

import os

from .errors import check_count

__all__ = ["THREAD_VARIABLES", "set_thread_budget", "thread_budget", "cores", "share_of_cores"]

#: the environment variables that size native pools not reachable through an API
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "LP_NUM_THREADS")

_BUDGET: dict[str, int | None] = {"threads": None}


def cores() -> int:
    """The CPU cores this process may run on (its affinity, as ``nproc``)."""
    return len(os.sched_getaffinity(0))


def share_of_cores(workers: int, total: int | None = None) -> int:
    """The threads each of ``workers`` workers gets: ``total`` (default :func:`cores`) // workers, at least 1."""
    check_count("workers", workers)
    return max(1, (cores() if total is None else int(total)) // workers)


def set_thread_budget(threads: int) -> None:
    """Size this process's native thread pools to ``threads`` (a positive integer). Call it before
    the process makes its first GL context (llvmpipe reads ``LP_NUM_THREADS`` then) and, for
    OpenMP/BLAS, before NumPy is imported (a spawned worker's first act)."""
    check_count("threads", threads)
    for name in THREAD_VARIABLES:
        os.environ[name] = str(threads)
    import cv2

    cv2.setNumThreads(threads)
    _BUDGET["threads"] = threads


def thread_budget() -> int | None:
    """The budget :func:`set_thread_budget` set in this process; None: none (libraries' defaults)."""
    return _BUDGET["threads"]
