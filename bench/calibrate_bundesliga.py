"""``glradial.calibrate`` on the shared Bundesliga frames, scored against the hand-labelled keypoints
(validation only: nothing is fitted on these frames or labels).

Usage: ``python bench/calibrate_bundesliga.py [--frames DIR] [--json OUT] [--limit N] [--shots]``

Each 640 x 640 file (a squashed 16:9 frame) is resized to 1280 x 720 (bicubic), calibrated with the
default first guess, and the 32 template keypoints are projected with the estimate (lens included).
Per frame: the RMS distance to the labelled keypoints (px at 1280 x 720). Reported per clip (the name's
prefix) and overall: share answered (not doubtful), median RMS over answered frames, share of all
frames within 5 and 10 px (a declined frame is a miss), the coverage of the stated bound
(``uncertainty_px`` >= the frame's keypoint RMS) on answered frames, and the floor: the RMS a plain
homography fitted to the frame's own labels leaves (label noise, lens, pitch size). A last row repeats
"all" without the frames whose labels are inconsistent (floor above :data:`CONSISTENT_PX`). The
pitch's half turn is resolved by the method (main camera on the near touchline), so no flipped scoring is needed.

``--shots``: the frames of one segment (``CLIP_SEGMENT_FRAME`` names) are sparse samples of the same
main camera (same lens, changing zoom), so each segment goes through :class:`glradial.ShotCalibrator`
as one shot (frames in index order; tracking from the previous sure frame, falling back to a fresh
search); two tables: each frame's own camera and the shot model's (nothing is fitted on the labels).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from figures import printed_report, write_figure

ROOT = Path(__file__).resolve().parents[1]
#: Frames whose own labels leave more than this (px) under a plain homography have inconsistent labels
#: (a few clicks on the wrong marking): reported apart, left out of the calibration.
CONSISTENT_PX = 10.0
DATA = ROOT.parent / "shared" / "data" / "broadcast_bundesliga"


def _floor(kp_m: np.ndarray, labels: np.ndarray) -> float:
    import cv2

    ok = np.isfinite(labels).all(1)
    if ok.sum() < 4:
        return float("nan")
    h, _ = cv2.findHomography(kp_m[ok, :2], labels[ok], 0)
    p = np.column_stack([kp_m[ok, :2], np.ones(ok.sum())]) @ h.T
    return float(np.sqrt(np.mean(np.sum((p[:, :2] / p[:, 2:] - labels[ok]) ** 2, 1))))


def main(argv: list[str] | None = None) -> int:

    sys.path.insert(0, str(ROOT))
    from glradial.camera.calibrate import calibrate

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=Path, default=DATA)
    parser.add_argument("--json", type=Path, help="write the per-frame rows here")
    parser.add_argument("--limit", type=int, default=0)
    parser.add_argument("--shots", action="store_true",
                        help="calibrate each segment (CLIP_SEGMENT) as one shot (glradial.calibrate_shot, frames in index "
                             "order): each frame's own camera, tracked, against the shot's lens as a function of the zoom")
    parser.add_argument("--calibrate-clip", metavar="CLIP",
                        help="calibrate the bound's quantile on this clip's answered frames (split conformal, 90 %%) "
                             "and write it to glradial/data/camera_trust.json; the other clip checks it")
    args = parser.parse_args(argv)
    labels = json.loads((args.frames / "keypoints" / "keypoints.json").read_text())
    names = sorted(labels["frames"])[: args.limit or None]
    if args.shots:
        own, shot = _shot_rows(args.frames, labels, names)
        with printed_report() as lines:
            print("Each frame's own camera, tracked through its segment:")
            _report(own)
            print("\nWith the segment's lens as a function of the zoom (glradial.calibrate_shot):")
            _report(shot)
        write_figure("calibrate_bundesliga_shots", {"report": lines})
        return 0
    rows = []
    for name in names:
        img = _image(args.frames, name)
        t = time.perf_counter()
        est = calibrate(img)
        rows.append(_row(name, est, labels, time.perf_counter() - t))
    with printed_report() as lines:
        _report(rows)
    write_figure("calibrate_bundesliga", {"report": lines})
    if args.calibrate_clip:
        _calibrate(rows, args.calibrate_clip)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


def _image(folder: Path, name: str) -> np.ndarray:
    """The frame ``name`` resized to 1280 x 720 (bicubic), RGB."""
    from glradial.evaluation.real_eval import read_broadcast

    return read_broadcast(folder / f"{name}.jpg")


def _row(name: str, est, labels: dict, seconds: float) -> dict:
    """The scored row of frame ``name``'s estimate against its labels (module docstring)."""
    from glradial.pitch import PitchTemplate

    kp = PitchTemplate().keypoints()
    lab = np.array([[np.nan, np.nan] if v is None else v for v in labels["frames"][name]], float)
    ok = np.isfinite(lab).all(1)
    rms = float("nan")
    if est.camera is not None:
        d = np.linalg.norm(est.project(kp)[ok] - lab[ok], axis=1)
        rms = float(np.sqrt(np.mean(np.where(np.isfinite(d), d, 1e4) ** 2)))
    print(f"{name}\t{est.reason}\trms={rms:.2f}\tbound={est.uncertainty_px:.2f}\t{seconds:.2f}s", file=sys.stderr, flush=True)
    return {"frame": name, "clip": name.split("_")[0], "answered": not est.doubtful, "reason": est.reason,
            "rms_px": rms, "bound_px": est.uncertainty_px, "rms_fit_px": est.rms_px, "floor_px": _floor(kp, lab), "seconds": seconds}


def _shot_rows(folder: Path, labels: dict, names: list[str]) -> tuple[list[dict], list[dict]]:
    """``--shots``: each segment (``CLIP_SEGMENT``) through :class:`glradial.ShotCalibrator`, its
    frames in index order; the rows of each frame's own estimate and of the shot model's."""
    from glradial.camera.shot_lens import ShotCalibrator

    segments: dict[str, list[str]] = {}
    for name in names:
        segments.setdefault(name.rsplit("_", 1)[0], []).append(name)
    own, shot = [], []
    for segment, members in sorted(segments.items()):
        members.sort(key=lambda n: int(n.rsplit("_", 1)[1]))
        calibrator = ShotCalibrator()
        t = time.perf_counter()
        for name in members:
            calibrator.add(_image(folder, name))
        done = calibrator.finish()
        dt = (time.perf_counter() - t) / len(members)
        model = done.lens_model
        print(f"{segment}: {len(members)} frames, shot model "
              f"{'none' if model is None else f'degree {model.degree} from {model.frames} frames'}", file=sys.stderr)
        for name, mine, est in zip(members, done.frame_estimates, done.estimates):
            own.append(_row(name, mine, labels, dt))
            shot.append(_row(name, est, labels, dt))
    return own, shot


def _calibrate(rows: list[dict], clip: str) -> None:
    """Split-conformal quantile of keypoint RMS / max(fit RMS, floor) over ``clip``'s answered frames."""

    from glradial.camera.estimate import CAMERA_TRUST_FILE, camera_trust
    from glradial.evaluation.trust_calibration import conformal_quantile
    from glradial.media.atomic import atomic_write_text

    trust = dict(camera_trust())
    floor = trust["floor_px"]
    scores = np.sort([r["rms_px"] / max(r["rms_fit_px"], floor) for r in rows
                      if r["clip"] == clip and r["answered"] and r["floor_px"] <= CONSISTENT_PX])
    n = len(scores)
    if n == 0:
        raise SystemExit(f"no answered frame in clip {clip!r}")
    q = conformal_quantile(scores)
    trust.update({"quantile": round(q, 3), "source": f"bench/calibrate_bundesliga.py --calibrate-clip {clip}: split-conformal "
                  f"90 % of keypoint RMS (hand labels) / fit RMS over its {n} answered frames with consistent labels "
                  f"(homography floor <= {CONSISTENT_PX} px)"})
    atomic_write_text(CAMERA_TRUST_FILE, json.dumps(trust, indent=2) + "\n")
    print(f"quantile {q:.3f} (clip {clip}, {n} answered frames) written to {CAMERA_TRUST_FILE}")


def _report(rows: list[dict]) -> None:
    print("| clip | frames | answered | median RMS (answered) | within 5 px | within 10 px | bound covers | "
          "homography floor (median) | s/frame |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    groups = [(c, [r for r in rows if c in ("all", r["clip"])]) for c in sorted({r["clip"] for r in rows}) + ["all"]]
    groups.append((f"all, labels consistent (floor <= {CONSISTENT_PX:g} px)", [r for r in rows if r["floor_px"] <= CONSISTENT_PX]))
    for clip, sel in groups:
        ans = [r for r in sel if r["answered"]]
        rms = np.array([r["rms_px"] for r in ans])
        good = lambda lim: sum(r["answered"] and r["rms_px"] <= lim for r in sel) / len(sel)  # noqa: E731
        cover = np.mean([r["bound_px"] >= r["rms_px"] for r in ans]) if ans else float("nan")
        print(f"| {clip} | {len(sel)} | {len(ans) / len(sel):.0%} | {np.median(rms) if len(rms) else float('nan'):.2f} | "
              f"{good(5):.0%} | {good(10):.0%} | {cover:.0%} | {np.nanmedian([r['floor_px'] for r in sel]):.2f} | "
              f"{np.mean([r['seconds'] for r in sel]):.2f} |")


if __name__ == "__main__":
    raise SystemExit(main())
