"""glradial.lens.metrics: known answers of the displacement metric, the corner radius and the manifold."""

from __future__ import annotations

import numpy as np
import pytest

from glradial.lens.lens import corner_radius
from glradial.lens.metrics import CORNER_RADIUS_16_9, PAPER_SIZE, distortion_loss, manifold_k2, max_displacement, max_displacement_px


def test_displacement_of_a_k1_error_alone_is_its_value_at_the_corner():
    # |P(r, a) - P(r, b)| = 0.01 r^3 grows with r: its maximum is at the corner, r = 0.5 sqrt(1 + (9/16)^2)
    expected = 1920 * 0.01 * 0.5**3 * (1 + (9 / 16) ** 2) ** 1.5
    assert max_displacement_px((-0.3, 0.05), (-0.29, 0.05)) == pytest.approx(expected, rel=1e-12)
    assert CORNER_RADIUS_16_9 == pytest.approx(corner_radius(PAPER_SIZE), rel=1e-15)
    # a 4:3 frame's corner is farther out: same error, larger displacement
    r43 = corner_radius((640, 480))
    assert max_displacement_px((-0.3, 0.05), (-0.29, 0.05), radius=r43) == pytest.approx(1920 * 0.01 * r43**3, rel=1e-12)


def test_displacement_finds_an_interior_maximum():
    # d1 r^3 + d2 r^5 with d1 = 0.1, d2 = -0.3 peaks at r^2 = 3 d1 / (5 |d2|) = 0.2 inside the frame
    # (3.58e-3; at the corner it is back down to 2.2e-4); 256 samples of [0, 0.5737] put one within
    # 0.0012 of the peak, where the relative drop is below 1e-4 (second-order flat)
    r = np.sqrt(0.2)
    peak = 0.1 * r**3 - 0.3 * r**5
    assert float(max_displacement((0.1, -0.3), (0.0, 0.0))) == pytest.approx(peak, rel=1e-4)


def test_manifold_and_distortion_loss():
    assert manifold_k2(-0.2) == pytest.approx(0.019 * -0.2 + 0.805 * 0.04)
    a = np.array([[-0.3, manifold_k2(-0.3)]])
    assert distortion_loss(a, a)[0] == 0.0
    # a k1 error e alone: sum over the 64 radii of (e r^3)^2
    radii = np.linspace(0.0, 0.7, 64)
    b = a + [[0.01, 0.0]]
    assert distortion_loss(a, b)[0] == pytest.approx(np.sum((0.01 * radii**3) ** 2), rel=1e-12)
