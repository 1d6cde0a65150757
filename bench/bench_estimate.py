"""Benchmark: ms per 1080p frame for glradial.estimate (area resize + ONNX inference), 1 and 2 threads,
and for the line-aware methods (``method="lines"`` and ``"auto"``).

Usage: ``python bench/bench_estimate.py [--model PATH] [--frames 30] [--pitch IMAGE]``

Prints, per thread count, the median wall time of the area resize alone, the inference alone and
the whole ``Estimator.estimate(method="net")`` call, and its ratio to a peer run in the same process
on the same frame: ``cv2.GaussianBlur`` (sigma 1) of the 1080p frame, a cheap per-frame operation
every video pipeline pays, to put the numbers in scale on whatever machine runs this. Then, on a
real broadcast frame upscaled to 1080p (``--pitch``, default the USL frame of
../shared/data/real_football/, or a synthetic pitch drawing when absent), the line detection, the
fit, and ``estimate(method="lines")`` / ``"auto"``, with the same peer ratio; ``auto`` is timed twice:
the estimation layer's (the CNN and the line fit, ``pitch=False``: what ``auto`` was before the pitch
camera fit was fed back, and what video still uses) and the public ``glradial.Estimator``'s, which also
runs the camera fit (:mod:`glradial.camera.estimator`; its answer's source is printed).
Targets (issues 5, 17): net <= 15 ms per 1080p frame, auto <= 40 ms, on one thread.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from figures import write_figure

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing
from glradial.camera.estimator import Estimator  # noqa: E402
from glradial.estimation.line_fit import fit_lines  # noqa: E402
from glradial.estimation.lines import detect_chains  # noqa: E402
from glradial.estimation.net_lines import default_model_path  # noqa: E402


def _pitch_frame(path: str) -> np.ndarray:
    """A 1080p RGB pitch frame: the image at ``path`` resized, or a drawing of pitch lines."""
    image = cv2.imread(path, cv2.IMREAD_COLOR)
    if image is None:
        image = np.full((720, 1280, 3), (40, 110, 40), np.uint8)
        for i in range(7):
            cv2.line(image, (-50, 60 + 100 * i), (1330, 40 + 110 * i), (230, 230, 230), 3, cv2.LINE_AA)
    return np.ascontiguousarray(cv2.resize(image, (1920, 1080), interpolation=cv2.INTER_CUBIC)[:, :, ::-1])


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
    parser.add_argument("--pitch", default=str(Path(__file__).resolve().parents[1].parent / "shared/data/real_football/usl_broadcast_0195.jpg"))
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    frame = cv2.GaussianBlur(rng.integers(0, 256, (1080, 1920, 3), dtype=np.uint8), (0, 0), 2.0)
    print(f"model {args.model}")
    results: dict[str, dict] = {}
    for threads in (1, 2):
        cv2.setNumThreads(threads)
        est = Estimator(args.model, threads=threads)
        small = est.preprocess(frame)
        resize = _median_ms(lambda: est.preprocess(frame), args.frames)
        infer = _median_ms(lambda: est.run(small[None]), args.frames)
        total = _median_ms(lambda: est.estimate(frame, method="net"), args.frames)
        blur = _median_ms(lambda: cv2.GaussianBlur(frame, (0, 0), 1.0), args.frames)
        print(f"threads {threads}: resize {resize:.2f} ms + inference {infer:.2f} ms; estimate() {total:.2f} ms per 1080p frame "
              f"({1000 / total:.0f} frames/s); peer cv2.GaussianBlur(1080p, sigma 1) {blur:.2f} ms -> ratio {total / blur:.2f}")
        pitch = _pitch_frame(args.pitch)
        first = est.estimate(pitch, method="net")
        net_pitch = (first.k1, first.k2)
        detect = _median_ms(lambda: detect_chains(pitch), args.frames)
        evidence = detect_chains(pitch)
        fit = _median_ms(lambda: fit_lines(evidence, prior=net_pitch), args.frames)
        lines = _median_ms(lambda: est.estimate(pitch, method="lines"), args.frames)
        auto = _median_ms(lambda: est.estimate(pitch, method="auto", pitch=False), args.frames)
        auto_pitch = _median_ms(lambda: est.estimate(pitch, method="auto"), args.frames)
        source = est.estimate(pitch, method="auto").method
        net = _median_ms(lambda: est.estimate(pitch, method="net"), args.frames)
        print(f"threads {threads}, 1080p pitch frame ({len(evidence.chains)} chains): detect {detect:.2f} ms + fit {fit:.2f} ms; "
              f"estimate(net) {net:.2f} ms, (lines) {lines:.2f} ms, (auto) {auto:.2f} ms; ratios to the blur peer "
              f"{net / blur:.2f} / {lines / blur:.2f} / {auto / blur:.2f}")
        print(f"threads {threads}, same frame: estimate(auto) with the pitch camera fit {auto_pitch:.2f} ms (answered from "
              f"{source}), {auto_pitch / auto:.2f} x auto without it; ratio to the blur peer {auto_pitch / blur:.2f}")
        results[f"threads_{threads}"] = {
            "noise_1080p_ms": {"resize": resize, "inference": infer, "estimate_net": total, "peer_gaussian_blur": blur},
            "pitch_1080p_ms": {"detect": detect, "fit": fit, "estimate_net": net, "estimate_lines": lines,
                               "estimate_auto_no_pitch": auto, "estimate_auto": auto_pitch},
            "pitch_chains": len(evidence.chains), "auto_answered_from": source}
    write_figure("bench_estimate", results)


if __name__ == "__main__":
    main()
