"""The paper's distortion loss (docs/DESIGN.md).

Convention: a lens is ``(k1, k2)`` in width-normalised lens units; the radial map is
``P(r, (k1, k2)) = r (1 + k1 r^2 + k2 r^4)``. Radii are ``samples`` points evenly spaced on
``[0, r_max]`` (both ends included), ``r_max = 0.7`` by default (beyond the 16:9 corner, 0.5737).

``distortion_loss(y, y_hat) = sum_i (P(r_i, y) - P(r_i, y_hat))^2`` per sample (a sum, as in the
paper; divide by ``samples`` for a mean). Since ``P(r, y) - P(r, y_hat) = r^3 dk1 + r^5 dk2`` it is
the quadratic form ``a dk1^2 + 2 c dk1 dk2 + b dk2^2`` with ``a = sum r^6``, ``c = sum r^8``,
``b = sum r^10``; the code evaluates the sum over radii literally (it is cheap) so that it reads like
the paper.

Training loss ``L = DL(y, (k1_hat, k2)) + DL(y, (k1, k2_hat))``: each coefficient judged with the
other one true. Optionally (``joint_weight`` w > 0, not the paper's) ``+ w DL_c(y, y_hat)``, both
coefficients judged together on radii up to the 16:9 corner radius (:data:`glradial.lens.metrics.CORNER_RADIUS_16_9`): the
quantity behind the evaluation's maximum displacement error, which rewards a k2 that offsets the
network's own k1 error inside the frame.

Two optional parts of the multi-task recipe (issue 28; after Janos & Benesova's sequel, our own
formulation), both off by default so that the loss above is unchanged:

* ``sample_weight`` (:func:`small_k1_weights`): each crop's regression loss weighted by
  ``1 + extra exp(-k1^2 / (2 scale^2))`` of its true k1, normalised by the batch's weight sum, so
  that near-zero lenses (the weakest in the evaluation) count more;
* :func:`comparator_loss`: a binary cross-entropy on which of two crops has the larger k1 and which
  the larger k2 (the comparator head of :class:`net.model.DistortionNet`).
"""

from __future__ import annotations

import numpy as np
import torch

from glradial.lens.metrics import CORNER_RADIUS_16_9, DISPLACEMENT_SAMPLES, LOSS_R_MAX, LOSS_SAMPLES, REPORT_WIDTH


def loss_radii(samples: int = LOSS_SAMPLES, r_max: float = LOSS_R_MAX, *, device=None, dtype=torch.float32) -> torch.Tensor:
    """``samples`` radii evenly spaced on ``[0, r_max]``."""
    if samples < 2:
        raise ValueError(f"samples must be >= 2, got {samples}")
    if not r_max > 0:
        raise ValueError(f"r_max must be positive, got {r_max}")
    return torch.linspace(0.0, r_max, samples, device=device, dtype=dtype)


def radial_map(r: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """``P(r, k) = r (1 + k1 r^2 + k2 r^4)`` for ``k`` of shape ``N x 2`` -> ``N x len(r)``."""
    r2 = r * r
    return r * (1.0 + k[:, :1] * r2 + k[:, 1:2] * r2 * r2)


def distortion_loss(y: torch.Tensor, y_hat: torch.Tensor, radii: torch.Tensor | None = None) -> torch.Tensor:
    """Per-sample ``DL(y, y_hat) = sum_i (P(r_i, y) - P(r_i, y_hat))^2`` -> shape ``N``."""
    if y.shape != y_hat.shape or y.ndim != 2 or y.shape[1] != 2:
        raise ValueError(f"y and y_hat must both be N x 2, got {tuple(y.shape)} and {tuple(y_hat.shape)}")
    if radii is None:
        radii = loss_radii(device=y.device, dtype=y.dtype)
    diff = radial_map(radii, y) - radial_map(radii, y_hat)
    return (diff * diff).sum(dim=1)


def training_loss(
    y: torch.Tensor, y_hat: torch.Tensor, radii: torch.Tensor | None = None, joint_weight: float = 0.0,
    sample_weight: torch.Tensor | None = None,
) -> torch.Tensor:
    """Batch mean of ``DL(y, (k1_hat, k2)) + DL(y, (k1, k2_hat))`` (scalar), plus ``joint_weight``
    times the batch mean of ``DL(y, y_hat)`` on ``LOSS_SAMPLES`` radii over ``[0, CORNER_RADIUS_16_9]``
    when ``joint_weight > 0`` (see the module docstring). With ``sample_weight`` (``N``, positive)
    the batch means are weighted means ``sum(w L) / sum(w)``; without it the plain means."""
    k1_only = torch.stack([y_hat[:, 0], y[:, 1]], dim=1)
    k2_only = torch.stack([y[:, 0], y_hat[:, 1]], dim=1)
    per_sample = distortion_loss(y, k1_only, radii) + distortion_loss(y, k2_only, radii)
    if joint_weight > 0:
        frame_radii = loss_radii(LOSS_SAMPLES, CORNER_RADIUS_16_9, device=y.device, dtype=y.dtype)
        joint = distortion_loss(y, y_hat, frame_radii)
    if sample_weight is None:
        loss = per_sample.mean()
        return loss + joint_weight * joint.mean() if joint_weight > 0 else loss
    if sample_weight.shape != per_sample.shape:
        raise ValueError(f"sample_weight must have shape {tuple(per_sample.shape)}, got {tuple(sample_weight.shape)}")
    if joint_weight > 0:
        per_sample = per_sample + joint_weight * joint
    return (sample_weight * per_sample).sum() / sample_weight.sum()


def small_k1_weights(k1: torch.Tensor, extra: float, scale: float) -> torch.Tensor:
    """Per-sample weights ``1 + extra * exp(-k1^2 / (2 scale^2))`` of the true ``k1`` (lens units):
    ``1 + extra`` at k1 = 0, back to about 1 for ``|k1|`` beyond ``3 scale``. ``extra >= 0``,
    ``scale > 0`` (``ValueError`` otherwise)."""
    if not extra >= 0:
        raise ValueError(f"extra must be >= 0, got {extra}")
    if not scale > 0:
        raise ValueError(f"scale must be positive, got {scale}")
    return 1.0 + extra * torch.exp(-0.5 * (k1 / scale) ** 2)


def comparison_partners(n: int, paired: bool, rng) -> np.ndarray:
    """int64 ``n``: the crop each crop of a batch is compared with. ``paired`` (a batch of adjacent
    pairs that share panorama, pose and field of view and differ only in the lens): the other crop
    of its pair, ``i ^ 1`` (draws nothing from ``rng``). Otherwise one random cycle through the
    batch (``rng``, a NumPy Generator): no crop is compared with itself."""
    if n < 2 or (paired and n % 2):
        raise ValueError(f"a batch of {n} crops cannot be {'paired' if paired else 'compared'}")
    if paired:
        return np.arange(n, dtype=np.int64) ^ 1
    order = rng.permutation(n)
    partner = np.empty(n, np.int64)
    partner[order] = np.roll(order, -1)
    return partner


def comparator_targets(y: torch.Tensor, partner: torch.Tensor) -> torch.Tensor:
    """``N x 2``: 1 where crop i's (k1, k2) is larger than its partner's, 0 where smaller, 0.5 on a tie."""
    other = y[partner]
    return 0.5 + 0.5 * torch.sign(y - other)


def comparator_loss(logits: torch.Tensor, y: torch.Tensor, partner: torch.Tensor) -> torch.Tensor:
    """Mean binary cross-entropy (nats) of the comparator's ``N x 2`` logits (k1, k2) against
    :func:`comparator_targets` of the true lenses ``y`` (``N x 2``) and ``partner`` (int64 ``N``)."""
    if logits.shape != y.shape:
        raise ValueError(f"logits must have the shape of y {tuple(y.shape)}, got {tuple(logits.shape)}")
    return torch.nn.functional.binary_cross_entropy_with_logits(logits, comparator_targets(y, partner))


def max_displacement_px(y: torch.Tensor, y_hat: torch.Tensor) -> torch.Tensor:
    """Per-sample ``max_r |P(r, y) - P(r, y_hat)|`` over ``[0, CORNER_RADIUS_16_9]`` in px of a
    ``REPORT_WIDTH``-wide frame (the torch twin of :func:`glradial.metrics.max_displacement_px`)."""
    r = torch.linspace(0.0, CORNER_RADIUS_16_9, DISPLACEMENT_SAMPLES, device=y.device, dtype=y.dtype)
    d = y - y_hat
    return REPORT_WIDTH * (d[:, :1] * r**3 + d[:, 1:2] * r**5).abs().amax(dim=1)


def error_scale_loss(y: torch.Tensor, y_hat: torch.Tensor, log_scale: torch.Tensor) -> torch.Tensor:
    """Batch mean of the Laplace negative log-likelihood ``log b + e / b`` of the network's own error
    ``e`` (:func:`max_displacement_px` of the detached ``y_hat``; px at 1920) under the predicted
    scale ``b = exp(log_scale)`` (clamped to [-3, 6]: 0.05 to 400 px). Its minimiser is ``b = E[e]``,
    the mean error of frames that look alike; only the error head learns from it."""
    error = max_displacement_px(y, y_hat.detach())
    log_b = log_scale.clamp(-3.0, 6.0)
    return (log_b + error / torch.exp(log_b)).mean()
