"""Accuracy of the line fit (``method="lines"`` / ``"auto"``) per source, fast enough to iterate on.

Usage: ``python bench/lines_accuracy.py [--cache /tmp/lines_accuracy.pkl] [--procedural 200] [--checkout DIR] [--pitch]
[--sources PREFIX] [--dump FILE]``

Builds the same samples as ``glradial evaluate --frames ../shared/data/real_football --procedural N
--remove-own-lens`` (seed 0: 12 paper + 12 extended lenses per frame at ``fit="crop"``, 48 + 48 crops
of the panorama, N held-out procedural crops), runs the CNN once per sample and caches frames, true
lenses and CNN readings in ``--cache`` (pickle; delete it to rebuild). Then runs the line detection
and fit (the code of ``--checkout``, default this checkout: compare two checkouts on one cache) on
every sample (``frame_evidence``, then ``judge`` per method) and prints, per group, the median and 90th
percentile of the maximum displacement error (px at 1920) of ``lines`` and ``auto``, the share of
frames with a line fit, and the mean fit time. Groups: real frames (all lenses), real frames with
``k1 <= -0.6``, 640x360 panorama crops, procedural test crops. Validation data only: no tuning
should be reported on the same samples without saying so (docs/LINES.md says which were used).
``--pitch`` also scores ``auto+pitch``, the public ``glradial.estimate(method="auto")``
(:mod:`glradial.camera.estimator`: the pitch camera fit's lens where the template fits, ``auto``
elsewhere), with the share of samples it answered from the pitch (``pitch %``); its ``--dump`` rows hold
the camera fit (``bundesliga_consistency.camera_record``) that ``bench/pitch_lens_choice.py`` replays.
``--sources procedural/`` scores only those samples (figure ``lines_accuracy_pitch_procedural``).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if __name__ == "__main__" and "--checkout" in sys.argv[:-1]:  # the checkout under test, before any import of it
    ROOT = Path(sys.argv[sys.argv.index("--checkout") + 1]).resolve()
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from figures import printed_report, write_figure  # noqa: E402

from glradial.estimation.lens_estimate import frame_evidence, judge  # noqa: E402
from glradial.estimation.net_lines import NetLinesEstimator, view_to_frame  # noqa: E402
from glradial.estimation.trust import view_features  # noqa: E402
from glradial.evaluation import real_eval  # noqa: E402
from glradial.lens.metrics import max_displacement_px  # noqa: E402

DATA = Path(__file__).resolve().parents[1].parent / "shared/data/real_football"


def _build(frames_dir: Path, procedural: int, lenses: int = 12, seed: int = 0) -> list[dict]:
    from glradial.remapping.remap import correct

    evaluator = real_eval.Evaluator(threads=1)
    frames, panoramas = real_eval.frames_in(frames_dir)
    sources: dict = {}
    for i, (name, f) in enumerate(frames):
        found = real_eval.agreed_own_lens(evaluator(f))
        if found is not None:
            f = correct(f, found, fit="crop")
        sources[f"real/{name}/paper"] = real_eval._distorted(f, real_eval.paper_lenses(lenses, seed * 1000 + i))
        sources[f"real/{name}/extended"] = real_eval._distorted(f, real_eval.extended_lenses(lenses, seed * 1000 + 500 + i))
    for i, (name, pano) in enumerate(panoramas):
        count = 4 * lenses
        sources[f"pano/{name}/paper"] = real_eval.panorama_crops(pano, real_eval.paper_lenses(count, seed * 1000 + 100 + i), seed + 1)
        sources[f"pano/{name}/extended"] = real_eval.panorama_crops(pano, real_eval.extended_lenses(count, seed * 1000 + 600 + i), seed + 2)
    if procedural:
        sources["procedural/test"] = real_eval.procedural_frames(procedural, seed=seed)
    out = []
    for name, items in sources.items():
        for truth, frame in items:
            k1, k2 = evaluator.estimator.run(evaluator.estimator.preprocess(frame)[None])[0]
            out.append({"source": name, "truth": tuple(map(float, truth)), "frame": frame, "net": (float(k1), float(k2))})
        print(f"built {name}", flush=True)
    return out


def _groups(samples: list[dict]) -> dict[str, list[int]]:
    groups: dict[str, list[int]] = {"real frames": [], "real k1<=-0.6": [], "panorama crops": [], "procedural": []}
    for i, s in enumerate(samples):
        if s["source"].startswith("real/"):
            groups["real frames"].append(i)
            if s["truth"][0] <= -0.6:
                groups["real k1<=-0.6"].append(i)
        elif s["source"].startswith("pano/"):
            groups["panorama crops"].append(i)
        else:
            groups["procedural"].append(i)
    for s in sorted({s["source"].rsplit("/", 1)[0] for s in samples if s["source"].startswith("real/")}):
        groups[s] = [i for i, x in enumerate(samples) if x["source"].startswith(s + "/")]
    return groups


def _report(samples: list[dict], errors: dict, pitched: list, has_fit: list, times: list) -> list[str]:
    """Print (and return) the per-group table of :func:`main`: median and p90 of each method's error,
    the share of frames with a line fit, the mean fit time (``auto+pitch`` columns when scored)."""
    pitch = "auto+pitch" in errors
    with printed_report() as lines:
        extra = f" {'auto+pitch':>10s} {'p90':>7s} {'pitch %':>7s}" if pitch else ""
        print(f"{'group':40s} {'n':>4s} {'lines med':>9s} {'p90':>7s} {'auto med':>9s} {'p90':>7s} {'fit %':>6s} {'ms':>6s}{extra}")
        for name, idx in _groups(samples).items():
            if not idx:
                continue
            el, ea = np.array(errors["lines"])[idx], np.array(errors["auto"])[idx]
            print(f"{name:40s} {len(idx):4d} {np.median(el):9.2f} {np.percentile(el, 90):7.2f} {np.median(ea):9.2f} "
                  f"{np.percentile(ea, 90):7.2f} {100 * np.mean(np.array(has_fit)[idx]):6.0f} {1000 * np.mean(np.array(times)[idx]):6.1f}"
                  + (f" {np.median(np.array(errors['auto+pitch'])[idx]):10.2f} {np.percentile(np.array(errors['auto+pitch'])[idx], 90):7.2f}"
                     f" {100 * np.mean(np.array(pitched)[idx]):7.0f}" if pitch else ""))
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cache", default="/tmp/lines_accuracy.pkl")
    parser.add_argument("--frames", default=str(DATA))
    parser.add_argument("--procedural", type=int, default=200)
    parser.add_argument("--dump", help="write per-sample results (JSON lines) here")
    parser.add_argument("--checkout", default=str(ROOT), help="the glradial checkout whose code is measured")
    parser.add_argument("--pitch", action="store_true", help="also score auto+pitch (the camera fit's lens fed back)")
    parser.add_argument("--sources", default="", help="only the samples whose source starts with this (e.g. procedural/)")
    args = parser.parse_args()
    cache = Path(args.cache)
    if cache.is_file():
        samples = pickle.loads(cache.read_bytes())
    else:
        samples = _build(Path(args.frames), args.procedural)
        cache.write_bytes(pickle.dumps(samples))
    samples = [s for s in samples if s["source"].startswith(args.sources)]
    errors: dict = {"lines": [], "auto": [], **({"auto+pitch": []} if args.pitch else {})}
    pitched = []
    has_fit, times, rows = [], [], []
    estimator = NetLinesEstimator(threads=1)
    for s in samples:
        frame = s["frame"]
        view = estimator.preprocess(frame)
        features = view_features(view)
        # the network's own expected error (error head), as NetLinesEstimator.estimate passes it: the CNN's bound
        net_error = estimator.run_with_error(view[None])[1]
        net_error = None if net_error is None else float(net_error[0])
        t0 = time.perf_counter()
        evidence = frame_evidence(frame, view_to_frame(s["net"], (frame.shape[1], frame.shape[0])), features,
                                  net_error_px=net_error)
        times.append(time.perf_counter() - t0)
        lines = evidence.lines
        has_fit.append(lines is not None)
        truth = np.array(s["truth"])
        for method in errors:
            e = judge(evidence, method.split("+")[0])
            if method == "auto+pitch":  # what glradial.estimate(method="auto") adds to the estimation layer's auto
                from bundesliga_consistency import camera_record

                from glradial.camera import estimator as pl

                auto = e
                e, camera = pl.with_pitch(frame, auto)
                pitched.append(e.method == "pitch")
                readings = {"k_auto": [auto.k1, auto.k2], "bound_auto": auto.uncertainty_px, "k_auto_pitch": [e.k1, e.k2],
                            "bound_auto_pitch": e.uncertainty_px, "camera_rms_px": None if camera is None else camera.rms_px,
                            "camera": None if camera is None else camera_record(frame, camera)}
            errors[method].append(float(max_displacement_px(np.array([e.k1, e.k2]), truth)))
        rows.append({"source": s["source"], "truth": s["truth"], "net": s["net"], "lines": None if lines is None else list(lines),
                     "err_auto": errors["auto"][-1], "err_lines": errors["lines"][-1],
                     **({"err_auto_pitch": errors["auto+pitch"][-1], "pitch": pitched[-1], **readings} if args.pitch else {})})
    lines = _report(samples, errors, pitched, has_fit, times)
    subset = "_" + args.sources.strip("/").replace("/", "_") if args.sources else ""  # a subset: its own figure
    write_figure("lines_accuracy" + ("_pitch" if args.pitch else "") + subset, {"report": lines})
    if args.dump:
        import json

        Path(args.dump).write_text("\n".join(json.dumps(r) for r in rows) + "\n")


if __name__ == "__main__":
    main()
