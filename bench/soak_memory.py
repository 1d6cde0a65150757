"""Memory soaks: resident set size (RSS, /proc/self/statm) before and after long runs, in one process.

* ``threads``  N short-lived threads, each doing one GL ``correct`` (each thread's EGL context and
  Remapper must be released when it ends; before they were, each thread kept ~4 MB on llvmpipe)
* ``correct``  N ``correct`` calls on one thread, alternating the GL and CPU backends, new
  coefficients each call (nothing may be keyed on them)
* ``estimate`` N ``estimate`` calls with the bundled model

Each soak warms up first (allocator pools, shader compilation, the onnxruntime arena), then prints
RSS before, after and the growth per item. Flat means the growth does not scale with N.

Run: ``python3 bench/soak_memory.py [--threads N] [--correct N] [--estimate N]`` (defaults 300,
20000, 3000: the figures in docs/CORE.md; 0 skips a soak).
"""

from __future__ import annotations

import argparse
import gc
import os
import threading
import time

import numpy as np
from figures import printed_report, write_figure

from glradial import correct
from glradial.estimation.net_lines import NetLinesEstimator

PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * PAGE / 2**20


def report(name: str, count: int, start: float, seconds: float) -> None:
    gc.collect()
    end = rss_mb()
    print(f"{name:9s} {count:6d} items: RSS {start:7.1f} -> {end:7.1f} MB, growth {end - start:+6.1f} MB "
          f"({(end - start) / count * 1024:+.2f} kB/item), {seconds:.1f} s", flush=True)


def soak_threads(count: int, frame: np.ndarray) -> None:
    def one() -> None:
        thread = threading.Thread(target=correct, args=(frame, -0.2, 0.03), kwargs={"backend": "gl"})
        thread.start()
        thread.join()

    for _ in range(5):
        one()
    gc.collect()
    start, t0 = rss_mb(), time.perf_counter()
    for _ in range(count):
        one()
    report("threads", count, start, time.perf_counter() - t0)


def soak_correct(count: int, frame: np.ndarray) -> None:
    for i in range(50):
        correct(frame, -0.2, 0.03, backend=("gl", "cpu")[i % 2])
    gc.collect()
    start, t0 = rss_mb(), time.perf_counter()
    for i in range(count):
        correct(frame, -0.2 + 1e-6 * i, 0.03, backend=("gl", "cpu")[i % 2])
    report("correct", count, start, time.perf_counter() - t0)


def soak_estimate(count: int) -> None:
    estimator = NetLinesEstimator()
    frame = np.random.default_rng(0).integers(0, 256, (360, 640, 3), dtype=np.uint8)
    for _ in range(20):
        estimator.estimate(frame)
    gc.collect()
    start, t0 = rss_mb(), time.perf_counter()
    for _ in range(count):
        estimator.estimate(frame)
    report("estimate", count, start, time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=300)
    parser.add_argument("--correct", type=int, default=20000)
    parser.add_argument("--estimate", type=int, default=3000)
    args = parser.parse_args()
    frame = np.random.default_rng(0).integers(0, 256, (180, 320, 3), dtype=np.uint8)
    print(f"frames 320×180 RGB uint8 for threads/correct, 640×360 for estimate; RSS at start {rss_mb():.1f} MB")
    with printed_report() as lines:
        if args.threads:
            soak_threads(args.threads, frame)
        if args.correct:
            soak_correct(args.correct, frame)
        if args.estimate:
            soak_estimate(args.estimate)
    write_figure("soak_memory", {"report": lines})


if __name__ == "__main__":
    main()
