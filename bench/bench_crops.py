"""Crops per second: glradial's GPU crop renderer vs py360convert.e2p, same panorama, same process.

Usage: python bench/bench_crops.py [--panorama PATH] [--width 4096] [--count 292] [--seconds 10]

The panorama (default: tests/data/panorama_field_2048x1024.jpg resized to --width × --width/2) is
uploaded once. Cases:
  * 224×224 outputs from 1280×720 lens geometry, anti-aliased (2×1 supersampled trilinear, the
    default; 2×2; and a single trilinear read for reference), exact inverse with 8 (the renderer's
    default) and 3 (crop_batches' default for the paper's distribution) Newton steps, Drap inverse;
  * 1280×720 outputs (trilinear mipmaps, exact inverse).
py360convert.e2p (bilinear, no anti-aliasing, no lens distortion, CPU) renders the same poses with
the same output sizes. Prints crops/s and the ratio glradial / py360convert.
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

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from glradial.crops import CropRenderer, sample_crop_params  # noqa: E402


def rate(fn, count: int, seconds: float) -> float:
    """Crops per second of ``fn(n)`` rendering ``n`` crops, repeated for at least ``seconds``."""
    fn(min(count, 8))  # warm up (compile, first upload of buffers)
    done, start = 0, time.perf_counter()
    while True:
        fn(count)
        done += count
        elapsed = time.perf_counter() - start
        if elapsed >= seconds:
            return done / elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panorama", default=str(ROOT / "tests/data/panorama_field_2048x1024.jpg"))
    parser.add_argument("--width", type=int, default=4096)
    parser.add_argument("--count", type=int, default=146, help="crops per render call (224 case)")
    parser.add_argument("--seconds", type=float, default=8.0)
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

    results = {}
    cases = [
        ("224x224 exact-8, AA 2x1 (default)", dict(out_size=(224, 224)), args.count),
        ("224x224 exact-3, AA 2x1 (stream)", dict(out_size=(224, 224), newton_steps=3), args.count),
        ("224x224 exact-3, AA 2x2", dict(out_size=(224, 224), newton_steps=3, supersample=2), args.count),
        ("224x224 exact-3, 1x1 trilinear", dict(out_size=(224, 224), newton_steps=3, supersample=1), args.count),
        ("224x224 drap, AA 2x1", dict(out_size=(224, 224), inverse="drap"), args.count),
        ("1280x720 exact-8, trilinear", dict(), max(1, args.count // 8)),
    ]
    for name, kwargs, count in cases:
        with CropRenderer(pano, size=(1280, 720), **kwargs) as renderer:
            out = np.empty((count, *renderer.out_size[::-1], 3), np.uint8)
            results[name] = rate(lambda n: renderer.render(params[:n], out=out[:n]), count, args.seconds)
    ref224 = rate(e2p((224, 224)), 8, args.seconds)
    ref1280 = rate(e2p((720, 1280)), 4, args.seconds)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average before the py360convert runs: {load:.1f}")
    print(f"{'case':34s} {'crops/s':>9s} {'vs py360convert.e2p':>20s}")
    for name, value in results.items():
        ref = ref224 if name.startswith("224") else ref1280
        print(f"{name:34s} {value:9.1f} {value / ref:19.1f}x")
    print(f"{'py360convert.e2p 224x224':34s} {ref224:9.1f}")
    print(f"{'py360convert.e2p 1280x720':34s} {ref1280:9.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
