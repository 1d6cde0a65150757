"""Benchmark: the camera's first guess (glradial.camera.first_guess) on the 109 real Bundesliga frames
against their hand-labelled pitch keypoints (validation only: nothing is fitted to these frames).

Usage: ``python bench/bundesliga_camera.py [--data DIR] [--lens none|auto] [--csv OUT] [--limit N] [--time-1080p]``

Each frame (stored squashed to 640x640) is resized to 1280x720 (cubic), given to ``first_guess`` on
one thread, and the best candidate's homography projects the 32 keypoints; the frame's error is the
RMS distance (px at 1280x720) to its labelled keypoints. Per clip (ids ``2e57b9`` and ``42ba34``) and
overall it prints the median RMS (unanswered frames count as infinitely wrong), the share of frames
within 5 and 10 px (unanswered frames are misses), the share answered, the median time per frame and
its ratio to a 1080p ``cv2.GaussianBlur`` (sigma 1) timed in the same process; beside them the floor
(a homography fitted by least squares to the frame's own labels), the best of the returned
candidates (how much is ranking), and how the frames outside 10 px split: wrong lines (RMS over
30 px), near misses (10-30 px), unanswered. The half-turn ambiguity is resolved by the method (main
camera on the near touchline) and is not scored both ways.

``--lens auto``: the frame's lens is first estimated by ``glradial.estimate`` (its own evidence, no
labels; timed apart), the first guess runs on the frame undistorted by it (``lens=``), and the
keypoints are projected with the homography and then distorted by that lens: how much of the
no-lens residual is the lens, with today's lens estimate.

``--time-1080p``: also the median time of ``first_guess`` on every 10th frame resized to 1920x1080
(issue 34 states its speed target at 1080p), with the same blur ratio.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one thread, before numpy loads its BLAS
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from figures import printed_report, write_figure  # noqa: E402

from glradial.camera.first_guess import first_guess  # noqa: E402
from glradial.pitch import PitchTemplate  # noqa: E402

CLIPS = ("2e57b9", "42ba34")


def _project(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    p = np.column_stack([points, np.ones(len(points))]) @ h.T
    return p[:, :2] / p[:, 2:3]


def _rms(h: np.ndarray, pitch: np.ndarray, labels: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((_project(h, pitch) - labels) ** 2, axis=1))))


def _blur_ms() -> float:
    frame = cv2.GaussianBlur(np.random.default_rng(0).integers(0, 256, (1080, 1920, 3), dtype=np.uint8), (0, 0), 2.0)
    times = []
    for _ in range(20):
        t0 = time.perf_counter()
        cv2.GaussianBlur(frame, (0, 0), 1.0)
        times.append((time.perf_counter() - t0) * 1000)
    return statistics.median(times)


def _frame(path: Path) -> np.ndarray:
    from glradial.evaluation.real_eval import read_broadcast

    return read_broadcast(path)


def _lens_of(frame: np.ndarray, mode: str):
    """``(lens or None, ms)``: the frame's lens by ``glradial.estimate`` for ``mode == "auto"``."""
    if mode == "none":
        return None, 0.0
    from glradial.estimation.net_lines import estimate_net_lines

    t0 = time.perf_counter()
    found = estimate_net_lines(frame)
    return found, (time.perf_counter() - t0) * 1000


def _keypoints(candidate, pitch: np.ndarray, lens) -> np.ndarray:
    """Keypoints (px of the frame) by a candidate's homography, then ``lens`` when given."""
    xy = _project(candidate.homography, pitch)
    return xy if lens is None else lens.distort_points(xy, (1280, 720))


def evaluate(data: Path, limit: int | None, lens_mode: str = "none") -> list[dict]:
    """One row per frame: its clip, error of the best candidate, of the best of all candidates, the
    floor, whether answered, the time (ms) and, with a lens mode, the lens and its time."""
    labels = json.loads((data / "keypoints" / "keypoints.json").read_text())
    pitch = np.array([k["pitch_m"][:2] for k in labels["keypoints"]], float)
    points, ids = PitchTemplate().sampled_points(0.25)
    rows = []
    names = sorted(labels["frames"])[:limit]
    for n, name in enumerate(names):
        kp = labels["frames"][name]
        seen = np.array([p is not None for p in kp])
        xy = np.array([p for p in kp if p is not None], float)
        frame = _frame(data / f"{name}.jpg")
        lens, lens_ms = _lens_of(frame, lens_mode)
        t0 = time.perf_counter()
        found = first_guess(frame, points, ids, lens=None if lens is None else (lens.k1, lens.k2))
        ms = (time.perf_counter() - t0) * 1000
        floor_h, _ = cv2.findHomography(pitch[seen], xy, 0)
        errors = [float(np.sqrt(np.mean(np.sum((_keypoints(c, pitch[seen], lens) - xy) ** 2, axis=1)))) for c in found]
        rows.append(dict(frame=name, clip=name.split("_")[0], answered=bool(found), ms=ms,
                         rms=errors[0] if errors else float("inf"), best_of=min(errors, default=float("inf")),
                         floor=_rms(floor_h, pitch[seen], xy), score=found[0].score if found else 0.0,
                         share=found[0].share if found else 0.0,
                         k1=lens.k1 if lens is not None else 0.0, k2=lens.k2 if lens is not None else 0.0,
                         lens_ms=lens_ms))
        print(f"[{n + 1}/{len(names)}] {name}: {rows[-1]['rms']:.1f} px (floor {rows[-1]['floor']:.1f}, "
              f"best of {len(found)} {rows[-1]['best_of']:.1f}) {ms:.0f} ms", file=sys.stderr)
    return rows


def summary(rows: list[dict], blur: float) -> str:
    rms = np.array([r["rms"] for r in rows])
    best = np.array([r["best_of"] for r in rows])
    floor = np.array([r["floor"] for r in rows])
    ms = statistics.median(r["ms"] for r in rows)
    answered = np.array([r["answered"] for r in rows])
    wrong = int(np.sum(answered & (rms > 30)))
    near = int(np.sum(answered & (rms > 10) & (rms <= 30)))
    return (f"n={len(rows):3d} median {np.median(rms):6.2f} px | <=5 px {np.mean(rms <= 5):5.1%} | <=10 px "
            f"{np.mean(rms <= 10):5.1%} | answered {np.mean(answered):5.1%} | {ms:5.0f} ms/frame "
            f"({ms / blur:5.1f}x blur) || best-of-candidates median {np.median(best):5.2f}, <=10 px "
            f"{np.mean(best <= 10):5.1%} | floor median {np.median(floor):4.2f} || outside 10 px: wrong (>30) "
            f"{wrong}, near miss (10-30) {near}, unanswered {int(np.sum(~answered))}")


def time_1080p(data: Path, blur: float) -> str:
    """The median ms of ``first_guess`` on every 10th frame at 1920x1080 and its ratio to ``blur``."""
    points, ids = PitchTemplate().sampled_points(0.25)
    frames = []
    for path in sorted(data.glob("*.jpg"))[::10]:
        image = cv2.imread(str(path), cv2.IMREAD_COLOR)
        frames.append(np.ascontiguousarray(cv2.resize(image, (1920, 1080), interpolation=cv2.INTER_CUBIC)[:, :, ::-1]))
    first_guess(frames[0], points, ids)  # warm-up
    times = []
    for frame in frames:
        t0 = time.perf_counter()
        first_guess(frame, points, ids)
        times.append((time.perf_counter() - t0) * 1000)
    ms = statistics.median(times)
    return f"1080p: {len(frames)} frames, first_guess median {ms:.0f} ms ({ms / blur:.1f}x blur)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=str(ROOT.parent / "shared/data/broadcast_bundesliga"))
    parser.add_argument("--lens", choices=("none", "auto"), default="none",
                        help="auto: undistort with glradial.estimate's lens first (timed apart)")
    parser.add_argument("--csv", default=None, help="write the per-frame rows here")
    parser.add_argument("--limit", type=int, default=None, help="only the first N frames (sorted by name)")
    parser.add_argument("--time-1080p", action="store_true", help="also time every 10th frame at 1920x1080")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    blur = _blur_ms()
    rows = evaluate(Path(args.data), args.limit, args.lens)
    print(f"1080p GaussianBlur (sigma 1), one thread: {blur:.2f} ms; lens: {args.lens}"
          + (f" (glradial.estimate median {statistics.median(r['lens_ms'] for r in rows):.0f} ms, not in the times below)"
             if args.lens != "none" else ""))
    with printed_report() as lines:
        for clip in CLIPS:
            part = [r for r in rows if r["clip"] == clip]
            if part:
                print(f"{clip}: {summary(part, blur)}")
        print(f"all   : {summary(rows, blur)}")
    write_figure(f"bundesliga_camera_{args.lens}", {"report": lines, "blur_ms": blur})
    if args.time_1080p:
        print(time_1080p(Path(args.data), blur))
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
