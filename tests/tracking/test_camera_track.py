"""The camera through a shot (glradial.tracking.camera_track) and pixels to the pitch (to_pitch), against
exact synthetic cameras: the renderer knows every frame's camera."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from glradial import Lens
from glradial.camera.calibrate import calibrate
from glradial.camera.estimate import CameraEstimate
from glradial.camera.model import Camera
from glradial.camera.views import render_view
from glradial.pitch import PitchTemplate
from glradial.tracking.camera_track import CameraTracker, carry, motion_of, track_cameras

KEYPOINTS = PitchTemplate().keypoints()


def _gap(a: Camera, b: Camera) -> float:
    """Median keypoint distance (px) between two cameras' projections."""
    d = np.linalg.norm(a.project(KEYPOINTS) - b.project(KEYPOINTS), axis=1)
    return float(np.nanmedian(d))


def _noisy(cam: Camera, seed: int, frame_seed: int, sigma: float = 3.0) -> np.ndarray:
    frame = render_view(cam, seed).frame.astype(np.float64)
    noise = np.random.default_rng(frame_seed).normal(0.0, sigma, frame.shape)
    return np.clip(frame + noise, 0, 255).astype(np.uint8)


def test_to_pitch_is_the_exact_inverse_of_project_lens_included():
    cam = Camera.look_at((5.0, -60.0, 18.0), (20.0, 5.0), 50.0, (1920, 1080), Lens(-0.32, 0.11))
    rng = np.random.default_rng(0)
    pitch = np.c_[rng.uniform(-52.5, 52.5, 400), rng.uniform(-34, 34, 400)]
    px = cam.project(pitch)
    seen = np.all(np.isfinite(px), axis=1) & (px[:, 0] > 0) & (px[:, 0] < 1919) & (px[:, 1] > 0) & (px[:, 1] < 1079)
    assert seen.sum() > 50
    back = CameraEstimate(cam, 2.0, False, "ok").to_pitch(px[seen])
    assert np.max(np.linalg.norm(back - pitch[seen], axis=1)) < 1e-3  # 1 mm on the pitch
    # above the horizon: no point of the plane
    assert np.all(np.isnan(cam.to_pitch([[960.0, -5000.0]])))
    with pytest.raises(ValueError, match="pixels must be an N×2"):
        cam.to_pitch(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="no camera"):
        CameraEstimate(None, 1280.0, True, "no_markings").to_pitch([[1.0, 2.0]])


def test_motion_of_reads_the_turn_and_zoom_and_carry_applies_it():
    a = Camera.look_at((0.0, -70.0, 20.0), (10.0, 0.0), 40.0, (1280, 720))
    turn = Rotation.from_rotvec([0.002, -0.015, 0.001]).as_matrix()
    b = Camera(turn @ a.rotation, a.position, a.focal * 1.04, a.size)
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-40, 50, 300), rng.uniform(-30, 30, 300)]
    ua, za = a.undistorted_lens_points(pts)
    ub, zb = b.undistorted_lens_points(pts)
    keep = (za > 0) & (zb > 0) & np.all(np.abs(ua) < 0.6, axis=1)
    noise = rng.normal(0, 0.1 / 1280, ub[keep].shape)  # 0.1 px
    motion = motion_of(a, ua[keep], ub[keep] + noise)
    assert motion.zoom == pytest.approx(1.04, rel=1e-3)
    assert np.allclose(motion.turn, turn, atol=1e-4)
    assert _gap(carry(a, motion), b) < 0.2
    assert _gap(carry(carry(a, motion), motion.inverse()), a) < 0.2


def test_a_static_camera_is_answered_on_every_frame_with_no_jitter():
    cam = Camera.look_at((0.0, -60.0, 16.0), (-30.0, 0.0), 45.0, (640, 360), Lens(-0.1, 0.02))
    tracker = CameraTracker(measure_every=2)
    answers = [tracker.push(_noisy(cam, 4, i), i / 25) for i in range(7)]
    assert all(not e.doubtful for e in answers)
    assert tracker.time == pytest.approx(6 / 25)
    proj = np.array([e.project(KEYPOINTS) for e in answers])
    jitter = np.linalg.norm(np.diff(proj, axis=0), axis=2)
    assert np.nanmedian(jitter) <= 0.5 * 640 / 1280  # the 0.5 px at 1280, here at 640
    assert max(_gap(e.camera, cam) for e in answers) < 2.0
    assert any(e.carried > 0 for e in answers) and any(e.carried == 0 for e in answers)


def _turning_shot(frames: int, seed: int) -> tuple[list[Camera], list[np.ndarray]]:
    """A pinhole camera turning and zooming about its centre: each frame the first one warped by its
    exact homography ``K_b R K_a⁻¹`` (the renderer's grain is drawn in the image, so rendering each
    frame anew would leave it still while the pitch moves)."""
    a = Camera.look_at((0.0, -60.0, 16.0), (-25.0, 2.0), 48.0, (640, 360))
    base = render_view(a, seed, players=150).frame
    cams, out = [], []
    for i in range(frames):
        turn = Rotation.from_rotvec([0.0, 0.004 * i, 0.0]).as_matrix()
        b = Camera(turn @ a.rotation, a.position, a.focal * 1.01 ** i, a.size)
        h = b.intrinsics @ turn @ np.linalg.inv(a.intrinsics)
        warped = cv2.warpPerspective(base, h, a.size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        cams.append(b)
        out.append(np.clip(warped + np.random.default_rng(i).normal(0, 2.0, warped.shape), 0, 255).astype(np.uint8))
    return cams, out


def _paint_out(frame: np.ndarray, cam: Camera) -> None:
    """The frame's markings painted over with its grass: alone it is declined."""
    grass = tuple(int(v) for v in np.median(frame[frame.shape[0] // 2:].reshape(-1, 3), axis=0))
    for _, line in PitchTemplate().polylines(0.25):
        xy = cam.project(line)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy) > 1:
            cv2.polylines(frame, [np.round(xy).astype(np.int32)], False, grass, 7)


def test_a_frame_that_alone_is_declined_takes_the_carried_camera():
    cams, frames = _turning_shot(5, 5)
    f = frames[3]
    _paint_out(f, cams[3])
    assert calibrate(f).doubtful
    tracker = CameraTracker(measure_every=1)
    answers = [tracker.push(frame) for frame in frames]
    assert not answers[3].doubtful and answers[3].carried == 1
    assert answers[3].uncertainty_px > answers[2].uncertainty_px
    assert _gap(answers[3].camera, cams[3]) < 1.5
    assert not answers[4].doubtful and answers[4].carried == 0


def test_tracker_rejects_what_it_cannot_use():
    with pytest.raises(ValueError, match="measure_every"):
        CameraTracker(measure_every=0)
    tracker = CameraTracker()
    with pytest.raises(TypeError, match="frame"):
        tracker.push([[0, 0]])
    with pytest.raises(ValueError, match="time"):
        tracker.push(np.zeros((36, 64, 3), np.uint8), math.nan)
    tracker.push(np.zeros((36, 64, 3), np.uint8))
    with pytest.raises(ValueError, match="frame size changed"):
        tracker.push(np.zeros((72, 128, 3), np.uint8))


def test_a_doubtful_estimate_says_why_in_numbers():
    from glradial.camera.calibrate import doubt_checks, doubt_reason
    from glradial.camera.estimate import camera_trust

    t = camera_trust()
    sure = {"inliers": 400, "elements": 4, "directions": 3, "spread": 0.3, "log_focal_sd": 0.01, "height_m": 20.0,
            "hfov_deg": 40.0, "support": 0.95, "rms_fit_px": 1.0, "missing": 0, "share": 0.9}
    assert doubt_checks(sure, t) == [] and doubt_reason(sure, t) == "ok"
    bad = {**sure, "support": t["min_support"] - 0.1, "rms_fit_px": t["max_rms_px"] + 0.6}
    failed = doubt_checks(bad, t)
    assert [reason for reason, _ in failed] == ["poor_fit", "poor_fit"] and doubt_reason(bad, t) == "poor_fit"
    detail = "; ".join(text for _, text in failed)
    assert detail == (f"support {bad['support']:.2f} < {t['min_support']}; "
                      f"rms {bad['rms_fit_px']:.2f} px > {t['max_rms_px']} px")
    cam = Camera.look_at((0.0, -60.0, 16.0), (0.0, 0.0), 45.0, (1280, 720))
    est = CameraEstimate(cam, 5.0, True, "poor_fit", ("halfway_line", "centre_circle"), 3.1, 400, 0.6, 0.01, detail=detail)
    assert est.why == detail
    assert CameraEstimate(cam, 5.0, False, "ok", ("a", "b"), 1.0, 400, 0.9, 0.01).why == ""
    assert est.as_dict()["why"] == est.why
    lost = CameraEstimate(cam, 9.0, True, "track_lost", carried=12, detail=detail)
    assert lost.why == f"carried 12 frames, bound 9.0 px; {detail}"


@pytest.mark.parametrize("focal, position", [(1e-8, (0.0, -60.0, 16.0)), (0.001, (0.0, -60.0, 16.0)),
                                             (1.0, (0.0, -2e9, 16.0)), (1.0, (0.0, -60.0, -3.0))])
def test_a_degenerate_fit_carries_no_camera(focal, position):
    cam = Camera(np.eye(3), np.array(position), focal, (1280, 720))
    est = CameraEstimate(cam, 3.0, False, "ok", ("a", "b"), 1.0, 300, 0.9, 0.01)
    assert est.camera is None and est.doubtful and est.reason == "poor_fit"
    assert "degenerate" in est.why and "position_m" not in est.as_dict()


def test_track_cameras_answers_the_frames_before_the_first_sure_one():
    cams, frames = _turning_shot(12, 6)
    _paint_out(frames[0], cams[0])  # no camera found on frame 0: the next search is on frame 10
    forward = [CameraTracker().push(f) for f in frames[:1]]
    assert forward[0].doubtful
    both = list(track_cameras(iter(frames)))  # lag 25: frame 10 is read before frame 0 is decided
    assert [i for i, _ in both] == list(range(12))
    assert all(not e.doubtful for _, e in both)
    assert max(_gap(e.camera, c) for (_, e), c in zip(both, cams)) < 1.5
    with pytest.raises(ValueError, match="lag"):
        next(track_cameras(iter(frames), lag=-1))
