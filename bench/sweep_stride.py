"""Pass 1's sampling stride (issue 45): for each ``every`` (frames between samples) and
``estimate_every`` (samples between per-frame estimates), :mod:`eval_shots`' per-shot accuracy,
coverage and doubt on clips with a known lens, beside pass 1's CPU time per frame.

CPU = ``time.process_time()`` of the whole process (all of pass 1's threads: decode, cut check,
line chains, matching, the estimator, the shots' joint fits) around each clip's pass 1, less the
thread time of the extra joint fit :mod:`eval_shots` runs for its calibration on shots read
otherwise; divided by the clip's frames. Wall-clock time is not used (the machine is shared).

Run: ``python bench/sweep_stride.py CLIPS STATIC CHECK --calibrate CLIPS,STATIC [--every 10,16,20,25]
[--estimate-every 3,2] [--timing ROUNDS] [--first-samples F] [--samples-per-stride S] [--max-stride M] [--name NAME]`` (clip folders from ``scripts/make_clips.py``, each scored as
a set; the bound's scales as ``bench/eval_shots.py --calibrate`` reads them, pooled over the
``--calibrate`` folders, named as folders); writes ``docs/figures/sweep_stride.json`` (``NAME.json``).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial, not an installed one
import eval_shots  # noqa: E402
from figures import write_figure  # noqa: E402

from glradial.errors import check_count  # noqa: E402
from glradial.video import shot_track  # noqa: E402
from glradial.video.shot_fit import fit_shot, joint_fit  # noqa: E402
from glradial.video.video_pipeline import default_estimator  # noqa: E402

#: per shot: (samples, pairs of samples matched, CPU s of fit_shot), of the last run
FITS: list[tuple[int, int, float]] = []


def _recording(fits: list, spent: list):
    """:func:`eval_shots._recording`, with the thread time of its extra joint fit kept in ``spent``
    and each shot's samples, pairs and fit time in :data:`FITS`."""

    def fit(evidence, **kwargs):
        start = time.thread_time()
        shot = fit_shot(evidence, **kwargs)
        FITS.append((len(evidence.samples), _pairs(evidence), time.thread_time() - start))
        joint = shot
        if shot.source != "joint":
            start = time.thread_time()
            joint = joint_fit(evidence, **kwargs)
            spent.append(time.thread_time() - start)
        frames = np.array([s.frame for s in evidence.samples])
        fits.append((shot, joint, frames, evidence.log_zooms(), evidence.camera()))
        return shot

    return fit


def _pairs(evidence) -> int:
    """Frame pairs with matches in ``evidence`` (0 where the collector does not say)."""
    pairs = getattr(evidence, "pairs", None)
    return len(pairs) if pairs is not None else -1


def run(clips: list[Path], estimator, every: int, estimate_every: int) -> tuple[list[dict], float]:
    """Rows of :func:`eval_shots.evaluate` for every clip and pass 1's CPU ms per frame over them."""
    rows, cpu, frames = [], 0.0, 0
    FITS.clear()
    tracker = functools.partial(shot_track.track_shots, every=every, estimate_every=estimate_every)
    for folder in clips:
        manifest = json.loads((folder / "manifest.json").read_text())
        for name, entry in manifest.items():
            spent: list[float] = []
            with mock.patch.object(eval_shots, "track_video", tracker), \
                    mock.patch.object(eval_shots, "_recording", lambda fits, spent=spent: _recording(fits, spent)):
                start = time.process_time()
                found = eval_shots.evaluate(folder / f"{name}.mp4", estimator, entry.get("sources"))
                cpu += time.process_time() - start - sum(spent)
            frames += sum(r["frames"] for r in found)
            for row in found:
                row["group"] = entry["group"]
            rows += found
    return rows, 1000 * cpu / frames


def timing(clips: list[Path], estimator, settings: list[tuple[int, int]], rounds: int) -> dict:
    """Pass 1 alone (no scoring), ``settings`` run in turn ``rounds`` times: CPU ms per frame of each
    round, per setting (interleaved, so that a change of load falls on all of them alike)."""
    paths = [folder / f"{name}.mp4" for folder in clips for name in json.loads((folder / "manifest.json").read_text())]
    out: dict = {f"{e}/{s}": [] for e, s in settings}
    for _ in range(rounds):
        for every, estimate_every in settings:
            start, frames = time.process_time(), 0
            for path in paths:
                frames += len(shot_track.track_shots(path, estimator, every=every, estimate_every=estimate_every,
                                                     progress=False).shot)
            out[f"{every}/{estimate_every}"].append(1000 * (time.process_time() - start) / frames)
            print(every, estimate_every, f"{out[f'{every}/{estimate_every}'][-1]:.2f} ms CPU/frame", flush=True)
    return out


def entry(rows: list[dict], cpu: float) -> dict:
    """One set's figures at one setting: CPU, accuracy, doubt, misses, the fits' cost (:data:`FITS`)."""
    summary = eval_shots.summary(rows)
    fits = np.array(FITS).reshape(-1, 3)
    return {"pass1_cpu_ms_per_frame": round(cpu, 2),
            **{k: summary[k] for k in ("shots", "median_px", "p90_px", "after_cut_p90_px", "coverage", "doubtful")},
            "doubtful_shots": sorted(f"{r['clip']}/{r['shot']}" for r in rows if r["doubtful"]),
            "missed_shots": sorted(f"{r['clip']}/{r['shot']}" for r in rows if not r["covered"]),
            "samples_per_shot": float(fits[:, 0].mean()), "pairs_per_shot": float(fits[:, 1].mean()),
            "fit_cpu_ms_per_frame": float(1000 * fits[:, 2].sum() / summary["frames"])}


def sweep(folders: list[Path], calibrate: set[str], estimator, settings: list[tuple[int, int]]) -> dict:
    """Per setting ``"EVERY/ESTIMATE_EVERY"``: each clip folder's :func:`entry`, and the two bound
    scales the folders in ``calibrate`` need, pooled (:func:`eval_shots.conformal_scale`); and the
    joint fit's CPU per shot fitted as a constant plus a cost per frame pair."""
    table, fits = {}, []
    for every, estimate_every in settings:
        row, pooled = {}, []
        for folder in folders:
            rows, cpu = run([folder], estimator, every, estimate_every)
            row[folder.name] = entry(rows, cpu)
            fits += FITS
            pooled += rows if folder.name in calibrate else []
            print(f"{every}/{estimate_every} {folder.name}: {json.dumps(row[folder.name])}", flush=True)
        row["bound_scale_needed"] = eval_shots.conformal_scale([r for r in pooled if r["kind"] != "static"])
        row["static_bound_scale_needed"] = eval_shots.conformal_scale([r for r in pooled if r["kind"] == "static"])
        table[f"{every}/{estimate_every}"] = row
    f = np.array(fits).reshape(-1, 3)
    paired = f[:, 1] > 0
    constant, per_pair = np.linalg.lstsq(np.c_[np.ones(paired.sum()), f[paired, 1]], 1000 * f[paired, 2], rcond=None)[0]
    return {"settings (EVERY/ESTIMATE_EVERY)": table, "joint_fit_cpu_ms_per_shot": {
        "constant": float(constant), "per_frame_pair": float(per_pair), "shots": int(paired.sum())}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", type=Path, nargs="+", help="clip folders (scripts/make_clips.py), each scored as a set")
    parser.add_argument("--every", default="10,16,20,25")
    parser.add_argument("--estimate-every", default="3,2")
    parser.add_argument("--calibrate", default="", help="folders whose shots calibrate the bound scales, comma-separated")
    parser.add_argument("--timing", type=int, default=2, metavar="ROUNDS",
                        help="then time pass 1 alone on the first folder, the settings in turn, ROUNDS times")
    parser.add_argument("--samples-per-stride", type=int, default=shot_track.SAMPLES_PER_STRIDE,
                        help="samples after which a shot's stride doubles (shot_track.SAMPLES_PER_STRIDE)")
    parser.add_argument("--first-samples", type=int, default=shot_track.FIRST_SAMPLES,
                        help="samples a shot takes at the first stride (shot_track.FIRST_SAMPLES)")
    parser.add_argument("--max-stride", type=int, default=shot_track.MAX_STRIDE,
                        help="the longest stride, in EVERY (shot_track.MAX_STRIDE; 1024: the schedule before it)")
    parser.add_argument("--name", default="sweep_stride", help="figure name (docs/figures/NAME.json)")
    args = parser.parse_args()
    for name in ("samples_per_stride", "first_samples", "max_stride"):
        check_count(f"--{name.replace('_', '-')}", getattr(args, name))
    # read by pass 1 at each sample (shot_track.stride)
    shot_track.SAMPLES_PER_STRIDE, shot_track.FIRST_SAMPLES = args.samples_per_stride, args.first_samples
    shot_track.MAX_STRIDE = args.max_stride
    estimator = default_estimator()
    settings = [(int(e), int(s)) for e in args.every.split(",") for s in args.estimate_every.split(",")]
    first = json.loads((args.clips[0] / "manifest.json").read_text())
    eval_shots.evaluate(args.clips[0] / f"{next(iter(first))}.mp4", estimator)  # warm-up: model load, first runs
    results = sweep(args.clips, set(args.calibrate.split(",")), estimator, settings)
    if args.timing:
        cpu = timing(args.clips[:1], estimator, settings, args.timing)
        for key, values in cpu.items():
            results["settings (EVERY/ESTIMATE_EVERY)"][key]["pass1_cpu_ms_per_frame_interleaved"] = values
            print(f"{key}: median {np.median(values):.2f} ms CPU/frame over {len(values)} rounds")
    results["samples_per_stride"], results["first_samples"] = args.samples_per_stride, args.first_samples
    results["max_stride"] = args.max_stride
    results["note"] = ("CPU: process_time of pass 1 (all its threads) per frame, less eval_shots' extra joint fit; "
                       "the interleaved figures run the settings in turn on the first folder, pass 1 alone")
    write_figure(args.name, results)


if __name__ == "__main__":
    main()
