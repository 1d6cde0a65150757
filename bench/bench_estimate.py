"""Benchmark: ms per 1080p frame for glradial.estimate (area resize + ONNX inference), 1 and 2 threads.

Usage: ``python bench/bench_estimate.py [--model PATH] [--frames 30]``

Prints, per thread count, the median wall time of the area resize alone, the inference alone and
the whole ``Estimator.estimate`` call, and its ratio to a peer run in the same process on the same
frame: ``cv2.GaussianBlur`` (sigma 1) of the 1080p frame, a cheap per-frame operation every video
pipeline pays, to put the numbers in scale on whatever machine runs this.
Target (issue 5): <= 20 ms per 1080p frame with 2 threads on this machine.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing
from glradial.estimator import Estimator, default_model_path  # noqa: E402


def _median_ms(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1000.0)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--model", default=str(default_model_path()))
    parser.add_argument("--frames", type=int, default=30)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    frame = cv2.GaussianBlur(rng.integers(0, 256, (1080, 1920, 3), dtype=np.uint8), (0, 0), 2.0)
    print(f"model {args.model}")
    for threads in (1, 2):
        cv2.setNumThreads(threads)
        est = Estimator(args.model, threads=threads)
        small = est.preprocess(frame)
        resize = _median_ms(lambda: est.preprocess(frame), args.frames)
        infer = _median_ms(lambda: est.run(small[None]), args.frames)
        total = _median_ms(lambda: est.estimate(frame), args.frames)
        blur = _median_ms(lambda: cv2.GaussianBlur(frame, (0, 0), 1.0), args.frames)
        print(f"threads {threads}: resize {resize:.2f} ms + inference {infer:.2f} ms; estimate() {total:.2f} ms per 1080p frame "
              f"({1000 / total:.0f} frames/s); peer cv2.GaussianBlur(1080p, sigma 1) {blur:.2f} ms -> ratio {total / blur:.2f}")


if __name__ == "__main__":
    main()
