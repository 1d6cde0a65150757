"""Calibrate the misfit term of the line fit's bound on rendered views through off-centre lenses.

Usage::

    python bench/misfit_calibration.py [--data ../shared/data] [--frames /tmp/misfit_frames.pkl]
        [--evidence /tmp/misfit_evidence.pkl] [--out trust_misfit.json | --write]

The estimator's lens model is radial about the frame centre; a camera whose principal point sits off
centre (the shared wide camera's, by ~6.5 % of the width) leaves the line fit reading a centred lens
that differs from the one a checkerboard calibration reports by more than the fit's own uncertainty.
The fit measures how far its lens moves when decentring terms are fitted with it
(``centre_shift_px``, :mod:`glradial.estimation.decentring`); the stated bound is the base bound of
whichever answer is taken in quadrature with ``misfit_weight · centre_shift_px``
(:meth:`glradial.estimation.trust.TrustModel.misfit_bound`).

Views (:func:`pitch_views.offcentre_views`: lenses k1 -0.8..-0.1 with the principal point 4-8 % of
the width off centre, scored against the centred lens of a simulated checkerboard calibration,
:func:`pitch_views.centred_fit`; high cameras, hfov 55-90 deg):

* ``calibration``: 10 views each of 8 validation-split procedural stadiums (seeds from
  :data:`CALIBRATION_START`), the only views ``misfit_weight`` is fitted on;
* ``held_out``: 10 views each of the next 8 validation-split stadiums;
* ``real_panorama_held_out``: 24 off-centre views of the real stadium panorama
  (``real_football/stadium_01_1k_tonemapped.jpg``, pitch-level camera, tilt -10..+8 deg); validation only.

None of these stadiums is used by the trust records (``glradial.evaluation.trust_calibration``) or by
``bench/pitch_views.py`` (whose ``offcentre`` source, six further stadiums, and the real wide camera
are a third and fourth check, not seen here).

Calibration (split conformal, :func:`glradial.evaluation.trust_calibration.conformal_quantile` at 90 %): over
the calibration views with a line fit (where the term can apply), each view's score is the weight
its bound (with the term off) needs to cover its error, ``sqrt(error² - bound²) / centre_shift_px`` (0 when
already covered; infinite where the shift is not measured); ``misfit_weight`` is the conformal
quantile of the scores. ``--out FILE`` writes the shipped calibration with that weight to ``FILE``
(judge other sets with it: ``python bench/pitch_views.py --trust FILE``); ``--write`` stores it in
``glradial/data/trust.json`` (which ships ``misfit_weight`` 0: the term is not applied, docs/LINES.md,
"The wide camera's bound"). Printed per split:
views, views with a line fit, coverage and median stated bound without and with the term (over all
views and over those with a fit), and the median error (px at 1920); the answers do not change.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
sys.path.insert(0, str(ROOT / "bench"))
from figures import write_figure  # noqa: E402
from pitch_views import _cached, cache_options, collect, offcentre_views, stadiums  # noqa: E402

from glradial.estimation.lens_estimate import judge  # noqa: E402
from glradial.estimation.trust import TRUST_FILE, load_trust, shipped_trust  # noqa: E402
from glradial.evaluation.trust_calibration import conformal_quantile  # noqa: E402
from glradial.lens.metrics import max_displacement_px  # noqa: E402

#: first seed of the calibration stadiums (validation split), stadiums per split, views per stadium
CALIBRATION_START, STADIUMS, VIEWS = 108, 8, 10


def build(data: Path) -> dict[str, list[tuple[str, np.ndarray, tuple]]]:
    """The three splits of the module docstring: ``(name, uint8 RGB frame, centred lens)``."""
    from glradial.evaluation.real_eval import read_rgb
    from glradial.synthesis.stadium_style import split_seeds

    seeds = split_seeds("val", 2 * STADIUMS, start=CALIBRATION_START)
    pano = read_rgb(data / "real_football" / "stadium_01_1k_tonemapped.jpg")
    return {"calibration": offcentre_views(stadiums(seeds[:STADIUMS]), VIEWS, rng_base=1900),
            "held_out": offcentre_views(stadiums(seeds[STADIUMS:]), VIEWS, rng_base=2900),
            "real_panorama_held_out": offcentre_views([("stadium_01", pano)], 24, rng_base=3900, tilt=(-10.0, 8.0),
                                                      pan=(-180.0, 180.0))}


def readings(items, trust) -> dict[str, np.ndarray]:
    """Per view under ``trust``: error and bound (px at 1920), whether the frame has a line fit, and
    the fit's ``centre_shift_px`` (0 where not measured)."""
    err, bound, lines, shift = [], [], [], []
    for _, ev, truth in items:
        e = judge(ev, "auto", trust)
        err.append(float(max_displacement_px(np.array([e.k1, e.k2]), np.array(truth, np.float64))))
        bound.append(e.uncertainty_px)
        lines.append(ev.lines is not None)
        shift.append(ev.centre_shift_px if ev.centre_shift_px is not None else 0.0)
    return {"err": np.array(err), "bound": np.array(bound), "lines": np.array(lines), "shift": np.array(shift)}


def needed_weight(r: dict[str, np.ndarray]) -> np.ndarray:
    """Per view with a line fit: the weight its bound needs to cover its error (0 when covered, inf
    where the shift is not measured)."""
    err, bound, shift = r["err"][r["lines"]], r["bound"][r["lines"]], r["shift"][r["lines"]]
    excess = np.sqrt(np.maximum(err**2 - bound**2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(err <= bound, 0.0, np.where(shift > 0, excess / shift, np.inf))


def table(evidence: dict, trust, weight: float) -> str:
    """Markdown: per split, coverage and median bound without (``misfit_weight`` 0) and with ``weight``."""
    rows = ["| split | views | with a line fit | median error px | coverage without / with | median bound px without / with "
            "| with a fit: coverage without / with | median bound without / with |", "| --- |" + " ---: |" * 7]
    for split, items in evidence.items():
        off, on = readings(items, replace(trust, misfit_weight=0.0)), readings(items, replace(trust, misfit_weight=weight))
        lines = off["lines"]
        cov = [float(np.mean(r["err"] <= r["bound"])) for r in (off, on)]
        lcov = [float(np.mean((r["err"] <= r["bound"])[lines])) if lines.any() else math.nan for r in (off, on)]
        lmed = [float(np.median(r["bound"][lines])) if lines.any() else math.nan for r in (off, on)]
        rows.append(f"| {split} | {len(items)} | {int(lines.sum())} | {np.median(on['err']):.1f} | {100 * cov[0]:.0f} / "
                    f"{100 * cov[1]:.0f} % | {np.median(off['bound']):.1f} / {np.median(on['bound']):.1f} | "
                    f"{100 * lcov[0]:.0f} / {100 * lcov[1]:.0f} % | {lmed[0]:.1f} / {lmed[1]:.1f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    cache_options(parser, "/tmp/misfit_frames.pkl", "/tmp/misfit_evidence.pkl")
    parser.add_argument("--out", type=Path, default=None, help="write the calibration with the fitted misfit_weight here")
    parser.add_argument("--write", action="store_true", help=f"store the fitted misfit_weight in {TRUST_FILE}")
    args = parser.parse_args(argv)
    frames = _cached(args.frames, lambda: build(args.data))
    evidence = _cached(args.evidence, lambda: collect(frames, list(frames)))
    trust = load_trust(args.trust) if args.trust else shipped_trust()
    scores = needed_weight(readings(evidence["calibration"], replace(trust, misfit_weight=0.0)))
    weight = conformal_quantile(scores)
    print(f"misfit_weight = {weight:.3f} (conformal 90 % of {len(scores)} calibration views with a line fit; "
          f"{int(np.sum(scores > 0))} need it, {int(np.sum(~np.isfinite(scores)))} unmeasured)")
    print(table(evidence, trust, weight))
    write_figure("misfit_calibration", {"misfit_weight": weight, "calibration_views": len(scores), "report": table(evidence, trust, weight).splitlines()})
    for path in ([args.out] if args.out else []) + ([TRUST_FILE] if args.write else []):
        if not math.isfinite(weight):
            raise SystemExit("misfit_weight is not finite: too many calibration misses the shift does not measure")
        replace(trust, misfit_weight=weight).save(path)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
