"""Per-shot evaluation of ``correct --auto``'s first pass on clips with a known lens per frame
(``scripts/make_clips.py``): per-frame error, error on the shots right after a cut, the stated
bound's coverage per shot, doubt; and the calibration of the bound's scale (split conformal:
calibrate on ``--calibrate`` clips, check on the others).

Error = maximum displacement between the lens read and the true one over the 16:9 frame, px at
1920 wide (:func:`glradial.lens.metrics.max_displacement_px`). A shot is covered when its worst frame's
error is within the stated ``uncertainty_px``.

Run: ``python bench/eval_shots.py CLIP_DIR [--calibrate proc_3,proc_11,real_a] [--json OUT.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from glradial.lens.metrics import max_displacement_px
from glradial.video.clips import read_truth
from glradial.video.shot_fit import BOUND_FLOOR_PX, BOUND_SCALE
from glradial.video.video_pipeline import default_estimator, track_video


def evaluate(clip: Path, estimator) -> list[dict]:
    """One row per true shot of ``clip``: errors, stated bound, doubt, and the raw sigma."""
    truth = read_truth(f"{clip}.truth.csv")
    start = time.perf_counter()
    track = track_video(clip, estimator, progress=False)
    seconds = time.perf_counter() - start
    error = max_displacement_px(track.lens, truth.lens)
    rows = []
    for shot in np.unique(truth.shot):
        frames = np.flatnonzero(truth.shot == shot)
        found = np.unique(track.shot[frames])
        stated = float(np.max(track.uncertainty_px[frames]))
        reasons = sorted({track.reason[i] for i in frames if track.reason[i]})
        rows.append({
            "clip": clip.stem, "shot": int(shot), "after_cut": bool(shot > 0), "frames": len(frames),
            "cut_found": bool(len(found) == 1 and (shot == 0 or track.shot[frames[0]] != track.shot[frames[0] - 1])),
            "median_px": float(np.median(error[frames])), "max_px": float(np.max(error[frames])),
            "stated_px": stated, "covered": bool(np.max(error[frames]) <= stated),
            "doubtful": bool(track.doubtful[frames].any()), "reason": ",".join(reasons),
            "sigma_px": (stated - BOUND_FLOOR_PX) / BOUND_SCALE, "errors": error[frames].tolist(),
            "seconds_per_frame": seconds / len(truth.shot),
        })
    return rows


def summary(rows: list[dict]) -> dict:
    errors = np.concatenate([r["errors"] for r in rows])
    after = np.concatenate([r["errors"] for r in rows if r["after_cut"]] or [np.zeros(0)])
    return {
        "shots": len(rows), "frames": int(len(errors)),
        "median_px": float(np.median(errors)), "p90_px": float(np.percentile(errors, 90)),
        "after_cut_median_px": float(np.median(after)) if len(after) else None,
        "after_cut_p90_px": float(np.percentile(after, 90)) if len(after) else None,
        "coverage": float(np.mean([r["covered"] for r in rows])),
        "doubtful": float(np.mean([r["doubtful"] for r in rows])),
        "median_stated_px": float(np.median([r["stated_px"] for r in rows])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", type=Path)
    parser.add_argument("--calibrate", default="proc_3,proc_11,real_a", help="clips the bound's scale is calibrated on")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--md", type=Path, help="write the per-shot table (markdown) here")
    args = parser.parse_args()
    manifest = json.loads((args.clips / "manifest.json").read_text())
    estimator = default_estimator()
    rows = []
    for name, entry in manifest.items():
        for row in evaluate(args.clips / f"{name}.mp4", estimator):
            row["group"] = entry["group"]
            rows.append(row)
            print(f"{row['clip']:>10} shot {row['shot']}: median {row['median_px']:5.1f} max {row['max_px']:5.1f} px, "
                  f"stated {row['stated_px']:5.1f} {'covered' if row['covered'] else 'MISSED '} "
                  f"{'doubtful(' + row['reason'] + ')' if row['doubtful'] else ''}", flush=True)
    calibrate = set(args.calibrate.split(","))
    needed = [(r["max_px"] - BOUND_FLOOR_PX) / max(r["sigma_px"], 1e-9) for r in rows if r["clip"] in calibrate]
    report = {
        "all": summary(rows),
        "real": summary([r for r in rows if r["group"] == "real"]),
        "procedural": summary([r for r in rows if r["group"] == "procedural"]),
        "held_out": summary([r for r in rows if r["clip"] not in calibrate]),
        "confident": summary([r for r in rows if not r["doubtful"]]) if any(not r["doubtful"] for r in rows) else None,
        "bound_scale_in_use": BOUND_SCALE,
        "bound_scale_p90_on_calibration": float(np.quantile(needed, 0.9)) if needed else None,
        "shots": [{k: v for k, v in r.items() if k != "errors"} for r in rows],
    }
    for key in ("all", "real", "procedural", "held_out", "confident"):
        print(key, json.dumps(report[key]))
    print("bound scale: in use", BOUND_SCALE, "p90 needed on the calibration clips", report["bound_scale_p90_on_calibration"])
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    if args.md:
        args.md.write_text(markdown(report, args.clips.name))


def markdown(report: dict, name: str) -> str:
    """The per-shot table and the summaries of ``report``."""
    lines = [f"Clip set `{name}`: per shot (error = max displacement vs the true lens, px at 1920)", "",
             "| clip | shot | median px | max px | stated px | covered | doubtful |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in report["shots"]:
        lines.append(f"| {r['clip']} | {r['shot']} | {r['median_px']:.1f} | {r['max_px']:.1f} | {r['stated_px']:.1f} | "
                     f"{'yes' if r['covered'] else '**no**'} | {r['reason'] if r['doubtful'] else ''} |")
    lines += ["", "| set | shots | median px | p90 px | after a cut: median / p90 px | coverage | doubtful | median stated px |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for key in ("all", "real", "procedural", "confident"):
        m = report[key]
        if m is None:
            continue
        after = "-" if m["after_cut_median_px"] is None else f"{m['after_cut_median_px']:.1f} / {m['after_cut_p90_px']:.1f}"
        lines.append(f"| {key} | {m['shots']} | {m['median_px']:.1f} | {m['p90_px']:.1f} | {after} | "
                     f"{100 * m['coverage']:.0f} % | {100 * m['doubtful']:.0f} % | {m['median_stated_px']:.1f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
