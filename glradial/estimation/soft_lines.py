"""Soft line evidence: long straight edges of soft, low-contrast frames with few or no pitch lines.

Used only where the white-line fit (:mod:`glradial.estimation.lines`,
:mod:`glradial.estimation.line_fit`) finds too little and the frame is soft (:func:`is_soft`): a view of a coarse panorama (a 1024-px
equirectangular panorama seen 45-60 degrees wide has about 150 source pixels across the frame, so
every edge is a ramp several frame pixels wide), a frame of stands, boards and mown grass with
hardly any white line.

Why a second detection: the white-line detector smooths with sigma 1.2 px of an 800-px copy and
needs Canny gradients of 30/70 grey levels; a board's foot, a stand tier or the boundary between two
mowing stripes of such a frame is a soft, low-contrast ramp that gives neither. Here the frame is

* reduced to :data:`SOFT_WIDTH` px wide (area interpolation): about the panorama's own resolution,
  where those ramps are a few pixels wide again, and
* contrast-stretched linearly (the :data:`STRETCH_PERCENT` and ``100 - STRETCH_PERCENT`` percentiles
  of its grey levels to 0 and 255), so the faint stripe and board edges reach the detector's
  thresholds. The stretch is one linear map for the whole frame on purpose: a local equalisation
  (CLAHE) bends each tile's tone curve differently, which moves the gradient maximum of a soft
  ramp; on the blurred stripe test scenes of ``tests/estimation/test_soft_lines.py`` it left 1-2 chains that
  a lens straightens where the linear stretch leaves 2-5, and errors of up to 54 px against at most 5.4 px;

then the same ridge/edge detection, orientation pieces, linking (with the CNN's lens as the hint)
and corner cutting run on it (:func:`glradial.estimation.lines.detect_chains`), and the chains go to
the same fit (:func:`glradial.estimation.line_fit.fit_lines`: straightness, vanishing points of
parallel families such as the mowing stripes or the boards and stand tiers of one side, robust
loss, outlier rejection). Curved structures (roof arches, the tiers of a bowl-shaped stand) fail
the fit's screening when no lens in the range straightens them, and an arch alone is one chain:
a fit needs at least two that agree.

Residuals and the fit's 1-sigma are in px of the :data:`SOFT_WIDTH` copy (``LineEvidence.width``),
so they are about 2.5 times coarser than the white-line fit's: a soft fit is a different kind of
evidence, with its own conformal quantile in the trust model (``TrustModel.q_soft``,
:mod:`glradial.estimation.trust`). The thresholds were chosen on real panorama crops (docs/LINES.md
says which, and gives figures on crops not used for the choice).

Convention: chain points are in lens units of the input frame (image width = 1, origin at the frame
centre, y down), exactly as :func:`~glradial.estimation.lines.detect_chains` gives them.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..lens.lens import lens_to_pixels, pixels_to_lens
from ..media.frames import to_rgb8
from .line_fit import LineFit, fit_lines
from .lines import Chain, LineEvidence, detect_chains

#: Width (px) of the copy soft edges are detected on (about twice the ~150 source pixels a 1024-px
#: panorama puts across a 45-60 degree view); the frame's aspect is kept.
SOFT_WIDTH = 320
#: Share (percent) of the grey levels clipped at each end by the linear contrast stretch.
STRETCH_PERCENT = 1.0
#: A frame is soft when at most this share of its pixels are Canny edges at the white-line detector's
#: scale (``LineEvidence.edge_density``): the real panorama crops without a white-line fit have
#: 0.0001-0.013, the Bundesliga broadcast frames without one 0.05-0.13 (sharp, busy crowds: there the
#: soft fit made the self-consistent error worse, 4.56 -> 4.59 px median).
SOFT_MAX_EDGE_DENSITY = 0.03


def is_soft(evidence: LineEvidence) -> bool:
    """Whether the white-line detection of a frame (``evidence``) says the frame is soft: few edges at
    its scale (:data:`SOFT_MAX_EDGE_DENSITY`). Only such frames get the soft-edge fit."""
    return evidence.edge_density <= SOFT_MAX_EDGE_DENSITY


def soft_gray(frame: np.ndarray, width: int = SOFT_WIDTH) -> np.ndarray:
    """An RGB ``H x W x 3`` (or gray, RGBA; uint8, uint16 or float in [0, 1]:
    :func:`glradial.media.frames.to_rgb8`, which raises TypeError/ValueError naming ``frame``
    otherwise) frame -> uint8 gray at most ``width`` px wide (area interpolation, aspect kept), its :data:`STRETCH_PERCENT` and ``100 - STRETCH_PERCENT``
    percentiles stretched linearly to 0 and 255 (a flat frame stays flat)."""
    gray = cv2.cvtColor(to_rgb8(frame, "frame", clip=False), cv2.COLOR_RGB2GRAY)
    height_full, width_full = gray.shape[:2]
    if width_full > width:
        size = (width, max(2, int(round(height_full * width / width_full))))
        gray = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    gray = gray.astype(np.float32)
    lo, hi = np.percentile(gray, (STRETCH_PERCENT, 100.0 - STRETCH_PERCENT))
    if hi - lo < 1.0:  # flat: nothing to stretch (and no noise to amplify)
        return np.round(gray).astype(np.uint8)
    return np.round(np.clip((gray - lo) * (255.0 / (hi - lo)), 0.0, 255.0)).astype(np.uint8)


def _to_frame(points: np.ndarray, small: tuple[int, int], size: tuple[int, int]) -> np.ndarray:
    """Lens units of the reduced copy (``small`` ``(w, h)``) -> lens units of the frame (``size``
    ``(W, H)``), through pixel centres (exact when the copy's height was rounded).

    Why not let :func:`~glradial.estimation.lines.detect_chains` reduce (it maps its own copy back):
    the stretch would then see the full frame, not the reduced copy, and its output changes. Tried
    (stretched full frame, ``max_width=SOFT_WIDTH``; ``bench/lines_accuracy.py --cache``, 2026-11-25):
    on the 48 held-out "extended" panorama crops ``auto`` went from 24.6 to 29.4 px median (the 48
    tuning crops 26.4 -> 21.1; 27 crops worse by over 0.5 px, 22 better; mean +1.5 px), procedural
    and real frames unchanged, so the stretch stays on the reduced copy and this mapping stays."""
    px = lens_to_pixels(points, small)
    full = (px + 0.5) * np.array([size[0] / small[0], size[1] / small[1]]) - 0.5
    return pixels_to_lens(full, size)


def detect_soft_chains(frame: np.ndarray, lens_hint: tuple[float, float] | None = None) -> LineEvidence:
    """Chains of soft edges of a uint8 RGB/gray ``frame`` (module docstring). ``lens_hint``: a rough
    ``(k1, k2)`` (the CNN's) to link pieces in the undistorted frame. Returns a
    :class:`~glradial.estimation.lines.LineEvidence` whose points are the frame's lens units and
    whose ``width`` is the reduced copy's (the pixel unit of its residuals)."""
    small = soft_gray(frame)
    found = detect_chains(small, max_width=small.shape[1], lens_hint=lens_hint)
    size = (frame.shape[1], frame.shape[0])
    chains = [Chain(_to_frame(c.points, found.size, size), c.kind, c.length) for c in found.chains]
    return LineEvidence(chains, size, found.width, found.overlays, found.edge_density)


def fit_soft_lines(frame: np.ndarray, prior: tuple[float, float] | None = None) -> LineFit:
    """The line fit (:func:`~glradial.estimation.line_fit.fit_lines`) of the soft chains of
    ``frame``, linked with ``prior`` (the CNN's ``(k1, k2)``) as the hint and with its k1 as the fit's
    weak prior; a family of lines meeting in one vanishing point (the mowing stripes) counts as one
    agreeing chain. ``ok`` is false, with a ``reason``, when they give no fit."""
    return fit_lines(detect_soft_chains(frame, lens_hint=prior), prior=prior, family_counts=True)
