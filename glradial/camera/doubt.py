"""The evidence a refined camera fit is judged on (:func:`doubt_features`): the one place the doubt
policy (:func:`glradial.camera.calibrate.judge`) and the benches that calibrate it read it from.

Units: px of a 1280-wide frame (:data:`glradial.camera.refine.REFERENCE_WIDTH`), metres, degrees.
"""

from __future__ import annotations

import math

from ..pitch.template import PitchTemplate
from .line_hypotheses import HEIGHT_RANGE
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
    ``inliers``, ``share`` (inliers / evidence points), ``pitch_share`` (the same among
    the points the camera puts on the pitch), ``support`` (share of the drawn markings the
    frame shows), ``spread`` (direction spread of the inliers, 0 to 1), ``drawn`` / ``missing`` (markings drawn in the
    frame / those the frame barely shows: :func:`glradial.camera.refine.element_support`), ``elements`` (markings with
    enough inliers), ``directions`` (:func:`directions`), ``log_focal_sd``, ``height_m`` (camera above
    the pitch), ``hfov_deg``, ``tilt_deg``, ``roll_deg``, ``k1``, ``k2``."""
    cam = fit.camera
    _, tilt, roll = cam.pan_tilt_roll
    return {"rms_fit_px": fit.rms_px, "inliers": fit.inliers, "share": fit.share, "pitch_share": fit.pitch_share, "support": fit.support,
            "spread": fit.spread, "drawn": fit.drawn, "missing": fit.missing, "elements": len(fit.elements), "directions": directions(fit.elements),
            "log_focal_sd": fit.log_focal_sd if math.isfinite(fit.log_focal_sd) else 1e3,
            "height_m": float(cam.position[2]), "hfov_deg": cam.hfov_deg, "tilt_deg": tilt, "roll_deg": roll,
            "k1": cam.lens.k1, "k2": cam.lens.k2}


def doubt_reason(features: dict, t: dict) -> str:
    """Why a fit with the evidence ``features`` (:func:`doubt_features`) is doubtful under the thresholds
    ``t`` (``glradial/data/camera_trust.json``: how each was chosen is said there); ``"ok"`` when it is not."""
    if features["inliers"] < t["min_points"] or features["elements"] < t["min_elements"]:
        return "too_few_markings"
    if features["directions"] < t["min_directions"]:
        return "weak_geometry"  # markings of one direction only
    if features["spread"] < t["min_spread"] or features["log_focal_sd"] > t["max_log_focal_sd"]:
        return "weak_geometry"  # one family of parallel image lines, or nothing else fixes the focal length
    if not t["min_height_m"] <= features["height_m"] <= HEIGHT_RANGE[1] or features["hfov_deg"] > t["max_hfov_deg"]:
        # a camera on the grass, above any main-camera position the search starts from, or wider than a
        # broadcast lens: lines fitted, not a pitch
        return "poor_fit"
    if features["support"] < t["min_support"] or features["rms_fit_px"] > t["max_rms_px"]:
        return "poor_fit"  # markings drawn where the frame shows none, or not on the lines it shows
    if features["missing"] > t["max_missing"] or features["share"] < t["min_share"]:
        return "poor_fit"  # whole markings missing, or most of the frame's line evidence left unexplained
    return "ok"
