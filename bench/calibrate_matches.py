"""``glradial.calibrate`` on the five shared matches, scored against their hand-labelled keypoints
(validation only: nothing is fitted on these frames or labels).

Usage: ``python bench/calibrate_matches.py [--matches 2e57b9,video_1] [--limit N] [--json ROWS.json]
[--no-1080p] [--rows ROWS.json ...] [--figure NAME] [--shots]``

Matches (file-name prefixes): Bundesliga ``2e57b9``, ``42ba34`` (``shared/data/broadcast_bundesliga``),
``08fd33``, ``121364`` and the World Cup 2022 ``video_1`` (``shared/data/broadcast_more``). Each
640 x 640 file (a squashed 16:9 frame) is resized to 1280 x 720 (bicubic, as the labels are),
calibrated with the default first guess, and the 32 template keypoints are projected with the
estimate (lens included). Frames with fewer than 4 labelled keypoints are left out (no floor).
Per frame: the RMS distance to the labelled keypoints (px at 1280 x 720; a keypoint projected nowhere
counts 10^4 px). Per match and overall: frames, share answered (not doubtful), Acc@5 and Acc@10 (share
of all frames answered within 5 / 10 px: a declined frame is a miss), median RMS over answered
frames, answered frames beyond 10 px (count and share of the answered), bound coverage
(``uncertainty_px`` >= the keypoint RMS, answered frames), ms per frame (median, p90) and the floor:
the RMS a plain homography fitted to the frame's own labels leaves (label noise, lens, pitch size).

Timing: one thread (OpenMP/BLAS variables set before numpy loads, ``cv2.setNumThreads(1)``), a fresh
1080p frame: each file is also resized to 1920 x 1080 and calibrated again (timed; its keypoint RMS,
scaled to px at 1280, is in the rows as ``rms_1080p_px``); beside it, the peer
``cv2.GaussianBlur(1080p, sigma 1)`` (the other camera benches' peer) timed on the same frame, and the
ratio. ``--no-1080p`` skips that pass (ms then from the 1280 x 720 run).

``--json``: one row per frame with everything the doubt rule reads, for each fit the method judged
(the search's, then the strong-lens retry's): ``fits`` (:func:`glradial.camera.calibrate.doubt_features`
plus that fit's own keypoint RMS), so a doubt rule can be re-scored offline (``bench/doubt_rules.py``)
without re-running calibrate; ``--rows`` summarises such files (e.g. of processes run on parts of
the matches). Figures: ``docs/figures/calibrate_matches.json`` (bench/figures.py), written when all
five matches are in and no ``--limit``.

``--shots``: each segment (``MATCH_SEGMENT_FRAME`` names) through :class:`glradial.ShotCalibrator`
as one shot (frames in index order); two tables: each frame's own camera and the shot model's.
The doubt thresholds and the bound are chosen from the ``--json`` rows by ``bench/doubt_rules.py``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
#: Frames whose own labels leave more than this (px) under a plain homography have inconsistent labels
#: (a few clicks on the wrong marking): reported apart, left out of the calibration.
CONSISTENT_PX = 10.0
#: :func:`repair_labels` drops at most this many clicks and keeps at least this many labels (a homography
#: fits any 4 exactly: 6 leave 4 coordinates over to test it)
REPAIR_DROPS, REPAIR_KEEP = 2, 6
DATA = ROOT.parent / "shared" / "data"
#: Each match (file-name prefix) and the shared folder that holds it.
MATCHES = {"2e57b9": "broadcast_bundesliga", "42ba34": "broadcast_bundesliga", "08fd33": "broadcast_more",
           "121364": "broadcast_more", "video_1": "broadcast_more"}
#: A keypoint projected nowhere (behind the camera, beyond the lens's range) counts this far (px).
NOWHERE_PX = 1e4
#: Acc@N thresholds (px at 1280) and the "wrong" line.
WITHIN_PX, WRONG_PX = (5.0, 10.0), 10.0


def match_of(name: str) -> str:
    """The match (a key of :data:`MATCHES`) of frame ``name``."""
    for match in MATCHES:
        if name.startswith(match + "_"):
            return match
    raise ValueError(f"frame {name!r} belongs to none of the matches {sorted(MATCHES)}")


def _labels_homography(kp_m: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray | None, np.ndarray, float]:
    """``(H, labelled, floor)``: the plain homography fitted to the frame's own labels (N x 2, NaN where
    unlabelled) from the template keypoints ``kp_m`` (N x 2+ metres; ``None`` with fewer than 4 labels or
    degenerate ones), which keypoints are labelled, and the RMS (px) it leaves at them (NaN with fewer
    than 4 labels, inf for degenerate ones)."""
    import cv2

    ok = np.isfinite(labels).all(1)
    if ok.sum() < 4:
        return None, ok, float("nan")
    h, _ = cv2.findHomography(kp_m[ok, :2], labels[ok], 0)
    if h is None:  # degenerate (e.g. collinear) labels: no homography
        return None, ok, float("inf")
    p = np.column_stack([kp_m[ok, :2], np.ones(ok.sum())]) @ h.T
    with np.errstate(divide="ignore", invalid="ignore"):  # a label on the fitted horizon: infinitely far
        return h, ok, float(np.sqrt(np.mean(np.sum((p[:, :2] / p[:, 2:] - labels[ok]) ** 2, 1))))


def homography_floor(kp_m: np.ndarray, labels: np.ndarray) -> float:
    """RMS (px) a plain homography fitted to the frame's own labels (N x 2, NaN where unlabelled)
    leaves at the template keypoints ``kp_m`` (N x 2+ metres); NaN with fewer than 4 labels."""
    return _labels_homography(kp_m, labels)[2]


def label_verdict(kp_m: np.ndarray, labels: np.ndarray) -> str:
    """Whether a frame's own labels (N x 2, NaN where unlabelled) can be a camera's view of the template
    keypoints ``kp_m`` (N x 2+ metres): ``"consistent"``; ``"mirrored"`` when the homography fitted to
    them turns the pitch over (its Jacobian's determinant, ``det H / w^3``, positive at every label: near
    and far, or left and right, swapped; a camera above the pitch on either touchline sees it with a
    negative one in these coordinates, x right and y toward the far touchline, image y down: the half
    turn keeps the sign); ``"inconsistent"`` when no homography fits them within :data:`CONSISTENT_PX`
    (:func:`homography_floor`) or the one fitted folds some labels through the horizon (mixed signs);
    ``"too_few"`` under 4 labels."""
    h, ok, floor = _labels_homography(kp_m, labels)
    if ok.sum() < 4:
        return "too_few"
    if h is None:  # degenerate labels
        return "inconsistent"
    w = np.column_stack([kp_m[ok, :2], np.ones(ok.sum())]) @ h[2]
    sign = np.sign(np.linalg.det(h) * w ** 3)
    if np.all(sign > 0):
        return "mirrored"
    if np.any(sign > 0) or not floor <= CONSISTENT_PX:
        return "inconsistent"
    return "consistent"


def repair_labels(kp_m: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray | None, tuple[int, ...]]:
    """The frame's labels with its wrong clicks left out, judged by the labels alone (never by a fit):
    labels a homography fits within :data:`CONSISTENT_PX` as they are (as the raw score reads them);
    mirrored ones (:func:`label_verdict`) ``None``; the others without the fewest (at most
    :data:`REPAIR_DROPS`) labels whose removal leaves >= :data:`REPAIR_KEEP` consistent ones (of those
    removals, the one with the smallest :func:`homography_floor`), and the dropped keypoint indices;
    ``None`` where no such removal exists (the frame cannot be scored)."""
    verdict = label_verdict(kp_m, labels)
    if verdict == "mirrored":
        return None, ()
    if homography_floor(kp_m, labels) <= CONSISTENT_PX:
        return labels, ()
    labelled = np.flatnonzero(np.isfinite(labels).all(1))
    if len(labelled) - 1 < REPAIR_KEEP:
        return None, ()
    for drops in range(1, REPAIR_DROPS + 1):
        if len(labelled) - drops < REPAIR_KEEP:
            break
        candidates = []  # (floor, dropped, kept) of each removal that leaves consistent labels
        for dropped in itertools.combinations(labelled.tolist(), drops):
            kept = labels.copy()
            kept[list(dropped)] = np.nan
            if label_verdict(kp_m, kept) == "consistent":
                candidates.append((homography_floor(kp_m, kept), dropped, kept))
        if candidates:
            _, dropped, kept = min(candidates, key=lambda c: c[0])
            return kept, dropped
    return None, ()


def keypoint_rms(camera, kp_m: np.ndarray, labels: np.ndarray, scale: float = 1.0) -> float:
    """RMS (px of the labels' frame) of ``camera``'s projection of ``kp_m`` divided by ``scale`` (the
    camera's frame over the labels') against ``labels`` (NaN rows unlabelled); NaN without a camera."""
    if camera is None:
        return float("nan")
    ok = np.isfinite(labels).all(1)
    d = np.linalg.norm(camera.project(kp_m)[ok] / scale - labels[ok], axis=1)
    return float(np.sqrt(np.mean(np.where(np.isfinite(d), d, NOWHERE_PX) ** 2)))


def load_frames(matches: list[str], limit: int) -> list[tuple[str, Path, np.ndarray]]:
    """``(name, file, labels N x 2)`` of each labelled frame (>= 4 keypoints) of ``matches``, the
    first ``limit`` of each match (all for 0), sorted by name."""
    out = []
    for folder in sorted({MATCHES[m] for m in matches}):
        labels = json.loads((DATA / folder / "keypoints" / "keypoints.json").read_text())["frames"]
        for match in matches:
            if MATCHES[match] != folder:
                continue
            names = sorted(n for n in labels if match_of(n) == match)
            rows = [(n, np.array([[np.nan, np.nan] if v is None else v for v in labels[n]], float)) for n in names]
            rows = [(n, lab) for n, lab in rows if np.isfinite(lab).all(1).sum() >= 4]
            out += [(n, DATA / folder / f"{n}.jpg", lab) for n, lab in rows[: limit or None]]
    return out


class Recorder:
    """Wraps :func:`glradial.camera.calibrate.judge_fit` while installed: keeps the doubt features of every
    fit the method judges (the search's, the retry's), in order."""

    def __init__(self) -> None:
        import glradial.camera.calibrate as cal

        self.module, self.judge, self.fits = cal, cal.judge_fit, []

    def __enter__(self) -> "Recorder":
        from glradial.camera.calibrate import doubt_features

        def recording(fit, points):
            est = self.judge(fit, points)
            self.fits.append((fit, None if fit is None else doubt_features(fit), est))
            return est

        self.fits = []
        self.module.judge_fit = recording
        return self

    def __exit__(self, *exc) -> None:
        self.module.judge_fit = self.judge


def score_frame(name: str, path: Path, labels: np.ndarray, kp: np.ndarray, hd: bool) -> dict:
    """The scored row of one frame (module docstring)."""
    import cv2

    from glradial.camera.calibrate import calibrate
    from glradial.evaluation.real_eval import read_broadcast, read_rgb

    img = read_broadcast(path)
    with Recorder() as rec:
        t, cpu = time.perf_counter(), time.process_time()
        est = calibrate(img)
        seconds, cpu = time.perf_counter() - t, time.process_time() - cpu
    repaired, dropped = repair_labels(kp, labels)

    def both(camera) -> dict:  # keypoint RMS against the labels, and against the repaired labels (NaN: unscorable)
        return {"rms_px": keypoint_rms(camera, kp, labels),
                "rms_repaired_px": float("nan") if repaired is None else keypoint_rms(camera, kp, repaired)}

    fits = [dict(features or {}, reason=e.reason, **both(None if fit is None else fit.camera)) for fit, features, e in rec.fits]
    row = {"frame": name, "match": match_of(name), "answered": not est.doubtful, "reason": est.reason,
           **both(est.camera), "bound_px": est.uncertainty_px, "rms_fit_px": est.rms_px,
           "floor_px": homography_floor(kp, labels), "labels": label_verdict(kp, labels), "seconds_720p": seconds,
           "scorable": repaired is not None, "labels_dropped": list(dropped), "fits": fits}
    if hd:
        big = np.ascontiguousarray(cv2.resize(read_rgb(path), (1920, 1080), interpolation=cv2.INTER_CUBIC))
        t, cpu = time.perf_counter(), time.process_time()
        est_hd = calibrate(big)
        row["seconds"], row["cpu_seconds"] = time.perf_counter() - t, time.process_time() - cpu
        blur = []
        for _ in range(5):
            t = time.perf_counter()
            cv2.GaussianBlur(big, (0, 0), 1.0)
            blur.append(time.perf_counter() - t)
        row.update(peer_seconds=float(np.median(blur)), answered_1080p=not est_hd.doubtful,
                   rms_1080p_px=keypoint_rms(est_hd.camera, kp, labels, 1.5))
    else:
        row["seconds"], row["cpu_seconds"] = seconds, cpu
    print(f"{name}\t{est.reason}\trms={row['rms_px']:.2f}\tbound={est.uncertainty_px:.2f}\t{row['seconds']:.2f}s",
          file=sys.stderr, flush=True)
    return row


def summarise(rows: list[dict]) -> dict:
    """The per-match figures of ``rows`` (module docstring), with ``"all"`` and the consistent-label subset."""
    groups = {m: [r for r in rows if r["match"] == m] for m in MATCHES}
    groups = {k: v for k, v in groups.items() if v}
    groups["all"] = rows
    groups[f"all, labels consistent (floor <= {CONSISTENT_PX:g} px)"] = [r for r in rows if r["floor_px"] <= CONSISTENT_PX]
    return {k: _figures(v) for k, v in groups.items() if v}


def _figures(sel: list[dict]) -> dict:
    ans = [r for r in sel if r["answered"]]
    rms = np.array([r["rms_px"] for r in ans])
    wrong = int(np.sum(rms > WRONG_PX))
    # beyond 10 px on a frame whose own labels no homography fits: the labels may be what is wrong
    doubtful_labels = sum(r["rms_px"] > WRONG_PX and not r["floor_px"] <= CONSISTENT_PX for r in ans)
    # the labels' own verdict (label_verdict): what is left beyond 10 px on consistent labels is a wrong camera
    mirrored = sum(r["rms_px"] > WRONG_PX and r.get("labels") == "mirrored" for r in ans)
    real = sum(r["rms_px"] > WRONG_PX and r.get("labels") == "consistent" for r in ans)
    ms = 1000 * np.array([r["seconds"] for r in sel])
    out = {"frames": len(sel), "answered": len(ans) / len(sel),
           **{f"acc_{lim:g}px": sum(r["answered"] and r["rms_px"] <= lim for r in sel) / len(sel) for lim in WITHIN_PX},
           "median_rms_px": float(np.median(rms)) if len(rms) else float("nan"),
           "wrong_answered": wrong, "wrong_with_inconsistent_labels": doubtful_labels,
           "wrong_with_mirrored_labels": mirrored, "wrong_on_consistent_labels": real,
           "wrong_share_of_answered": wrong / len(ans) if ans else 0.0,
           "bound_covers": float(np.mean([r["bound_px"] >= r["rms_px"] for r in ans])) if ans else float("nan"),
           "ms_median": float(np.median(ms)), "ms_p90": float(np.percentile(ms, 90)),
           "floor_median_px": float(np.nanmedian([r["floor_px"] for r in sel]))}
    if all("scorable" in r for r in sel):  # scored against the repaired labels (repair_labels), scorable frames only
        ok = [r for r in sel if r["scorable"]]
        ok_ans = [r for r in ok if r["answered"]]
        wrong_repaired = sum(r["rms_repaired_px"] > WRONG_PX for r in ok_ans)
        out.update(unscorable=len(sel) - len(ok), labels_repaired=sum(bool(r["labels_dropped"]) for r in ok),
                   acc_10px_repaired=sum(r["rms_repaired_px"] <= WRONG_PX for r in ok_ans) / max(len(ok), 1),
                   wrong_answered_repaired=wrong_repaired, wrong_share_repaired=wrong_repaired / max(len(ok_ans), 1))
    if all("cpu_seconds" in r for r in sel):  # CPU time of the process: what survives a shared machine's load
        cpu = 1000 * np.array([r["cpu_seconds"] for r in sel])
        out.update(cpu_ms_median=float(np.median(cpu)), cpu_ms_p90=float(np.percentile(cpu, 90)))
    if all("peer_seconds" in r for r in sel):
        out["ratio_to_blur_median"] = float(np.median([r["seconds"] / r["peer_seconds"] for r in sel]))
    return out


def report(summary: dict) -> None:
    """Print ``summary`` (:func:`summarise`) as a markdown table."""
    print("| match | frames | answered | Acc@5 | Acc@10 | median RMS (answered) | answered > 10 px (labels: floor > 10 / "
          "mirrored / consistent) | repaired labels: Acc@10, answered > 10 px (unscorable) | bound covers | "
          "ms median / p90 (x blur) | CPU ms median / p90 | floor (median) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, f in summary.items():
        ratio = f" (x{f['ratio_to_blur_median']:.0f})" if "ratio_to_blur_median" in f else ""
        cpu = f"{f['cpu_ms_median']:.0f} / {f['cpu_ms_p90']:.0f}" if "cpu_ms_median" in f else "-"
        repaired = (f"{f['acc_10px_repaired']:.0%}, {f['wrong_answered_repaired']} = {f['wrong_share_repaired']:.0%} "
                    f"({f['unscorable']})" if "unscorable" in f else "-")
        print(f"| {name} | {f['frames']} | {f['answered']:.0%} | {f['acc_5px']:.0%} | {f['acc_10px']:.0%} | "
              f"{f['median_rms_px']:.2f} | {f['wrong_answered']} ({f['wrong_share_of_answered']:.0%}; "
              f"{f['wrong_with_inconsistent_labels']} / {f['wrong_with_mirrored_labels']} / "
              f"{f['wrong_on_consistent_labels']}) | {repaired} | "
              f"{f['bound_covers']:.0%} | {f['ms_median']:.0f} / {f['ms_p90']:.0f}{ratio} | {cpu} | {f['floor_median_px']:.2f} |")


def report_wrong(rows: list[dict]) -> None:
    """Print each answered frame beyond 10 px with its labels' homography floor and verdict
    (:func:`label_verdict`): a label error (floor > 10 px, mirrored) or a wrong camera (consistent labels)."""
    wrong = [r for r in rows if r["answered"] and r["rms_px"] > WRONG_PX]
    if not wrong:
        return
    print(f"\nAnswered beyond {WRONG_PX:g} px (keypoint RMS; the labels' own homography floor; the labels' verdict):")
    for r in wrong:
        repaired = ("" if "scorable" not in r else f"; repaired labels (without keypoints {r['labels_dropped']}): "
                    f"{r['rms_repaired_px']:.1f} px" if r["scorable"] else "; labels unscorable")
        print(f"  {r['frame']}: {r['rms_px']:.1f} px, floor {r['floor_px']:.1f} px, labels {r.get('labels', '?')}{repaired}")


def main(argv: list[str] | None = None) -> int:
    import cv2

    from glradial.pitch import PitchTemplate

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--matches", default=",".join(MATCHES), help="comma-separated match prefixes (default: all five)")
    parser.add_argument("--limit", type=int, default=0, help="first N labelled frames of each match (0: all)")
    parser.add_argument("--json", type=Path, help="write the per-frame rows here")
    parser.add_argument("--no-1080p", action="store_true", help="skip the timed 1920 x 1080 pass")
    parser.add_argument("--rows", type=Path, nargs="+", metavar="ROWS.json",
                        help="summarise the rows of earlier --json runs (e.g. one per process) instead of calibrating")
    parser.add_argument("--figure", default="calibrate_matches", help="the figure's name (docs/figures/NAME.json)")
    parser.add_argument("--shots", action="store_true",
                        help="calibrate each segment (MATCH_SEGMENT) as one shot (glradial.calibrate_shot, frames in index "
                             "order): each frame's own camera, tracked, against the shot's lens as a function of the zoom")
    args = parser.parse_args(argv)
    matches = [m.strip() for m in args.matches.split(",") if m.strip()]
    unknown = [m for m in matches if m not in MATCHES]
    if unknown or not matches:
        raise SystemExit(f"--matches: unknown {unknown or args.matches!r}; choose among {', '.join(MATCHES)}")
    cv2.setNumThreads(1)
    kp = PitchTemplate().keypoints()
    frames = load_frames(matches, args.limit)
    if args.shots:
        own, shot = _shot_rows(frames, kp)
        print("Each frame's own camera, tracked through its segment:")
        report(summarise(own))
        print("\nWith the segment's lens as a function of the zoom (glradial.calibrate_shot):")
        report(summarise(shot))
        return 0
    rows = [] if not args.rows else [r for f in args.rows for r in json.loads(f.read_text()) if r["match"] in matches]
    for i, (name, path, labels) in enumerate([] if args.rows else frames):
        print(f"[{i + 1}/{len(frames)}]", end=" ", file=sys.stderr)
        rows.append(score_frame(name, path, labels, kp, not args.no_1080p))
    add_label_verdicts(rows, matches)
    summary = summarise(rows)
    report(summary)
    report_wrong(rows)
    if args.json:
        from glradial.media.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps(rows, indent=1))
    if not args.limit and {r["match"] for r in rows} == set(MATCHES):  # the figure is of all five matches
        from figures import write_figure

        write_figure(args.figure, summary)
    return 0


def add_label_verdicts(rows: list[dict], matches: list[str]) -> None:
    """Rows of earlier runs (``--rows``) get their frame's :func:`label_verdict` where they lack one."""
    from glradial.pitch import PitchTemplate

    kp = PitchTemplate().keypoints()
    labels = {name: lab for name, _, lab in load_frames(matches, 0)}
    for r in rows:
        if "labels" not in r and r["frame"] in labels:
            r["labels"] = label_verdict(kp, labels[r["frame"]])


def _shot_rows(frames: list, kp: np.ndarray) -> tuple[list[dict], list[dict]]:
    """``--shots``: each segment (``MATCH_SEGMENT``) through :class:`glradial.ShotCalibrator`, its
    frames in index order; the rows of each frame's own estimate and of the shot model's."""
    from glradial.camera.shot_lens import ShotCalibrator
    from glradial.evaluation.real_eval import read_broadcast

    segments: dict[str, list] = {}
    for item in frames:
        segments.setdefault(item[0].rsplit("_", 1)[0], []).append(item)
    own, shot = [], []
    for segment, members in sorted(segments.items()):
        members.sort(key=lambda m: int(m[0].rsplit("_", 1)[1]))
        calibrator = ShotCalibrator()
        t = time.perf_counter()
        for _, path, _ in members:
            calibrator.add(read_broadcast(path))
        done = calibrator.finish()
        dt = (time.perf_counter() - t) / len(members)
        for (name, _, labels), mine, est in zip(members, done.frame_estimates, done.estimates):
            for out, e in ((own, mine), (shot, est)):
                out.append({"frame": name, "match": match_of(name), "answered": not e.doubtful, "reason": e.reason,
                            "rms_px": keypoint_rms(e.camera, kp, labels), "bound_px": e.uncertainty_px,
                            "rms_fit_px": e.rms_px, "floor_px": homography_floor(kp, labels), "seconds": dt})
    return own, shot


if __name__ == "__main__":
    raise SystemExit(main())
