"""Soft-edge evidence (glradial/estimation/soft_lines.py) on frames with few or no pitch lines.

Oracle: a ground plane of mowing stripes (5 m bands, 6-8 grey levels apart, blurred like a view of
a coarse panorama) drawn through the analytic homography of a pinhole camera with a known pose
(tests/pitch_template.py), then seen through a known lens (exact inverse maps, cv2.remap). The
stripe boundaries are straight, parallel lines on the plane: after the right undistortion they are
straight and share one vanishing point.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest
from pitch_template import distorted, homography, render

import glradial
from glradial.estimation import lens_estimate
from glradial.estimation.line_fit import fit_lines
from glradial.estimation.lines import detect_chains
from glradial.estimation.soft_lines import SOFT_WIDTH, detect_soft_chains, fit_soft_lines, soft_gray
from glradial.estimation.trust import FrameEvidence, ViewFeatures, shipped_trust
from glradial.lens.metrics import manifold_k2, max_displacement_px

SIZE = (1280, 720)
#: Cameras a few metres above the pitch looking across it (camera xyz, target xy, hfov degrees).
POSES = [((52.5, -10.0, 6.0), (40.0, 50.0), 50.0), ((30.0, -8.0, 5.0), (55.0, 60.0), 55.0)]
LIGHT, DARK, TRACK, SKY = (70, 125, 60), (62, 112, 54), (110, 100, 95), (150, 170, 200)


def stripes(h: np.ndarray, size=SIZE, stripe_m: float = 5.0, blur_px: float = 3.0, supersample: int = 2) -> np.ndarray:
    """Mowing stripes (bands of constant x, ``stripe_m`` wide) on the 68 m wide pitch plane, a track
    behind it and sky above the horizon, seen through the pinhole homography ``h`` (pitch -> px),
    supersampled, then blurred with ``blur_px`` (a soft view)."""
    width, height = size
    step = 1.0 / supersample
    to_px = np.array([[step, 0, (step - 1) / 2], [0, step, (step - 1) / 2], [0, 0, 1]])
    v, u = np.mgrid[0:height * supersample, 0:width * supersample].astype(np.float64)
    p = np.stack([u, v, np.ones_like(u)], axis=-1) @ (np.linalg.inv(h) @ to_px).T
    ground = p[..., 2] > 0
    x, y = p[..., 0] / p[..., 2], p[..., 1] / p[..., 2]
    image = np.empty(u.shape + (3,), np.float32)
    image[:] = SKY
    pitch = ground & (y < 68.0)
    light = np.floor(x / stripe_m) % 2 == 0
    image[pitch & light], image[pitch & ~light] = LIGHT, DARK
    image[ground & (y >= 68.0) & (y < 80.0)] = TRACK
    image = cv2.GaussianBlur(cv2.resize(image, size, interpolation=cv2.INTER_AREA), (0, 0), blur_px)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def _arch(sagitta_px: float, size=SIZE, blur_px: float = 3.0) -> np.ndarray:
    """A pale roof arch (a circular band across the frame, its middle ``sagitta_px`` above its ends)
    over a dark stand, no lens: a curved structure, not a straight line."""
    width, height = size
    half = width / 2
    radius = (half**2 + sagitta_px**2) / (2 * sagitta_px)
    centre = (half, 0.3 * height + radius)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    inside = np.hypot(u - centre[0], v - centre[1]) < radius
    image = np.where(inside[..., None], np.float32((120, 70, 50)), np.float32((200, 200, 190)))
    return np.clip(np.round(cv2.GaussianBlur(image, (0, 0), blur_px)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("pose", POSES, ids=["across", "oblique"])
@pytest.mark.parametrize("k1", [-0.5, 0.15])
def test_blurred_stripes_are_read_from_their_vanishing_point(pose, k1):
    """Only mowing stripes, soft and 6-8 grey levels apart: the white-line fit finds nothing, the
    soft-edge fit reads the lens. The tolerance: 8 px at 1920 (the fits read 0.8-5.4 px off with a
    CNN-like hint 30 % off; their own 1-sigma is 11-34 px, so 8 px is well inside their noise)."""
    k2 = float(manifold_k2(k1))
    frame = distorted(stripes(homography(*pose, SIZE)), k1, k2)
    hint = (0.7 * k1, k2)
    white = fit_lines(detect_chains(frame, lens_hint=hint), prior=hint)
    assert not white.ok
    fit = fit_soft_lines(frame, prior=hint)
    assert fit.ok and fit.families >= 1, fit
    assert max_displacement_px(np.array([fit.k1, fit.k2]), np.array([k1, k2])) <= 8.0
    assert fit.sigma_px > 0 and math.isfinite(fit.sigma_px)


@pytest.mark.parametrize("pose", POSES, ids=["across", "oblique"])
def test_stripes_through_the_estimator_are_within_the_bound_or_doubtful(pose):
    """The whole estimator on the stripe scenes: the stated 90 % bound covers the real error, or
    the estimate is doubtful (it never claims an accuracy it does not have). Doubt is not the
    answer to everything: under the strong barrel (k1 -0.5, about 150 px at the corner) the soft fit
    reads the lens within 1 px and its bound (14-17 px) is far from the uncorrected frame, so the
    frame is corrected (doubt by benefit)."""
    for k1 in (-0.5, 0.15):
        truth = np.array([k1, float(manifold_k2(k1))])
        frame = distorted(stripes(homography(*pose, SIZE)), *truth)
        estimate = glradial.estimate(frame)
        error = float(max_displacement_px(np.array([estimate.k1, estimate.k2]), truth))
        assert math.isfinite(estimate.uncertainty_px)
        assert estimate.doubtful or error <= estimate.uncertainty_px, (estimate, error)
        if k1 < 0:
            assert not estimate.doubtful and estimate.reason == "ok" and error <= estimate.uncertainty_px, (estimate, error)


@pytest.mark.parametrize("sagitta", [40.0, 150.0])
def test_a_curved_arch_alone_is_not_read_as_a_line(sagitta):
    """A roof arch, no lens: one curved edge. Whether or not some lens of the range could straighten
    it (a 40 px sagitta could be one, 150 px not), one chain is no fit, and the estimator says so."""
    frame = _arch(sagitta)
    chains = detect_soft_chains(frame, lens_hint=(0.0, 0.0))
    assert len(chains.chains) >= 1  # the arch is found as an edge...
    fit = fit_soft_lines(frame, prior=(0.0, 0.0))
    assert not fit.ok and fit.reason in ("no_line_candidates", "too_few_chains")  # ...and not read
    estimate = glradial.estimate(frame)
    assert estimate.doubtful or estimate.uncertainty_px >= max_displacement_px(np.array([estimate.k1, estimate.k2]),
                                                                               np.zeros(2))


def test_the_soft_detector_runs_only_where_white_lines_give_no_fit(monkeypatch):
    """Speed: on a line-rich pitch frame the soft detection never runs (docs/BENCH.md's budget)."""
    from glradial.estimation import soft_lines

    def forbidden(*args, **kwargs):
        raise AssertionError("soft detection ran on a line-rich frame")

    monkeypatch.setattr(soft_lines, "fit_soft_lines", forbidden)
    frame = distorted(render(homography((40.0, -35.0, 18.0), (14.0, 30.0), 50.0, SIZE), SIZE), -0.3, 0.09)
    evidence = lens_estimate.frame_evidence(frame, (-0.25, 0.06), ViewFeatures(0.5, 40.0, 0.5, 1.0))
    assert evidence.lines is not None and not evidence.soft


def test_soft_evidence_is_bounded_with_its_own_quantile_or_ignored():
    """A soft fit is bounded by ``q_soft`` times the line scale; a model without ``q_soft`` falls back
    to the CNN, doubtful (``too_few_lines``), as before soft evidence existed; a noisy frame stays
    ``noise_frame`` even when its stretched noise gave soft "lines"."""
    trust = replace(shipped_trust(), q_soft=2.0)
    evidence = FrameEvidence((-0.2, 0.04), (-0.3, 0.07), 10.0, 3, 3, green=0.6, gray_std=30.0, edge_density=0.01,
                             fit_difficulty=12.0, soft=True)
    lens, source, bound, _, _ = trust.judge(evidence, "lines")
    assert source == "lines" and lens == (-0.3, 0.07)
    assert bound == pytest.approx(2.0 * trust.lines_scale(evidence))
    assert trust.judge(evidence, "lines")[2] == pytest.approx(2.0 / trust.q_lines * trust.judge(replace(evidence, soft=False), "lines")[2])
    lens, source, bound, doubtful, reason = replace(trust, q_soft=0.0).judge(evidence, "auto")
    assert (source, lens, doubtful, reason) == ("net", (-0.2, 0.04), True, "too_few_lines")
    noisy = replace(evidence, edge_density=0.5)
    assert trust.judge(noisy, "auto")[4] == "noise_frame"


@pytest.mark.parametrize("kind", ["blank", "noise", "tiny"])
def test_degenerate_frames_give_no_soft_fit_and_no_exception(kind):
    rng = np.random.default_rng(3)
    frame = {"blank": np.full((720, 1280, 3), 90, np.uint8),
             "noise": rng.integers(0, 256, (720, 1280, 3), dtype=np.uint8),
             "tiny": rng.integers(0, 256, (3, 5, 3), dtype=np.uint8)}[kind]
    gray = soft_gray(frame)
    assert gray.dtype == np.uint8 and gray.shape[1] == min(SOFT_WIDTH, frame.shape[1])
    fit = fit_soft_lines(frame, prior=(0.0, 0.0))
    assert not fit.ok and fit.reason
    assert np.isfinite([fit.k1, fit.k2]).all()


def test_bad_frames_are_refused_naming_the_argument():
    with pytest.raises(TypeError, match="frame"):
        fit_soft_lines([[0, 1], [2, 3]])
    with pytest.raises(ValueError, match="frame"):
        detect_soft_chains(np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(ValueError, match="frame"):
        soft_gray(np.full((8, 8, 3), 2.0))
