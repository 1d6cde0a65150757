"""Per-shot lens versus per-frame lens on procedural zoom shots with exact cameras (issue 34, item 4).

Usage: ``python bench/camera_zoom.py [--shots N] [--frames F] [--size WxH] [--noise SIGMA] [--zoom Z]
[--seed S] [--json OUT]``

Each shot: :func:`glradial.camera.views.zoom_cameras` (a main camera zooming in by ``Z`` times on a
penalty box or the centre circle, its lens following the zoom from barrel, k1 -0.30..-0.15, toward
pincushion, k1 -0.02..0.06, linearly in the field of view; k2 on the manifold), rendered by
:func:`glradial.camera.views.render_view` (one stadium texture per shot) with independent Gaussian
noise of ``SIGMA`` grey levels per frame, and calibrated by :class:`glradial.ShotCalibrator` (what
:func:`glradial.calibrate_shot` runs).

Reported over all frames of all shots, for the frames' own estimates ("frame": tracked frame to
frame as ``glradial calibrate VIDEO`` did before the shot model) and the shot model's ("shot"): share
answered (not doubtful), and over answered frames the median and 90th percentile of the lens error
(max displacement at 1920 wide, :func:`glradial.lens.metrics.max_displacement_px`), the share with a
lens error above 2 px, the median focal-length error, the median keypoint reprojection RMS (px of the
rendered frame) and the share of frames whose lens came from the shot model. Seeds ``S, S+1, ...``
(default 20000: not used elsewhere).
"""

from __future__ import annotations

import argparse
import json
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
sys.path.insert(0, str(ROOT / "bench"))


def run_shot(seed: int, frames: int, size: tuple[int, int], noise: float, zoom: float) -> list[dict]:
    """One zoom shot: per frame, the errors of the frame's own estimate and of the shot model's."""
    from camera_procedural import _errors

    from glradial.camera.shot_lens import ShotCalibrator
    from glradial.camera.views import render_view, zoom_cameras
    from glradial.pitch import PitchTemplate

    pitch = PitchTemplate()
    cams = zoom_cameras(np.random.default_rng(seed), frames, size, zoom)
    rng = np.random.default_rng(seed + 1)

    views = []
    for cam in cams:
        frame = render_view(cam, seed).frame.astype(np.float64)
        views.append(np.clip(frame + rng.normal(0.0, noise, frame.shape), 0, 255).astype(np.uint8))
    calibrator = ShotCalibrator(pitch)
    t = time.perf_counter()
    for frame in views:
        calibrator.add(frame)
    tracked = time.perf_counter()
    shot = calibrator.finish()
    per_frame, refit = (tracked - t) / frames, (time.perf_counter() - tracked) / frames
    rows = []
    for i, (cam, own, est, from_shot) in enumerate(zip(cams, shot.frame_estimates, shot.estimates, shot.from_shot)):
        rows.append({"seed": seed, "frame": i, "from_shot": from_shot, "seconds": per_frame, "refit_seconds": refit,
                     "degree": None if shot.lens_model is None else shot.lens_model.degree,
                     "frame_est": _errors(own, cam, pitch), "shot_est": _errors(est, cam, pitch)})
    return rows


def summary(rows: list[dict], key: str) -> dict:
    """The figures of the module docstring for ``key`` ("frame_est" or "shot_est")."""
    answered = [r[key] for r in rows if r[key]["answered"]]
    lens = np.array([a["lens_err_px_1920"] for a in answered])
    out = {"frames": len(rows), "answered": len(answered) / max(len(rows), 1)}
    if answered:
        out.update({"lens_median_px": float(np.median(lens)), "lens_p90_px": float(np.percentile(lens, 90)),
                    "lens_over_2px": float(np.mean(lens > 2.0)),
                    "focal_median_pct": 100 * float(np.median([abs(a["focal_rel_err"]) for a in answered])),
                    "kp_median_px": float(np.median([a["kp_rms_px"] for a in answered if a.get("kp_rms_px") is not None]))})
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--shots", type=int, default=6)
    parser.add_argument("--frames", type=int, default=16)
    parser.add_argument("--size", default="1280x720")
    parser.add_argument("--noise", type=float, default=8.0, help="Gaussian noise per frame (grey levels)")
    parser.add_argument("--zoom", type=float, default=1.8, help="focal length ratio, tele over wide")
    parser.add_argument("--seed", type=int, default=20000)
    parser.add_argument("--json", type=Path, help="write the per-frame rows here")
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    rows = []
    for s in range(args.shots):
        shot_rows = run_shot(args.seed + 10 * s, args.frames, size, args.noise, args.zoom)
        rows += shot_rows
        print(f"shot {s}: seed {args.seed + 10 * s}, model degree {shot_rows[0]['degree']}, "
              f"{summary(shot_rows, 'frame_est')} -> {summary(shot_rows, 'shot_est')}", file=sys.stderr, flush=True)
    print(f"{args.shots} shots x {args.frames} frames at {size[0]}x{size[1]}, noise {args.noise}, zoom {args.zoom}x, "
          f"tracked {np.median([r['seconds'] for r in rows]):.3f} s/frame, shot model and refit "
          f"{np.median([r['refit_seconds'] for r in rows]):.3f} s/frame (one thread, medians over shots)")
    print("| lens | answered | lens error median / p90 (px at 1920) | lens > 2 px | focal error median | keypoint RMS median | lens from the shot model |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, key in (("per frame", "frame_est"), ("per shot (zoom model)", "shot_est")):
        s = summary(rows, key)
        from_shot = np.mean([r["from_shot"] for r in rows]) if key == "shot_est" else 0.0
        print(f"| {name} | {s['answered']:.0%} | {s.get('lens_median_px', float('nan')):.2f} / {s.get('lens_p90_px', float('nan')):.2f} | "
              f"{s.get('lens_over_2px', float('nan')):.0%} | {s.get('focal_median_pct', float('nan')):.3f} % | "
              f"{s.get('kp_median_px', float('nan')):.2f} px | {from_shot:.0%} |")
    write_figure("camera_zoom", {name: summary(rows, key) for name, key in (("per frame", "frame_est"), ("per shot", "shot_est"))})
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
