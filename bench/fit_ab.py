"""The per-shot joint fit of pass 1 (:func:`glradial.video.shot_fit.fit_shot`), this checkout's
against a reference revision's (default ``main``), on the same evidence, interleaved in one process.

Evidence: every shot's :class:`~glradial.video.shot_fit.ShotEvidence` as pass 1
(:func:`glradial.video.shot_track.track_shots`, default stride) collects it on the clips given
(videos, or clip folders of ``scripts/make_clips.py``). Each shot is then fitted by the two
``fit_shot`` in turn, ``--rounds`` times; CPU = ``time.thread_time()`` of each call (the machine is
shared: wall-clock time is not used). The answers are compared per shot: the largest displacement
between the two lenses over the shot's sampled zooms (px at 1920, the 16:9 corner), the two bounds
and doubts.

Run: ``python bench/fit_ab.py CLIP_OR_FOLDER... [--ref main] [--rounds 3] [--cache FILE]``; writes
``docs/figures/fit_ab.json`` (with ``--name``, ``docs/figures/NAME.json``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import pickle
import subprocess
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial, not an installed one
from figures import ROOT, write_figure  # noqa: E402

from glradial.lens.metrics import max_displacement_px  # noqa: E402
from glradial.video import shot_fit, shot_track  # noqa: E402
from glradial.video.video_pipeline import default_estimator  # noqa: E402


def videos(paths: list[Path]) -> list[Path]:
    """The videos named, and those of the clip folders named (their manifest's order)."""
    out = []
    for path in paths:
        if path.is_dir():
            out += [path / f"{name}.mp4" for name in json.loads((path / "manifest.json").read_text())]
        else:
            out.append(path)
    return out


def capture(paths: list[Path]) -> list[tuple[str, dict, shot_fit.ShotEvidence]]:
    """``(clip/shot, fit_shot's keyword arguments, evidence)`` of every shot pass 1 fits on ``paths``."""
    estimator, shots = default_estimator(), []
    for path in paths:
        found = []

        def record(evidence, found=found, **kwargs):
            found.append((f"{path.stem}/{len(found)}", kwargs, evidence))
            return shot_fit.fit_shot(evidence, **kwargs)

        with mock.patch.object(shot_track, "fit_shot", record):
            shot_track.track_shots(path, estimator, progress=False, ahead=False)
        shots += found
        print(f"{path.name}: {len(found)} shots", flush=True)
    return shots


def reference(rev: str):
    """``glradial/video/shot_fit.py`` of git revision ``rev``, imported beside this checkout's."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:glradial/video/shot_fit.py"],
                            capture_output=True, text=True, check=True).stdout
    spec = importlib.util.spec_from_loader("glradial.video._shot_fit_ref", loader=None)
    module = importlib.util.module_from_spec(spec)
    module.__package__ = "glradial.video"
    sys.modules[spec.name] = module
    exec(compile(source, f"{rev}:shot_fit.py", "exec"), module.__dict__)
    return module


def compare(name: str, evidence, ref, new, cpu: dict) -> dict:
    """One shot's row: both fits' CPU (ms, median over rounds) and how far their answers lie apart."""
    z = evidence.log_zooms()
    lens = [np.atleast_2d(s.lens_at(z if s.zooming else np.zeros(1))) for s in (ref, new)]
    if len(lens[0]) != len(lens[1]):
        lens = [np.atleast_2d(s.lens_at(z)) for s in (ref, new)]
    return {"shot": name, "camera": evidence.camera(), "samples": len(evidence.samples), "pairs": len(evidence.pairs),
            "ref_cpu_ms": float(np.median(cpu["ref"])), "new_cpu_ms": float(np.median(cpu["new"])),
            "lens_apart_px": float(np.max(max_displacement_px(lens[0], lens[1]))),
            "ref_bound_px": ref.uncertainty_px, "new_bound_px": new.uncertainty_px,
            "ref": [ref.source, ref.doubtful, ref.reason], "new": [new.source, new.doubtful, new.reason]}


def summary(rows: list[dict]) -> dict:
    """Both fits' total CPU (ms) over ``rows``, its ratio, and the largest differences of answers."""
    ref, new = (sum(r[f"{k}_cpu_ms"] for r in rows) for k in ("ref", "new"))
    return {"shots": len(rows), "ref_cpu_ms": ref, "new_cpu_ms": new, "ref_over_new": ref / new,
            "lens_apart_px_max": max(r["lens_apart_px"] for r in rows),
            "bound_apart_px_max": max(abs(r["ref_bound_px"] - r["new_bound_px"]) for r in rows),
            "verdicts_differ": [r["shot"] for r in rows if r["ref"] != r["new"]]}


def run(shots: list, ref_module, rounds: int) -> list[dict]:
    """Each shot fitted by the reference and this checkout in turn, ``rounds`` times."""
    rows = []
    for name, kwargs, evidence in shots:
        cpu: dict = {"ref": [], "new": []}
        for _ in range(rounds):
            for key, fit in (("ref", ref_module.fit_shot), ("new", shot_fit.fit_shot)):
                start = time.thread_time()
                answer = fit(evidence, **kwargs)
                cpu[key].append(1000 * (time.thread_time() - start))
                if key == "ref":
                    ref = answer
                else:
                    new = answer
        rows.append(compare(name, evidence, ref, new, cpu))
        print(json.dumps(rows[-1]), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("clips", type=Path, nargs="+", help="videos or clip folders (scripts/make_clips.py)")
    parser.add_argument("--ref", default="main", help="git revision of the reference fit")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--cache", type=Path, help="pickle of the captured evidence: read if there, else written")
    parser.add_argument("--name", default="fit_ab", help="figure name (docs/figures/NAME.json)")
    args = parser.parse_args()
    if args.cache and args.cache.exists():
        shots = pickle.loads(args.cache.read_bytes())
    else:
        shots = capture(videos(args.clips))
        if args.cache:
            args.cache.write_bytes(pickle.dumps(shots))
    shot_fit.load_solver()
    rows = run(shots, reference(args.ref), args.rounds)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", args.ref], capture_output=True, text=True).stdout.strip()
    groups = {"all": rows, **{camera: [r for r in rows if r["camera"] == camera] for camera in ("static", "pan", "zoom")}}
    results = {"ref": f"{args.ref} ({commit})", "rounds": args.rounds,  # flat: one row of docs/FIGURES.md
               **{f"{name} {key}": value for name, group in groups.items() if group for key, value in summary(group).items()},
               "shots": [f"{r['shot']} {r['camera']}: {r['ref_cpu_ms']:.0f} -> {r['new_cpu_ms']:.0f} ms, lens apart "
                         f"{r['lens_apart_px']:.2f} px, bound {r['ref_bound_px']:.2f} -> {r['new_bound_px']:.2f} px" for r in rows]}
    print(json.dumps(summary(rows)))
    write_figure(args.name, results)


if __name__ == "__main__":
    main()
