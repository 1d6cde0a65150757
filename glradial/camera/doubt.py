"""The evidence a refined camera fit is judged on (:func:`doubt_features`): the one place the doubt
policy (:func:`glradial.camera.calibrate.judge`) and the benches that calibrate it read it from.

Units: px of a 1280-wide frame (:data:`glradial.camera.refine.REFERENCE_WIDTH`), metres, degrees.
"""

from __future__ import annotations

import math

from ..pitch.template import PitchTemplate
from .refine import Fit


def directions(elements: tuple[str, ...], pitch: PitchTemplate | None = None) -> int:
    """How many independent marking directions the elements labelled ``elements`` give: lines along the
    pitch (x), lines across it (y), curves (the circle and the arcs); 0 to 3."""
    kinds = {}
    for e in (pitch or PitchTemplate()).elements():
        if e.kind == "arc":
            kinds[e.label] = "curve"
        else:
            kinds[e.label] = "along" if abs(e.b[0] - e.a[0]) >= abs(e.b[1] - e.a[1]) else "across"
    return len({kinds[label] for label in elements if label in kinds})


def doubt_features(fit: Fit) -> dict[str, float]:
    """The doubt evidence of ``fit`` (JSON-ready): ``rms_fit_px`` (inliers' RMS, px at 1280),
    ``inliers``, ``share`` (inliers / evidence points), ``support`` (share of the drawn markings the
    frame shows), ``spread`` (direction spread of the inliers, 0 to 1), ``elements`` (markings with
    enough inliers), ``directions`` (:func:`directions`), ``log_focal_sd``, ``height_m`` (camera above
    the pitch), ``hfov_deg``, ``tilt_deg``, ``roll_deg``, ``k1``, ``k2``."""
    cam = fit.camera
    _, tilt, roll = cam.pan_tilt_roll
    return {"rms_fit_px": fit.rms_px, "inliers": fit.inliers, "share": fit.share, "support": fit.support,
            "spread": fit.spread, "elements": len(fit.elements), "directions": directions(fit.elements),
            "log_focal_sd": fit.log_focal_sd if math.isfinite(fit.log_focal_sd) else 1e3,
            "height_m": float(cam.position[2]), "hfov_deg": cam.hfov_deg, "tilt_deg": tilt, "roll_deg": roll,
            "k1": cam.lens.k1, "k2": cam.lens.k2}
