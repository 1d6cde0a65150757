"""CPU time of pass 1's per-sample evidence (:class:`glradial.video.shot_evidence.ShotCollector`:
line chains, the per-frame estimate on every ``ESTIMATE_EVERY``-th sample, matches) of this
checkout against another revision's, on the same frames, taking turns in one process.

The other revision's ``glradial`` is extracted with ``git archive`` into a temporary folder as the
package ``glradial_base`` (its imports are relative), with its own bundled estimator. Each clip
(default: ``bench_video.py``'s 150-frame pan at 960x540, made if missing) is sampled as pass 1
samples a shot: every ``EVERY``-th frame, at most ``ESTIMATE_WIDTH`` px wide, up to ``--samples``;
the samples are fed to each side's collector serially on this thread (pass 1's ``ahead=False``),
the sides taking turns sample by sample, ``--rounds`` times. CPU = ``time.process_time()``
(onnxruntime's threads included) of each sample's ``add``, the least of the rounds, summed over the
samples; wall-clock time is not used (the machine is shared).
Each side's evidence is compared (:func:`agreement`: chain points, estimates, matched points), and
the base's with itself a round later: the estimator's last bits vary from run to run (a lens hint
1e-11 apart may cut a chain at a corner elsewhere), so that is the floor of any difference.

Run: ``python bench/bench_evidence.py [--base main] [--rounds 5] [CLIP.mp4 ...]``;
writes ``docs/figures/bench_evidence.json``.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial, not an installed one
from figures import write_figure  # noqa: E402

from glradial.media.video_io import VideoReader  # noqa: E402
from glradial.video.shot_track import ESTIMATE_EVERY, ESTIMATE_WIDTH, EVERY  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def base_package(rev: str, into: Path) -> str:
    """Extract revision ``rev``'s ``glradial`` into ``into/glradial_base``; its package name."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "glradial"], capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    (into / "glradial").rename(into / "glradial_base")
    sys.path.insert(0, str(into))
    return "glradial_base"


def samples(clip: Path, count: int) -> list[np.ndarray]:
    """Every :data:`EVERY`-th frame of ``clip`` (uint8 RGB, at most :data:`ESTIMATE_WIDTH` wide), ``count`` at most."""
    frames = []
    with VideoReader(clip, order="rgb", max_width=ESTIMATE_WIDTH) as reader:
        for index, frame in enumerate(reader):
            if index % EVERY == 0:
                frames.append(np.ascontiguousarray(frame))
            if len(frames) == count:
                break
    return frames


def evidence(sides: dict, frames: list[np.ndarray], flip: bool) -> tuple[dict, dict]:
    """One shot's evidence of ``frames`` by each side's collector (``{name: (package, estimator)}``),
    the sides taking turns sample by sample (``flip``: the other one first); the evidence and the CPU
    seconds of each sample's :meth:`add` per side."""
    collectors = {name: importlib.import_module(f"{pkg}.video.shot_evidence").ShotCollector(est, ESTIMATE_EVERY)
                  for name, (pkg, est) in sides.items()}
    names = list(sides)[::-1] if flip else list(sides)
    cpu: dict[str, list[float]] = {name: [] for name in sides}
    for i, frame in enumerate(frames):
        for name in names if i % 2 == 0 else names[::-1]:
            start = time.process_time()
            collectors[name].add(i * EVERY, frame)
            cpu[name].append(time.process_time() - start)
    return {name: c.finish() for name, c in collectors.items()}, cpu


def agreement(a, b) -> dict:
    """How far two shots' evidence differs: the share of samples whose chains are the same bit for
    bit, the largest difference of their estimates' k1, and the share of frame pairs matched alike
    (same pair, same points)."""
    chains = [len(x.evidence.chains) == len(y.evidence.chains)
              and all(np.array_equal(p.points, q.points) for p, q in zip(x.evidence.chains, y.evidence.chains))
              for x, y in zip(a.samples, b.samples)]
    k1 = [abs(x.estimate.k1 - y.estimate.k1) for x, y in zip(a.samples, b.samples)
          if x.estimate is not None and y.estimate is not None]
    pairs = {(i, j): m for i, j, m in a.pairs}
    alike = [(i, j) in pairs and np.array_equal(pairs[i, j].a, m.a) and np.array_equal(pairs[i, j].b, m.b)
             for i, j, m in b.pairs]
    return {"same_chains": round(float(np.mean(chains)), 3), "max_k1_diff": float(max(k1, default=0.0)),
            "same_matches": round(float(np.mean(alike)) if alike else 1.0, 3)}


def measure(clips: list[Path], count: int, rounds: int, package: str) -> list[dict]:
    """Per clip: CPU ms per sample of each side (each sample's least over ``rounds``: the load of a
    shared machine only adds), their ratio, and whether the two sides' evidence is the same."""
    from glradial.video.video_pipeline import default_estimator

    sides = {"base": (package, importlib.import_module(f"{package}.video.video_pipeline").default_estimator()),
             "head": ("glradial", default_estimator())}
    rows = []
    for clip in clips:
        frames = samples(clip, count)
        found, _ = evidence(sides, frames, False)  # warm-up
        done = [evidence(sides, frames, r % 2 == 1) for r in range(rounds)]
        runs = [cpu for _, cpu in done]
        base, head = (sum(min(run[name][i] for run in runs) for i in range(len(frames))) * 1000 / len(frames)
                      for name in ("base", "head"))
        rows.append({"clip": clip.name, "size": list(frames[0].shape[1::-1]), "samples": len(frames),
                     "base_cpu_ms_per_sample": round(base, 2), "head_cpu_ms_per_sample": round(head, 2),
                     "base_over_head": round(base / head, 2),
                     "head_vs_base": agreement(found["base"], found["head"]),
                     "base_vs_base": agreement(found["base"], done[0][0]["base"])})  # main's own repeatability
        print(rows[-1], flush=True)
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("clips", nargs="*", type=Path, help="clips to sample (default: bench_video's pan at 960x540)")
    parser.add_argument("--base", default="main", help="the revision to compare with (git)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--samples", type=int, default=15, help="samples per clip (one shot)")
    args = parser.parse_args()
    clips = args.clips
    with tempfile.TemporaryDirectory() as tmp:
        if not clips:
            import bench_video

            clips = [Path(tmp) / "pan_960x540.mp4"]
            bench_video.make_clip(clips[0], (960, 540), 150, "pan", bench_video.bundled_frame_path())
        rows = measure(clips, args.samples, args.rounds, base_package(args.base, Path(tmp)))
    head, base = (sum(r[f"{s}_cpu_ms_per_sample"] * r["samples"] for r in rows) for s in ("head", "base"))
    print("all clips: base / head", round(base / head, 2))
    by_clip = lambda key: {Path(r["clip"]).stem: r[key] for r in rows}  # noqa: E731
    write_figure("bench_evidence", {
        "base": args.base, "rounds": args.rounds, "samples_per_clip": args.samples,
        "base_over_head": {**by_clip("base_over_head"), "all": round(base / head, 2)},
        "base_cpu_ms_per_sample": by_clip("base_cpu_ms_per_sample"), "head_cpu_ms_per_sample": by_clip("head_cpu_ms_per_sample"),
        **{f"{name}_{side}": {Path(r["clip"]).stem: r[side][name] for r in rows}
           for side in ("head_vs_base", "base_vs_base") for name in ("same_chains", "same_matches", "max_k1_diff")}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
