"""CPU time of pass 1's per-sample evidence (:class:`glradial.video.shot_evidence.ShotCollector`:
line chains, the per-frame estimate on every ``ESTIMATE_EVERY``-th sample, matches) of this
checkout against another revision's, on the same frames, taking turns in one process.

The other revision's ``glradial`` is extracted with ``git archive`` into a temporary folder as the
package ``glradial_base`` (its imports are relative), with its own bundled estimator. Each clip
(default: ``bench_video.py``'s 150-frame pan at 960x540, made if missing) is sampled as pass 1
samples a shot: every ``EVERY``-th frame, at most ``ESTIMATE_WIDTH`` px wide, up to ``--samples``;
the samples are fed to each side's collector serially on this thread (pass 1's ``ahead=False``),
the sides alternating, ``--rounds`` times. CPU = ``time.process_time()`` (onnxruntime's threads
included) per sample, the median of the rounds; wall-clock time is not used (the machine is shared).
Each side's evidence is compared: chain points, estimates, matched points and zooms, bit for bit.

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


def evidence(package: str, estimator, frames: list[np.ndarray]):
    """One shot's evidence of ``frames`` by ``package``'s collector, and the CPU seconds it took."""
    collector_class = importlib.import_module(f"{package}.video.shot_evidence").ShotCollector
    start = time.process_time()
    collector = collector_class(estimator, ESTIMATE_EVERY)
    for i, frame in enumerate(frames):
        collector.add(i * EVERY, frame)
    found = collector.finish()
    return found, time.process_time() - start


def same(a, b) -> bool:
    """Whether two shots' evidence holds the same chains, estimates, matches and zooms, bit for bit."""
    def flat(ev):
        chains = [c.points for s in ev.samples for c in s.evidence.chains]
        estimates = [(s.estimate.k1, s.estimate.k2) if s.estimate is not None else None for s in ev.samples]
        matches = [m for _, _, p in ev.pairs for m in (p.a, p.b)]
        return chains, estimates, matches, [(i, j) for i, j, _ in ev.pairs], list(ev.zoom)

    (ca, ea, ma, pa, za), (cb, eb, mb, pb, zb) = flat(a), flat(b)
    return (len(ca) == len(cb) and all(np.array_equal(x, y) for x, y in zip(ca, cb)) and ea == eb and pa == pb
            and all(np.array_equal(x, y) for x, y in zip(ma, mb)) and za == zb)


def measure(clips: list[Path], count: int, rounds: int, package: str) -> list[dict]:
    """Per clip: CPU ms per sample of each side (median of ``rounds``), their ratio, and whether they agree."""
    from glradial.video.video_pipeline import default_estimator

    sides = {"base": (package, importlib.import_module(f"{package}.video.video_pipeline").default_estimator()),
             "head": ("glradial", default_estimator())}
    rows = []
    for clip in clips:
        frames = samples(clip, count)
        found = {name: evidence(pkg, est, frames)[0] for name, (pkg, est) in sides.items()}  # warm-up
        cpu: dict[str, list[float]] = {name: [] for name in sides}
        for r in range(rounds):
            for name in (["base", "head"] if r % 2 == 0 else ["head", "base"]):
                cpu[name].append(evidence(*sides[name], frames)[1] * 1000 / len(frames))
        base, head = (float(np.median(cpu[n])) for n in ("base", "head"))
        rows.append({"clip": clip.name, "size": list(frames[0].shape[1::-1]), "samples": len(frames),
                     "base_cpu_ms_per_sample": round(base, 2), "head_cpu_ms_per_sample": round(head, 2),
                     "base_over_head": round(base / head, 2), "identical": same(found["base"], found["head"])})
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
    total = {"base_over_head": round(base / head, 2), "identical": all(r["identical"] for r in rows)}
    print("all clips:", total)
    write_figure("bench_evidence", {"base": args.base, "rounds": args.rounds, "clips": rows, "all": total})
    return 0


if __name__ == "__main__":
    sys.exit(main())
