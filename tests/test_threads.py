"""The thread budget (glradial.threads): a process given budget 1 runs its native pools on one
thread each, as each library reports it or as the process's own thread list shows (FFmpeg names its
frame threads ``av:CODEC:df*``; libx264 starts its worker threads when the encoder opens); without a
budget the same code uses the libraries' defaults, which on a machine of 2+ cores start those threads."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from glradial.threads import cores, set_thread_budget, share_of_cores

PROBE = r"""
import json, os, sys
from pathlib import Path
budget, folder = int(sys.argv[1]), Path(sys.argv[2])
if budget:
    from glradial.threads import set_thread_budget
    set_thread_budget(budget)
import cv2, numpy as np
from glradial import Estimator
from glradial.media.video_io import VideoInfo, VideoReader, VideoWriter

def names():  # a thread may end between the listing and the read of its name: skipped
    out = []
    for t in Path("/proc/self/task").iterdir():
        try:
            out.append((t / "comm").read_text().strip())
        except FileNotFoundError:
            pass
    return out

base, started, decoders = len(names()), 0, set()
with VideoWriter(folder / f"c{budget}.mp4", VideoInfo.of((320, 180), 25, codec="h264", pix_fmt="yuv420p")) as writer:
    for i in range(12):
        writer.write(np.full((180, 320, 3), 20 * i, np.uint8))
        started = max(started, len(names()) - base)
with VideoReader(folder / f"c{budget}.mp4") as reader:
    frames = sum(1 for _ in reader.items())
    decoders |= {n for n in names() if n.startswith("av:")}
print(json.dumps({"cv2": cv2.getNumThreads(), "encoder_threads": started, "decoder_threads": sorted(decoders),
                  "frames": frames, "onnxruntime": Estimator().threads,
                  "env": {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "LP_NUM_THREADS")}}))
"""


def probe(budget: int, folder) -> dict:
    run = subprocess.run([sys.executable, "-c", PROBE, str(budget), str(folder)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


def test_a_budget_of_one_thread_holds_in_every_pool(tmp_path):
    one = probe(1, tmp_path)
    assert one["frames"] == 12
    assert one["cv2"] == 1 and one["onnxruntime"] == 1
    assert one["env"] == {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "LP_NUM_THREADS": "1"}
    assert one["encoder_threads"] == 0 and one["decoder_threads"] == []
    if cores() < 2:
        pytest.skip("one core: the libraries' defaults start no extra threads either")
    free = probe(0, tmp_path)  # the same code without a budget: the libraries' own threads (the check can fail)
    assert free["cv2"] > 1 and free["onnxruntime"] is None
    assert free["encoder_threads"] > 0 and free["decoder_threads"]


def test_share_of_cores_and_bad_budgets():
    assert share_of_cores(1, 16) == 16 and share_of_cores(3, 16) == 5 and share_of_cores(32, 16) == 1
    assert share_of_cores(2) == max(1, cores() // 2)
    for bad in (0, -1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="threads must be a positive integer"):
            set_thread_budget(bad)
        if bad != "2":
            with pytest.raises(ValueError, match="workers must be a positive integer"):
                share_of_cores(bad)
