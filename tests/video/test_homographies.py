"""The batched least-squares homography of the shot fit (frame_motion.homographies_of) against
OpenCV's ``findHomography(a, b, 0)`` (normalised DLT + Levenberg-Marquardt), the independent oracle."""

from __future__ import annotations

import cv2
import numpy as np

from glradial.video.frame_motion import homographies_of


def _sets(rng: np.random.Generator, count: int, n: int, noise: float) -> tuple[np.ndarray, ...]:
    """``count`` point sets (lens units, a 16:9 frame) and their images under random camera-like
    homographies (a few % of scale, shear and perspective), radially distorted a little and noisy:
    no homography fits them exactly, as in the shot fit."""
    a = rng.uniform(-0.5, 0.5, (count, n, 2)) * [1.0, 0.5625]
    truth = np.tile(np.eye(3), (count, 1, 1))
    truth[:, :2, :] += rng.normal(0, 0.04, (count, 2, 3))
    truth[:, 2, :2] += rng.normal(0, 0.1, (count, 2))
    q = np.concatenate([a, np.ones((count, n, 1))], axis=-1) @ np.swapaxes(truth, -1, -2)
    b = q[..., :2] / q[..., 2:3]
    b = b * (1 - 0.05 * np.sum(b * b, axis=-1, keepdims=True)) + rng.normal(0, noise, b.shape)
    return a, b, truth


def _cost(h: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    q = np.c_[a, np.ones(len(a))] @ h.T
    return float(np.sum((q[:, :2] / q[:, 2:3] - b) ** 2))


def test_homographies_match_opencv_least_squares():
    """Each set's homography is OpenCV's to within what its LM leaves unconverged: the transfer
    error (sum of squares) never worse than OpenCV's by 1e-9 relative (two Gauss-Newton steps from
    the DLT leave ~1e-11; the DLT alone is ~1e-2 worse) and better by at most 1e-6 (where
    OpenCV's LM stopped short, ~5e-8 seen); the matrices agree to 1e-4 (a flat direction of the cost; OpenCV stops there). On exact
    correspondences both recover the true homography to 1e-9."""
    rng = np.random.default_rng(3)
    a, b, _ = _sets(rng, 12, 150, 1e-3)
    h, ok = homographies_of(a, b)
    assert ok.all() and np.allclose(h[:, 2, 2], 1.0)
    for p in range(len(a)):
        ref = cv2.findHomography(a[p], b[p], 0)[0]
        ref /= ref[2, 2]
        ours, theirs = _cost(h[p], a[p], b[p]), _cost(ref, a[p], b[p])
        assert theirs * (1 - 1e-6) <= ours <= theirs * (1 + 1e-9)
        assert np.abs(h[p] - ref).max() < 1e-4
    a, _, truth = _sets(rng, 4, 40, 0.0)
    q = np.concatenate([a, np.ones((4, 40, 1))], axis=-1) @ np.swapaxes(truth, -1, -2)
    h, ok = homographies_of(a, q[..., :2] / q[..., 2:3])
    assert ok.all() and np.allclose(h, truth / truth[:, 2:3, 2:3], rtol=0, atol=1e-9)


def test_masked_sets_and_warm_start_and_degenerate_sets():
    """Padded sets: the masked points do not count (the same as fitting the real ones alone); a
    start from a neighbour's homography refines to the same answer; sets of fewer than 4 points
    are flagged. (The matrices themselves are compared through their transfer error: along the
    cost's flat direction neither solve converges to 1e-9.)"""
    rng = np.random.default_rng(5)
    a, b, _ = _sets(rng, 3, 120, 1e-3)
    mask = np.arange(120) < np.array([[120], [60], [3]])
    b_padded = np.where(mask[..., None], b, 7.0)  # garbage where masked
    h, ok = homographies_of(a, b_padded, mask)
    assert ok.tolist() == [True, True, False]
    for p, n in ((0, 120), (1, 60)):
        alone, _ = homographies_of(a[p, :n], b[p, :n])
        assert np.allclose(h[p], alone, rtol=0, atol=1e-10)
    moved = b[:2] * (1 + 2e-5 * np.sum(b[:2] ** 2, axis=-1, keepdims=True))  # a lens step of the solver's differences
    warm, _ = homographies_of(a[:2], moved, mask[:2], start=h[:2])
    for p, n in ((0, 120), (1, 60)):
        ref = cv2.findHomography(a[p, :n], moved[p, :n], 0)[0]
        ours, theirs = _cost(warm[p], a[p, :n], moved[p, :n]), _cost(ref / ref[2, 2], a[p, :n], moved[p, :n])
        assert theirs * (1 - 1e-6) <= ours <= theirs * (1 + 1e-9)
