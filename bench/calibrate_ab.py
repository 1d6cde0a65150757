"""CPU time of ``glradial.calibrate`` on fresh 1080p frames: this checkout against an earlier revision,
interleaved frame by frame in one process, one thread (the ratio a loaded machine leaves intact).

Usage: ``python bench/calibrate_ab.py [--base REV] [--per N] [--offset K]``

The base revision's ``glradial/`` (``git archive REV``) is imported beside this checkout's as the
package ``glradial_base`` (its imports are relative). Frames: every ``len / N``-th labelled frame of
each of the five shared matches from the ``K``-th (:func:`calibrate_matches.load_frames`), resized to
1920 x 1080 (bicubic) as ``bench/calibrate_matches.py`` does; each is calibrated by both, in
alternating order, timed with ``time.process_time`` (CPU of the process; OpenMP/BLAS and OpenCV on one
thread). Printed per match and overall: CPU ms median of each, the ratio of the sums and the median of
the per-frame ratios; and whether the answers agree: the same ``reason`` and the keypoint RMS (px at
1280, :func:`calibrate_matches.keypoint_rms`) of both. Figure: ``docs/figures/calibrate_ab.json``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def import_base(rev: str, into: Path):
    """``glradial.camera.calibrate`` of revision ``rev``, imported as ``glradial_base`` from ``into``."""
    import importlib

    tar = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "glradial"], capture_output=True, check=True).stdout
    with tarfile.open(fileobj=BytesIO(tar)) as archive:
        archive.extractall(into, filter="data")
    (into / "glradial").rename(into / "glradial_base")
    sys.path.insert(0, str(into))
    return importlib.import_module("glradial_base.camera.calibrate")


def main(argv: list[str] | None = None) -> int:
    import cv2
    from calibrate_matches import MATCHES, keypoint_rms, load_frames

    import glradial.camera.calibrate as head
    from glradial.evaluation.real_eval import read_rgb
    from glradial.pitch import PitchTemplate

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--base", default="main", help="the revision compared against (default: main)")
    parser.add_argument("--per", type=int, default=12, help="frames per match (default 12)")
    parser.add_argument("--offset", type=int, default=0, help="first frame of each match's stride")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    kp = PitchTemplate().keypoints()
    every = load_frames(list(MATCHES), 0)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = import_base(args.base, Path(tmp))
        warm = np.zeros((1080, 1920, 3), np.uint8)
        warm[500:510] = 255  # imports, caches and first-call set-ups of both, untimed
        base.calibrate(warm), head.calibrate(warm)
        for match in MATCHES:
            mine = [f for f in every if f[0].startswith(match + "_")]
            for i, (name, path, labels) in enumerate(mine[args.offset:: max(1, len(mine) // args.per)][: args.per]):
                frame = np.ascontiguousarray(cv2.resize(read_rgb(path), (1920, 1080), interpolation=cv2.INTER_CUBIC))
                got = {}
                for key, module in (("base", base), ("head", head))[:: 1 if i % 2 == 0 else -1]:
                    cpu = time.process_time()
                    est = module.calibrate(frame)
                    got[key] = (time.process_time() - cpu, est.reason, keypoint_rms(est.camera, kp, labels, 1.5))
                rows.append({"frame": name, "match": match, **{f"{k}_{f}": v[j] for k, v in got.items()
                                                                 for j, f in enumerate(("cpu_s", "reason", "rms_px"))}})
                print(f"{name}\t{got['base'][0] * 1000:.0f} -> {got['head'][0] * 1000:.0f} ms", file=sys.stderr, flush=True)
    results = {m: _figures([r for r in rows if r["match"] == m]) for m in MATCHES} | {"all": _figures(rows)}
    print("| match | frames | base CPU ms median | head CPU ms median | sum ratio | median ratio | same reason | "
          "max RMS change (px) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, f in results.items():
        print(f"| {name} | {f['frames']} | {f['base_cpu_ms_median']:.0f} | {f['head_cpu_ms_median']:.0f} | "
              f"{f['cpu_sum_ratio']:.3f} | {f['cpu_ratio_median']:.3f} | {f['same_reason']:.0%} | {f['rms_change_max_px']:.3f} |")
    from figures import write_figure

    write_figure("calibrate_ab", {"base": args.base, **results})
    return 0


def _figures(rows: list[dict]) -> dict:
    base, head = np.array([r["base_cpu_s"] for r in rows]), np.array([r["head_cpu_s"] for r in rows])
    both = [abs(r["base_rms_px"] - r["head_rms_px"]) for r in rows
            if np.isfinite(r["base_rms_px"]) and np.isfinite(r["head_rms_px"])]
    return {"frames": len(rows), "base_cpu_ms_median": 1000 * float(np.median(base)),
            "head_cpu_ms_median": 1000 * float(np.median(head)), "cpu_sum_ratio": float(head.sum() / base.sum()),
            "cpu_ratio_median": float(np.median(head / base)),
            "same_reason": float(np.mean([r["base_reason"] == r["head_reason"] for r in rows])),
            "rms_change_max_px": float(max(both, default=0.0))}


if __name__ == "__main__":
    raise SystemExit(main())
