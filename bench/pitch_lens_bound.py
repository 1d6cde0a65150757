"""Split-conformal calibration of the lens bound that ``glradial.estimate(method="auto")`` states when
it answers from the pitch camera fit (:func:`glradial.camera.estimator.lens_bound_px`).

Usage: ``python bench/pitch_lens_bound.py --procedural CAL.json [--test TEST.json] [--bundesliga DUMP.jsonl]
[--calibrate-clip 2e57b9] [--write]``

The bound is ``q * max(rms, floor)``: ``rms`` the camera fit's marking RMS (px at 1280,
``CameraEstimate.rms_px``), ``floor`` ``lens_floor_px`` (0.3 px, as the camera's own bound), ``q`` the
90 % split-conformal quantile (the ``ceil(0.9 (n + 1))``-th smallest) of ``error / max(rms, floor)``, the
error being the lens's max displacement at 1920 wide (:func:`glradial.lens.metrics.max_displacement_px`).

Two calibration sets, the larger quantile shipped (as for the camera's bound, docs/CAMERA.md):

* ``--procedural``: the answered rows of ``bench/camera_procedural.py --views 80 --seed 0 --json CAL.json``
  (views with exact lenses; error against the renderer's lens); ``--test``: the same for held-out seeds
  (``--seed 10000 --views 100``), coverage printed.
* ``--bundesliga``: ``bench/bundesliga_consistency.py --dump DUMP.jsonl`` rows of ``pitch alone`` (the camera
  fit's lens alone; ``auto+pitch`` in dumps made before the combination) answered from the pitch (real
  frames, a known lens applied; the error is the self-consistent one, which also carries
  the error of the reading of the unmodified frame); quantile on ``--calibrate-clip``, coverage printed on
  the other clip (held out). Validation data: calibrated on one clip, checked on the other.

``--write`` stores ``lens_quantile``, ``lens_floor_px`` and ``lens_source`` in ``glradial/data/camera_trust.json``.
The shipped ``lens_quantile`` now comes from ``bench/pitch_lens_choice.py`` (chosen with the weight across
the five matches, leave one match out); this bench remains the procedural check.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from figures import printed_report, write_figure  # noqa: E402

from glradial.evaluation.trust_calibration import conformal_quantile  # noqa: E402

FLOOR_PX = 0.3


def procedural(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """``(errors px at 1920, fit RMS px at 1280)`` of the answered views of a camera_procedural JSON."""
    rows = [r for r in json.loads(path.read_text())["rows"] if r["answered"] and r.get("lens_err_px_1920") is not None]
    return np.array([r["lens_err_px_1920"] for r in rows]), np.array([r["rms_fit_px"] for r in rows])


def bundesliga(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per clip, ``(self-consistent errors, camera fit RMS)`` of the samples answered from the pitch."""
    out: dict = {}
    rows = [json.loads(line) for line in path.read_text().splitlines()]
    method = "pitch alone" if any(r["method"] == "pitch alone" for r in rows) else "auto+pitch"
    for r in rows:
        if r["truth"] is not None and r["method"] == method and r["source"] == "pitch":
            out.setdefault(r["clip"], []).append((r["error_px"], r["camera_rms_px"]))
    return {clip: (np.array(v)[:, 0], np.array(v)[:, 1]) for clip, v in out.items()}


def _covers(name: str, errors: np.ndarray, rms: np.ndarray, q: float) -> None:
    bound = q * np.maximum(rms, FLOOR_PX)
    print(f"  {name}: {len(errors)} answered, error median {np.median(errors):.2f} px, p90 {np.percentile(errors, 90):.2f}; "
          f"bound median {np.median(bound):.2f} px, covers {np.mean(errors <= bound):.1%}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--procedural", type=Path, required=True)
    parser.add_argument("--test", type=Path)
    parser.add_argument("--bundesliga", type=Path)
    parser.add_argument("--calibrate-clip", default="2e57b9")
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args(argv)
    errors, rms = procedural(args.procedural)
    q_proc = conformal_quantile(errors / np.maximum(rms, FLOOR_PX))
    print(f"procedural quantile {q_proc:.3f} ({len(errors)} answered calibration views)")
    sets = {"procedural calibration": (errors, rms)}
    if args.test:
        sets["procedural held out"] = procedural(args.test)
    q_real = None
    if args.bundesliga:
        clips = bundesliga(args.bundesliga)
        e, r = clips[args.calibrate_clip]
        q_real = conformal_quantile(e / np.maximum(r, FLOOR_PX))
        print(f"Bundesliga quantile {q_real:.3f} (clip {args.calibrate_clip}, {len(e)} samples answered from the pitch)")
        sets.update({f"Bundesliga {clip}" + (" (calibration)" if clip == args.calibrate_clip else " (held out)"): v
                     for clip, v in sorted(clips.items())})
    q = max(q_proc, q_real or 0.0)
    with printed_report() as lines:
        for name, label in ((q_proc, "procedural"), (q_real, "Bundesliga"), (q, "shipped (the larger)")):
            if name is not None:
                print(f"coverage with the {label} quantile {name:.3f}:")
                for set_name, (e, r) in sets.items():
                    _covers(set_name, e, r, name)
    write_figure("pitch_lens_bound", {"procedural_quantile": q_proc, "bundesliga_quantile": q_real, "shipped_quantile": q,
                                      "report": lines})
    if args.write:
        from glradial.camera.estimate import CAMERA_TRUST_FILE
        from glradial.media.atomic import atomic_write_text

        source = (f"bench/pitch_lens_bound.py: split-conformal 90 % of lens max-displacement error (px at 1920) / "
                  f"max(fit RMS, {FLOOR_PX}); procedural {q_proc:.3f} ({args.procedural.name}, {len(errors)} answered views)")
        if q_real is not None:
            source += f"; Bundesliga clip {args.calibrate_clip} self-consistent {q_real:.3f} (other clip held out)"
        trust = json.loads(CAMERA_TRUST_FILE.read_text(encoding="utf-8"))
        trust.update({"lens_quantile": round(q, 3), "lens_floor_px": FLOOR_PX, "lens_source": source + "; shipped: the larger"})
        atomic_write_text(CAMERA_TRUST_FILE, json.dumps(trust, indent=2) + "\n")
        print(f"lens_quantile {q:.3f} written to {CAMERA_TRUST_FILE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
