"""Benchmark: procedural stadium panoramas on this machine's GL (llvmpipe on CPU-only machines).

Usage: python bench/bench_stadium.py [--size 4096x2048] [--seeds 0 1 2] [--full]

Prints wall time and process CPU time (llvmpipe's threads run in this process) per panorama for
1, 4 (rotated grid, edges only) and 9 (3x3, edges only) samples, and ratios against a peer run in
the same process: a NumPy ray caster of the same panorama geometry that shades only the ground plane
with a checkerboard (no markings, no stands): the floor of what per-pixel work costs on the CPU.
--full also renders one 8192x4096 panorama (must work; slow on llvmpipe).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from figures import write_figure

from glradial.gl.egl import renderer_name, thread_context
from glradial.synthesis.stadium import StadiumRenderer
from glradial.synthesis.stadium_style import sample_style


def numpy_ground_checker(style, size: tuple[int, int]) -> np.ndarray:
    """Peer: same camera and equirectangular mapping, ground plane z = 0 only, 5 m checkerboard."""
    w, h = size
    lon = ((np.arange(w) + 0.5) / w - 0.5) * 2.0 * math.pi
    lat = (0.5 - (np.arange(h) + 0.5) / h) * math.pi
    lon, lat = np.meshgrid(lon, lat)
    yaw = math.radians(style.yaw)
    f = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    r = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    cl = np.cos(lat)
    d = (cl * np.cos(lon))[..., None] * f + (cl * np.sin(lon))[..., None] * r
    dz = np.sin(lat)
    cam = np.asarray(style.camera)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dz < 0, -cam[2] / dz, np.nan)
    gx = cam[0] + t * d[..., 0]
    gy = cam[1] + t * d[..., 1]
    checker = ((np.floor(gx / 5.0) + np.floor(gy / 5.0)) % 2 == 0)
    out = np.zeros((h, w, 3), np.uint8)
    out[..., 1] = np.where(np.isnan(t), 0, np.where(checker, 160, 110))
    return out


def _timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="4096x2048")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--full", action="store_true", help="also render one 8192x4096 panorama")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.lower().split("x"))
    ctx = thread_context()
    print(f"renderer: {renderer_name(ctx)}; size {size[0]}x{size[1]}")
    results: dict[str, dict] = {}
    with StadiumRenderer(ctx) as renderer:
        renderer.render(sample_style(0), (64, 32))  # compile and warm up
        out = np.empty((size[1], size[0], 3), np.uint8)
        for seed in args.seeds:
            style = sample_style(seed)
            peer_wall, peer_cpu = _timed(lambda: numpy_ground_checker(style, size))
            line = [f"seed {seed:3d} ({style.camera_kind:11s} {style.lighting:8s})",
                    f"numpy ground-only peer {peer_wall:5.1f} s wall {peer_cpu:5.1f} s cpu"]
            for ss in (1, 2, 3):
                wall, cpu = _timed(lambda: renderer.render(style.with_overrides(supersample=ss), size, out=out))
                line.append(f"ss={ss}: {wall:5.1f} s wall {cpu:5.1f} s cpu ({wall / peer_wall:4.2f}x peer)")
                results[f"{size[0]}x{size[1]} seed {seed} ss={ss}"] = {"wall_s": wall, "cpu_s": cpu, "peer_wall_s": peer_wall,
                                                                     "ratio_to_numpy_peer": wall / peer_wall}
            print(" | ".join(line), flush=True)
        if args.full:
            wall, cpu = _timed(lambda: renderer.render(sample_style(args.seeds[0]), (8192, 4096)))
            print(f"8192x4096 seed {args.seeds[0]} (default ss=2): {wall:.1f} s wall {cpu:.1f} s cpu")
            results[f"8192x4096 seed {args.seeds[0]} ss=2"] = {"wall_s": wall, "cpu_s": cpu}
    write_figure("bench_stadium", results)


if __name__ == "__main__":
    main()
