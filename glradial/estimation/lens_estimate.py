"""A lens estimate that says how sure it is, and the choice between the CNN and the line fit.

Convention:
    :class:`LensEstimate` is a :class:`glradial.Lens` (width-normalised ``(k1, k2)``, forward model
    ``p_d = p_u (1 + k1 r^2 + k2 r^4)``) that also carries
    ``uncertainty_px``: a bound on the maximum radial displacement error over the 16:9 frame
    (:func:`glradial.lens.metrics.max_displacement_px`, px of a 1920-wide frame) meant to hold for about
    90 % of frames; ``method``: ``"net"`` (the CNN) or ``"lines"`` (the line fit); ``chains``: the
    line chains the fit used (0 for the CNN).

Calibration: the constants below were measured on procedural stadium crops of the **validation**
split rendered with known lenses (never on real photographs) by :func:`glradial.evaluation.real_eval.calibrate`
(docs/LINES.md, "Confidence"): ``NET_UNCERTAINTY_PX`` is the 90th percentile of the CNN's error
there; a line fit's bound is ``LINES_UNCERTAINTY_SCALE * sigma_px + LINES_UNCERTAINTY_FLOOR_PX``
where ``sigma_px`` is the fit's own 1-sigma (:class:`glradial.estimation.line_fit.LineFit`).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import KW_ONLY, dataclass

import numpy as np

from ..lens.lens import Lens, real_number
from ..lens.options import METHODS, SOURCES

#: 90th percentile of the CNN's maximum displacement error (px at 1920) on validation crops.
NET_UNCERTAINTY_PX = 16.0
#: A line fit's 90 % bound: scale on its 1-sigma displacement plus a floor (px at 1920).
LINES_UNCERTAINTY_SCALE = 0.27
LINES_UNCERTAINTY_FLOOR_PX = 0.5
#: Stated for a frame with no usable structure (blank, noise): half the displacement between the
#: ends of the real-lens range k1 in [-1.0, 0.4] on the manifold (px at 1920).
NO_EVIDENCE_UNCERTAINTY_PX = 60.0
#: A frame is blank below this gray standard deviation (levels of 255), or noise when more than
#: this share of its pixels are edges yet no chain was found.
BLANK_STD, NOISE_EDGE_DENSITY = 2.0, 0.12


@dataclass(frozen=True)
class LensEstimate(Lens):
    """An estimated :class:`glradial.Lens` with its confidence (see the module docstring).

    Usable wherever a ``Lens`` is (``.k1``, ``.k2`` and every ``Lens`` method). ``uncertainty_px``
    is finite and positive; larger means less sure.
    """

    _: KW_ONLY  # after Lens's k1, k2, cx, cy, pixel_aspect: these are given by name
    uncertainty_px: float = NO_EVIDENCE_UNCERTAINTY_PX
    method: str = "net"
    chains: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        value = real_number("uncertainty_px", self.uncertainty_px)
        if value <= 0.0:
            raise ValueError(f"uncertainty_px must be positive, got {value}")
        object.__setattr__(self, "uncertainty_px", value)
        if self.method not in SOURCES:
            raise ValueError(f"method must be one of {SOURCES}, got {self.method!r}")
        if isinstance(self.chains, bool) or not isinstance(self.chains, (numbers.Integral, np.integer)) or self.chains < 0:
            raise ValueError(f"chains must be a non-negative integer, got {self.chains!r}")
        object.__setattr__(self, "chains", int(self.chains))

    @property
    def lens(self) -> Lens:
        """The bare :class:`glradial.Lens` ``(k1, k2)``."""
        return Lens(self.k1, self.k2)

    def as_dict(self) -> dict:
        """``{"k1", "k2", "method", "uncertainty_px", "chains"}`` (JSON-ready)."""
        return {"k1": self.k1, "k2": self.k2, "method": self.method,
                "uncertainty_px": self.uncertainty_px, "chains": self.chains}


def check_method(method: object) -> str:
    """Validate the ``method`` argument (``"auto"``, ``"net"`` or ``"lines"``)."""
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return method


def lines_uncertainty(sigma_px: float) -> float:
    """Calibrated 90 % bound (px at 1920) of a line fit with raw 1-sigma ``sigma_px``."""
    return LINES_UNCERTAINTY_SCALE * sigma_px + LINES_UNCERTAINTY_FLOOR_PX


def net_estimate(k1: float, k2: float, frame: np.ndarray | None = None, edge_density: float | None = None) -> LensEstimate:
    """The CNN's answer with its calibrated bound, or :data:`NO_EVIDENCE_UNCERTAINTY_PX` when the
    uint8 ``frame`` is blank, or is noise: ``edge_density`` (of its
    :class:`glradial.estimation.lines.LineEvidence`, when the frame gave no line fit) above
    :data:`NOISE_EDGE_DENSITY`."""
    uncertainty = NET_UNCERTAINTY_PX
    if frame is not None:
        from .lines import gray_copy

        blank = float(gray_copy(frame, 320).std()) < BLANK_STD
        if blank or (edge_density is not None and edge_density > NOISE_EDGE_DENSITY):
            uncertainty = NO_EVIDENCE_UNCERTAINTY_PX
    return LensEstimate(float(k1), float(k2), uncertainty_px=uncertainty, method="net", chains=0)


def fit_frame(frame: np.ndarray, net: tuple[float, float]):
    """The line evidence of the uint8 RGB ``frame`` (pieces linked with the CNN's ``net`` lens as the
    hint) and its :class:`glradial.estimation.line_fit.LineFit` (the CNN's k1 as the prior)."""
    from .line_fit import fit_lines
    from .lines import detect_chains

    evidence = detect_chains(frame, lens_hint=net)
    return evidence, fit_lines(evidence, prior=net)


def line_candidates(frame: np.ndarray, net: tuple[float, float]) -> tuple[LensEstimate, LensEstimate | None]:
    """The CNN's estimate of the uint8 RGB ``frame`` (``net`` = its ``(k1, k2)``) and the line fit's
    (``None`` when the frame has no usable lines or the fit fails), each with its bound."""
    evidence, fit = fit_frame(frame, net)
    if not fit.ok or not (math.isfinite(fit.k1) and math.isfinite(fit.k2) and math.isfinite(fit.sigma_px)):
        return net_estimate(net[0], net[1], frame, evidence.edge_density), None
    fallback = net_estimate(net[0], net[1], frame)
    return fallback, LensEstimate(fit.k1, fit.k2, uncertainty_px=lines_uncertainty(fit.sigma_px), method="lines", chains=fit.chains)


def choose(net: LensEstimate, lines: LensEstimate | None, method: str) -> LensEstimate:
    """``method="lines"``: the line fit whenever there is one; ``"auto"``: the line fit when its
    bound is below the CNN's; ``"net"``: the CNN. Without a line fit, the CNN's answer (labelled
    ``method="net"``: an estimate never claims lines it does not have)."""
    if method == "net" or lines is None:
        return net
    if method == "auto" and lines.uncertainty_px >= net.uncertainty_px:
        return net
    return lines


def estimate_with_lines(frame: np.ndarray, net: tuple[float, float], method: str) -> LensEstimate:
    """Combine the CNN's ``net`` ``(k1, k2)`` with the line fit of the uint8 RGB ``frame``
    (:func:`line_candidates`, then :func:`choose`)."""
    return choose(*line_candidates(frame, net), method)
