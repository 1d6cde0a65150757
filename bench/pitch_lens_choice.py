"""Choose the lens fed back (weight, manifold pull, bound, agreement) leave one match out, offline.

Usage: ``python bench/pitch_lens_choice.py DUMP.jsonl [DUMP.jsonl ...] [PROCEDURAL.jsonl] [--ship]``

``DUMP``: ``bench/bundesliga_consistency.py --dump`` rows (the five shared matches' frames, each with a
known lens applied; validation data, nothing is fitted on it: four numbers are chosen from grids).
Each sample's camera fit (its raw ``(k1, k2)``, marking RMS and verdict) and the estimation layer's
``auto`` reading (lens, bound) are in the dump, so the lens ``glradial.estimate`` would answer under
other settings is replayed exactly (:func:`glradial.camera.estimator.combine`, the function
``pitch_lens`` calls) and scored self-consistently as the bench scores it
(``bundesliga_consistency.exact_error_px``: the reading of a distorted frame against the applied lens
composed with the same method's reading of the unmodified frame).

Settings (``glradial/data/camera_trust.json``): ``lens_weight`` (the camera lens's share),
``lens_manifold_pull`` (how far the fit's lens is pulled toward the manifold),
``lens_quantile`` (the camera lens's bound: split-conformal 90 % of its self-consistent error over
``max(fit RMS, lens_floor_px)``, computed on the chosen-on matches for each pull) and
``lens_agreement`` (the reading is mixed in only where it lies within this many times the camera
lens's bound of it; beyond, the camera's lens alone; ``lens_weight_floor_by_bounds`` stays as shipped, 0). ``lens_max_hfov_deg`` is the widest sure camera of the chosen-on matches
(beyond it the bound would be extrapolated: the camera lens is not fed back). On a set of matches the
choice minimises the largest per-match self-consistent median (the issue's goal is per match), ties
broken by the largest p90, their mean, then by the share of samples whose stated bound covers the error. Each match is
reported with the settings chosen on the four others; ``--ship`` writes those chosen on all five.
Largest medians within :data:`MEDIAN_TIE_PX` of the smallest tie (noise), broken by the largest p90.
``PROCEDURAL``: ``bench/lines_accuracy.py --pitch --sources procedural/ --dump`` rows (rendered crops
with exact lenses): a constraint on every choice, never a held-out match: median and p90 of their
error within :data:`PROCEDURAL_TOLERANCE` of the estimation layer's reading alone (before the lens
was fed back; settings that exceed it lose to any that do not).
Figure: ``docs/figures/lens_consistency_lomo.json``.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

#: The candidate settings.
GRID = {"lens_weight": [0.25, 0.5, 0.75, 1.0], "lens_manifold_pull": [0.0, 0.25, 0.5],
        "lens_agreement": [0.5, 1.0, 1.5, 2.0, 3.0], "lens_shift_weight": [0.0, 1.0]}
#: The procedural test crops' rows (``bench/lines_accuracy.py --pitch --dump``: exact truth) count as this clip:
#: a constraint on every choice, never a match held out.
PROCEDURAL = "procedural"
#: How much worse (relative) than the estimation layer's reading alone the procedural crops may get, median
#: and p90: within their sampling noise (bootstrap SD over the 200 crops: 9 % of the median, 16 % of the p90).
PROCEDURAL_TOLERANCE = 0.05


def samples(paths: list[Path]) -> list[dict]:
    """One dict per (frame, applied lens): clip, frame, truth (None: the unmodified frame), the ``auto``
    reading ``(k, bound)`` and the camera fit (``None`` where it was not run)."""
    out: dict = {}
    for path in paths:
        for i, line in enumerate(path.read_text().splitlines()):
            r = json.loads(line)
            if "source" in r and "k_auto" in r:  # a procedural crop of bench/lines_accuracy.py --pitch: exact truth
                if r["source"].startswith("procedural/"):
                    out[path, i] = procedural_row(r)
                continue
            if r["method"] != "auto":
                continue
            key = (r["frame"], None if r["truth"] is None else tuple(r["truth"]))
            cam = r.get("camera")
            out[key] = {"clip": r["clip"], "frame": r["frame"], "truth": key[1], "auto": (tuple(r["k"]), r["bound_px"]),
                        "camera": None if cam is None or cam.get("k") is None else
                        {"k": tuple(cam["k"]), "ok": cam["reason"] == "ok", "rms": r["camera_rms_px"],
                         "shift": float("nan") if cam.get("centre_shift_px") is None else cam["centre_shift_px"],
                         "hfov": cam["hfov_deg"]}}
    return list(out.values())


def procedural_row(r: dict) -> dict:
    """A row of :func:`samples` from a ``bench/lines_accuracy.py --pitch --dump`` line of a procedural crop:
    its truth is the crop's exact lens (``exact``: scored without an own reading)."""
    cam = r.get("camera")
    return {"clip": PROCEDURAL, "frame": None, "truth": tuple(r["truth"]), "exact": True,
            "auto": (tuple(r["k_auto"]), r["bound_auto"]),
            "camera": None if cam is None or cam.get("k") is None else
            {"k": tuple(cam["k"]), "ok": cam["reason"] == "ok", "rms": r["camera_rms_px"],
             "shift": float("nan") if cam.get("centre_shift_px") is None else cam["centre_shift_px"],
             "hfov": cam["hfov_deg"]}}


class Replay:
    """The lens fed back under other settings, with the pulled camera lenses cached per pull."""

    def __init__(self, rows: list[dict]) -> None:
        self.rows, self._pulled = rows, {}

    def pulled(self, k: tuple, pull: float) -> tuple[float, float]:
        from glradial.camera.estimator import pulled_lens
        from glradial.lens.lens import Lens

        if (k, pull) not in self._pulled:
            lens = pulled_lens(Lens(*k), pull)
            self._pulled[k, pull] = (lens.k1, lens.k2)
        return self._pulled[k, pull]

    def reading(self, row: dict, t: dict) -> tuple[tuple[float, float], float, bool]:
        """``(k, stated bound, from the pitch)`` of ``row`` under the settings ``t``."""
        from glradial.camera.estimator import combine, pitch_bound_px

        (ka, ba), cam = row["auto"], row["camera"]
        if cam is None or not cam["ok"] or cam["rms"] > t["max_rms_px"]:  # the rule's RMS check, replayed
            return ka, ba, False
        bound = pitch_bound_px(cam["rms"], cam["shift"], t)
        return combine(self.pulled(cam["k"], t["lens_manifold_pull"]), bound, ka, ba, t, cam["hfov"])

    def errors(self, t: dict, pitch_alone: bool = False) -> list[tuple[str, float, float, bool, float]]:
        """``(clip, self-consistent error, stated bound, from the pitch, fit RMS)`` of every distorted
        sample under ``t`` (``pitch_alone``: the camera lens alone where the camera is sure)."""
        from bundesliga_consistency import exact_error_px

        t = dict(t, lens_weight=1.0, lens_agreement=1e6) if pitch_alone else t
        own = {r["frame"]: self.reading(r, t)[0] for r in self.rows if r["truth"] is None}
        out = []
        for r in self.rows:
            if r.get("exact"):  # a procedural crop: the reading against the exact lens
                k, bound, pitched = self.reading(r, t)
                rms = r["camera"]["rms"] if r["camera"] else float("nan")
                out.append((r["clip"], exact_px(tuple(map(float, k)), r["truth"]), bound, pitched, rms))
            elif r["truth"] is not None and r["frame"] in own:
                k, bound, pitched = self.reading(r, t)
                rms = r["camera"]["rms"] if r["camera"] else float("nan")
                own_k = tuple(map(float, own[r["frame"]]))
                out.append((r["clip"], exact_error_px(tuple(map(float, k)), r["truth"], own_k)[0], bound, pitched, rms))
        return out


@functools.lru_cache(maxsize=1 << 16)
def exact_px(k: tuple[float, float], truth: tuple[float, float]) -> float:
    """Max displacement error (px at 1920) of the reading ``k`` against the exact lens ``truth``."""
    from glradial.lens.metrics import max_displacement_px

    return float(max_displacement_px(np.array(k), np.array(truth)))


def lens_quantile(replay: Replay, t: dict, clips: set[str]) -> float:
    """``lens_quantile`` on ``clips``: split-conformal 90 % of the camera lens's own error over
    ``max(fit RMS, lens_floor_px)`` where the camera is sure (module docstring)."""
    from glradial.evaluation.trust_calibration import conformal_quantile

    errs = [(e, rms) for clip, e, _, pitched, rms in replay.errors(t, pitch_alone=True) if clip in clips and pitched]
    return round(conformal_quantile([e / max(rms, t["lens_floor_px"]) for e, rms in errs]), 3)


def widest(replay: Replay, t: dict, clips: set[str]) -> float:
    """``lens_max_hfov_deg`` on ``clips``: the widest field of view (degrees, to the next degree up) among
    the sure cameras the bound is calibrated on: beyond it the bound would be extrapolated."""
    return float(np.ceil(max(r["camera"]["hfov"] for r in replay.rows if r["clip"] in clips and r["camera"]
                             and r["camera"]["ok"] and r["camera"]["rms"] <= t["max_rms_px"])))


def medians(errors: list, clips: set[str]) -> dict[str, float]:
    return {c: float(np.median([e for clip, e, *_ in errors if clip == c])) for c in sorted(clips)}


def procedural_excess(replay: Replay, errors: list) -> float:
    """How much worse the procedural crops' errors under a setting (``errors``: :meth:`Replay.errors`) are
    than the estimation layer's reading alone on them (what they were before the lens was fed back): the
    larger relative excess of the median and of the p90 beyond :data:`PROCEDURAL_TOLERANCE`; 0 within it
    or without procedural rows."""
    e = [err for clip, err, *_ in errors if clip == PROCEDURAL]
    if not e:
        return 0.0
    alone = [exact_px(tuple(map(float, r["auto"][0])), r["truth"]) for r in replay.rows if r["clip"] == PROCEDURAL]
    excess = max(np.median(e) / np.median(alone), np.percentile(e, 90) / np.percentile(alone, 90)) - 1.0
    return float(max(0.0, excess - PROCEDURAL_TOLERANCE))


#: Largest per-match medians within this many px of the smallest count as equal (a match's median over
#: its 15 frames has a frame-bootstrap standard error of 0.17-0.91 px): among them the smallest largest
#: per-match p90 wins.
MEDIAN_TIE_PX = 0.25


def choose(replay: Replay, base: dict, clips: set[str]) -> dict:
    """The settings of :data:`GRID` (and ``lens_quantile``) chosen on ``clips`` (module docstring): among
    those that keep the procedural crops within :data:`PROCEDURAL_TOLERANCE` of the reading alone (the
    least excess first), the smallest largest per-match median (within :data:`MEDIAN_TIE_PX`), then the
    smallest largest per-match p90, the mean median, the share of bounds that cover."""
    base = dict(base, lens_max_hfov_deg=widest(replay, base, clips))
    quantiles = {p: lens_quantile(replay, dict(base, lens_manifold_pull=p), clips) for p in GRID["lens_manifold_pull"]}
    scored = []
    for values in itertools.product(*GRID.values()):
        t = dict(base, **dict(zip(GRID, values)))
        t["lens_quantile"] = quantiles[t["lens_manifold_pull"]]
        errors = replay.errors(t)
        m = list(medians(errors, clips).values())
        p90 = max(float(np.percentile([e for clip, e, *_ in errors if clip == c], 90)) for c in clips)
        covers = float(np.mean([e <= bound for clip, e, bound, *_ in errors if clip in clips]))
        scored.append((procedural_excess(replay, errors), max(m), p90, float(np.mean(m)), -covers, len(scored), t))
    least = min(s[0] for s in scored)
    scored = [s for s in scored if s[0] == least]
    best = min(s[1] for s in scored)
    return min((s for s in scored if s[1] <= best + MEDIAN_TIE_PX), key=lambda s: s[2:6])[-1]


def summary(errors: list, clips: list[str]) -> dict:
    out = {}
    for c in clips:
        sel = [row for row in errors if row[0] == c]
        e = np.array([row[1] for row in sel])
        out[c] = {"n": len(sel), "median_px": float(np.median(e)), "p90_px": float(np.percentile(e, 90)),
                  "from_pitch": float(np.mean([row[3] for row in sel])),
                  "bound_covers": float(np.mean([row[1] <= row[2] for row in sel]))}
    return out


def main(argv: list[str] | None = None) -> int:
    from figures import printed_report, write_figure

    from glradial.camera.estimate import camera_trust

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dumps", type=Path, nargs="+")
    parser.add_argument("--ship", action="store_true", help="write the settings chosen on all matches to camera_trust.json")
    args = parser.parse_args(argv)
    replay = Replay(samples(args.dumps))
    base = dict(camera_trust())
    clips = sorted({r["clip"] for r in replay.rows} - {PROCEDURAL})
    shown = clips + sorted({r["clip"] for r in replay.rows} & {PROCEDURAL})
    keys = (*GRID, "lens_quantile", "lens_max_hfov_deg")
    held, chosen = [], {}
    for c in clips:
        t = choose(replay, base, set(clips) - {c})
        chosen[c] = {k: t[k] for k in keys}
        held += [row for row in replay.errors(t) if row[0] == c]
        print(f"held out {c}: chosen on the others {chosen[c]}", file=sys.stderr, flush=True)
    final = choose(replay, base, set(clips))
    held += [row for row in replay.errors(final) if row[0] == PROCEDURAL]  # never held out: a constraint on each choice
    shipped = summary(replay.errors(dict(base, **{k: base.get(k, GRID[k][0]) for k in GRID})), shown)
    lomo = summary(held, shown)
    on_all = summary(replay.errors(final), shown)
    with printed_report() as lines:
        print("| match | samples | shipped before: median / p90 (px at 1920) | held out: median / p90 | from pitch | "
              "bound covers | chosen on all five: median / p90 | bound covers | chosen without it |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for c in shown:
            s, h, a = shipped[c], lomo[c], on_all[c]
            print(f"| {c} | {h['n']} | {s['median_px']:.2f} / {s['p90_px']:.1f} | {h['median_px']:.2f} / {h['p90_px']:.1f} | "
                  f"{h['from_pitch']:.0%} | {h['bound_covers']:.0%} | {a['median_px']:.2f} / {a['p90_px']:.1f} | "
                  f"{a['bound_covers']:.0%} | {chosen.get(c, 'a constraint on each choice')} |")
        alone = [exact_px(tuple(map(float, r["auto"][0])), r["truth"]) for r in replay.rows if r["clip"] == PROCEDURAL]
        if alone:  # what the procedural crops are held to (within PROCEDURAL_TOLERANCE)
            print(f"{PROCEDURAL}, the reading alone (before the lens was fed back): median / p90 "
                  f"{np.median(alone):.2f} / {np.percentile(alone, 90):.2f}")
        print(f"chosen on all {len(clips)}: { {k: final[k] for k in keys} }")
    write_figure("lens_consistency_lomo", {"shipped_settings": {k: base.get(k) for k in keys}, "shipped": shipped,
                                           "held_out": lomo, "chosen_without": chosen, "on_all": on_all,
                                           "chosen_on_all": {k: final[k] for k in keys}, "report": lines})
    if args.ship:
        from glradial.camera.estimate import ship_camera_trust

        trust = {k: final[k] for k in keys}
        trust["lens_choice_source"] = (
            f"bench/pitch_lens_choice.py on bench/bundesliga_consistency.py --limit 15 --dump (five shared matches) and "
            f"bench/lines_accuracy.py --pitch --sources procedural/ --dump ({len(replay.rows)} samples in all): {', '.join(keys)} "
            f"chosen on all five as the grid point with the smallest largest per-match self-consistent median (ties within "
            f"{MEDIAN_TIE_PX} px: the smallest largest p90) among those keeping the procedural crops within "
            f"{PROCEDURAL_TOLERANCE:.0%} of the reading alone (lens_quantile: split-conformal 90 % of the camera lens's "
            f"error / max(RMS, lens_floor_px) for that pull); each match's figure in docs/figures/"
            f"lens_consistency_lomo.json is of the settings chosen without it: {chosen}")
        print(f"written to {ship_camera_trust(trust)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
