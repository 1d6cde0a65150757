"""A lens estimate that says how sure it is and whether to trust it, and the choice between the
CNN and the line fit.

Convention:
    :class:`LensEstimate` is a :class:`glradial.Lens` (width-normalised ``(k1, k2)``, forward model
    ``p_d = p_u (1 + k1 r^2 + k2 r^4)``) that also carries
    ``uncertainty_px``: a 90 % bound on the maximum radial displacement error over the 16:9 frame
    (:func:`glradial.lens.metrics.max_displacement_px`, px of a 1920-wide frame); ``method``: ``"net"``
    (the CNN) or ``"lines"`` (the line fit); ``chains``: the line chains the fit used (0 for the
    CNN); ``doubtful`` and ``reason``: whether the estimate should not be applied, and why (one of
    :data:`glradial.estimation.trust.REASONS`; ``"ok"`` when not doubtful).

The bound and the doubt come from :mod:`glradial.estimation.trust` (split-conformal calibration on real
validation frames, shipped in ``glradial/data/trust.json``; docs/LINES.md, "Confidence").
"""

from __future__ import annotations

import math
import numbers
from dataclasses import KW_ONLY, dataclass

import numpy as np

from ..errors import check_flag
from ..lens.lens import Lens, real_number
from ..lens.options import METHODS, SOURCES
from .trust import REASONS, FrameEvidence, TrustModel, ViewFeatures, shipped_trust

#: The default ``uncertainty_px`` of a bare LensEstimate: no evidence of the bound (px at 1920).
NO_EVIDENCE_UNCERTAINTY_PX = 60.0


@dataclass(frozen=True)
class LensEstimate(Lens):
    """An estimated :class:`glradial.Lens` with its confidence (see the module docstring).

    Usable wherever a ``Lens`` is (``.k1``, ``.k2`` and every ``Lens`` method). ``uncertainty_px``
    is finite and positive; larger means less sure.

    Args:
        k1, k2, cx, cy, pixel_aspect: as :class:`glradial.Lens`.
        uncertainty_px: the calibrated bound on the correction's error, px at 1920 wide (> 0; given
            by name, like the rest).
        method: which reading it is (``"net"``, ``"lines"``, ``"pitch"`` ...: ``glradial.lens.options.SOURCES``).
        chains: how many line chains the line fit used (0 for the CNN).
        doubtful: True when the estimate should not be applied as if sure.
        reason: ``"ok"`` exactly when not doubtful, else why (``glradial.estimation.trust.REASONS``).

    Raises:
        ValueError: a bad number, an unknown ``method`` or ``reason``, or ``reason`` not matching ``doubtful``.
        TypeError: ``doubtful`` is not a bool.

    Example:
        >>> import glradial
        >>> est = glradial.LensEstimate(-0.21, 0.04, uncertainty_px=3.5, method="lines", chains=12)
        >>> est.lens, est.doubtful
        (Lens(k1=-0.21, k2=0.04, cx=0.0, cy=0.0, pixel_aspect=1.0), False)
        >>> sorted(est.as_dict())[:3]
        ['chains', 'doubtful', 'k1']
    """

    _: KW_ONLY  # after Lens's k1, k2, cx, cy, pixel_aspect: these are given by name
    uncertainty_px: float = NO_EVIDENCE_UNCERTAINTY_PX
    method: str = "net"
    chains: int = 0
    doubtful: bool = False
    reason: str = "ok"

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
        object.__setattr__(self, "doubtful", check_flag("doubtful", self.doubtful))
        if self.reason not in REASONS or (self.reason == "ok") == self.doubtful:
            raise ValueError(f"reason must be one of {REASONS} ('ok' exactly when not doubtful), got {self.reason!r} "
                             f"with doubtful={self.doubtful}")

    @property
    def lens(self) -> Lens:
        """The bare :class:`glradial.Lens` ``(k1, k2)``."""
        return Lens(self.k1, self.k2)

    def as_dict(self) -> dict:
        """``{"k1", "k2", "pixel_aspect", "method", "uncertainty_px", "chains", "doubtful", "reason"}``
        (JSON-ready; ``glradial correct --lens`` reads it back, pixel aspect included)."""
        return {"k1": self.k1, "k2": self.k2, "pixel_aspect": self.pixel_aspect, "method": self.method,
                "uncertainty_px": self.uncertainty_px, "chains": self.chains, "doubtful": self.doubtful,
                "reason": self.reason}


def check_method(method: object) -> str:
    """Validate the ``method`` argument (``"auto"``, ``"net"`` or ``"lines"``)."""
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    return method


def frame_evidence(frame: np.ndarray, net: tuple[float, float], view_features: ViewFeatures,
                   lines: bool = True, net_error_px: float | None = None) -> FrameEvidence:
    """The :class:`glradial.estimation.trust.FrameEvidence` of the uint8 RGB ``frame``: the CNN's ``net``
    ``(k1, k2)`` (frame geometry), the features of its 16:9 view
    (:func:`glradial.estimation.trust.view_features`: green share, grey spread, grass region) and, with ``lines``, its line fit (pieces linked with the
    CNN's lens as the hint, the CNN's k1 as the prior; where it gives no fit on a soft frame, the soft-edge
    fit of :mod:`glradial.estimation.soft_lines`, marked ``soft``); ``net_error_px``: the network's own expected
    error, when its model has an error head."""
    green, gray_std, grass, grass_width = view_features
    net = (float(net[0]), float(net[1]))
    net_error = None if net_error_px is None else float(net_error_px)
    if not lines:
        return FrameEvidence(net, green=green, gray_std=gray_std, net_error_px=net_error, grass=grass, grass_width=grass_width)
    from . import soft_lines
    from .line_fit import fit_lines
    from .lines import detect_chains

    evidence = detect_chains(frame, lens_hint=net)
    fit = fit_lines(evidence, prior=net)
    soft = False
    if not fit.ok and soft_lines.is_soft(evidence):  # too little for the white-line fit, and a soft frame
        soft_fit = soft_lines.fit_soft_lines(frame, prior=net)
        if soft_fit.ok:
            fit, soft = soft_fit, True
    usable = fit.ok and math.isfinite(fit.k1) and math.isfinite(fit.k2) and math.isfinite(fit.sigma_px)
    return FrameEvidence(net, (float(fit.k1), float(fit.k2)) if usable else None,
                         float(fit.sigma_px) if usable else math.inf, int(fit.chains) if usable else 0,
                         int(fit.candidates), green, gray_std, float(evidence.edge_density), net_error,
                         float(fit.rms_px), int(fit.families), int(fit.conics), float(fit.reach),
                         float(fit.difficulty) if usable else math.inf, soft, grass, grass_width,
                         float(fit.centre_shift_px) if usable and math.isfinite(fit.centre_shift_px) else None)


def judge(evidence: FrameEvidence, method: str, trust: TrustModel | None = None) -> LensEstimate:
    """The :class:`LensEstimate` ``method`` gives on ``evidence``: the line fit or the CNN (``auto``:
    the line fit when its bound is below the CNN's), its calibrated bound and doubt
    (:meth:`glradial.estimation.trust.TrustModel.judge`; ``trust`` defaults to the shipped calibration)."""
    trust = trust if trust is not None else shipped_trust()
    (k1, k2), source, bound, doubtful, reason = trust.judge(evidence, check_method(method))
    chains = evidence.chains if source == "lines" else 0
    return LensEstimate(k1, k2, uncertainty_px=bound, method=source, chains=chains, doubtful=doubtful, reason=reason)
