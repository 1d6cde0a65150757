"""Which test decides whether the CNN's answer alone (a pitch view without any line fit) is corrected?

Usage::

    python bench/cnn_alone_doubt.py [--records docs/eval/trust_records.json]
        [--evidence /tmp/pitch_views_evidence.pkl]

The shipped rule (:meth:`glradial.estimation.trust.TrustModel.judge`, reason ``too_few_lines``):
the answer is corrected when its stated 90 % bound, ``q_no_lines_rel`` times its error head's
expected error ``h``, is below its own shift ``s`` from no lens (the identity lens lies outside the
bound). Compared with two one-sided tests calibrated on the same frames of the trust records (those
without a white-line fit, as ``q_no_lines_rel``). The *overshoot* of an answer past the truth toward
no lens, ``o = (s + d(answer, truth) - d(0, truth)) / 2`` (``d`` the maximum displacement, px at
1920): ``0 <= o <= min(s, d)`` by the triangle inequality, ``o = s`` when the truth is no lens, and
correcting helps exactly when ``o < s / 2``. ``q_over`` is the conformal 90 % quantile of ``o / h``:

* ``one-sided identity``: corrected when ``q_over h < s`` (no lens lies outside the one-sided 90 %
  set, though it may lie inside the stated bound);
* ``one-sided benefit``: corrected when ``2 q_over h < s`` (correcting helps for every truth of
  that set).

Printed: on the trust records' frames without any line fit, cross-fitted (each fold judged with the
quantiles of the other; truths as ``glradial.evaluation.trust_calibration`` scores them), and on the pitch
views of ``bench/pitch_views.py`` (its ``--evidence`` cache; the quantiles of all records; every
other frame keeps the shipped verdict): frames corrected, left uncorrected where the answer would
have helped, corrected and made worse.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from figures import write_figure  # noqa: E402

from glradial.estimation.lens_estimate import judge  # noqa: E402
from glradial.estimation.trust import shift_px, shipped_trust  # noqa: E402
from glradial.evaluation.trust_calibration import conformal_quantile, load_records  # noqa: E402
from glradial.lens.metrics import max_displacement_px  # noqa: E402

RULES = ("shipped (stated bound)", "one-sided identity", "one-sided benefit")


def _distances(answer, truth) -> tuple[float, float, float]:
    """``(s, d, identity)``: the answer's shift, its error and the identity lens's error (px at 1920)."""
    k, t = np.array(answer, np.float64), np.array(truth, np.float64)
    return shift_px(tuple(k)), float(max_displacement_px(k, t)), float(max_displacement_px(np.zeros(2), t))


def overshoot(answer, truth) -> float:
    """How far ``answer`` overshoots ``truth`` toward no lens (px at 1920; module docstring)."""
    s, d, ident = _distances(answer, truth)
    return (s + d - ident) / 2.0


def quantiles(records, trust) -> tuple[float, float]:
    """``(q_no_lines_rel, q_over)`` of ``records`` without a white-line fit (their CNN answers)."""
    err, over = [], []
    for r in records:
        if r.evidence.lines is None or r.evidence.soft:
            truth = r.truth("net", trust)
            err.append(_distances(r.evidence.net, truth)[1] / r.evidence.net_error_px)
            over.append(overshoot(r.evidence.net, truth) / r.evidence.net_error_px)
    return conformal_quantile(np.array(err)), conformal_quantile(np.array(over))


def corrected(rule: str, shift: float, head: float, q_err: float, q_over: float) -> bool:
    """Whether ``rule`` corrects a CNN-alone answer of ``shift`` px whose error head expects ``head`` px."""
    if rule == RULES[0]:
        return q_err * head < shift
    return (1.0 if rule == RULES[1] else 2.0) * q_over * head < shift


def _tally(cases, q_err: float, q_over: float) -> dict[str, tuple[int, int, int]]:
    """``{rule: (corrected, left would help, corrected worse)}`` over ``(s, d, identity, head)`` cases."""
    out = {}
    for rule in RULES:
        flags = [(corrected(rule, s, h, q_err, q_over), d < ident, d > ident) for s, d, ident, h in cases]
        out[rule] = (sum(c for c, _, _ in flags), sum(not c and helps for c, helps, _ in flags),
                     sum(c and worse for c, _, worse in flags))
    return out


def records_table(records, trust) -> list[str]:
    lines, total = [], {rule: np.zeros(3, int) for rule in RULES}
    n = 0
    for fold in sorted({r.fold for r in records}):
        q_err, q_over = quantiles([r for r in records if r.fold != fold], trust)
        lines.append(f"fold {fold} judged with q_no_lines_rel {q_err:.2f}, q_over {q_over:.2f} (fitted on the other fold)")
        cases = []
        for r in records:
            if r.fold == fold and r.evidence.lines is None and trust.no_evidence(r.evidence) is None:
                cases.append((*_distances(r.evidence.net, r.truth("auto", trust)), r.evidence.net_error_px))
        n += len(cases)
        for rule, counts in _tally(cases, q_err, q_over).items():
            total[rule] += counts
    lines += [f"trust records without any line fit: {n} frames (cross-fitted)", _head()]
    return lines + [_row(rule, n, *total[rule]) for rule in RULES]


def views_table(evidence: dict, not_pitch: tuple, q_err: float, q_over: float, trust) -> list[str]:
    """Totals over the pitch sources: the CNN-alone frames under each rule, every other frame as shipped."""
    fixed, cases, n = np.zeros(3, int), [], 0
    for source, items in evidence.items():
        if source in not_pitch:
            continue
        for _, ev, truth in items:
            n += 1
            e = judge(ev, "auto", trust)
            s, d, ident = _distances((e.k1, e.k2), truth)
            if ev.lines is None and trust.no_evidence(ev) is None:
                cases.append((s, d, ident, ev.net_error_px))
            else:
                fixed += (not e.doubtful, e.doubtful and d < ident, not e.doubtful and d > ident)
    tally = _tally(cases, q_err, q_over)
    lines = [f"pitch views: {n} frames, {len(cases)} of them the CNN alone (quantiles of all records)", _head()]
    return lines + [_row(rule, n, *(fixed + tally[rule])) for rule in RULES]


def _head() -> str:
    return f"{'rule':24s} {'n':>4s} {'corrected':>10s} {'left, would help':>17s} {'corrected, worse':>17s}"


def _row(rule: str, n: int, done: int, left: int, worse: int) -> str:
    return f"{rule:24s} {n:4d} {done:10d} {left:9d} ({100 * left / n:4.1f} %) {worse:9d} ({100 * worse / n:4.1f} %)"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", type=Path, default=ROOT / "docs" / "eval" / "trust_records.json")
    parser.add_argument("--evidence", type=Path, default=None, help="bench/pitch_views.py's --evidence cache")
    args = parser.parse_args(argv)
    trust, records = shipped_trust(), load_records(args.records)
    lines = records_table(records, trust)
    print("\n".join(lines))
    if args.evidence is not None:
        sys.path.insert(0, str(ROOT / "bench"))
        from pitch_views import NOT_PITCH_SOURCES

        q_err, q_over = quantiles(records, trust)
        print(f"\nall records: q_no_lines_rel {q_err:.2f} (shipped {trust.q_no_lines_rel:.2f}), q_over {q_over:.2f}")
        with open(args.evidence, "rb") as f:
            views = views_table(pickle.load(f), NOT_PITCH_SOURCES, q_err, q_over, trust)
        print("\n".join(views))
        lines += ["", f"all records: q_no_lines_rel {q_err:.2f}, q_over {q_over:.2f}", "", *views]
    write_figure("cnn_alone_doubt", {"report": lines})
    return 0


if __name__ == "__main__":
    sys.exit(main())
