"""The line fit's misfit signal (issue 35): how far its centred lens moves when decentring terms are
fitted with it, and the bound term it feeds.

Oracles: chains are straight lines of a 1280 x 720 frame moved by ``Lens.distort_points`` with the
principal point off centre (the physical lens, not the decentring model the signal linearises); the
centred lens that best straightens them is found by ``scipy.optimize.least_squares``; the lens the
signal should move towards is the true lens's radial part, whose displacement from the centred fit
is computed directly."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import least_squares

from glradial import Lens
from glradial.estimation.decentring import MIN_CHAINS, centre_shift_px
from glradial.estimation.lens_estimate import judge
from glradial.estimation.trust import FrameEvidence, load_trust, shipped_trust
from glradial.lens import lensfuncs
from glradial.lens.metrics import manifold_k2, max_displacement_px

SIZE = (1280, 720)
NO_PRIOR = 1e6  # k2 prior sigma: none


def chains(lens: Lens, n_lines: int = 8, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """16 points of each of ``n_lines`` straight lines across the frame, moved by ``lens``, inside the
    frame, in frame-centred lens units; and their chain index."""
    width, height = SIZE
    rng = np.random.default_rng(seed)
    points, chain = [], []
    for _ in range(n_lines):
        xs, ys = rng.uniform(0, width, 2), rng.uniform(0, height, 2)
        ideal = np.array([xs[0], ys[0]]) + np.linspace(-0.5, 1.5, 200)[:, None] * np.array([xs[1] - xs[0], ys[1] - ys[0]])
        seen = lens.distort_points(ideal, SIZE)
        seen = seen[np.all((seen >= 0) & (seen <= [width - 1, height - 1]), axis=1)]
        if len(seen) < 20:
            continue
        seen = seen[np.linspace(0, len(seen) - 1, 16).astype(int)]
        points.append(np.stack([(seen[:, 0] + 0.5 - width / 2) / width, (seen[:, 1] + 0.5 - height / 2) / width], axis=1))
        chain.append(np.full(16, len(points) - 1))
    return np.concatenate(points), np.concatenate(chain)


def centred_fit(points: np.ndarray, chain: np.ndarray, start: tuple[float, float]) -> np.ndarray:
    """The centred ``(k1, k2)`` that makes the chains straightest (perpendicular residuals, px)."""
    def residuals(k):
        undistorted, _ = lensfuncs.undistort_point_exact(points, k[0], k[1])
        out = []
        for c in range(chain.max() + 1):
            q = undistorted[chain == c] - undistorted[chain == c].mean(axis=0)
            out.append(q @ np.linalg.svd(q, full_matrices=False)[2][1] * SIZE[0])
        return np.concatenate(out)
    return least_squares(residuals, start).x


def test_a_centred_lens_read_exactly_does_not_move():
    for k1 in (-0.6, -0.2, 0.1):
        k = (k1, float(manifold_k2(k1)))
        points, chain = chains(Lens(*k))
        assert centre_shift_px(points, chain, np.ones(chain.max() + 1), SIZE[0], *k, NO_PRIOR) < 0.01


@pytest.mark.parametrize("k1", [-0.3, -0.6])
@pytest.mark.parametrize("angle", [0.3, 2.0])
def test_the_shift_measures_how_far_an_off_centre_lens_leaves_the_centred_fit(k1, angle):
    """The shift approximates the displacement between the centred fit and the true lens's radial
    part: one Gauss-Newton step with the decentring of a principal-point offset to first order, so
    within 25 % (+ 0.3 px) for offsets up to 3 % of the width and 35 % at 8 % (the neglected terms
    are of second order in the offset; measured 0-29 %), and growing with the offset."""
    k = (k1, float(manifold_k2(k1)))
    shifts = []
    for offset in (0.01, 0.03, 0.08):
        points, chain = chains(Lens(*k, offset * math.cos(angle), offset * math.sin(angle)))
        fit = centred_fit(points, chain, k)
        truth = float(max_displacement_px(np.array(k), fit))
        shift = centre_shift_px(points, chain, np.ones(chain.max() + 1), SIZE[0], fit[0], fit[1], NO_PRIOR)
        assert abs(shift - truth) <= (0.25 if offset <= 0.03 else 0.35) * truth + 0.3, (offset, shift, truth)
        shifts.append(shift)
    assert shifts[0] < shifts[1] < shifts[2]


def test_too_few_chains_or_an_unreachable_radius_is_not_measured():
    k = (-0.4, float(manifold_k2(-0.4)))
    points, chain = chains(Lens(*k, 0.05, 0.0))
    two = chain < MIN_CHAINS - 1
    assert math.isnan(centre_shift_px(points[two], chain[two], np.ones(MIN_CHAINS - 1), SIZE[0], *k, NO_PRIOR))
    # a pincushion lens so strong that it folds before the frame's corners: no undistortion, no figure
    assert math.isnan(centre_shift_px(points * 3.0, chain, np.ones(chain.max() + 1), SIZE[0], 1.5, 1.0, NO_PRIOR))


def test_the_bound_grows_in_quadrature_with_the_shift_whichever_answer_is_taken():
    """The term is added after the choice between the line fit and the CNN: the answer is the same
    with and without it, the bound is the old one in quadrature with weight x shift, and a frame
    without a measured shift (or a model with weight 0) states what it stated before."""
    trust = replace(shipped_trust(), misfit_weight=0.5)
    off = replace(trust, misfit_weight=0.0)
    k = (-0.5, float(manifold_k2(-0.5)))
    pitch = dict(grass=0.5, grass_width=1.0, net_error_px=3.0)
    for lines, sigma in ((k, 4.0), ((-0.45, float(manifold_k2(-0.45))), 400.0)):  # the fit taken; the CNN taken
        evidence = FrameEvidence(k, lines, sigma, 6, 6, families=1, **pitch)
        before = judge(evidence, "auto", off)
        for shift, expected in ((30.0, math.hypot(before.uncertainty_px, 15.0)), (None, before.uncertainty_px),
                                (math.nan, before.uncertainty_px)):
            after = judge(replace(evidence, centre_shift_px=shift), "auto", trust)
            assert (after.k1, after.k2, after.method) == (before.k1, before.k2, before.method)
            assert after.uncertainty_px == pytest.approx(expected)
        assert judge(replace(evidence, centre_shift_px=30.0), "auto", off).uncertainty_px == before.uncertainty_px
    assert {judge(FrameEvidence(k, k, 4.0, 6, 6, **pitch), "auto", off).method,
            judge(FrameEvidence(k, (-0.45, float(manifold_k2(-0.45))), 400.0, 6, 6, **pitch), "auto", off).method} == {"lines", "net"}
    restored = FrameEvidence.from_dict(replace(FrameEvidence(k, k, 4.0, 6, 6), centre_shift_px=12.5).as_dict())
    assert restored.centre_shift_px == 12.5


def test_a_negative_misfit_weight_is_refused(tmp_path):
    path = tmp_path / "trust.json"
    replace(shipped_trust(), misfit_weight=-1.0).save(path)
    with pytest.raises(ValueError, match="misfit_weight"):
        load_trust(path)
