"""Calibrate and check the trust model (:mod:`glradial.estimation.trust`) on real validation frames: split
conformal, calibrated on some clips and checked on the others.

Usage (in a checkout with ../shared beside it; collecting takes ~8 min on one core, fitting seconds)::

    python -m glradial.evaluation.trust_calibration [--data ../shared/data] [--records docs/eval/trust_records.json] [--recollect] [--write]
        [--report docs/eval/trust.md]

Steps:
    1. **Collect** (cached in ``--records``; reused unless ``--recollect``): the
       :class:`glradial.estimation.trust.FrameEvidence` of each validation frame with its applied lens. Sources:
       ``broadcast`` (the 109 Bundesliga frames, two clips, restored to 1280×720, 3 known lenses each,
       self-consistent: scored against the applied lens composed with the reading of the unmodified
       frame), ``real_frames`` (the USL and football360 frames of ``real_football``, 12 lenses each,
       self-consistent too), ``real_panorama`` (crops of the real stadium_01 panorama, two pose
       seeds) and ``procedural`` (validation-split stadium crops). Each frame belongs to an
       independence group (a clip, a real frame, a pose seed, a stadium) and each group to one of two
       folds.
    2. **Fit** per fold: the scale's spread feature (the fit's 1-sigma or its difficulty),
       ``floor_px``, ``sigma_weight`` and ``disagree_weight`` (a small grid: the triple that makes the median bound on line-rich frames smallest, each half of the
       fold's independence groups bounded by the quantile of the other half), then
       ``q_lines`` = the conformal 90 % quantile (``ceil((n + 1) 0.9)``-th smallest) of
       ``|error| / scale`` over the fold's white-line fit answers, ``q_soft`` the same over its
       soft-edge fits (:mod:`glradial.estimation.soft_lines`; same scale), ``q_net`` the same of the CNN's errors and
       ``q_no_lines`` of the CNN's errors on the frames without a line fit.
       ``disagree_max_px`` is the conformal 95 % quantile of the line/CNN disagreement on the fold's
       line-rich frames.
    3. **Check**: each frame is judged with the model fitted on the *other* fold; coverage (share of
       frames whose error is inside the stated bound) overall, per source and per quartile of the
       fit's own difficulty, median stated bound on line-rich frames and doubt rates.
    4. ``--write``: the model fitted on **all** folds goes to ``glradial/data/trust.json``.

Re-run after any change to the line fit or the CNN (their evidence changes): ``--recollect``.
Validation only: these frames never train the network.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from ..estimation.lens_estimate import judge
from ..estimation.trust import TRUST_FILE, FrameEvidence, TrustModel, line_scale, shipped_trust
from ..lens.metrics import max_displacement_px

#: The 90 % target of the bound, and the share of disagreements that are not doubtful.
COVERAGE, DISAGREE_QUANTILE = 0.9, 0.95
#: Scale the CNN's bound by its error head's expected error (when every record has one).
USE_ERROR_HEAD = True
#: A frame is line-rich when its line fit has at least this many agreeing chains.
LINE_RICH_CHAINS = 4
#: Grid of the scale's floor (px at 1920), weight of the fit's 1-sigma and of the line/CNN disagreement.
FLOOR_GRID = (1.0, 2.0, 3.0, 5.0, 7.0, 10.0)
SIGMA_GRID = (0.25, 0.5, 1.0)
WEIGHT_GRID = (0.0, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0)
#: Counts of the collection (frames per source, lenses per frame).
BROADCAST_LENSES, REAL_LENSES, PANORAMA_CROPS, PROCEDURAL_CROPS = 3, 12, 24, 64
#: Real frames (stems in real_football) and their fold; other frames of the folder are ignored.
REAL_FRAME_FOLDS = {"usl_broadcast_0195": 0, "usl_broadcast_0460": 1, "football360_cam_0000000": 0,
                    "football360_cam_0012000": 1, "football360_cam_0019000": 0}
#: Sources of real pitch frames (the doubt-rate limit is stated on their line-rich frames).
REAL_PITCH_SOURCES = ("broadcast", "real_frames")
#: Broadcast clips and their fold.
BROADCAST_FOLDS = {"42ba34": 0, "2e57b9": 1}


@dataclass(frozen=True)
class Record:
    """One validation frame: where from (``source``, independence ``group``, ``fold``), the applied
    lens, the fit scale of its distortion and, for self-consistent sources, the evidence of the
    unmodified frame (``own``)."""

    source: str
    group: str
    fold: int
    applied: tuple[float, float]
    evidence: FrameEvidence
    own: FrameEvidence | None = None
    scale: float = 1.0

    def truth(self, method: str, trust: TrustModel) -> tuple[float, float]:
        """The lens ``method``'s answer is scored against (self-consistent when ``own`` is set)."""
        if self.own is None:
            return self.applied
        from .real_eval import self_consistent_truth

        own = judge(self.own, method, trust)
        return self_consistent_truth(self.applied, (own.k1, own.k2), self.scale)

    @property
    def line_rich(self) -> bool:
        return self.evidence.lines is not None and not self.evidence.soft and self.evidence.chains >= LINE_RICH_CHAINS

    def as_dict(self) -> dict:
        return {"source": self.source, "group": self.group, "fold": self.fold, "applied": list(self.applied),
                "scale": self.scale, "evidence": self.evidence.as_dict(),
                "own": self.own.as_dict() if self.own is not None else None}

    @classmethod
    def from_dict(cls, d: dict) -> "Record":
        own = FrameEvidence.from_dict(d["own"]) if d.get("own") else None
        return cls(d["source"], d["group"], int(d["fold"]), tuple(d["applied"]), FrameEvidence.from_dict(d["evidence"]),
                   own, float(d.get("scale", 1.0)))


# -- collection -----------------------------------------------------------------------------------
def _self_consistent(evaluator, frame: np.ndarray, source: str, group: str, fold: int,
                     lenses: list[tuple[float, float]]) -> Iterator[Record]:
    from .real_eval import self_consistent_items

    own = evaluator.evidence(frame)
    for applied, scale, distorted in self_consistent_items(frame, lenses):
        yield Record(source, group, fold, applied, evaluator.evidence(distorted), own, scale)


def collect(data: Path, evaluator, progress: Callable[[str], None] = print, seed: int = 0) -> list[Record]:
    """Evidence of every validation frame (see the module docstring, step 1)."""
    from .real_eval import applied_lenses, broadcast_frames, centre_16_9, panorama_crops, procedural_frames, read_rgb

    records: list[Record] = []
    for clip, frames in broadcast_frames(data / "broadcast_bundesliga").items():
        for i, (name, frame) in enumerate(frames):
            lenses = applied_lenses(BROADCAST_LENSES, seed * 1000 + i)
            records += _self_consistent(evaluator, frame, "broadcast", clip, BROADCAST_FOLDS.get(clip, i % 2), lenses)
        progress(f"broadcast {clip}: {len(frames)} frames")
    real = data / "real_football"
    for j, (stem, fold) in enumerate(REAL_FRAME_FOLDS.items()):
        path = next(real.glob(stem + ".*"), None)
        if path is not None:
            frame = centre_16_9(read_rgb(path))
            records += _self_consistent(evaluator, frame, "real_frames", stem, fold, applied_lenses(REAL_LENSES, 500 + j))
    progress("real frames done")
    pano_path = real / "stadium_01_1k_tonemapped.jpg"
    if pano_path.is_file():
        pano = read_rgb(pano_path)
        for fold in (0, 1):
            for truth, frame in panorama_crops(pano, applied_lenses(PANORAMA_CROPS, 700 + fold), seed + 11 + fold):
                records.append(Record("real_panorama", f"stadium_01/poses{fold}", fold, truth, evaluator.evidence(frame)))
        progress("real panorama crops done")
    stadiums = 4
    for idx, (truth, frame) in enumerate(procedural_frames(PROCEDURAL_CROPS, stadiums, split="val", seed=seed + 3)):
        stadium = min(idx * stadiums // PROCEDURAL_CROPS, stadiums - 1)
        records.append(Record("procedural", f"val/{stadium}", stadium % 2, truth, evaluator.evidence(frame)))
    progress("procedural crops done")
    return records


def save_records(records: list[Record], path: Path) -> None:
    from ..media.atomic import atomic_write_text

    atomic_write_text(path, json.dumps([r.as_dict() for r in records]))


def load_records(path: Path) -> list[Record]:
    return [Record.from_dict(d) for d in json.loads(Path(path).read_text())]


# -- fitting ----------------------------------------------------------------------------------------
def conformal_quantile(scores: np.ndarray, level: float = COVERAGE) -> float:
    """The ``ceil((n + 1) level)``-th smallest score (split conformal; the largest when n is small)."""
    scores = np.sort(np.asarray(scores, np.float64))
    if len(scores) == 0:
        raise ValueError("no calibration scores")
    rank = min(math.ceil((len(scores) + 1) * level), len(scores))
    return float(scores[rank - 1])


def _errors(records: list[Record], trust: TrustModel, method: str = "auto") -> tuple[np.ndarray, np.ndarray, list]:
    """``(error px, bound px, estimates)`` of ``method`` on each record under ``trust``."""
    est = [judge(r.evidence, method, trust) for r in records]
    truth = np.array([r.truth(method, trust) for r in records])
    err = max_displacement_px(np.array([(e.k1, e.k2) for e in est]), truth)
    return err, np.array([e.uncertainty_px for e in est]), est


def fit(records: list[Record], base: TrustModel) -> TrustModel:
    """The trust model calibrated on ``records`` (module docstring, step 2); thresholds of the
    no-evidence rules are kept from ``base``."""
    net_err, _, _ = _errors(records, base, "net")
    q_net = conformal_quantile(net_err)
    no_fit = np.array([r.evidence.lines is None or r.evidence.soft for r in records])  # no white-line fit
    q_no_lines = conformal_quantile(net_err[no_fit]) if no_fit.any() else q_net
    own = np.array([r.evidence.net_error_px or np.nan for r in records], np.float64)
    q_net_rel = q_no_lines_rel = 0.0
    if USE_ERROR_HEAD and np.all(own > 0):  # the network's error head: a per-frame scale for its own answers
        q_net_rel = conformal_quantile(net_err / own)
        q_no_lines_rel = conformal_quantile(net_err[no_fit] / own[no_fit]) if no_fit.any() else q_net_rel
    lined = [r for r in records if r.evidence.lines is not None and not r.evidence.soft]
    err, _, _ = _errors(lined, base, "lines")  # the line fit's answer does not depend on the scale
    spreads = {"sigma_px": np.array([r.evidence.sigma_px for r in lined]),
               "difficulty": np.array([r.evidence.difficulty for r in lined])}
    if not np.all(np.isfinite(spreads["difficulty"])):
        del spreads["difficulty"]  # evidence collected before the fit reported its difficulty
    disagree = np.array([r.evidence.disagreement_px for r in lined])
    rich = np.array([r.line_rich for r in lined])
    halves = _halves(lined)
    best = None
    for feature, spread in spreads.items():
        for floor in FLOOR_GRID:
            for a in SIGMA_GRID:
                for weight in WEIGHT_GRID:
                    scale = line_scale(floor, a, spread, weight, disagree)
                    bound = np.empty(len(lined))
                    for half in (0, 1):  # the shape is judged on groups its quantile did not see
                        bound[halves == half] = conformal_quantile((err / scale)[halves != half]) * scale[halves == half]
                    median = float(np.median(bound[rich] if rich.any() else bound))
                    if best is None or median < best[0]:
                        best = (median, replace(base, floor_px=floor, sigma_weight=a, disagree_weight=weight,
                                                scale_feature=feature, q_lines=conformal_quantile(err / scale),
                                                q_net=q_net, q_no_lines=q_no_lines, q_net_rel=q_net_rel,
                                                q_no_lines_rel=q_no_lines_rel))
    trust = replace(best[1], q_soft=_soft_quantile([r for r in records if r.evidence.soft], best[1]))
    rich = [r for r in lined if r.line_rich]
    disagree = np.array([r.evidence.disagreement_px for r in (rich or lined)])
    return replace(trust, disagree_max_px=conformal_quantile(disagree, DISAGREE_QUANTILE),
                   note=f"python -m glradial.evaluation.trust_calibration on {len(records)} validation frames")


def _soft_quantile(soft: list[Record], trust: TrustModel) -> float:
    """``q_soft``: the conformal 90 % quantile of ``|error| / scale`` of the soft-edge fits (the scale
    of ``trust``, whose shape was chosen on the white-line fits); 0 (soft fits unused) without any."""
    if not soft:
        return 0.0
    err, _, _ = _errors(soft, replace(trust, q_soft=1.0), "lines")  # the answer does not depend on q_soft
    return conformal_quantile(err / np.array([trust.lines_scale(r.evidence) for r in soft]))


def _halves(records: list[Record]) -> np.ndarray:
    """0/1 per record: its independence group's half (groups alternate in sorted order), so that a
    choice made on one half is judged on groups it did not see; all 0 with a single group."""
    groups = sorted({r.group for r in records})
    half = {g: i % 2 for i, g in enumerate(groups)}
    out = np.array([half[r.group] for r in records])
    return out if len(groups) > 1 else np.zeros(len(records), int)


def cross_check(records: list[Record], base: TrustModel) -> tuple[list[dict], dict[int, TrustModel]]:
    """Each record judged with the model fitted on the other fold: rows with source, group,
    difficulty, error, bound, doubt, reason, line-rich and the identity lens's error (leaving the lens in)."""
    models = {fold: fit([r for r in records if r.fold != fold], base) for fold in sorted({r.fold for r in records})}
    rows = []
    for fold, trust in models.items():
        mine = [r for r in records if r.fold == fold]
        err, bound, est = _errors(mine, trust, "auto")
        identity = max_displacement_px(np.zeros(2), np.array([r.truth("auto", trust) for r in mine]).reshape(-1, 2))
        for r, e, b, x, i in zip(mine, err, bound, est, identity):
            rows.append({"source": r.source, "group": r.group, "fold": fold, "difficulty": r.evidence.difficulty,
                         "error_px": float(e), "bound_px": float(b), "doubtful": x.doubtful, "reason": x.reason,
                         "line_rich": r.line_rich, "method": x.method, "identity_px": float(i)})
    return rows, models


def coverage_table(rows: list[dict]) -> list[tuple[str, int, float, float, float, float, float, float]]:
    """``(group, n, coverage, median error, median bound, doubtful share, left uncorrected where the
    estimate would have helped, corrected and made worse)`` overall, per source and per quartile of
    difficulty (frames without a fit are the hardest). "Helped" / "worse": the error after correcting
    with the estimate below / above the identity lens's error (``identity_px``; NaN when not given)."""
    def stats(name: str, sel: list[dict]) -> tuple:
        err = np.array([r["error_px"] for r in sel])
        bound = np.array([r["bound_px"] for r in sel])
        doubt = np.array([bool(r["doubtful"]) for r in sel])
        ident = np.array([r.get("identity_px", math.nan) for r in sel], np.float64)
        known = bool(np.all(np.isfinite(ident)))
        return (name, len(sel), float(np.mean(err <= bound)), float(np.median(err)), float(np.median(bound)),
                float(doubt.mean()), float(np.mean(doubt & (err < ident))) if known else math.nan,
                float(np.mean(~doubt & (err > ident))) if known else math.nan)

    out = [stats("all", rows)]
    for source in sorted({r["source"] for r in rows}):
        out.append(stats(f"source {source}", [r for r in rows if r["source"] == source]))
    for group in sorted({r["group"] for r in rows if r["source"] == "broadcast"}):
        out.append(stats(f"broadcast clip {group}", [r for r in rows if r["group"] == group]))
    order = sorted(rows, key=lambda r: r["difficulty"])
    quarter = -(-len(order) // 4)
    for q in range(4):
        part = order[q * quarter:(q + 1) * quarter]
        if part:
            out.append(stats(f"difficulty quartile {q + 1}" + (" (hardest)" if q == 3 else ""), part))
    rich = [r for r in rows if r["line_rich"]]
    if rich:
        out.append(stats(f"line-rich (>= {LINE_RICH_CHAINS} chains)", rich))
    real_rich = [r for r in rich if r["source"] in REAL_PITCH_SOURCES]
    if real_rich:
        out.append(stats("line-rich real pitch frames", real_rich))
    sure = [r for r in rows if not r["doubtful"]]
    if sure:
        out.append(stats("not doubtful", sure))
    return out


def report(rows: list[dict], models: dict[int, TrustModel], shipped: TrustModel, n_records: int) -> str:
    """Markdown of the cross-fitted check (docs/eval/trust.md)."""
    lines = ["# Trust: coverage of the stated 90 % bound on real validation frames", "",
             "Command: `python -m glradial.evaluation.trust_calibration --records docs/eval/trust_records.json --write "
             "--report docs/eval/trust.md` (add `--recollect` to measure the evidence again, ~8 min; module "
             "docstring of `glradial/evaluation/trust_calibration.py`). Split conformal, cross-fitted: every frame is judged with the bound "
             "calibrated on the other fold (other clips, other real frames, other poses, other stadiums). "
             "Method `auto`. Errors: max displacement over the 16:9 frame, px at 1920; broadcast and real "
             "frames self-consistent (applied lens composed with the reading of the unmodified frame).", "",
             f"{n_records} frames. Coverage counts every frame, doubtful or not (a doubtful frame still states "
             "its bound). Left, would help: doubtful frames whose estimate is closer to the truth than leaving "
             "the lens in (the identity lens's error, same metric); corrected, worse: frames not doubtful whose "
             "estimate is farther from it (shares of the group's frames).", "",
             "| group | n | inside bound | median error px | median bound px | doubtful | left, would help | corrected, worse |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, n, cov, err, bound, doubt, left, worse in coverage_table(rows):
        lines.append(f"| {name} | {n} | {100 * cov:.1f} % | {err:.2f} | {bound:.2f} | {100 * doubt:.1f} % | "
                     f"{100 * left:.1f} % | {100 * worse:.1f} % |")
    reasons: dict[str, int] = {}
    for r in rows:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    lines += ["", "Reasons: " + ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())), "",
              "Models (fold = the fold they were checked on; fitted on the other):", "",
              "| fitted | q_lines | q_soft | q_net px | q_no_lines px | q_net_rel | q_no_lines_rel | spread | floor px | "
              "spread weight | disagree weight | disagree max px |",
              "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
    for name, m in [*((f"for fold {f}", m) for f, m in models.items()), ("shipped (all folds)", shipped)]:
        lines.append(f"| {name} | {m.q_lines:.3f} | {m.q_soft:.3f} | {m.q_net:.1f} | {m.q_no_lines:.1f} | {m.q_net_rel:.2f} | "
                     f"{m.q_no_lines_rel:.2f} | {m.scale_feature} | {m.floor_px:g} | {m.sigma_weight:g} | {m.disagree_weight:g} | "
                     f"{m.disagree_max_px:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m glradial.evaluation.trust_calibration", description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[3] / "shared" / "data"),
                        help="folder with broadcast_bundesliga/ and real_football/ (default ../shared/data)")
    parser.add_argument("--records", default="docs/eval/trust_records.json",
                        help="evidence cache (default docs/eval/trust_records.json, the shipped collection)")
    parser.add_argument("--recollect", action="store_true", help="collect again even if --records exists")
    parser.add_argument("--write", action="store_true", help=f"write the model fitted on all folds to {TRUST_FILE}")
    parser.add_argument("--report", help="write the Markdown check here (e.g. docs/eval/trust.md)")
    parser.add_argument("--threads", type=int, default=1, help="onnxruntime threads (default 1)")
    args = parser.parse_args(argv)
    from ..media.atomic import atomic_write_text

    records_path = Path(args.records)
    if records_path.is_file() and not args.recollect:
        records = load_records(records_path)
    else:
        from .real_eval import Evaluator

        data = Path(args.data)
        if not (data / "broadcast_bundesliga").is_dir():
            raise SystemExit(f"glradial.evaluation.trust_calibration: {data}/broadcast_bundesliga not found (give --data)")
        records = collect(data, Evaluator(threads=args.threads))
        save_records(records, records_path)
    base = shipped_trust()
    rows, models = cross_check(records, base)
    shipped = fit(records, base)
    text = report(rows, models, shipped, len(records))
    print(text)
    if args.report:
        atomic_write_text(Path(args.report), text)
    if args.write:
        shipped.save(TRUST_FILE)
        print(f"wrote {TRUST_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
