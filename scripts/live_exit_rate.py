"""How often a script that exits without closing its :class:`glradial.LiveCorrector` aborts.

Each run is a fresh interpreter running the child below: a 1280x720 corrector (fixed lens, or
``"auto"`` with its worker thread or process; ``--backend`` cpu or gl) fed ``--frames`` frames at
50 fps in real time, pulled as they come, then the script ends within ``--linger`` s (uniformly at
random) without ``close()``. A run that ends with a signal (SIGABRT: "terminate called without an
active exception") or another non-zero status counts as failed. The outcome is a race between the
workers' native calls and the interpreter's finalization: the rate depends on the machine's load,
so compare variants (and versions, with ``PYTHONPATH`` pointing at each checkout) in the same
conditions. The deterministic form of the same failure is ``tests/video/test_live_exit.py``.

Run from a checkout: ``PYTHONPATH=. python scripts/live_exit_rate.py [--runs 30] [--lens fixed|auto|autothread] [--backend cpu|gl]
[--frames 60] [--linger 0.05]``; prints ``failed/runs`` and the exit statuses seen.
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import subprocess
import sys
import time


def child(lens: str, backend: str, frames: int, linger: float) -> None:
    """One run (in its own interpreter): correct ``frames`` frames, then end without close()."""
    import numpy as np

    import glradial

    size = (1280, 720)
    frame = np.random.default_rng(0).integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
    frame[size[1] // 2:] = (40, 140, 40)
    chosen = glradial.Lens(-0.2, 0.03) if lens == "fixed" else "auto"
    auto = {"worker": "thread"} if lens == "autothread" else None
    live = glradial.LiveCorrector(chosen, size, 50, backend=backend, auto=auto)
    start = time.monotonic()
    for i in range(frames):
        live.push(frame, i / 50)
        live.pull_ready()
        time.sleep(max(0.0, start + (i + 1) / 50 - time.monotonic()))
    time.sleep(random.uniform(0.0, linger))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--lens", choices=("fixed", "auto", "autothread"), default="autothread")
    parser.add_argument("--backend", choices=("cpu", "gl"), default="cpu")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--linger", type=float, default=0.05, help="the script ends within this many s after the last frame")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.lens, args.backend, args.frames, args.linger)
        return
    if args.runs < 1:
        parser.error(f"--runs must be >= 1, got {args.runs}")
    command = [sys.executable, os.path.abspath(__file__), "--child", "--lens", args.lens, "--backend", args.backend,
               "--frames", str(args.frames), "--linger", str(args.linger)]
    statuses: collections.Counter = collections.Counter()
    for run in range(args.runs):
        done = subprocess.run(command, capture_output=True, text=True)
        statuses[done.returncode] += 1
        print(f"\r{run + 1}/{args.runs} runs", end="", file=sys.stderr, flush=True)
    failed = args.runs - statuses[0]
    print(f"\n{args.lens} {args.backend}: {failed}/{args.runs} failed; exit statuses {dict(statuses)}")


if __name__ == "__main__":
    main()
