"""Texture to texture: ``Remapper.render_texture`` (what a graphics tool embedding glradial runs)
against the CPU path (``glradial.correct(..., backend="cpu")``: cached fixed-point maps through
``cv2.remap``), same frame sizes, same process, taking turns.

Usage: python bench/bench_texture.py [--sizes 1920x1080 3840x2160] [--rounds 7] [--frames 20]

GL: the source texture lives on the GPU; each frame is one draw into a framebuffer, timed to
``ctx.finish()`` (no upload, no read-back: the embedding case). Also timed: upload + draw +
read-back (``Remapper.correct`` on a NumPy frame), the path ``backend="gl"`` takes. CPU: one
``correct`` call per frame on a NumPy frame with the maps cached. RGBA8 (key and fill) and RGBA16F.
Medians over ``--rounds`` rounds of ``--frames`` frames; the renderer's name is printed (Mesa
llvmpipe on a machine without a GPU: there the GL figures are a CPU rasteriser's).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from figures import write_figure  # noqa: E402

import glradial  # noqa: E402
from glradial.gl import egl  # noqa: E402

LENS = glradial.Lens(-0.25, 0.05)


def per_frame_ms(fn, frames: int) -> float:
    start = time.perf_counter()
    for _ in range(frames):
        fn()
    return (time.perf_counter() - start) / frames * 1e3


def cases(ctx, remapper: glradial.Remapper, size: tuple[int, int], dtype: str):
    width, height = size
    rng = np.random.default_rng(0)
    frame = (rng.random((height, width, 4)) * (255 if dtype == "f1" else 1)).astype(np.uint8 if dtype == "f1" else np.float32)
    source = ctx.texture(size, 4, frame.tobytes() if dtype == "f1" else frame.astype(np.float16).tobytes(), dtype=dtype)
    target_texture = ctx.texture(size, 4, dtype=dtype)
    target = ctx.framebuffer(color_attachments=[target_texture])

    def texture_to_texture():
        remapper.render_texture(source, target, LENS)
        ctx.finish()

    def gl_numpy():
        remapper.correct(frame, LENS, alpha="premultiplied")

    def cpu_numpy():
        glradial.correct(frame, LENS, backend="cpu", alpha="premultiplied")

    return {"texture to texture (GL)": texture_to_texture, "NumPy via GL (upload, draw, read back)": gl_numpy,
            "NumPy via CPU (cv2.remap, cached maps)": cpu_numpy}, (source, target_texture, target)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["1920x1080", "3840x2160"])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    ctx = egl.create_context()
    remapper = glradial.Remapper(ctx)
    print(f"renderer: {egl.renderer_name(ctx)}")
    results: dict[str, dict] = {"renderer": egl.renderer_name(ctx)}
    for text in args.sizes:
        size = tuple(int(v) for v in text.lower().split("x"))
        for dtype, label in (("f1", "RGBA8"), ("f2", "RGBA16F")):
            timers, objects = cases(ctx, remapper, size, dtype)
            for fn in timers.values():
                fn()  # programs, maps and textures made before timing
            times = {name: [] for name in timers}
            for _ in range(args.rounds):
                for name, fn in timers.items():
                    times[name].append(per_frame_ms(fn, args.frames))
            cpu = statistics.median(times["NumPy via CPU (cv2.remap, cached maps)"])
            for name, values in times.items():
                median = statistics.median(values)
                print(f"{text} {label:8s} {name:40s} {median:8.2f} ms/frame {1e3 / median:8.1f} fps  "
                      f"{cpu / median:5.2f}x the CPU path's speed")
                results[f"{text} {label} {name}"] = {"ms_per_frame": median, "speed_vs_cpu_path": cpu / median}
            for obj in objects:
                obj.release()
    remapper.release()
    egl.destroy_context(ctx)
    write_figure("bench_texture", results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
