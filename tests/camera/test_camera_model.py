"""The camera model against independent oracles: OpenCV's projectPoints (with OpenCV distortion
coefficients converted from the width-normalised lens by ``Lens.to_opencv``), the homography of a
known camera, its decomposition, the half turn, and the pitch->pixel->pitch round trip."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from glradial import Lens
from glradial.camera.model import Camera, decompose_homography, lens_points_to_pitch

CAMERAS = [
    Camera.look_at((0.0, -70.0, 22.0), (-30.0, 5.0), 40.0, (1280, 720), Lens(-0.15, 0.02)),
    Camera.look_at((12.0, -55.0, 14.0), (40.0, -10.0), 14.0, (1920, 1080), Lens(-0.3, 0.07), roll=0.8),
    Camera.look_at((-5.0, -90.0, 30.0), (0.0, 0.0), 65.0, (720, 576), Lens(0.05, 0.0), roll=-1.5),
]


@pytest.mark.parametrize("cam", CAMERAS)
def test_projection_matches_opencv(cam):
    rng = np.random.default_rng(0)
    pts = rng.uniform([-52.5, -34.0, 0.0], [52.5, 34.0, 2.5], (400, 3))
    uv, z = cam.undistorted_lens_points(pts)
    r = np.hypot(*uv.T)
    # compare where the frame (and a margin) sees, in front of the camera
    use = (z > 0) & (r < 0.6)
    k, dist = cam.lens.to_opencv(cam.size, focal=cam.focal * cam.size[0])
    rvec, _ = cv2.Rodrigues(cam.rotation)
    ref, _ = cv2.projectPoints(pts[use], rvec, -cam.rotation @ cam.position, k, dist)
    np.testing.assert_allclose(cam.project(pts[use]), ref[:, 0], atol=1e-6)
    # N x 2 input is z = 0
    flat = pts[use].copy()
    flat[:, 2] = 0.0
    np.testing.assert_allclose(cam.project(flat[:, :2]), cam.project(flat), atol=1e-9)


def test_points_behind_the_camera_or_past_the_fold_are_nan():
    cam = CAMERAS[0]
    assert np.isnan(cam.project([[0.0, -100.0, 0.0]])).all()  # behind
    strong = Camera(cam.rotation, cam.position, cam.focal, cam.size, Lens(-0.6, 0.0))
    far = np.array([[-300.0, 200.0, 0.0]])  # undistorted radius beyond where k1 = -0.6 folds (0.745)
    assert np.hypot(*strong.undistorted_lens_points(far)[0].T)[0] > strong.lens.fold_radius()
    assert np.isnan(strong.project(far)).all()


def test_a_batch_of_cameras_projects_as_each_alone():
    # project_many takes each lens's fold radius from the scalar root for a few lenses and the vectorised
    # one for many: 20 cameras (some folding in view) in one batch give each camera's own projection
    from glradial.camera.model import project_many

    rng = np.random.default_rng(3)
    cams = [Camera(c.rotation, c.position, c.focal, c.size, Lens(k1, 0.1 * k1 * k1))
            for c in CAMERAS[:1] for k1 in rng.uniform(-0.7, 0.3, 20)]
    pts = np.column_stack([rng.uniform(-150, 150, (300, 2)), np.zeros(300)])
    many = project_many(np.stack([c.rotation for c in cams]), np.stack([c.position for c in cams]),
                        np.array([c.focal for c in cams]), np.array([c.lens.k1 for c in cams]),
                        np.array([c.lens.k2 for c in cams]), cams[0].size, pts)
    alone = np.stack([c.project(pts) for c in cams])
    ahead = np.stack([c.undistorted_lens_points(pts)[1] > 0 for c in cams])
    assert (np.isnan(alone).any(-1) & ahead).any() and np.isfinite(alone).any()  # some folded, some seen
    np.testing.assert_allclose(many, alone, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(np.isnan(many), np.isnan(alone))


@pytest.mark.parametrize("cam", CAMERAS)
def test_homography_is_the_pinhole_projection_of_the_plane(cam):
    pts = np.random.default_rng(1).uniform([-50, -30], [50, 30], (50, 2))
    pinhole = Camera(cam.rotation, cam.position, cam.focal, cam.size)
    p = np.column_stack([pts, np.ones(len(pts))]) @ cam.homography.T
    xy = p[:, :2] / p[:, 2:]
    ok = np.isfinite(pinhole.project(pts)).all(1)
    np.testing.assert_allclose(xy[ok], pinhole.project(pts)[ok], atol=1e-7)


@pytest.mark.parametrize("cam", CAMERAS)
def test_decomposition_recovers_a_known_camera(cam):
    h = cam.homography * -3.7  # any scale, either sign
    back = decompose_homography(h, cam.size)
    assert back is not None
    assert back.focal == pytest.approx(cam.focal, rel=1e-9)
    np.testing.assert_allclose(back.rotation, cam.rotation, atol=1e-9)
    np.testing.assert_allclose(back.position, cam.position, atol=1e-7)


def test_half_turn_and_mirror():
    cam = CAMERAS[0]
    turned = cam.turned()
    assert turned.position[1] > 0
    pts = np.random.default_rng(2).uniform([-50, -30], [50, 30], (20, 2))
    # the turned camera sees the turned pitch exactly as the camera sees the pitch
    np.testing.assert_allclose(turned.project(-pts), cam.project(pts), atol=1e-7)
    # its homography decomposes back to the near-touchline camera
    back = decompose_homography(turned.homography, cam.size)
    np.testing.assert_allclose(back.position, cam.position, atol=1e-7)
    # a mirrored pitch is no camera above the plane
    assert decompose_homography(cam.homography @ np.diag([-1.0, 1.0, 1.0]), cam.size) is None


def test_pan_tilt_roll_and_field_of_view():
    cam = Camera.look_at((0.0, -60.0, 20.0), (0.0, 0.0), 30.0, (1280, 720), roll=2.0)
    pan, tilt, roll = cam.pan_tilt_roll
    assert pan == pytest.approx(0.0, abs=1e-9)
    assert tilt == pytest.approx(np.degrees(np.arctan2(20.0, 60.0)))
    assert roll == pytest.approx(2.0)
    assert cam.hfov_deg == pytest.approx(30.0)
    right = Camera.look_at((0.0, -60.0, 20.0), (30.0, 0.0), 30.0, (1280, 720))
    assert right.pan_tilt_roll[0] == pytest.approx(np.degrees(np.arctan2(30.0, 60.0)))


@pytest.mark.parametrize("cam", CAMERAS[:2])
def test_pixels_back_to_the_pitch(cam):
    pts = np.random.default_rng(3).uniform([-20, -20], [20, 20], (30, 2))
    xy = cam.project(pts)
    ok = np.isfinite(xy).all(1) & (xy[:, 0] > 0) & (xy[:, 0] < cam.size[0]) & (xy[:, 1] > 0) & (xy[:, 1] < cam.size[1])
    np.testing.assert_allclose(lens_points_to_pitch(cam, xy[ok]), pts[ok], atol=1e-6)


@pytest.mark.parametrize("kwargs, word", [
    ({"rotation": np.eye(2)}, "rotation"), ({"rotation": np.diag([1.0, 1.0, -1.0])}, "rotation"),
    ({"position": [0.0, 1.0]}, "position"), ({"focal": -1.0}, "focal"), ({"focal": "1"}, "focal"),
    ({"size": (1280.5, 720)}, "width"), ({"lens": (0.1, 0.0)}, "lens")])
def test_bad_camera_arguments_are_named(kwargs, word):
    args = {"rotation": np.eye(3), "position": np.zeros(3), "focal": 1.0, "size": (1280, 720), **kwargs}
    with pytest.raises((ValueError, TypeError), match=word):
        Camera(**args)


def test_bad_points_are_named():
    with pytest.raises(ValueError, match="points"):
        CAMERAS[0].project(np.zeros((4, 4)))


def test_one_decomposition_serves_the_camera_and_the_first_guess():
    # the first guess's batched pinhole reading and decompose_homography agree with the known cameras
    from glradial.camera.line_hypotheses import camera_of

    h = np.stack([cam.homography * s for cam, s in zip(CAMERAS, (1.0, -2.5, 1e-3))])
    for cam, hk in zip(CAMERAS, h):
        focal, centre, metric = camera_of(hk[None], cam.size)
        assert metric[0] and focal[0] == pytest.approx(cam.focal, rel=1e-9)
        np.testing.assert_allclose(centre[0], cam.position, atol=1e-6)
        assert decompose_homography(hk, cam.size).focal == pytest.approx(float(focal[0]), rel=1e-12)
