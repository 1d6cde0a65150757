"""Per-shot evaluation of ``correct --auto``'s first pass on clips with a known lens per frame
(``scripts/make_clips.py``): per-frame error, error on the shots right after a cut, the stated
bound's coverage per shot, doubt; and the calibration of the shot fit's bound (split conformal:
the scales are read off the ``--calibrate`` clips, the others check them).

Error = maximum displacement between the lens read and the true one over the 16:9 frame, px at
1920 wide (:func:`glradial.lens.metrics.max_displacement_px`). A shot is covered when its worst frame's
error is within the stated ``uncertainty_px``.

Calibration (docs/eval/shots.md, "The bound"): every shot with a joint fit (lines or frame pairs,
:func:`glradial.video.shot_fit.joint_fit`), whichever reading the shot then takes, gives the scale
its joint fit would have needed, ``(worst frame's error of the joint fit - BOUND_FLOOR_PX) / sigma``;
the static shots' and the moving shots' (pans, zooms) are pooled apart, and each scale is the
split-conformal 90 % quantile of its pool (the ``ceil((n + 1) 0.9)``-th smallest of ``n``): the
values for ``shot_fit.STATIC_BOUND_SCALE`` and ``shot_fit.BOUND_SCALE``. Re-run it whenever the
line fit or the trust model changes (the per-frame estimates seed the fit and compete with it)::

    python scripts/make_clips.py CLIPS                       # the main set
    python scripts/make_clips.py STATIC --set static         # more static shots
    python bench/eval_shots.py CLIPS STATIC --calibrate all  # prints the two scales needed

Run: ``python bench/eval_shots.py CLIP_DIR [CLIP_DIR ...] [--calibrate all|none|clip,clip]
[--json OUT.json] [--md OUT.md]``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial, not an installed one
from figures import write_figure  # noqa: E402

from glradial.lens.metrics import max_displacement_px  # noqa: E402
from glradial.video import shot_track  # noqa: E402
from glradial.video.clips import read_truth  # noqa: E402
from glradial.video.shot_fit import (  # noqa: E402
    BOUND_FLOOR_PX,
    BOUND_SCALE,
    STATIC_BOUND_SCALE,
    fit_shot,
    joint_fit,
)
from glradial.video.video_pipeline import default_estimator, track_video  # noqa: E402

#: the bound's target coverage (per shot)
COVERAGE = 0.9


def _recording(fits: list):
    """``fit_shot`` that also keeps, per shot, the joint fit it was weighed against."""

    def fit(evidence, **kwargs):
        shot = fit_shot(evidence, **kwargs)
        joint = shot if shot.source == "joint" else joint_fit(evidence, **kwargs)
        frames = np.array([s.frame for s in evidence.samples])
        fits.append((shot, joint, frames, evidence.log_zooms(), evidence.camera()))
        return shot

    return fit


def evaluate(clip: Path, estimator, sources: list[str] | None = None, own: dict[str, float] | None = None) -> list[dict]:
    """One row per true shot of ``clip``: errors, stated bound, doubt, and the joint fit's error and
    1-sigma (for the calibration). ``own``: the k1 a source picture reads as by itself (a real
    view that is not exactly pinhole); its shots are also scored against the true lens with that
    reading added, at the shot's zoom (``k1_own / zoom^2``, to first order), beside the truth."""
    truth = read_truth(f"{clip}.truth.csv")
    fits: list = []
    start = time.perf_counter()
    with mock.patch.object(shot_track, "fit_shot", _recording(fits)):
        track = track_video(clip, estimator, progress=False)
    seconds = time.perf_counter() - start
    error = max_displacement_px(track.lens, truth.lens)
    rows = []
    for shot in np.unique(truth.shot):
        frames = np.flatnonzero(truth.shot == shot)
        picture = sources[int(shot)] if sources else ""
        with_own = truth.lens[frames] + np.outer((own or {}).get(picture, math.nan) / truth.zoom[frames] ** 2, [1.0, 0.0])
        found = np.unique(track.shot[frames])
        read, joint, sampled, zoom, kind = fits[int(np.bincount(track.shot[frames]).argmax())]
        joint_px = math.nan
        if joint is not None:
            joint_px = float(np.max(max_displacement_px(joint.lens_at(shot_track._log_zoom_at(frames, sampled, zoom)),
                                                        truth.lens[frames])))
        stated = float(np.max(track.uncertainty_px[frames]))
        reasons = sorted({track.reason[i] for i in frames if track.reason[i]})
        rows.append({
            "clip": clip.stem, "shot": int(shot), "after_cut": bool(shot > 0), "frames": len(frames),
            "picture": picture, "kind": kind, "read_by": read.source,
            "cut_found": bool(len(found) == 1 and (shot == 0 or track.shot[frames[0]] != track.shot[frames[0] - 1])),
            "median_px": float(np.median(error[frames])), "max_px": float(np.max(error[frames])),
            "stated_px": stated, "covered": bool(np.max(error[frames]) <= stated),
            "doubtful": bool(track.doubtful[frames].any()), "reason": ",".join(reasons),
            "k1_offset": float(np.median(track.lens[frames, 0] - truth.lens[frames, 0])),
            "joint_max_px": joint_px, "joint_sigma_px": joint.sigma_px if joint is not None else math.nan,
            "joint_stated_px": joint.uncertainty_px if joint is not None else math.nan,
            "near_cut_max_px": float(np.max(error[frames[:3]] if shot > 0 else error[frames[-3:]])),
            "errors": error[frames].tolist(), "errors_own": max_displacement_px(track.lens[frames], with_own).tolist(), "seconds_per_frame": seconds / len(truth.shot),
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
        "near_cut_max_px": max((r["near_cut_max_px"] for r in rows if len(rows) > 1), default=None),
        "coverage": float(np.mean([r["covered"] for r in rows])),
        "doubtful": float(np.mean([r["doubtful"] for r in rows])),
        "median_stated_px": float(np.median([r["stated_px"] for r in rows])),
    }


def by_picture(rows: list[dict], own: dict[str, float]) -> list[dict]:
    """Per source picture: shots, median error against the truth, median k1 read minus true, the
    picture's own reading and the median error against the truth with it added."""
    out = []
    for picture in sorted({r["picture"] for r in rows if r["picture"]}):
        mine = [r for r in rows if r["picture"] == picture]
        errors = np.concatenate([r["errors"] for r in mine])
        with_own = np.concatenate([r["errors_own"] for r in mine])
        out.append({"picture": picture, "shots": len(mine), "median_px": float(np.median(errors)),
                    "k1_offset": float(np.median([r["k1_offset"] for r in mine])), "own_k1": own.get(picture),
                    "median_with_own_px": float(np.median(with_own)) if np.isfinite(with_own).all() else None})
    return out


def conformal_scale(rows: list[dict], coverage: float = COVERAGE) -> dict:
    """The split-conformal scale of the joint fit's bound on ``rows`` (module docstring): the
    ``ceil((n + 1) coverage)``-th smallest needed scale of the ``n`` shots with a joint fit
    (``inf`` when ``n`` is too small for that coverage), and ``n``."""
    needed = np.sort([(r["joint_max_px"] - BOUND_FLOOR_PX) / r["joint_sigma_px"] for r in rows
                      if math.isfinite(r["joint_max_px"]) and r["joint_sigma_px"] > 0])
    rank = math.ceil((len(needed) + 1) * coverage)
    return {"shots": int(len(needed)), "scale": float(needed[rank - 1]) if rank <= len(needed) else math.inf,
            "largest": float(needed[-1]) if len(needed) else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", type=Path, nargs="+", help="clip folders made by scripts/make_clips.py")
    parser.add_argument("--calibrate", default="none",
                        help="clips the bound's scales are calibrated on: 'all', 'none' or clip names, comma-separated")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--md", type=Path, help="write the per-shot table (markdown) here")
    parser.add_argument("--own", action="append", default=[], metavar="PICTURE=K1",
                        help="a source picture's own reading (k1), scored beside the truth (repeatable)")
    args = parser.parse_args()
    own = {}
    for item in args.own:
        picture, _, k1 = item.partition("=")
        try:
            own[picture] = float(k1)
        except ValueError:
            parser.error(f"--own must be PICTURE=K1, got {item!r}")
    estimator = default_estimator()
    rows = []
    for folder in args.clips:
        manifest = json.loads((folder / "manifest.json").read_text())
        for name, entry in manifest.items():
            for row in evaluate(folder / f"{name}.mp4", estimator, entry.get("sources"), own):
                row["group"] = entry["group"]
                rows.append(row)
                print(f"{row['clip']:>10} shot {row['shot']} {row['kind']:>6}: median {row['median_px']:5.1f} max {row['max_px']:5.1f} px, "
                      f"stated {row['stated_px']:5.1f} {'covered' if row['covered'] else 'MISSED '} ({row['read_by']}) "
                      f"{'doubtful(' + row['reason'] + ')' if row['doubtful'] else ''}", flush=True)
    calibrate = {r["clip"] for r in rows} if args.calibrate == "all" else set(args.calibrate.split(",")) - {"none"}
    used = [r for r in rows if r["clip"] in calibrate]
    report = {
        "all": summary(rows),
        "real": summary([r for r in rows if r["group"] == "real"]) if any(r["group"] == "real" for r in rows) else None,
        "procedural": summary([r for r in rows if r["group"] == "procedural"]) if any(r["group"] == "procedural" for r in rows) else None,
        "confident": summary([r for r in rows if not r["doubtful"]]) if any(not r["doubtful"] for r in rows) else None,
        "bound_scale_in_use": BOUND_SCALE, "static_bound_scale_in_use": STATIC_BOUND_SCALE,
        "calibrated_on": sorted(calibrate),
        "bound_scale_needed": conformal_scale([r for r in used if r["kind"] != "static"]) if used else None,
        "static_bound_scale_needed": conformal_scale([r for r in used if r["kind"] == "static"]) if used else None,
        "clips": {clip: summary([r for r in rows if r["clip"] == clip]) for clip in sorted({r["clip"] for r in rows})},
        "pictures": by_picture(rows, own),
        "shots": [{k: v for k, v in r.items() if k not in ("errors", "errors_own")} for r in rows],
    }
    for key in ("all", "real", "procedural", "confident"):
        print(key, json.dumps(report[key]))
    for clip, entry in report["clips"].items():
        print(f"clip {clip}: median {entry['median_px']:.2f} p90 {entry['p90_px']:.2f} px, "
              f"within three frames of a cut {entry['near_cut_max_px']:.2f} px at most")
    for entry in report["pictures"]:
        print(json.dumps(entry))
    if used:
        print(f"BOUND_SCALE (pans, zooms): in use {BOUND_SCALE}, needed {report['bound_scale_needed']}")
        print(f"STATIC_BOUND_SCALE: in use {STATIC_BOUND_SCALE}, needed {report['static_bound_scale_needed']}")
    write_figure("eval_shots_" + "_".join(folder.name for folder in args.clips), {k: v for k, v in report.items() if k != "shots"})
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
    if args.md:
        args.md.write_text(markdown(report, ", ".join(folder.name for folder in args.clips)))


def markdown(report: dict, name: str) -> str:
    """The per-shot table and the summaries of ``report``."""
    lines = [f"Clip set `{name}`: per shot (error = max displacement vs the true lens, px at 1920)", "",
             "| clip | shot | camera | read by | median px | max px | stated px | covered | doubtful |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in report["shots"]:
        lines.append(f"| {r['clip']} | {r['shot']} | {r['kind']} | {r['read_by']} | {r['median_px']:.1f} | {r['max_px']:.1f} | "
                     f"{r['stated_px']:.1f} | {'yes' if r['covered'] else '**no**'} | {r['reason'] if r['doubtful'] else ''} |")
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
