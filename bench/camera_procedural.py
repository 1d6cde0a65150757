"""``glradial.calibrate`` on procedural pitch views with exact cameras (held-out seeds), and the
split-conformal calibration of its bound.

Usage: ``python bench/camera_procedural.py [--views N] [--seed S] [--calibrate] [--timing N] [--json OUT]``

Views: :func:`glradial.camera.views.random_camera` (main-camera poses, 16-64 degree fields of view,
lenses on the Lopez-Antequera manifold, k1 in [-0.35, 0.05]) rendered by
:func:`glradial.camera.views.render_view` at 1280 x 720 (grass with mowing stripes and grain, players,
a stand band, the lens applied with exact maps). Test views use seeds ``S, S+1, ...`` (default 10000);
``--calibrate`` uses seeds 0.. instead and writes the procedural quantile (``procedural_quantile``) to
``glradial/data/camera_trust.json``; the shipped bound uses ``quantile``, calibrated on the real matches
(``bench/doubt_rules.py --ship``), the larger.

Per view: the keypoint reprojection RMS (the template's 32 keypoints that fall in the frame, px at
1280 x 720), the marking error (RMS over the template sampled every metre, in-frame; what the bound
states), the focal length's relative error, the lens's max-displacement error at 1920 wide
(:func:`glradial.lens.metrics.max_displacement_px`). Reported: share answered (not doubtful), and over
answered views the medians and the share of confident wrong answers (keypoint RMS above 10 px); the
bound's coverage. ``--timing N``: N views rendered at 1920 x 1080, ``calibrate`` timed on one thread
(cv2 and BLAS), beside ``cv2.GaussianBlur`` (sigma 1) of the same frame in the same process (the ratio).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import numpy as np  # noqa: E402
from figures import write_figure  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _errors(est, cam, pitch) -> dict:
    from glradial.lens.metrics import max_displacement_px

    width, height = cam.size
    row = {"k_true": [cam.lens.k1, cam.lens.k2], "hfov_true": cam.hfov_deg, "answered": not est.doubtful,
           "reason": est.reason, "bound_px": est.uncertainty_px, "rms_fit_px": est.rms_px, "support": est.support,
           "elements": len(est.markings), "inliers": est.inliers, "focal_sd": est.focal_sd}
    if est.camera is None:
        return row
    inside = lambda p: np.isfinite(p).all(1) & (p[:, 0] >= 0) & (p[:, 0] <= width - 1) & (p[:, 1] >= 0) & (p[:, 1] <= height - 1)  # noqa: E731
    kp = pitch.keypoints()
    t = cam.project(kp)
    use = inside(t)
    e = np.linalg.norm(est.project(kp)[use] - t[use], axis=1)
    row["kp_rms_px"] = float(np.sqrt(np.mean(np.where(np.isfinite(e), e, 1e4) ** 2))) if use.any() else None
    dense = np.concatenate([p for _, p in pitch.polylines(1.0)])
    t = cam.project(dense)
    use = inside(t)
    e = np.linalg.norm(est.project(dense)[use] - t[use], axis=1)
    row["marking_rms_px"] = float(np.sqrt(np.mean(np.where(np.isfinite(e), e, 1e4) ** 2))) if use.any() else None
    row["focal_rel_err"] = est.focal / cam.focal - 1.0
    row["lens_err_px_1920"] = float(max_displacement_px(np.array([cam.lens.k1, cam.lens.k2]), np.array([est.lens.k1, est.lens.k2])))
    return row


def run_views(n: int, seed: int, size=(1280, 720)) -> list[dict]:
    from glradial.camera.calibrate import calibrate
    from glradial.camera.views import random_camera, render_view
    from glradial.pitch import PitchTemplate

    pitch = PitchTemplate()
    rows = []
    for i in range(n):
        cam = random_camera(np.random.default_rng(seed + i), size)
        view = render_view(cam, seed + i)
        t = time.perf_counter()
        est = calibrate(view.frame)
        row = {"seed": seed + i, "seconds": time.perf_counter() - t, **_errors(est, cam, pitch)}
        rows.append(row)
        print(json.dumps(row), file=sys.stderr, flush=True)
    return rows


def report(rows: list[dict]) -> dict:
    ans = [r for r in rows if r["answered"]]
    get = lambda key: np.array([r[key] for r in ans if r.get(key) is not None], float)  # noqa: E731
    kp = get("kp_rms_px")
    wrong = float(np.mean(kp > 10.0)) if len(kp) else math.nan
    marking = get("marking_rms_px")
    bounds = np.array([r["bound_px"] for r in ans if r.get("marking_rms_px") is not None])
    out = {"views": len(rows), "answered": len(ans) / max(len(rows), 1),
           "median_kp_rms_px": float(np.median(kp)) if len(kp) else math.nan,
           "median_abs_focal_err": float(np.median(np.abs(get("focal_rel_err")))) if len(ans) else math.nan,
           "median_lens_err_px_1920": float(np.median(get("lens_err_px_1920"))) if len(ans) else math.nan,
           "confident_wrong_share": wrong,
           "bound_covers": float(np.mean(bounds >= marking)) if len(marking) else math.nan,
           "median_seconds_1280": float(np.median([r["seconds"] for r in rows]))}
    for k, v in out.items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
    return out


def calibrate_bound(rows: list[dict]) -> float:
    """Split-conformal quantile of marking error / max(fit RMS, floor) over answered views."""
    from glradial.camera.estimate import camera_trust
    from glradial.evaluation.trust_calibration import conformal_quantile

    floor = camera_trust()["floor_px"]
    return conformal_quantile([r["marking_rms_px"] / max(r["rms_fit_px"], floor) for r in rows
                               if r["answered"] and r.get("marking_rms_px") is not None])


def timing(n: int) -> None:
    import cv2

    from glradial.camera.calibrate import calibrate
    from glradial.camera.views import random_camera, render_view

    cv2.setNumThreads(1)
    for i in range(n):
        frame = render_view(random_camera(np.random.default_rng(20000 + i), (1920, 1080)), 20000 + i).frame
        calibrate(frame)  # caches (the view dictionary of this frame shape) out of the timing
        t = []
        for _ in range(3):
            s = time.perf_counter()
            est = calibrate(frame)
            t.append(time.perf_counter() - s)
        b = []
        for _ in range(20):
            s = time.perf_counter()
            cv2.GaussianBlur(frame, (0, 0), 1.0)
            b.append(time.perf_counter() - s)
        tracked = []
        for _ in range(3):
            s = time.perf_counter()
            calibrate(frame, previous=est) if est.camera is not None else None
            tracked.append(time.perf_counter() - s)
        print(f"1080p view {i}: calibrate {1000 * np.median(t):.0f} ms, tracking from the previous camera "
              f"{1000 * np.median(tracked):.0f} ms; peer cv2.GaussianBlur(1080p, sigma 1) {1000 * np.median(b):.2f} ms "
              f"-> ratios {np.median(t) / np.median(b):.0f} / {np.median(tracked) / np.median(b):.0f} ({est.reason})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--views", type=int, default=100)
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--calibrate", action="store_true", help="calibration seeds (0..); write the bound's quantile")
    parser.add_argument("--timing", type=int, default=0, metavar="N")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.views:
        seed = args.seed if args.seed is not None else (0 if args.calibrate else 10000)
        rows = run_views(args.views, seed)
        summary = report(rows)
        write_figure("camera_procedural", {"views": args.views, "seed": seed, **summary})
        if args.calibrate:
            from glradial.camera.estimate import CAMERA_TRUST_FILE
            from glradial.media.atomic import atomic_write_text

            q = calibrate_bound(rows)
            trust = json.loads(CAMERA_TRUST_FILE.read_text())
            trust.update({"procedural_quantile": round(q, 3), "procedural_source": f"bench/camera_procedural.py --calibrate "
                          f"--views {args.views} (seeds {seed}..{seed + args.views - 1}): split-conformal 90 % of marking RMS / fit RMS"})
            atomic_write_text(CAMERA_TRUST_FILE, json.dumps(trust, indent=2) + "\n")
            print(f"procedural quantile {q:.3f} written to {CAMERA_TRUST_FILE}")
        if args.json:
            args.json.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    if args.timing:
        timing(args.timing)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
