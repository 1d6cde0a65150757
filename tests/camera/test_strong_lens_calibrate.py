"""``calibrate`` on views through a strong barrel lens (k1 -0.6 .. -0.7): the straight-line first guess
misses them, so the search runs on the frame undistorted with the line fit's lens and the refinement
starts from that lens (``glradial.camera.calibrate._strong_lens_retry``). Oracle: the exact camera the
procedural renderer used. Without the retry both views below are ``poor_fit`` with the lens 75-200 px
off (checked on the branch's base)."""

from __future__ import annotations

import numpy as np
import pytest

from glradial import Lens
from glradial.camera.calibrate import calibrate
from glradial.camera.first_guess import STRONG_LENS_PX, strong_lens
from glradial.camera.model import Camera
from glradial.camera.views import render_view
from glradial.lens.metrics import manifold_k2, max_displacement_px

SIZE = (640, 360)


def _truth(k1: float) -> Camera:
    # the main camera 16 m behind the touchline, 15 m up, a 55-degree view of the right half
    return Camera.look_at((0.0, -50.0, 15.0), (20.0, 0.0), 55.0, SIZE, Lens(k1, float(manifold_k2(k1))))


@pytest.mark.parametrize("k1", [-0.6, -0.7])
def test_a_strong_barrel_view_gets_a_sure_camera_with_its_lens(k1):
    truth = _truth(k1)
    est = calibrate(render_view(truth, seed=3).frame)
    assert not est.doubtful and est.reason == "ok"
    # the lens to within 2 px of max displacement at 1920 wide (the applied one moves the corner ~190 px;
    # the same bound test_calibrate holds the weak-lens view to), the focal length to 1 %
    err = max_displacement_px(np.array([est.lens.k1, est.lens.k2]), np.array([truth.lens.k1, truth.lens.k2]))
    assert err < 2.0
    assert est.focal == pytest.approx(truth.focal, rel=0.01)
    np.testing.assert_allclose(est.position, truth.position, atol=1.5)


def test_strong_lens_reads_only_strong_lenses():
    strong = strong_lens(render_view(_truth(-0.6), seed=3).frame)
    assert strong is not None
    assert max_displacement_px(np.array([strong.k1, strong.k2]), np.array([-0.6, manifold_k2(-0.6)])) < STRONG_LENS_PX
    weak = Camera.look_at((0.0, -50.0, 15.0), (20.0, 0.0), 55.0, SIZE, Lens(-0.02, float(manifold_k2(-0.02))))
    assert strong_lens(render_view(weak, seed=3).frame) is None


@pytest.mark.parametrize("k1", [-0.7, -0.2, 0.3])
def test_lens_width_scale_is_the_width_of_the_mapped_strip(k1):
    """The support's visibility test widens or squeezes a painted line by the lens
    (``glradial.camera.refine.lens_width_scale``). Oracle: two parallel lines 1e-5 apart pushed through
    the lens's forward map (``Lens.distort_points``), their distance measured across the mapped line."""
    from glradial.camera.refine import lens_width_scale

    lens, size = Lens(k1, float(manifold_k2(k1))), (1280, 720)
    rng = np.random.default_rng(5)
    uv = rng.uniform(-0.45, 0.45, (40, 2)) * (1.0, 0.5)
    uv[0] = (0.0, 0.0)
    angle = rng.uniform(0, np.pi, 40)
    tangent = np.column_stack([np.cos(angle), np.sin(angle)])
    normal = tangent[:, ::-1] * (-1, 1)
    eps = 1e-5

    def mapped(p):  # lens units (image widths from the centre) through the forward map, in lens units
        centre = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2])
        return (lens.distort_points(p * size[0] + centre, size) - centre) / size[0]

    a, b, c = mapped(uv), mapped(uv + eps * tangent), mapped(uv + eps * normal)
    direction = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    d = c - a
    across = np.abs(direction[:, 0] * d[:, 1] - direction[:, 1] * d[:, 0]) / eps
    np.testing.assert_allclose(lens_width_scale(lens, uv, tangent), across, rtol=1e-3)
    assert lens_width_scale(lens, uv[:1], tangent[:1])[0] == 1.0
