"""Evaluate a distortion estimator (ONNX or checkpoint) on held-out crops: metrics, tables, plots.

Usage::

    python -m net.evaluate --model glradial/models/glradial_k1k2.onnx --out docs/eval [--n 800]

Test set: ``--n`` crops drawn from the paper's distribution over the held-out **test** split of the
procedural stadiums (:func:`glradial.stadium_style.split_seeds` "test": never used in training),
rendered like the training crops (no augmentation); plus, as an out-of-domain figure, crops of the
real panorama ``tests/data/panorama_field_2048x1024.jpg``.

Metrics (DESIGN.md), for predictions ``y_hat = (k1_hat, k2_hat)`` against labels ``y``:

* ``mean_dl``: mean distortion loss ``DL(y, y_hat)`` (sum over 64 radii on [0, 0.7]);
* ``k1_mae``, ``k2_mae``: mean absolute coefficient errors;
* ``median_max_px`` / ``p90_max_px``: median / 90th percentile of the maximum displacement error
  ``1920 * max_{r <= 0.5737} |P(r, y) - P(r, y_hat)|`` (pixels of a 1920-wide frame);
* ``a_beats_b``: share of images where method A (both coefficients from the net) has a smaller DL
  than method B (the net's k1 and ``k2 = 0.019 k1 + 0.805 k1^2``); the paper reports 0.612;
* the same for method B and for the trivial baseline that always predicts the training mean.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

#: Width (pixels) at which displacement errors are reported, and the 16:9 corner radius.
REPORT_WIDTH = 1920
CORNER_RADIUS_16_9 = 0.5 * math.hypot(1.0, 9.0 / 16.0)
LOSS_RADII = np.linspace(0.0, 0.7, 64)
DISPLACEMENT_RADII = np.linspace(0.0, CORNER_RADIUS_16_9, 256)
#: Mean (k1, k2) of the paper's training distribution: k1 ~ U[-0.7, 0.3] -> -0.2;
#: E[k2] = 0.019 E[k1] + 0.805 E[k1^2] = 0.019 (-0.2) + 0.805 (0.04 + 1/12) = 0.0955.
TRAINING_MEAN = (-0.2, 0.019 * -0.2 + 0.805 * (0.04 + 1.0 / 12.0))


def manifold_k2(k1: np.ndarray) -> np.ndarray:
    """Lopez-Antequera manifold ``k2 = 0.019 k1 + 0.805 k1^2``."""
    return 0.019 * k1 + 0.805 * k1 * k1


def radial_map(r: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``P(r, k) = r (1 + k1 r^2 + k2 r^4)`` for ``k`` N x 2 -> N x len(r) (float64)."""
    k = np.asarray(k, np.float64)
    r2 = r * r
    return r * (1.0 + k[:, :1] * r2 + k[:, 1:2] * r2 * r2)


def distortion_loss(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Per-sample DL (sum over :data:`LOSS_RADII`), the NumPy twin of :func:`net.loss.distortion_loss`."""
    d = radial_map(LOSS_RADII, y) - radial_map(LOSS_RADII, y_hat)
    return (d * d).sum(axis=1)


def max_displacement_px(y: np.ndarray, y_hat: np.ndarray, width: int = REPORT_WIDTH) -> np.ndarray:
    """``width * max_{r <= 0.5737} |P(r, y) - P(r, y_hat)|`` per sample (pixels)."""
    return width * np.abs(radial_map(DISPLACEMENT_RADII, y) - radial_map(DISPLACEMENT_RADII, y_hat)).max(axis=1)


def method_b(pred: np.ndarray) -> np.ndarray:
    """The net's k1 with ``k2`` from the manifold."""
    pred = np.asarray(pred, np.float64)
    return np.stack([pred[:, 0], manifold_k2(pred[:, 0])], axis=1)


def metrics(pred: np.ndarray, labels: np.ndarray) -> dict:
    """All metrics of predictions ``N x 2`` against labels ``N x 2`` (see the module docstring)."""
    pred = np.asarray(pred, np.float64)
    labels = np.asarray(labels, np.float64)
    if pred.shape != labels.shape or pred.ndim != 2 or pred.shape[1] != 2:
        raise ValueError(f"pred and labels must both be N x 2, got {pred.shape} and {labels.shape}")
    b = method_b(pred)
    dl_a, dl_b = distortion_loss(labels, pred), distortion_loss(labels, b)
    px_a, px_b = max_displacement_px(labels, pred), max_displacement_px(labels, b)
    mean = np.broadcast_to(np.array(TRAINING_MEAN), labels.shape)
    px_mean = max_displacement_px(labels, mean)
    return {
        "n": int(len(labels)),
        "mean_dl": float(dl_a.mean()),
        "k1_mae": float(np.abs(pred[:, 0] - labels[:, 0]).mean()),
        "k2_mae": float(np.abs(pred[:, 1] - labels[:, 1]).mean()),
        "median_max_px": float(np.median(px_a)),
        "p90_max_px": float(np.percentile(px_a, 90)),
        "a_beats_b": float((dl_a < dl_b).mean()),
        "b_mean_dl": float(dl_b.mean()),
        "b_median_max_px": float(np.median(px_b)),
        "b_p90_max_px": float(np.percentile(px_b, 90)),
        "baseline_mean_dl": float(distortion_loss(labels, mean).mean()),
        "baseline_median_max_px": float(np.median(px_mean)),
    }
