"""Lens-estimation metrics and the reference numbers they use, defined once (NumPy; no torch).

Conventions (docs/DESIGN.md): coefficients are width-normalised (image width = 1, origin at the principal
point); the radial map is ``P(r, k) = r (1 + k1 r^2 + k2 r^4)``.

* :data:`PAPER_SIZE` -- the 1280 x 720 frame geometry of the paper's crops, which labels refer to.
* :data:`CORNER_RADIUS_16_9` -- lens-unit radius of a 16:9 frame's corner (0.5 * sqrt(1 + (9/16)^2)).
* :func:`manifold_k2` -- the Lopez-Antequera manifold of real lenses, ``k2 = 0.019 k1 + 0.805 k1^2``.
* :func:`max_displacement` -- the headline metric: ``max_{r <= R} |P(r, a) - P(r, b)|`` in lens units
  (image widths) over the frame (``R`` = corner radius); :func:`max_displacement_px` reports it in
  pixels of a :data:`REPORT_WIDTH` (1920) wide frame.
* :func:`distortion_loss` -- the paper's distortion loss (sum of squared radial differences over
  :data:`LOSS_RADII`), the NumPy twin of ``net.loss.distortion_loss``.
* :func:`median_interval` -- 95 % percentile-bootstrap interval of a median.
"""

from __future__ import annotations

import numpy as np

from .lens import corner_radius

__all__ = [
    "PAPER_SIZE",
    "REPORT_WIDTH",
    "CORNER_RADIUS_16_9",
    "LOSS_R_MAX",
    "LOSS_SAMPLES",
    "LOSS_RADII",
    "BOOTSTRAP_DRAWS",
    "manifold_k2",
    "radial_map",
    "distortion_loss",
    "max_displacement",
    "max_displacement_px",
    "median_interval",
]

#: Frame geometry (W, H) of the paper's crops; (k1, k2) labels refer to it.
PAPER_SIZE: tuple[int, int] = (1280, 720)
#: Width (pixels) at which displacement errors are reported.
REPORT_WIDTH = 1920
#: Lens-unit radius of the corner of a 16:9 frame (0.5737...).
CORNER_RADIUS_16_9 = corner_radius(PAPER_SIZE)
#: Outer radius (lens units) of the distortion loss's samples: beyond the 16:9 corner, as in the paper.
LOSS_R_MAX = 0.7
#: Number of radii at which the distortion loss compares radial maps.
LOSS_SAMPLES = 64
#: Radii (lens units) at which the distortion loss compares radial maps (both ends included).
LOSS_RADII = np.linspace(0.0, LOSS_R_MAX, LOSS_SAMPLES)
#: Resamples behind :func:`median_interval`.
BOOTSTRAP_DRAWS = 1000
#: Samples of the radius in :func:`max_displacement` (the difference is a smooth odd quintic).
DISPLACEMENT_SAMPLES = 256


def manifold_k2(k1: float | np.ndarray) -> float | np.ndarray:
    """Lopez-Antequera manifold of real lenses: ``k2 = 0.019 k1 + 0.805 k1^2`` (lens units)."""
    return 0.019 * k1 + 0.805 * k1 * k1


def radial_map(r: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``P(r, k) = r (1 + k1 r^2 + k2 r^4)`` for ``k`` of shape ``(..., 2)`` -> ``(..., len(r))`` float64."""
    k = np.asarray(k, np.float64)
    r = np.asarray(r, np.float64)
    r2 = r * r
    return r * (1.0 + k[..., :1] * r2 + k[..., 1:2] * r2 * r2)


def distortion_loss(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Per-sample distortion loss ``sum_r (P(r, y) - P(r, y_hat))^2`` over :data:`LOSS_RADII`."""
    d = radial_map(LOSS_RADII, y) - radial_map(LOSS_RADII, y_hat)
    return (d * d).sum(axis=-1)


def max_displacement(a: np.ndarray, b: np.ndarray, radius: float = CORNER_RADIUS_16_9,
                     samples: int = DISPLACEMENT_SAMPLES) -> np.ndarray:
    """``max_{0 <= r <= radius} |P(r, a) - P(r, b)|`` in lens units (image widths).

    ``a`` and ``b`` are arrays ``(..., 2)`` of (k1, k2) (broadcast against each other); the result
    has their broadcast shape without the last axis. ``radius`` defaults to the 16:9 corner.
    """
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    r = np.linspace(0.0, float(radius), int(samples))
    displacement = d[..., 0:1] * r**3 + d[..., 1:2] * r**5
    return np.max(np.abs(displacement), axis=-1)


def max_displacement_px(a: np.ndarray, b: np.ndarray, width: float = REPORT_WIDTH,
                        radius: float = CORNER_RADIUS_16_9) -> np.ndarray:
    """:func:`max_displacement` in pixels of a ``width``-pixel-wide frame (default 1920)."""
    return float(width) * max_displacement(a, b, radius)


def median_interval(values: np.ndarray, draws: int = BOOTSTRAP_DRAWS, seed: int = 0) -> list[float]:
    """95 % percentile-bootstrap interval ``[lo, hi]`` of the median of ``values``."""
    values = np.asarray(values, np.float64)
    resamples = np.random.default_rng(seed).integers(0, len(values), size=(draws, len(values)))
    lo, hi = np.percentile(np.median(values[resamples], axis=1), [2.5, 97.5])
    return [float(lo), float(hi)]
