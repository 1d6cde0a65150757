"""Re-score ``calibrate``'s doubt rule offline on the rows of ``bench/calibrate_matches.py --json``, and
choose its thresholds leave one match out (validation: thresholds only, no model is fitted).

Usage: ``python bench/doubt_rules.py ROWS.json [--max-wrong 0.01] [--ship]``

Each row holds every fit calibrate judged on that frame (the search's, then the strong-lens retry's
where the first was declined), with its doubt features (:func:`glradial.camera.calibrate.doubt_features`)
and its own keypoint RMS. A rule (the shipped ``camera_trust.json`` with some thresholds replaced) is
replayed as calibrate applies it (:func:`replay`): the search's fit is answered when the rule passes
it; otherwise the retry's, when one was recorded and passes. Caveat: a retry is recorded only where the
shipped rule declined the search's fit, so a rule stricter than the one the rows were made with sees
no retry where it would have run one (it can only under-count its answers).

Thresholds searched (:data:`GRID`): ``min_support``, ``max_missing`` (markings drawn where the frame
shows none), ``min_share`` (share of the frame's line evidence the fit explains), ``min_directions``; then
``max_rms_px`` (:data:`RMS_GRID`) with those held. Choice on a set of matches: the most answered within
10 px (pooled Acc@10) among the rules whose answered frames beyond 10 px stay within ``--max-wrong``
of the answered (pooled); of the rules within :data:`SLACK` of that best Acc@10, the strictest
(a margin against wrong fits the chosen-on matches do not show). The choice reads only frames whose labels are
consistent (homography floor <= ``CONSISTENT_PX``, not mirrored: ``calibrate_matches.label_verdict``; a
frame with a wrong click cannot say whether a camera is right); every frame is reported. Leave one match out: each match is scored with
the rule chosen on the four others; the table (same figures as calibrate_matches.py, one scoring path)
is written to ``docs/figures/calibrate_matches_lomo.json``. ``--ship``: the rule chosen on all five
is written to ``glradial/data/camera_trust.json`` with how it was chosen. The bound (``floor_px``,
``quantile``) is chosen with the rule, on the same matches (:func:`choose_bound`).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

#: The thresholds searched and their candidate values.
#: The chosen rule is the strictest (:func:`_strictness`) whose Acc@10 is within this of the best's:
#: margin against matches with other wrong fits than the ones it was chosen on.
SLACK = 0.01
#: The bound's floors tried (px at 1280; :func:`choose_bound`).
BOUND_FLOORS = (0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
GRID = {"min_support": [round(x, 3) for x in np.arange(0.30, 0.851, 0.025)], "max_missing": [0, 1, 2, 3, 99],
        "min_share": [0.0] + [round(x, 3) for x in np.arange(0.2, 0.501, 0.025)], "min_directions": [1, 2]}
#: Chosen after :data:`GRID`, the others held at that choice: the fit's own RMS (px at 1280; a wrong camera
#: fitted to the few lines of a narrow view leaves more than a right one).
RMS_GRID = {"max_rms_px": [1.1, 1.2, 1.3, 1.4, 1.5, 1.75, 2.0, 2.5]}


def replay(row: dict, t: dict) -> dict:
    """``row`` (a calibrate_matches.py row) as calibrate would have answered under the thresholds ``t``."""
    fit = _answered_fit(row, t)
    if fit is None:
        return dict(row, answered=False, rms_px=float("nan"), rms_repaired_px=float("nan"), bound_px=1280.0,
                    reason="declined")
    return dict(row, answered=True, rms_px=fit["rms_px"], rms_repaired_px=fit.get("rms_repaired_px", float("nan")),
                reason="ok",
                bound_px=t["quantile"] * max(fit["rms_fit_px"], t["floor_px"]))


def _acc10(rows: list[dict], t: dict, max_wrong: float) -> float:
    """Pooled Acc@10 of ``t`` on ``rows``; -1 where its answered frames beyond 10 px exceed ``max_wrong``."""
    got = [replay(r, t) for r in rows]
    ans = [g for g in got if g["answered"]]
    if ans and sum(g["rms_px"] > 10.0 for g in ans) / len(ans) > max_wrong:
        return -1.0
    return sum(g["answered"] and g["rms_px"] <= 10.0 for g in got) / len(got)


def _strictness(values: tuple, grid: dict = GRID) -> float:
    """How strict a rule of ``grid`` values is: the mean position of each in its grid (0 to 1; a
    "max" threshold counts from its end)."""
    pos = [grid[k].index(v) / (len(grid[k]) - 1) for k, v in zip(grid, values)]
    return float(np.mean([1 - p if k.startswith("max") else p for k, p in zip(grid, pos)]))


def choose(rows: list[dict], base: dict, max_wrong: float, slack: float = SLACK, grid: dict = GRID) -> dict:
    """The thresholds of ``grid`` (others from ``base``) chosen on ``rows`` (module docstring)."""
    scored = [(_acc10(rows, dict(base, **dict(zip(grid, v))), max_wrong), v) for v in itertools.product(*grid.values())]
    best = max(a for a, _ in scored)
    values = max((v for a, v in scored if a >= best - slack), key=lambda v: _strictness(v, grid))
    return dict(base, **dict(zip(grid, values)))


def choose_rule(rows: list[dict], base: dict, max_wrong: float) -> dict:
    """The rule and its bound chosen on ``rows``: :data:`GRID`, then :data:`RMS_GRID` with those held,
    then the bound (:func:`choose_bound`)."""
    rule = choose(rows, base, max_wrong)
    return choose_bound(rows, choose(rows, rule, max_wrong, grid=RMS_GRID))


def _commit() -> str:
    import subprocess

    return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()


def choose_bound(rows: list[dict], t: dict) -> dict:
    """``t`` with the bound's ``floor_px`` (of :data:`BOUND_FLOORS`) and ``quantile`` chosen on ``rows``:
    for each floor, the split-conformal 90 % quantile of keypoint RMS / max(fit RMS, floor) over the frames
    ``t`` answers; the floor whose bounds are the narrowest (median) wins."""
    from glradial.evaluation.trust_calibration import conformal_quantile

    fits = [f for f in (_answered_fit(r, t) for r in rows) if f is not None]
    best = None
    for floor in BOUND_FLOORS:
        q = conformal_quantile([f["rms_px"] / max(f["rms_fit_px"], floor) for f in fits])
        width = float(np.median([q * max(f["rms_fit_px"], floor) for f in fits]))
        if best is None or width < best[0]:
            best = (width, floor, q)
    return dict(t, floor_px=best[1], quantile=round(best[2], 3))


def _answered_fit(row: dict, t: dict) -> dict | None:
    from glradial.camera.calibrate import doubt_reason

    return next((f for f in row["fits"] if "support" in f and doubt_reason(f, t) == "ok"), None)


def main(argv: list[str] | None = None) -> int:
    from calibrate_matches import CONSISTENT_PX, MATCHES, add_label_verdicts, report, report_wrong, summarise

    from glradial.camera.estimate import camera_trust

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("rows", type=Path)
    parser.add_argument("--max-wrong", type=float, default=0.01, help="largest share of answered frames beyond 10 px")
    parser.add_argument("--ship", action="store_true", help="write the rule chosen on all matches to camera_trust.json")
    args = parser.parse_args(argv)
    rows = json.loads(args.rows.read_text())
    base = dict(camera_trust())
    matches = [m for m in MATCHES if any(r["match"] == m for r in rows)]
    add_label_verdicts(rows, matches)
    print("As recorded (the rule the rows were made with):")
    report(summarise([replay(r, base) for r in rows]))
    held, chosen = [], {}
    # a frame with a wrong click or mirrored labels cannot say whether a camera is right
    scored = [r for r in rows if r["floor_px"] <= CONSISTENT_PX and r.get("labels") != "mirrored"]
    keys = (*GRID, *RMS_GRID, "floor_px", "quantile")
    for m in matches:
        others = [r for r in scored if r["match"] != m]
        t = choose_rule(others, base, args.max_wrong)
        chosen[m] = {k: float(t[k]) for k in keys}
        held += [replay(r, t) for r in rows if r["match"] == m]
        print(f"held out {m}: chosen on the others {chosen[m]}", file=sys.stderr)
    print(f"\nLeave one match out (each match scored with the rule chosen on the others, wrong <= {args.max_wrong:.0%}):")
    summary = summarise(held)
    report(summary)
    report_wrong(held)
    final = choose_rule(scored, base, args.max_wrong)
    final = {k: float(final[k]) for k in keys}
    print(f"\nChosen on all {len(matches)} matches: {final}")
    from figures import write_figure

    write_figure("calibrate_matches_lomo", {"max_wrong": args.max_wrong, "chosen_without": chosen, "table": summary,
                                            "chosen_on_all": final})
    if args.ship:
        print(f"written to {_ship(final, chosen, args.max_wrong)}")
    return 0


def _ship(final: dict, chosen: dict, max_wrong: float) -> Path:
    """camera_trust.json with the rule ``final`` chosen on all matches, and notes of how (``chosen``: each
    match's rule chosen without it)."""
    from glradial.camera.estimate import ship_camera_trust

    trust = {k: int(v) if v == int(v) and k in ("max_missing", "min_directions") else v for k, v in final.items()}
    how = (f"bench/doubt_rules.py ROWS --ship, ROWS from bench/calibrate_matches.py --json on the five shared "
           f"matches (rows made with the rule then shipped; commit {_commit()})")
    trust["doubt_source"] = (f"{how}: {', '.join(GRID)} chosen on the five matches (frames with consistent labels, "
                             f"not mirrored), then {', '.join(RMS_GRID)} with those held, "
                             f"as the strictest rule within {SLACK:.0%} of the most frames within 10 px among those "
                             f"answering at most {max_wrong:.0%} beyond 10 px; nothing fitted. Each match's figures "
                             f"in docs/figures/calibrate_matches_lomo.json are of the rule chosen without it (leave one "
                             f"match out): {chosen}")
    trust["source"] = (f"quantile and floor_px: {how}: for each floor in {list(BOUND_FLOORS)} px, the split-conformal 90 % "
                       f"quantile of keypoint RMS (hand labels) / max(fit RMS, floor) over the frames the shipped rule "
                       f"answers; the floor with the narrowest median bound. min_spread, min_height_m, max_hfov_deg, "
                       f"max_log_focal_sd, min_points, min_elements, max_rms_px: as before (procedural views and "
                       f"non-pitch line drawings, tests/test_pitch_doubt.py)")
    return ship_camera_trust(trust)


if __name__ == "__main__":
    raise SystemExit(main())
