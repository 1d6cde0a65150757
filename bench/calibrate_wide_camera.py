"""``glradial.calibrate`` and ``glradial.estimate`` on the shared real wide camera (validation only).

Usage: ``python bench/calibrate_wide_camera.py [--frames N] [--json OUT]``

Frames: the ``wide_camera`` source of ``bench/pitch_views.py`` (N = 30 frames spread over
``../shared/data/real_wide_camera/wide_pitch_camera.mp4``, reduced to 1536 x 864). Truth: the
checkerboard lens (k1 -0.6615, k2 +0.4098, centred; the camera's real principal point is off centre,
so a centred model keeps a misfit of a few px). Per frame: the camera's verdict, its lens's error
(max displacement at 1920 wide, :func:`glradial.lens.metrics.max_displacement_px`) against the
checkerboard lens and the camera lens's own bound (:func:`glradial.camera.estimator.lens_bound_px`, with the
lens's :func:`~glradial.camera.estimator.centre_shift_px`; inf, none known, beyond ``lens_max_hfov_deg``:
``camera_bound_known`` counts the sure frames with one),
the focal length and field of view (a static camera: they should agree across frames), and what
``glradial.estimate(frame)`` (the default ``method="auto"``) reads: its error, bound and verdict.
Nothing is fitted here.

``--twin``: procedural twins of this camera (a diagnostic of what the centred lens model costs): the
pitch rendered by :func:`glradial.camera.views.render_view` through the pose frame 0's fit reads
(rotation; position (-1.0, -48.8, 7.5) m and field of view 72.4 degrees, what most frames agree on),
the checkerboard lens applied about the centre or about a principal point moved by ``(cx, cy)``
widths (the pinhole image translated, then distorted about the moved point), three textures each.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from figures import write_figure

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))


def _row(name: str, frame: np.ndarray, truth: tuple) -> dict:
    import glradial
    from glradial.camera.estimator import centre_shift_px, lens_bound_px
    from glradial.lens.metrics import max_displacement_px

    k_true = np.array(truth, float)
    cam = glradial.calibrate(frame)
    row = {"frame": name, "reason": cam.reason, "sure": not cam.doubtful, "rms_px": cam.rms_px if cam.camera else None,
           "support": cam.support, "markings": list(cam.markings)}
    if cam.camera is not None:
        err = float(max_displacement_px(np.array([cam.lens.k1, cam.lens.k2]), k_true))
        shift = centre_shift_px(frame, cam)
        row.update(k1=cam.lens.k1, k2=cam.lens.k2, lens_err_px=err, lens_bound_px=lens_bound_px(cam, shift), centre_shift_px=shift,
                   focal=cam.focal, hfov_deg=cam.hfov_deg, position_m=cam.position.tolist())
    est = glradial.estimate(frame)
    row.update(est_method=est.method, est_err_px=float(max_displacement_px(np.array([est.k1, est.k2]), k_true)),
               est_bound_px=est.uncertainty_px, est_doubtful=est.doubtful, est_reason=est.reason)
    return row


#: Principal-point offsets (widths) of the twins: centred, the plumb-line centre of frame 0
#: (scripts/plumb_lines.py, free centre), a smaller vertical one, a horizontal one.
TWIN_OFFSETS = ((0.0, 0.0), (0.016, -0.082), (0.0, -0.06), (0.03, 0.0))


def twins(frame0: np.ndarray, truth: tuple) -> list[dict]:
    """The ``--twin`` rows (module docstring)."""
    import cv2

    import glradial
    from glradial.camera.model import Camera
    from glradial.camera.views import render_view
    from glradial.lens.lens import focal_from_hfov
    from glradial.lens.metrics import max_displacement_px

    height, width = frame0.shape[:2]
    size = (width, height)
    rotation = glradial.calibrate(frame0).camera.rotation
    scale = glradial.Lens(*truth).fit_scale(size, "crop", "distort")
    focal = focal_from_hfov(72.4)
    rows = []
    for seed in (1, 2, 3):
        canvas = Camera(rotation, np.array([-1.0, -48.8, 7.5]), focal / scale, size)
        pinhole = render_view(canvas, seed=seed).frame
        for cx, cy in TWIN_OFFSETS:
            img = cv2.warpAffine(pinhole, np.float32([[1, 0, cx * width], [0, 1, cy * width]]), size,
                                 borderMode=cv2.BORDER_REPLICATE)
            mx, my = glradial.Lens(*truth, cx, cy).maps(size, direction="distort", scale=scale)
            cam = glradial.calibrate(cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
            row = {"seed": seed, "centre": [cx, cy], "reason": cam.reason, "support": cam.support, "rms_px": cam.rms_px}
            if cam.camera is not None:
                row.update(lens_err_px=float(max_displacement_px(np.array([cam.lens.k1, cam.lens.k2]), np.array(truth))),
                           hfov_deg=cam.hfov_deg)
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def report(rows: list[dict]) -> dict:
    sure = [r for r in rows if r["sure"]]
    out = {"frames": len(rows), "sure": len(sure), "reasons": {}}
    for r in rows:
        out["reasons"][r["reason"]] = out["reasons"].get(r["reason"], 0) + 1
    if sure:
        err = np.array([r["lens_err_px"] for r in sure])
        hfov = np.array([r["hfov_deg"] for r in sure])
        known = [r["lens_bound_px"] for r in sure if np.isfinite(r["lens_bound_px"])]  # inf: no bound known there
        out.update(camera_lens_err_median_px=float(np.median(err)), camera_lens_err_max_px=float(err.max()),
                   camera_bound_known=len(known),
                   camera_bound_covers=float(np.mean([r["lens_err_px"] <= r["lens_bound_px"] for r in sure])),
                   camera_bound_median_px=float(np.median(known)) if known else None,
                   hfov_median_deg=float(np.median(hfov)), hfov_sd_deg=float(hfov.std()),
                   focal_rel_sd=float(np.std([r["focal"] for r in sure]) / np.mean([r["focal"] for r in sure])))
    est = np.array([r["est_err_px"] for r in rows])
    out.update(estimate_err_median_px=float(np.median(est)), estimate_err_p90_px=float(np.percentile(est, 90)),
               estimate_doubtful=float(np.mean([r["est_doubtful"] for r in rows])),
               estimate_bound_covers=float(np.mean([r["est_err_px"] <= r["est_bound_px"] for r in rows])),
               estimate_bound_median_px=float(np.median([r["est_bound_px"] for r in rows])),
               estimate_from_pitch=int(sum(r["est_method"] == "pitch" for r in rows)))
    return out


def main(argv: list[str] | None = None) -> int:
    from pitch_views import _wide_camera

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--json", type=Path, help="write every frame's row here")
    parser.add_argument("--twin", action="store_true", help="procedural twins of the camera instead (module docstring)")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    args = parser.parse_args(argv)
    frames = _wide_camera(args.data, args.frames)
    if args.twin:
        twins(frames[0][1], frames[0][2])
        return 0
    rows = []
    for name, frame, truth in frames:
        rows.append(_row(name, frame, truth))
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    summary = report(rows)
    print(json.dumps(summary, indent=1))
    write_figure("calibrate_wide_camera", summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
