"""Crops per second: glradial's GPU crop renderer vs py360convert.e2p, same panorama, same process.

Usage: python bench/bench_crops.py [--panorama PATH] [--width 4096] [--count 146] [--rounds 9]

The panorama (default: tests/data/panorama_field_2048x1024.jpg resized to --width × --width/2) is
uploaded once. Cases:
  * 224×224 outputs from 1280×720 lens geometry, anti-aliased: the default (one trilinear mipmap
    read per pixel at its footprint, exact inverse as a per-crop series with Newton where the series
    is rejected); 2×1 supersampled trilinear (``supersample="auto"``: near-square sample footprints,
    closest to an area resize of the full frame); the per-pixel Newton inverse only (the renderer
    before the series); 2×2; the paper's Drap inverse;
  * 1280×720 outputs (trilinear mipmaps, exact inverse).
py360convert.e2p (bilinear, no anti-aliasing, no lens distortion, CPU) renders the same poses with
the same output sizes. The cases and py360convert run interleaved, one call each per round, for
--rounds rounds (the 224×224 cases first, then the 1280×720 ones); crops/s are medians over the
rounds and ratios are of medians, so that a machine whose speed drifts (other jobs, shared cores)
biases no case.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from figures import write_figure

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from glradial.synthesis.crops import CropRenderer, sample_crop_params  # noqa: E402


def crops_per_second(fn, count: int) -> float:
    """Crops per second of one call ``fn(count)``."""
    start = time.perf_counter()
    fn(count)
    return count / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panorama", default=str(ROOT / "tests/data/panorama_field_2048x1024.jpg"))
    parser.add_argument("--width", type=int, default=4096)
    parser.add_argument("--count", type=int, default=146, help="crops per render call (224 cases)")
    parser.add_argument("--rounds", type=int, default=9, help="interleaved rounds (medians are reported)")
    args = parser.parse_args()

    image = cv2.imread(args.panorama, cv2.IMREAD_COLOR)
    if image is None:
        raise SystemExit(f"cannot read {args.panorama}")
    pano = np.ascontiguousarray(cv2.cvtColor(cv2.resize(image, (args.width, args.width // 2), interpolation=cv2.INTER_CUBIC), cv2.COLOR_BGR2RGB))
    params = sample_crop_params(args.count, seed=0)
    print(f"panorama {pano.shape[1]}×{pano.shape[0]}, LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'unset')}, cpu count {os.cpu_count()}")

    import py360convert

    def e2p(out_hw: tuple[int, int]):
        def run(n: int) -> None:
            for p in params[:n]:
                vfov = math.degrees(2 * math.atan(math.tan(math.radians(p.hfov) / 2) * 720 / 1280))
                py360convert.e2p(pano, (p.hfov, vfov), p.pan, p.tilt, out_hw, in_rot_deg=p.roll, mode="bilinear")

        return run

    cases = [
        ("224x224 exact, 1x1 trilinear (default)", dict(out_size=(224, 224)), args.count),
        ("224x224 exact, AA 2x1 (auto)", dict(out_size=(224, 224), supersample="auto"), args.count),
        ("224x224 Newton per pixel, 1x1", dict(out_size=(224, 224), series_inverse=False), args.count),
        ("224x224 exact, AA 2x2", dict(out_size=(224, 224), supersample=2), args.count),
        ("224x224 drap, 1x1", dict(out_size=(224, 224), inverse="drap"), args.count),
        ("1280x720 exact, trilinear", dict(), max(1, args.count // 8)),
    ]
    runs = {}
    renderers = []
    for name, kwargs, count in cases:
        renderer = CropRenderer(pano, size=(1280, 720), **kwargs)
        renderers.append(renderer)
        out = np.empty((count, *renderer.out_size[::-1], 3), np.uint8)
        run = (lambda r, o: lambda n: r.render(params[:n], out=o[:n]))(renderer, out)
        run(min(count, 8))  # warm up: compile, first upload of buffers
        runs[name] = (run, count)
    # Two phases (224×224 cases, then 1280×720), each with its own py360convert reference: a
    # 1280×720 e2p call between the 224×224 ones leaves the allocator in a state that slows those
    # ~2× (measured), which would flatter the ratio.
    phases = [
        [name for name in runs if name.startswith("224")] + ["py360convert.e2p 224x224"],
        [name for name in runs if name.startswith("1280")] + ["py360convert.e2p 1280x720"],
    ]
    runs["py360convert.e2p 224x224"] = (e2p((224, 224)), 8)
    runs["py360convert.e2p 1280x720"] = (e2p((720, 1280)), 2)
    rates: dict[str, list[float]] = {name: [] for name in runs}
    for phase in phases:
        runs[phase[-1]][0](1)  # warm up
        for _ in range(args.rounds):
            for name in phase:
                run, count = runs[name]
                rates[name].append(crops_per_second(run, count))
    for renderer in renderers:
        renderer.release()
    report({name: float(np.median(values)) for name, values in rates.items()}, args.rounds)
    return 0


def report(median: dict[str, float], rounds: int) -> None:
    """Print the median crops/s of each case with its ratio to py360convert's, and write the figure."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"{rounds} interleaved rounds, load average at the end: {load:.1f}")
    print(f"{'case':40s} {'crops/s':>9s} {'vs py360convert.e2p':>20s}")
    ratios = {}
    for name, value in median.items():
        if name.startswith("py360"):
            continue
        ratios[name] = value / median["py360convert.e2p 224x224" if name.startswith("224") else "py360convert.e2p 1280x720"]
        print(f"{name:40s} {value:9.1f} {ratios[name]:19.1f}x")
    for name in ("py360convert.e2p 224x224", "py360convert.e2p 1280x720"):
        print(f"{name:40s} {median[name]:9.1f}")
    write_figure("bench_crops", {"crops_per_s": median, "ratio_to_py360convert": ratios, "rounds": rounds})


if __name__ == "__main__":
    raise SystemExit(main())
