"""``calibrate``: the whole camera of one frame (lens, focal length, pose) from the pitch markings.

Steps: the white-line points (:func:`glradial.camera.white_lines.line_points`); first guesses, either given (plane
homographies to the frame's undistorted pixels, best first, e.g. a dedicated first-guess search), the
previous frame's camera (tracking a video: one start, shorter gates), or by default the line and
circle hypotheses of :mod:`glradial.camera.first_guess`, with glradial's dictionary of synthetic views
(:mod:`glradial.camera.first_views`) where that search finds nothing; each decomposed into a camera
(:func:`glradial.camera.model.decompose_homography`) and refined (:func:`glradial.camera.refine.refine`);
the fit with the most inliers is judged (:mod:`glradial.camera.estimate`'s doubt policy and bound).
A doubtful answer of glradial's own search on a frame whose line-fit lens is strong
(:func:`glradial.camera.first_guess.strong_lens`) is retried from a search on the frame undistorted
with that lens, the starts carrying it (:func:`_strong_lens_retry`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

from ..lens.lens import Lens
from ..media.frames import to_rgb8
from ..pitch.template import PitchTemplate
from .estimate import CameraEstimate, camera_trust
from .first_guess import first_guess as search
from .first_guess import strong_lens
from .first_views import first_views
from .line_hypotheses import HEIGHT_RANGE
from .model import Camera, decompose_homography
from .refine import Fit, refine
from .white_lines import LinePoints, line_points

#: Spacing (m) of the template points the first-guess search takes, and the most first guesses it returns.
SEARCH_STEP, SEARCH_CANDIDATES = 0.25, 3
#: Gates (px at 1280) when tracking from the previous frame's camera.
TRACK_GATES = (15.0, 6.0, 3.0)
#: The coarse stage (every first guess: pinhole, wide gates) and the fine stage (the best
#: :data:`FINE_STARTS` coarse fits: lens free, narrow gates).
COARSE_GATES, FINE_GATES, FINE_STARTS = (60.0, 30.0, 15.0, 8.0), (10.0, 6.0, 4.0, 3.0), 2
#: A coarse fit this well supported (and explaining this share of the evidence) ends the search.
EARLY_SUPPORT, EARLY_SHARE = 0.9, 0.45
#: The coarse and the fine stage fit at most this many evidence points (evenly thinned); the support
#: is measured on all of them.
COARSE_POINTS, FINE_POINTS = 250, 1000
#: Residual evaluations per round of the coarse stage (a start is only sorted out there).
COARSE_NFEV = 30
#: Bound (px at 1280) of an estimate without a camera.
NO_CAMERA_PX = 1280.0


def check_pitch(pitch: object) -> PitchTemplate:
    """``pitch``, or the default 105 x 68 m :class:`PitchTemplate` for ``None``; ``TypeError`` otherwise."""
    if pitch is None:
        return PitchTemplate()
    if not isinstance(pitch, PitchTemplate):
        raise TypeError(f"pitch must be a glradial.pitch.PitchTemplate or None, got {pitch!r}")
    return pitch


def _starts(lines: LinePoints, pitch: PitchTemplate, *, first_guess: list[np.ndarray] | None = None,
            previous: Camera | CameraEstimate | None = None, rgb: np.ndarray | None = None,
            lens: Lens | None = None) -> list[Camera]:
    if previous is not None:
        cam = previous.camera if isinstance(previous, CameraEstimate) else previous
        if not isinstance(cam, Camera):
            raise TypeError(f"previous must be a Camera or a CameraEstimate with a camera, got {previous!r}")
        return [cam.with_size(lines.size)]
    homographies = _searched(rgb, lines, pitch, lens) if first_guess is None else list(first_guess)
    return _cameras(homographies, lines.size, lens)


def _searched(rgb: np.ndarray, lines: LinePoints, pitch: PitchTemplate, lens: Lens | None) -> list[np.ndarray]:
    """glradial's own first guesses (plane homographies to the frame undistorted by ``lens``; the
    frame's own pixels for ``None``): the line and circle search
    (:func:`glradial.camera.first_guess.first_guess`) on the frame undistorted by ``lens``, or, where it
    finds nothing, the dictionary of synthetic views (:func:`first_views`) on the white-line points
    undistorted by the same lens (one path for a given lens reading and the strong-lens retry)."""
    points, labels = _search_points(pitch)
    found = [c.homography for c in search(rgb, points, labels, lens=None if lens is None else (lens.k1, lens.k2),
                                          max_candidates=SEARCH_CANDIDATES)]
    if found:
        return found
    flat = lines.xy if lens is None else lens.undistort_points(lines.xy, lines.size)
    return first_views(flat[np.isfinite(flat).all(1)], lines.size, pitch)


@lru_cache(maxsize=8)
def _search_points(pitch: PitchTemplate) -> tuple[np.ndarray, np.ndarray]:
    """``pitch``'s markings sampled every :data:`SEARCH_STEP` m with their labels (read-only; sampled
    once per template, not per frame)."""
    points, labels = pitch.sampled_points(SEARCH_STEP)
    points.flags.writeable = labels.flags.writeable = False
    return points, labels


def _cameras(homographies: list[np.ndarray], size: tuple[int, int], lens: Lens | None) -> list[Camera]:
    """The cameras of plane ``homographies`` (:func:`decompose_homography`; those that decompose), each
    carrying ``lens`` (``None``: the decomposition's own, pinhole)."""
    cams = []
    for h in homographies:
        cam = decompose_homography(h, size)
        if cam is not None:
            cams.append(cam if lens is None else Camera(cam.rotation, cam.position, cam.focal, cam.size, lens))
    return cams


def _check_first_guess(first_guess: object) -> list[np.ndarray]:
    if isinstance(first_guess, np.ndarray) and first_guess.shape == (3, 3):
        first_guess = [first_guess]
    try:
        hs = [np.asarray(h, dtype=np.float64) for h in first_guess]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise TypeError(f"first_guess must be a list of 3×3 homographies, got {first_guess!r}") from None
    for i, h in enumerate(hs):
        if h.shape != (3, 3) or not np.all(np.isfinite(h)):
            raise ValueError(f"first_guess[{i}] must be a finite 3×3 homography, got {h.tolist()}")
    return hs


# The doubt evidence and rule: the one place calibrate's judgement and the benches that choose its
# thresholds (bench/calibrate_matches.py, bench/doubt_rules.py) read them from.


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


def doubt_checks(features: dict, t: dict) -> list[tuple[str, str]]:
    """The doubt rule, each check once: ``(reason, what failed in numbers)`` for every check the fit with
    the evidence ``features`` (:func:`doubt_features`) fails under the thresholds ``t``
    (``glradial/data/camera_trust.json``: how each was chosen is said there), in the order the reasons
    take precedence; ``[]`` when it is sure. Pixels at 1280 wide."""
    f = features
    checks = (
        ("too_few_markings", f["inliers"] < t["min_points"], lambda: f"inliers {f['inliers']} < {t['min_points']}"),
        ("too_few_markings", f["elements"] < t["min_elements"], lambda: f"markings {f['elements']} < {t['min_elements']}"),
        ("weak_geometry", f["directions"] < t["min_directions"], lambda: f"directions {f['directions']} < {t['min_directions']}"),
        # one family of parallel image lines, or nothing else fixes the focal length
        ("weak_geometry", f["spread"] < t["min_spread"], lambda: f"direction spread {f['spread']:.3f} < {t['min_spread']}"),
        ("weak_geometry", f["log_focal_sd"] > t["max_log_focal_sd"],
         lambda: f"focal sd {f['log_focal_sd']:.3f} > {t['max_log_focal_sd']}"),
        # a camera on the grass, above any main-camera position the search starts from, or wider than a
        # broadcast lens: lines fitted, not a pitch
        ("poor_fit", not t["min_height_m"] <= f["height_m"] <= HEIGHT_RANGE[1],
         lambda: f"height {f['height_m']:.1f} m outside {t['min_height_m']}-{HEIGHT_RANGE[1]} m"),
        ("poor_fit", f["hfov_deg"] > t["max_hfov_deg"], lambda: f"hfov {f['hfov_deg']:.1f} deg > {t['max_hfov_deg']} deg"),
        # markings drawn where the frame shows none, or not on the lines it shows
        ("poor_fit", f["support"] < t["min_support"], lambda: f"support {f['support']:.2f} < {t['min_support']}"),
        ("poor_fit", f["rms_fit_px"] > t["max_rms_px"], lambda: f"rms {f['rms_fit_px']:.2f} px > {t['max_rms_px']} px"),
        # whole markings missing, or most of the frame's line evidence left unexplained
        ("poor_fit", f["missing"] > t["max_missing"], lambda: f"missing markings {f['missing']} > {t['max_missing']:g}"),
        ("poor_fit", f["share"] < t["min_share"], lambda: f"explained share {f['share']:.2f} < {t['min_share']}"),
    )
    # the texts are formatted only for the checks that fail (the benches replay the rule on many fits)
    return [(reason, text()) for reason, failed, text in checks if failed]


def doubt_reason(features: dict, t: dict) -> str:
    """Why a fit with the evidence ``features`` is doubtful (the first of :func:`doubt_checks`);
    ``"ok"`` when it is not."""
    failed = doubt_checks(features, t)
    return failed[0][0] if failed else "ok"


def judge_fit(fit: Fit | None, points: int) -> CameraEstimate:
    """The estimate of a refined fit (or of none) under the doubt policy of ``camera_trust.json``."""
    t = camera_trust()
    if fit is None:
        reason = "no_markings" if points < t["min_points"] else "poor_fit"
        return CameraEstimate(None, NO_CAMERA_PX, True, reason)
    bound = t["quantile"] * max(fit.rms_px, t["floor_px"])
    failed = doubt_checks(doubt_features(fit), t)
    reason = failed[0][0] if failed else "ok"
    return CameraEstimate(fit.camera, bound, bool(failed), reason, fit.elements, fit.rms_px, fit.inliers, fit.support,
                          fit.log_focal_sd, detail="; ".join(text for _, text in failed))


def _score(fit: Fit) -> float:  # on the coarse stage's thinned points and on the fine stage's, alike
    """How well a fit explains the frame: evidence explained times markings supported."""
    return fit.share * fit.support


def calibrate(frame: np.ndarray, *, pitch: PitchTemplate | None = None,
              first_guess: Sequence[np.ndarray] | None = None,
              previous: Camera | CameraEstimate | None = None, lens: Lens | None = None) -> CameraEstimate:
    """The camera of ``frame`` (uint8/uint16/float RGB or gray array, any size) from the markings of
    ``pitch`` (default: 105 x 68 m, :class:`glradial.pitch.PitchTemplate`).

    ``first_guess``: plane homographies (pitch ``(x, y, 1)`` -> undistorted pixels of this frame),
    best first, instead of glradial's own search (:func:`glradial.camera.first_guess.first_guess`, then
    the dictionary of synthetic views where it finds nothing). ``previous``: the previous frame's camera (a
    video): refined from there with shorter gates, falling back to a fresh search when that fit is
    doubtful. ``lens``: a reading of the frame's lens (e.g. the estimation layer's,
    :mod:`glradial.camera.estimator`) that the search undistorts the white lines with and the coarse
    stage holds (the fine stage frees it), in place of the strong-lens retry; default none (pinhole
    starts, then the retry where the frame's lens is strong). Never raises for a frame that shows
    no pitch: the estimate is then doubtful with a reason.

    Args:
        frame: H×W×3 RGB or H×W gray array (uint8, uint16 or float in [0, 1]).
        pitch: the pitch's markings (metres); default FIFA's 105 × 68 m.
        first_guess: homographies to start from (above), best first.
        previous: the previous frame's camera, for a video.
        lens: a reading of the frame's lens (width-normalised) to start the search from.

    Returns:
        A :class:`glradial.CameraEstimate` (``doubtful`` and ``reason`` say whether to use it).

    Raises:
        TypeError: ``frame`` is not an array, or ``lens`` not a :class:`glradial.Lens`.
        ValueError: a bad ``pitch`` or ``first_guess``.

    Example:
        >>> import numpy as np, glradial
        >>> empty = glradial.calibrate(np.zeros((90, 160, 3), np.uint8))  # no pitch in sight
        >>> empty.doubtful, empty.reason, empty.camera is None
        (True, 'no_markings', True)
    """
    if not isinstance(frame, np.ndarray):
        raise TypeError(f"frame must be a numpy image array, got {type(frame).__name__}")
    pitch = check_pitch(pitch)
    if first_guess is not None:
        first_guess = _check_first_guess(first_guess)
    if lens is not None and not isinstance(lens, Lens):
        raise TypeError(f"lens must be a glradial.Lens or None, got {type(lens).__name__}")
    rgb = to_rgb8(frame)
    return calibrate_points(rgb, line_points(rgb), pitch, first_guess, previous, lens)


def calibrate_points(rgb: np.ndarray, lines: LinePoints, pitch: PitchTemplate, first_guess: list[np.ndarray] | None,
                     previous: Camera | CameraEstimate | None, lens: Lens | None = None) -> CameraEstimate:
    """:func:`calibrate` of the uint8 RGB frame ``rgb`` whose white-line points ``lines``
    (:func:`glradial.camera.white_lines.line_points`) are already extracted (arguments checked)."""
    if len(lines.xy) < camera_trust()["min_points"]:
        return judge_fit(None, len(lines.xy))
    if previous is not None:
        fine_lines = lines.thinned(FINE_POINTS)
        tracked = judge_fit(refine(_starts(lines, pitch, previous=previous)[0], fine_lines.xy, fine_lines.angle, pitch,
                               gates=TRACK_GATES, lens_from=1, support_xy=lines.tree), len(lines.xy))
        if not tracked.doubtful:
            return tracked
    judged = judge_fit(_search_fit(_starts(lines, pitch, first_guess=first_guess, rgb=rgb, lens=lens), lines, pitch), len(lines.xy))
    if judged.doubtful and first_guess is None and lens is None:  # a given lens reading already did what the retry does
        judged = _strong_lens_retry(rgb, lines, pitch, judged)
    return judged


def _search_fit(starts: list[Camera], lines: LinePoints, pitch: PitchTemplate) -> Fit | None:
    """The best fit from ``starts``: a coarse stage (lens held at each start's) from every start, then
    the :data:`FINE_STARTS` best of them refined with the lens free, best first, stopping at the first
    fine fit the doubt rule passes (the others are only refined while none does)."""
    fine_lines, coarse_lines = lines.thinned(FINE_POINTS), lines.thinned(COARSE_POINTS)
    coarse = []
    for cam in starts:
        fit = refine(cam, coarse_lines.xy, coarse_lines.angle, pitch, fit_lens=False, gates=COARSE_GATES,
                     support_xy=lines.tree, hold_position=1, max_nfev=COARSE_NFEV)
        if fit is not None:
            coarse.append(fit)
            if fit.support >= EARLY_SUPPORT and fit.share >= EARLY_SHARE:
                coarse = [fit]  # a start that already explains the frame: no need to try the others
                break
    fits = []
    for start in sorted(coarse, key=_score, reverse=True)[:FINE_STARTS]:
        fit = refine(start.camera, fine_lines.xy, fine_lines.angle, pitch, gates=FINE_GATES, lens_from=1,
                     support_xy=lines.tree)
        if fit is not None:
            if doubt_reason(doubt_features(fit), camera_trust()) == "ok":
                return fit
            fits.append(fit)
    return max(fits, key=_score) if fits else None


def _strong_lens_retry(rgb: np.ndarray, lines: LinePoints, pitch: PitchTemplate, judged: CameraEstimate) -> CameraEstimate:
    """A strongly distorted frame (:func:`glradial.camera.first_guess.strong_lens`): the first guess
    searched on the frame undistorted with the line fit's lens (the dictionary of views on the
    undistorted line points where that finds nothing), each start given that lens, then the
    same refinement in the distorted frame (the lens held in the coarse stage, free in the fine one).
    Its answer replaces the doubtful ``judged`` when it is sure, or doubtful too but with a camera
    that more evidence points lie on (a doubtful answer says more then; it is still not applied)."""
    lens = strong_lens(rgb)
    if lens is None:
        return judged
    retried = judge_fit(_search_fit(_starts(lines, pitch, rgb=rgb, lens=lens), lines, pitch), len(lines.xy))
    if not retried.doubtful or (retried.camera is not None and retried.inliers > judged.inliers):
        return retried
    return judged
