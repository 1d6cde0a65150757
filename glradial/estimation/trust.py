"""How far to trust a lens estimate: a per-frame scale, a split-conformal 90 % bound, and doubt.

Convention:
    Every figure is the maximum radial displacement over the 16:9 frame in px of a 1920-wide frame
    (:func:`glradial.lens.metrics.max_displacement_px`). A frame's :class:`FrameEvidence` holds what the
    estimator saw (the CNN's and the line fit's lenses, the fit's 1-sigma and chain counts, how much
    of the frame is pitch green, its grey-level spread, its edge density); :class:`TrustModel` turns it
    into ``uncertainty_px`` (a 90 % bound) and a doubt verdict.

Bound (split conformal):
    * a line fit: ``scale = sqrt(floor² + (a · sigma)² + (w · disagreement)²)`` where ``sigma`` is the
      fit's own 1-sigma or, with ``scale_feature = "difficulty"``, its difficulty (:attr:`glradial.estimation.line_fit.LineFit.sigma_px`) and ``disagreement`` the displacement
      between the line fit and the CNN; bound ``= q_lines · scale``;
    * a soft-edge fit (:mod:`glradial.estimation.soft_lines`, where the white-line fit found too
      little): the same scale, bound ``= q_soft · scale``, ``q_soft`` calibrated on soft fits alone
      (their residuals are in px of a 320-px copy); a model without it (``q_soft = 0``) ignores them;
    * where a fit's chains say how much its lens leans on the principal point sitting at the
      centre (``centre_shift_px``, :mod:`glradial.estimation.decentring`), the bound of whichever
      answer is taken (chosen on the bounds above) in quadrature with ``misfit_weight ·
      centre_shift_px`` (:meth:`TrustModel.misfit_bound`; ``misfit_weight`` calibrated split-conformally
      on rendered views through off-centre lenses, ``bench/misfit_calibration.py``; 0 leaves the
      bound as it was): the centred model's misfit holds for the CNN's centred answer too;
    * the CNN alone: bound ``= q_net`` or, when its model has an error head and the calibration
      measured it, ``q_net_rel · net_error_px`` (the network's own expected error of the frame);
      ``q_no_lines`` / ``q_no_lines_rel`` instead when a line fit was sought and none was found (such
      frames are harder: close-ups, blurred grass, curved stands);
    * a frame with no pitch evidence (blank, noise, not a pitch): at least the largest displacement
      between the answer and any lens of the real range (k1 in [-1.0, 0.4], k2 on the manifold): "anything".
    ``floor``, ``a``, ``w``, ``q_lines``, ``q_net``, ``q_no_lines`` and their ``_rel`` forms are calibrated on validation frames of some clips and
    checked on the others by :mod:`glradial.evaluation.trust_calibration` (``python -m glradial.evaluation.trust_calibration``), which writes
    them to ``glradial/data/trust.json`` (loaded here; docs/LINES.md, "Confidence").

Doubt by benefit (:attr:`glradial.LensEstimate.reason`, first match wins; :data:`REASONS`): an
estimate is doubtful when correcting with it cannot be shown to help.
    No usable evidence: ``blank_frame`` (grey std below ``blank_std``), ``noise_frame`` (no line fit
    and more than ``noise_edge_density`` of the pixels are edges), ``not_a_pitch`` (no grass region
    of a pitch, :meth:`TrustModel.is_pitch`: one wide region of one pitch green reaching the lower
    part of the view, any share of it; or a narrower one with painted lines on it), ``too_few_lines``
    (neither a white-line fit of at least two agreeing chains nor a soft-edge fit: the answer is
    the CNN's alone, and its own calibrated bound, ``q_no_lines_rel`` times its error head's
    expected error, reaches the uncorrected frame; where it does not, the CNN's answer is applied).
    A soft-edge fit is evidence: its frame is judged by benefit like a white-line fit's, with its
    own calibrated bound (``q_soft``), whichever answer (the fit's or the CNN's) states less.
    The bound reaches the uncorrected frame: ``evidence_disagrees`` (the line fit and the CNN are
    more than ``disagree_max_px`` apart, and the answer not taken is at least that far from the
    identity lens: were it the truth, correcting would not help; unless the answer's own bound is
    under half its shift, so that correcting helps whatever truth the bound admits), ``weak_geometry`` (the identity lens
    lies within the stated bound of the answer: ``uncertainty_px`` at least the answer's own maximum
    displacement, :func:`shift_px`); else ``ok``. A frame with 200 px of barrel read 12 px off is
    corrected; a near-pinhole frame whose lens is within its bound is left alone (leaving it costs
    at most the bound).
    With ``method="net"`` no line fit is run, so only the first, third and ``weak_geometry`` apply.

New diagnostics of the line fit become features by adding a field to :class:`FrameEvidence` and a
term to :meth:`TrustModel.lines_scale`, then re-running the calibration.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, fields, replace
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..lens.metrics import manifold_k2, max_displacement_px

#: Machine-readable reasons of :attr:`glradial.LensEstimate.reason` ("ok" = not doubtful).
REASONS = ("ok", "blank_frame", "noise_frame", "not_a_pitch", "too_few_lines", "evidence_disagrees", "weak_geometry")
#: Reasons under which the frame gives no pitch evidence: the bound is the whole lens range.
NO_EVIDENCE_REASONS = ("blank_frame", "noise_frame", "not_a_pitch")
#: The range of real lenses "anything" spans (k1, lens units; k2 on the manifold).
LENS_RANGE_K1 = (-1.0, 0.4)
#: Pitch green in OpenCV HSV (H 0..180, S and V 0..255): hue band (36..190 degrees: grass under
#: warm or cold broadcast colour, artificial turf), least saturation and value.
GREEN_HUE, GREEN_MIN_SATURATION, GREEN_MIN_VALUE = (18, 95), 50, 40
#: Width of the hue window (OpenCV hue units of 2 degrees) that one pitch's green falls into.
GREEN_WINDOW = 12
#: The grass region (:func:`grass_region`): the largest 8-connected region of the view in its
#: dominant pitch-green hue window, closed over painted lines and players by a square of
#: GRASS_CLOSE px (of the 384-px network input). It is a pitch's grass when it covers at least
#: GRASS_MIN_AREA of the view, reaches below GRASS_LOW of the view's height (a pitch lies under the
#: stands and the sky; the lowest rows may show the near stand of a high camera), fills at least GRASS_MIN_FILL
#: of its bounding box (a trapezoid seen in perspective, not a fractal or scattered foliage) and spans
#: GRASS_WIDE of the view's width, or GRASS_NARROW with painted lines on it (a white-line fit with a
#: vanishing-point family). Any share of the frame: wide views, stands, sky, roofs, tracks.
GRASS_CLOSE, GRASS_MIN_AREA, GRASS_LOW, GRASS_MIN_FILL, GRASS_WIDE, GRASS_NARROW = 5, 0.05, 0.4, 0.25, 0.6, 0.3
#: The shipped calibration (written by ``python -m glradial.evaluation.trust_calibration``).
TRUST_FILE = Path(__file__).resolve().parents[1] / "data" / "trust.json"


@dataclass(frozen=True)
class FrameEvidence:
    """What one frame gave the estimator (see the module docstring).

    ``net``: the CNN's ``(k1, k2)`` in the frame's geometry; ``lines``: the line fit's, ``None``
    without a fit (or when not run); ``sigma_px``: the fit's 1-sigma (inf without a fit);
    ``chains``/``candidates``: chains that agree with the fit / passed screening; ``green``: share of
    the 16:9 view in its dominant pitch-green hue window (:func:`view_features`); ``gray_std``: grey-level standard deviation (0..255);
    ``edge_density``: share of Canny edge pixels (``None`` when lines were not run);
    ``net_error_px``: the network's own expected error (its error head, px at 1920; ``None`` for a
    model without one); ``rms_px``, ``families``, ``conics``, ``reach``, ``fit_difficulty``: the line
    fit's diagnostics (:class:`glradial.estimation.line_fit.LineFit`; ``fit_difficulty`` inf without
    a fit, ``None`` when not measured); ``soft``: the fit is the soft-edge fit
    (:mod:`glradial.estimation.soft_lines`, run where the white-line fit found too little), bounded
    with its own quantile ``q_soft``; ``centre_shift_px``: the fit's
    :attr:`glradial.estimation.line_fit.LineFit.centre_shift_px` (px at 1920; ``None`` when not measured).
    """

    net: tuple[float, float]
    lines: tuple[float, float] | None = None
    sigma_px: float = math.inf
    chains: int = 0
    candidates: int = 0
    green: float = 1.0
    gray_std: float = 255.0
    edge_density: float | None = None
    net_error_px: float | None = None
    rms_px: float | None = None
    families: int = 0
    conics: int = 0
    reach: float | None = None
    fit_difficulty: float | None = None
    soft: bool = False
    grass: float | None = None
    grass_width: float = 0.0
    centre_shift_px: float | None = None

    @property
    def disagreement_px(self) -> float:
        """Displacement between the line fit and the CNN (px at 1920); NaN without a fit."""
        if self.lines is None:
            return math.nan
        return float(max_displacement_px(np.array(self.lines, np.float64), np.array(self.net, np.float64)))

    @property
    def difficulty(self) -> float:
        """The fit's own difficulty (:attr:`glradial.estimation.line_fit.LineFit.difficulty`, or its
        1-sigma where not measured; px at 1920, inf without a fit). Larger is harder."""
        if self.lines is None:
            return math.inf
        return float(self.fit_difficulty) if self.fit_difficulty is not None else float(self.sigma_px)

    def as_dict(self) -> dict:
        """JSON-ready (inf as None)."""
        out = asdict(self)
        out["sigma_px"] = None if not math.isfinite(self.sigma_px) else self.sigma_px
        if self.fit_difficulty is not None and not math.isfinite(self.fit_difficulty):
            out["fit_difficulty"] = "inf"
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "FrameEvidence":
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in data.items() if k in known}
        values["net"] = tuple(values["net"])
        values["lines"] = tuple(values["lines"]) if values.get("lines") is not None else None
        values["sigma_px"] = math.inf if values.get("sigma_px") is None else values["sigma_px"]
        if values.get("fit_difficulty") == "inf":
            values["fit_difficulty"] = math.inf
        return cls(**values)


class ViewFeatures(NamedTuple):
    """What the 16:9 view (the network input) shows, before any line is sought: ``green`` the share
    of it in its dominant pitch-green hue window, ``gray_std`` the grey-level spread (0..255),
    ``grass`` the share of it in its grass region (0 when the region does not pass
    :func:`grass_region`'s shape test) and ``grass_width`` that region's width (share of the view's)."""

    green: float
    gray_std: float
    grass: float = 0.0
    grass_width: float = 0.0


def pitch_green(rgb: np.ndarray, window: int = GREEN_WINDOW) -> tuple[np.ndarray, np.ndarray]:
    """``(band, green)``, boolean masks of a uint8 RGB image: its pixels in the pitch-green band
    (:data:`GREEN_HUE`, saturated, not dark), and those of them in the band's dominant hue window
    ``window`` OpenCV hue units wide (the pitch's own green; stands and boards are other hues)."""
    import cv2

    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    # OpenCV's range test and histogram: the same masks and counts as the numpy comparisons, in one pass each
    band = cv2.inRange(hsv, (GREEN_HUE[0], GREEN_MIN_SATURATION, GREEN_MIN_VALUE), (GREEN_HUE[1], 255, 255))
    hist = cv2.calcHist([hsv], [0], band, [181], [0, 181]).ravel().astype(np.float64)
    low = int(np.argmax(np.convolve(hist, np.ones(window), "valid")))
    own = cv2.inRange(hsv, (max(low, GREEN_HUE[0]), GREEN_MIN_SATURATION, GREEN_MIN_VALUE),
                      (min(low + window - 1, GREEN_HUE[1]), 255, 255))
    return band > 0, own > 0


def _green_mask(view: np.ndarray) -> tuple[np.ndarray, float]:
    """The view's pixels in its dominant :data:`GREEN_WINDOW`-wide hue window of the pitch-green band
    (:func:`pitch_green`), and their share of the view."""
    green = pitch_green(view)[1]
    return green, float(np.count_nonzero(green)) / max(green.size, 1)


def grass_region(mask: np.ndarray) -> tuple[float, float]:
    """``(area, width)`` of the grass region of a pitch-green ``mask`` (shares of the view's area and
    width; :data:`GRASS_CLOSE` and the shape test of the constants above): the largest connected
    region after closing, ``(0, 0)`` when none, ``(0, width)`` when it does not reach the lower part of
    the view or fills too little of its bounding box."""
    import cv2

    closed = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((GRASS_CLOSE, GRASS_CLOSE), np.uint8))
    count, _, stats, _ = cv2.connectedComponentsWithStats(closed, connectivity=8)
    if count <= 1:
        return 0.0, 0.0
    left, top, width, height, area = stats[1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))]
    rows, cols = mask.shape
    shaped = top + height >= GRASS_LOW * rows and area >= GRASS_MIN_FILL * width * height
    return (float(area) / mask.size if shaped else 0.0), float(width) / cols


def view_features(view: np.ndarray) -> ViewFeatures:
    """The :class:`ViewFeatures` of a small uint8 RGB view (the network input). A pitch is one green,
    while test patterns and street scenes spread their colours (``green``: testsrc2 0.16, mandelbrot
    0.06, a road photo 0.10, close broadcast frames 0.36 and up); its grass is one wide region in the
    lower part of the picture whatever its share (wide views, stands and sky: 0.10 and up)."""
    import cv2

    mask, green = _green_mask(view)
    grass, width = grass_region(mask)
    gray = cv2.cvtColor(view, cv2.COLOR_RGB2GRAY)
    return ViewFeatures(green, float(gray.std()), grass, width)


@lru_cache(maxsize=1)
def _range_lenses() -> np.ndarray:
    k1 = np.linspace(LENS_RANGE_K1[0], LENS_RANGE_K1[1], 57)
    return np.stack([k1, manifold_k2(k1)], axis=1)


def anything_bound(k: tuple[float, float]) -> float:
    """Largest displacement (px at 1920) between lens ``k`` and any lens of the real range."""
    return float(max_displacement_px(_range_lenses(), np.array(k, np.float64)).max())


def line_scale(floor_px, sigma_weight, spread, disagree_weight, disagreement):
    """``sqrt(floor² + (sigma_weight · spread)² + (disagree_weight · disagreement)²)``: the per-frame
    scale of a line fit (px at 1920; module docstring), of floats or of NumPy arrays alike."""
    return np.sqrt(floor_px**2 + (sigma_weight * spread) ** 2 + (disagree_weight * disagreement) ** 2)


def shift_px(k: tuple[float, float]) -> float:
    """How far lens ``k`` moves the frame: its maximum displacement from the identity lens (px at 1920)."""
    return float(max_displacement_px(np.array(k, np.float64), np.zeros(2)))


def benefit_doubt(lens: tuple[float, float], bound: float, evidence: FrameEvidence, other_answer: bool,
                  disagree_max_px: float) -> str:
    """Doubt by benefit (module docstring): ``"weak_geometry"`` when the stated ``bound`` reaches
    the uncorrected frame (the identity lens is within ``bound`` of ``lens``: correcting cannot be
    shown to help); ``"evidence_disagrees"`` when, with ``other_answer`` (a line fit was run), the
    line fit and the CNN are more than ``disagree_max_px`` apart and correcting with ``lens`` would
    not help if the other answer were the truth (their disagreement is at least the other answer's
    own shift), unless the bound itself shows that correcting helps whatever truth it admits (twice
    the bound below the answer's shift: the displacement metric is a norm, so every lens within the
    bound is nearer the answer than the identity); else ``"ok"``."""
    shift = shift_px(lens)
    sure = 2.0 * bound < shift  # every lens within the bound is nearer the answer than no lens
    if other_answer and evidence.lines is not None and evidence.disagreement_px > disagree_max_px and not sure:
        other = evidence.net if tuple(lens) == tuple(evidence.lines) else evidence.lines
        if evidence.disagreement_px >= shift_px(other):
            return "evidence_disagrees"
    if not bound < shift:
        return "weak_geometry"
    return "ok"


@dataclass(frozen=True)
class TrustModel:
    """Calibrated constants of the bound and the doubt rules (module docstring; ``trust.json``)."""

    q_lines: float
    q_net: float
    q_no_lines: float
    floor_px: float
    sigma_weight: float
    disagree_weight: float
    disagree_max_px: float
    green_min: float
    blank_std: float
    noise_edge_density: float
    q_net_rel: float = 0.0
    q_no_lines_rel: float = 0.0
    scale_feature: str = "sigma_px"
    q_soft: float = 0.0
    misfit_weight: float = 0.0
    note: str = ""

    def lines_scale(self, evidence: FrameEvidence) -> float:
        """The per-frame scale of a line fit (px at 1920): its 1-sigma (or, with ``scale_feature =
        "difficulty"``, the fit's difficulty), the line/CNN disagreement and a floor."""
        spread = evidence.difficulty if self.scale_feature == "difficulty" else evidence.sigma_px
        return float(line_scale(self.floor_px, self.sigma_weight, spread, self.disagree_weight, evidence.disagreement_px))

    def lines_bound(self, evidence: FrameEvidence) -> float:
        """``q_lines`` (``q_soft`` for a soft-edge fit) times :meth:`lines_scale` (px at 1920)."""
        return (self.q_soft if evidence.soft else self.q_lines) * self.lines_scale(evidence)

    def misfit_bound(self, bound: float, evidence: FrameEvidence) -> float:
        """``bound`` in quadrature with ``misfit_weight`` times the line fit's ``centre_shift_px``, where
        measured (px at 1920): the centred model's misfit, whichever answer is taken."""
        shift = evidence.centre_shift_px
        if shift is None or not math.isfinite(shift) or self.misfit_weight <= 0.0:
            return bound
        return math.hypot(bound, self.misfit_weight * shift)

    def net_bound(self, evidence: FrameEvidence, no_lines: bool) -> float:
        """The CNN's bound (px at 1920): relative to its own expected error when calibrated and
        given (``q_*_rel > 0``), else the constant; ``no_lines``: a line fit was sought, none found."""
        rel = self.q_no_lines_rel if no_lines else self.q_net_rel
        if rel > 0.0 and evidence.net_error_px is not None and evidence.net_error_px > 0.0:
            return rel * evidence.net_error_px
        return self.q_no_lines if no_lines else self.q_net

    def is_pitch(self, evidence: FrameEvidence) -> bool:
        """Whether the view shows a pitch: a grass region of :data:`GRASS_MIN_AREA` or more that is
        :data:`GRASS_WIDE` wide, or :data:`GRASS_NARROW` wide with painted lines on it (a white-line fit
        with a vanishing-point family); for records without the grass region (``grass`` None), the
        older rule (``green_min`` of the view in one pitch green)."""
        if evidence.grass is None:
            return evidence.green >= self.green_min
        if evidence.grass < GRASS_MIN_AREA:
            return False
        painted = evidence.lines is not None and not evidence.soft and evidence.families > 0
        return evidence.grass_width >= GRASS_WIDE or (painted and evidence.grass_width >= GRASS_NARROW)

    def no_evidence(self, evidence: FrameEvidence) -> str | None:
        """``blank_frame``, ``noise_frame``, ``not_a_pitch`` or ``None``."""
        if evidence.gray_std < self.blank_std:
            return "blank_frame"
        no_fit = evidence.lines is None or evidence.soft  # contrast-equalised noise can give soft "lines"
        if no_fit and evidence.edge_density is not None and evidence.edge_density > self.noise_edge_density:
            return "noise_frame"
        if not self.is_pitch(evidence):
            return "not_a_pitch"
        return None

    def judge(self, evidence: FrameEvidence, method: str) -> tuple[tuple[float, float], str, float, bool, str]:
        """``(lens, source, uncertainty_px, doubtful, reason)`` for ``method`` ("auto", "net",
        "lines"): which answer, its bound and the doubt verdict (doubt by benefit, module docstring).
        A soft-edge fit counts only under a model calibrated for it (``q_soft > 0``)."""
        if evidence.soft and self.q_soft <= 0.0:
            evidence = replace(evidence, lines=None, sigma_px=math.inf, chains=0, fit_difficulty=math.inf, soft=False,
                               centre_shift_px=None)
        use_lines = evidence.lines is not None and method != "net"
        white = evidence.lines is not None and not evidence.soft  # a soft fit: the white-line fit found too little
        net_bound = self.net_bound(evidence, no_lines=method != "net" and not white)
        bound = self.lines_bound(evidence) if use_lines else net_bound
        if use_lines and method == "auto" and bound >= net_bound:
            use_lines, bound = False, net_bound
        lens, source = (evidence.lines, "lines") if use_lines else (evidence.net, "net")
        bound = self.misfit_bound(bound, evidence)  # after the choice: the misfit is the model's, not one answer's
        empty = self.no_evidence(evidence)
        if empty is not None:
            return lens, source, max(bound, anything_bound(lens)), True, empty
        if method != "net" and evidence.lines is None:  # no line evidence: the CNN alone, by its own bound
            doubtful = not bound < shift_px(lens)
            return lens, source, bound, doubtful, "too_few_lines" if doubtful else "ok"
        reason = benefit_doubt(lens, bound, evidence, other_answer=method != "net", disagree_max_px=self.disagree_max_px)
        return lens, source, bound, reason != "ok", reason

    def save(self, path: str | Path) -> None:
        from ..media.atomic import atomic_write_text

        atomic_write_text(Path(path), json.dumps(asdict(self), indent=1) + "\n")


def load_trust(path: str | Path | None = None) -> TrustModel:
    """The calibrated :class:`TrustModel` (default: the shipped :data:`TRUST_FILE`), checked against
    the ``trust`` schema (:mod:`glradial.schemas`): ``ValueError`` naming the file and the field."""
    from ..schemas import validate

    path = Path(path) if path is not None else TRUST_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"trust calibration {path} is unreadable: {err}") from None
    validate(data, "trust", f"trust calibration {path}")  # the fields of TrustModel, typed
    return TrustModel(**data)


@lru_cache(maxsize=1)
def shipped_trust() -> TrustModel:
    """The shipped calibration, read once."""
    return load_trust()
