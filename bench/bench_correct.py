"""Frame correction throughput: glradial's backends against OpenCV, in one process.

Prints the median ms/frame (paths interleaved) and each path's ratio to ``cv2.remap`` with cached fixed-point maps (the fastest
CPU peer: what a careful OpenCV user writes), for 720p / 1080p / 4K (--no-4k skips it), RGB and
RGBA uint8:

* ``glradial auto``  the default path (``correct(frame, k1, k2)``)
* ``glradial cpu``   ``backend="cpu"`` (cached maps + cv2.remap + fill of source-less pixels)
* ``glradial gl``    ``backend="gl"`` (upload + draw + readback), split into its three stages
* ``cv2.remap``      cached ``initUndistortRectifyMap`` maps converted to CV_16SC2
* ``cv2.undistort``  recomputes its maps every call

Run: ``python3 bench/bench_correct.py [--frames N] [--no-4k] [--threads T]`` (4K runs N/4 frames). OpenCV uses ``T`` threads
(default: all cores, 2 on the project machine).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np
from figures import write_figure

from glradial import correct
from glradial.gl import egl
from glradial.lens.lens import Lens
from glradial.remapping import remap

K1, K2 = -0.3, 0.06


def per_frame_ms(paths: dict, frames: int) -> dict[str, float]:
    """Median ms/frame of each path, the paths taking turns frame by frame so that load from other
    processes on the shared machine falls on all of them alike."""
    for fn in paths.values():
        fn()  # warm: maps cached, programs compiled, textures allocated
    samples: dict[str, list[float]] = {name: [] for name in paths}
    for _ in range(frames):
        for name, fn in paths.items():
            start = time.perf_counter()
            fn()
            samples[name].append((time.perf_counter() - start) * 1000.0)
    return {name: float(np.median(values)) for name, values in samples.items()}


def gl_stages(frame: np.ndarray, frames: int) -> tuple[float, float, float]:
    """(upload, draw, readback) ms/frame on the thread's Remapper, each stage finished with
    ctx.finish() so the next one does not absorb its time."""
    remapper = remap._thread_remapper()
    ctx = remapper.ctx
    h, w, c = frame.shape
    out = np.empty_like(frame)
    remapper.correct(frame, K1, K2, out=out)
    lens = Lens(K1, K2)
    program_args = (remapper._source, remapper._fbo, (0, 0, w, h), lens, "undistort", 1.0, "linear", "exact", (0.0,) * 4, 0)
    totals = [0.0, 0.0, 0.0]
    for _ in range(frames):
        t0 = time.perf_counter()
        remapper._source.write(frame)
        ctx.finish()
        t1 = time.perf_counter()
        remapper._draw(*program_args)
        ctx.finish()
        t2 = time.perf_counter()
        remapper._fbo.read_into(out, components=c, alignment=1, dtype="f1")
        t3 = time.perf_counter()
        totals[0] += t1 - t0
        totals[1] += t2 - t1
        totals[2] += t3 - t2
    return tuple(1000.0 * t / frames for t in totals)  # type: ignore[return-value]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--no-4k", dest="uhd", action="store_false", help="skip 3840×2160")
    parser.add_argument("--threads", type=int, default=None, help="cv2.setNumThreads")
    args = parser.parse_args()
    if args.threads is not None:
        cv2.setNumThreads(args.threads)
    ctx = egl.thread_context()
    print(f"GL renderer: {egl.renderer_name(ctx)}; auto backend -> {remap.auto_backend()}; "
          f"OpenCV {cv2.__version__} with {cv2.getNumThreads()} threads; lens k1={K1}, k2={K2}")
    sizes = [(1280, 720), (1920, 1080)] + ([(3840, 2160)] if args.uhd else [])
    rng = np.random.default_rng(0)
    print(f"{'frame':>16} {'path':>16} {'ms/frame':>9} {'fps':>7} {'÷ cv2.remap':>11}")
    results: dict[str, dict] = {}
    for w, h in sizes:
        for channels in (3, 4):
            frame = rng.integers(0, 256, (h, w, channels), dtype=np.uint8)
            camera = np.array([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1.0]])
            dist = np.array([K1, K2, 0, 0.0])
            m1, m2 = cv2.initUndistortRectifyMap(camera, dist, None, camera, (w, h), cv2.CV_16SC2)
            frames = max(3, args.frames if w < 3000 else args.frames // 4)
            paths = {
                "cv2.remap": lambda: cv2.remap(frame, m1, m2, cv2.INTER_LINEAR),
                "glradial auto": lambda: correct(frame, K1, K2),
                "glradial cpu": lambda: correct(frame, K1, K2, backend="cpu"),
                "glradial gl": lambda: correct(frame, K1, K2, backend="gl"),
                "cv2.undistort": lambda: cv2.undistort(frame, camera, dist),
            }
            timings = per_frame_ms(paths, frames)
            base = timings["cv2.remap"]
            label = f"{w}×{h} {'RGB' if channels == 3 else 'RGBA'}"
            for name, ms in timings.items():
                print(f"{label:>16} {name:>16} {ms:9.2f} {1000 / ms:7.1f} {ms / base:11.2f}")
            results[label] = {"ms_per_frame": timings, "ratio_to_cv2_remap": {n: ms / base for n, ms in timings.items()}}
            if channels == 3:  # RGBA goes through the premultiplied float path (remapping/alpha.py): other textures
                upload, draw, readback = gl_stages(frame, max(3, frames // 2))
                print(f"{label:>16} {'gl stages':>16}  upload {upload:.2f} ms, draw {draw:.2f} ms, readback {readback:.2f} ms")
                results[label]["gl_stages_ms"] = {"upload": upload, "draw": draw, "readback": readback}
    write_figure("bench_correct", {"lens": {"k1": K1, "k2": K2}, "renderer": egl.renderer_name(ctx), "frames": results})


if __name__ == "__main__":
    main()
