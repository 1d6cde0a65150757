"""``glradial live --camera``: the camera of every frame carried by the image motion, its OpenTrackIO
samples, OUTPUT none, and the transports (SRT on loopback through the system's ffmpeg).

Oracles: analytic geometry (a camera turned and zoomed about its centre: the motion homography is
``K_t R K_0^-1``), procedural pitch views with their exact cameras (glradial.camera.views), the
OpenTrackIO schema of shared/specs read by jsonschema, the OpenTrackIO rotation convention written
out here (intrinsic Z, X, Y; Y forward, Z up), and ffmpeg as the SRT peer."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SPEC = ROOT.parent / "shared" / "specs" / "opentrackio" / "schema.json"
SIZE, RATE = (640, 360), 25
NIL = "urn:uuid:00000000-0000-0000-0000-000000000000"


def _validator():
    import jsonschema

    path = SPEC if SPEC.is_file() else ROOT / "glradial" / "data" / "opentrackio_schema.json"
    return jsonschema.Draft202012Validator(json.loads(path.read_text()))


def _turn(axis: str, degrees: float) -> np.ndarray:
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def _otio_rotation(rotation: dict) -> np.ndarray:
    """World -> camera rows (right, down, forward) of OpenTrackIO's pan/tilt/roll, written from the standard."""
    axes = _turn("z", rotation["pan"]) @ _turn("x", rotation["tilt"]) @ _turn("y", rotation["roll"])
    return np.stack([axes[:, 0], -axes[:, 2], axes[:, 1]])


def _shot(frames: int, pan_deg: float = 0.4, zoom: float = 1.01):
    """A main camera panning and zooming about its fixed centre (pinhole), and its views: the
    procedural view of the first camera warped by ``K_t R K_0^-1`` (exact for a pinhole camera
    turning about its centre: the texture moves with the pitch)."""
    import cv2

    from glradial.camera.model import Camera
    from glradial.camera.views import render_view

    first = Camera.look_at((0.0, -60.0, 20.0), (-20.0, 5.0), 40.0, SIZE)
    first = Camera(first.rotation, first.position, first.focal * 1.1, SIZE)  # a little in: the pan shows no border
    image = render_view(Camera(first.rotation, first.position, first.focal / 1.1, SIZE), seed=2, players=6).frame
    cameras, views = [], []
    for i in range(frames):
        camera = Camera(_turn("y", pan_deg * i) @ first.rotation, first.position, first.focal * zoom**i, SIZE)
        warp = camera.homography @ np.linalg.inv(Camera(first.rotation, first.position, first.focal / 1.1, SIZE).homography)
        cameras.append(camera)
        views.append(cv2.warpPerspective(image, warp, SIZE, flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT))
    return cameras, views


def test_a_homography_reads_as_the_turn_and_a_zoom_about_the_centre():
    from glradial.camera.model import Camera
    from glradial.lens.lens import Lens
    from glradial.tracking.camera_track import carry
    from glradial.tracking.live_camera import motion_of_homography

    start = Camera.look_at((5.0, -55.0, 18.0), (10.0, 3.0), 35.0, (1280, 720), Lens(-0.1, 0.02))
    turn = _turn("y", 3.0) @ _turn("x", -1.5) @ _turn("z", 0.4)
    focal = start.focal * 1.3
    motion = np.diag([focal, focal, 1.0]) @ turn @ np.diag([1 / start.focal, 1 / start.focal, 1.0])  # lens units
    moved = carry(start, motion_of_homography(start, 2.5 * motion))  # any scale of a homography
    assert moved.focal == pytest.approx(focal, rel=1e-12)
    np.testing.assert_allclose(moved.rotation, turn @ start.rotation, atol=1e-12)
    np.testing.assert_array_equal(moved.position, start.position)
    assert moved.lens == start.lens


def test_tracker_carries_the_first_fit_through_a_pan_and_zoom():
    from glradial.pitch.template import PitchTemplate
    from glradial.tracking.live_camera import LiveCameraTracker

    cameras, frames = _shot(8)
    tracker = LiveCameraTracker(SIZE, RATE, worker="inline", every=100)  # one fit, on frame 0; the rest carried
    points = PitchTemplate().keypoints()
    for index, (camera, frame) in enumerate(zip(cameras, frames)):
        state = tracker.push(frame, index / RATE)
        assert (state.index, state.fit_index, state.reason, state.doubtful) == (index, 0, "ok", False)
        truth, seen = camera.project(points), state.camera.project(points)
        inside = np.isfinite(truth).all(1) & (np.abs(truth - np.array(SIZE) / 2) < np.array(SIZE) / 2).all(1)
        rms = float(np.sqrt(np.mean(np.sum((seen[inside] - truth[inside]) ** 2, 1))))
        assert inside.sum() >= 4 and rms <= 2.0, (index, rms)  # px at 640 wide
    assert tracker.fits == 1


def test_tracker_says_lost_after_a_cut_and_pending_before_any_fit():
    from glradial.tracking.live_camera import LOST, PENDING, LiveCameraTracker

    cameras, frames = _shot(2)
    tracker = LiveCameraTracker(SIZE, RATE, worker="inline", every=100)
    assert tracker.push(frames[0], 0.0).reason == "ok"
    flat = np.full_like(frames[0], 90)  # a cut to a frame with nothing to follow
    state = tracker.push(flat, 1 / RATE)
    assert (state.doubtful, state.reason, state.camera) == (True, LOST, None)
    pending = LiveCameraTracker(SIZE, RATE, worker="thread")  # its worker warming up: nothing fitted yet
    try:
        first = pending.push(frames[0], 0.0)
        assert (first.doubtful, first.reason, first.camera) == (True, PENDING, None)
    finally:
        pending.close()


def test_a_wide_frame_is_fitted_on_a_copy_and_its_camera_sees_the_stream():
    """A 1280x720 frame is fitted on its 960-wide copy (what the white lines are found on anyway):
    the copy is OpenCV's area resize of the frame (a decoded frame converted and shrunk by FFmpeg in
    one pass: within 2 grey levels on average), and the camera the tracker gives sees 1280x720,
    within 2 px (at 1280) of the procedural view's exact camera."""
    import av
    import cv2

    from glradial.camera.model import Camera
    from glradial.camera.views import render_view
    from glradial.pitch.template import PitchTemplate
    from glradial.tracking.live_camera import LiveCameraTracker, _fit_copy

    size = (1280, 720)
    truth = Camera.look_at((0.0, -60.0, 20.0), (-20.0, 5.0), 40.0, size)
    frame = render_view(truth, seed=2, players=6).frame
    copy = _fit_copy(frame)
    np.testing.assert_array_equal(copy, cv2.resize(frame, (960, 540), interpolation=cv2.INTER_AREA))
    decoded = av.VideoFrame.from_ndarray(frame, format="rgb24").reformat(format="yuv420p")
    shrunk = _fit_copy(decoded)
    assert shrunk.shape == (540, 960, 3)
    reference = cv2.resize(decoded.to_ndarray(format="rgb24"), (960, 540), interpolation=cv2.INTER_AREA)
    assert np.mean(np.abs(shrunk.astype(int) - reference)) < 2.0
    tracker = LiveCameraTracker(size, RATE, worker="inline")
    state = tracker.push(frame, 0.0)
    assert (state.reason, state.fit_index) == ("ok", 0) and state.camera.size == size
    points = PitchTemplate().keypoints()
    expected, seen = truth.project(points), state.camera.project(points)
    inside = np.isfinite(expected).all(1) & (np.abs(expected - np.array(size) / 2) < np.array(size) / 2).all(1)
    assert inside.sum() >= 4
    assert float(np.sqrt(np.mean(np.sum((seen[inside] - expected[inside]) ** 2, 1)))) <= 2.0


def test_the_first_fit_starts_on_the_first_frame_and_a_push_may_wait_for_it():
    """``start_on`` sends the first decoded frame to the worker at once; frame 0's push, allowed to
    wait, gets that fit (sure, ``fit_index`` 0) rather than "pending", and the frames after it carry it."""
    from glradial.tracking.live_camera import LOST, LiveCameraTracker

    cameras, frames = _shot(3)
    tracker = LiveCameraTracker(worker="thread")
    with pytest.raises(ValueError, match="for_stream"):
        tracker.start_on(frames[0])
    tracker.for_stream(SIZE, RATE)
    with pytest.raises(ValueError, match="640x360"):
        tracker.start_on(frames[0][:100])
    try:
        tracker.wait_ready()
        tracker.start_on(frames[0])
        first = tracker.push(frames[0], 0.0, wait=120.0)
        assert (first.fit_index, first.reason, first.doubtful, tracker.fits) == (0, "ok", False, 1)
        states = [tracker.push(frame, i / RATE) for i, frame in enumerate(frames[1:], 1)]
        assert all(s.fit_index >= 0 and not s.doubtful for s in states)
        with pytest.raises(ValueError, match="after the first push"):
            tracker.start_on(frames[0])
    finally:
        tracker.close()
    skipped = LiveCameraTracker.started(SIZE, RATE, worker="thread")  # frame 0 fitted, then never pushed (dropped)
    try:
        skipped.start_on(frames[0], 0.0)
        state = skipped.push(frames[1], 1 / RATE, wait=120.0)  # the fit of frame 0 lands: no motion from it to here
        assert (state.index, state.doubtful, state.reason, state.camera, skipped.fits) == (1, True, LOST, None, 1)
    finally:
        skipped.close()


def test_camera_samples_validate_and_carry_the_calibrate_json_fields():
    from glradial.camera.calibrate import calibrate
    from glradial.export.opentrackio import TrackingCamera, camera_frame_sample
    from glradial.tracking.live_camera import LiveCamera

    cameras, frames = _shot(1)
    estimate = calibrate(frames[0])
    assert not estimate.doubtful
    otio = TrackingCamera(SIZE, 9.59, 1.0, rate=RATE, timecode="10:00:00:00")
    live = LiveCamera(3, estimate, False, "ok", estimate.uncertainty_px, 0)
    sample = camera_frame_sample(live.fields(), otio, 3, NIL, timestamp_s=0.12)
    assert _validator().is_valid(sample)
    mine = sample["custom"]["glradial"]
    written = estimate.as_dict()  # what calibrate --json prints for the frame
    for name in ("homography", "k1", "k2", "doubtful", "reason", "uncertainty_px"):
        assert mine[name] == written[name], name
    transform = sample["transforms"][0]
    np.testing.assert_allclose(_otio_rotation(transform["rotation"]), estimate.rotation, atol=1e-9)
    np.testing.assert_allclose([transform["translation"][k] for k in "xyz"], estimate.position, atol=1e-9)
    assert sample["lens"]["pinholeFocalLength"] == pytest.approx(estimate.focal * 9.59)
    assert sample["timing"]["timecode"]["frames"] == 3 and sample["tracker"]["status"] == "camera tracked"
    doubtful = camera_frame_sample(LiveCamera(4, None, True, "pending", math.nan, -1).fields(), otio, 4, NIL)
    assert _validator().is_valid(doubtful)
    assert "transforms" not in doubtful and "lens" not in doubtful
    assert doubtful["tracker"]["status"] == "camera tracked: DOUBTFUL (pending)"


def _clip(path: Path, frames: list[np.ndarray]) -> Path:
    from glradial.media.video_io import EncodeOptions, VideoInfo, VideoWriter

    with VideoWriter(path, VideoInfo.of(SIZE, RATE, codec="libx264"), options=EncodeOptions(crf=16, preset="ultrafast")) as writer:
        for frame in frames:
            writer.write(frame)
    return path


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs ffmpeg")
def test_cli_camera_to_a_samples_file_without_video(tmp_path):
    cameras, frames = _shot(12)
    clip = _clip(tmp_path / "shot.mp4", frames)
    samples = tmp_path / "samples.jsonl"
    done = subprocess.run([sys.executable, "-m", "glradial", "live", str(clip), "none", "--camera", "--sensor", "2/3-inch",
                           "--opentrackio", str(samples), "--max-delay", "1000"], cwd=ROOT, capture_output=True, text=True,
                          timeout=180)
    assert done.returncode == 0, done.stderr
    assert "written to no video (OUTPUT none)" in done.stderr
    rows = [json.loads(line) for line in samples.read_text().splitlines()]
    validator = _validator()
    assert rows and all(validator.is_valid(r) for r in rows)
    numbers = [r["timing"]["sequenceNumber"] for r in rows]
    assert numbers == sorted(set(numbers))
    for row in rows:  # a sure sample is a camera; a doubtful one says why
        fields = row["custom"]["glradial"]
        assert fields["doubtful"] == (fields["reason"] != "ok")
        assert ("transforms" in row) == ("k1" in fields)


@pytest.mark.parametrize("argv, message", [
    (["-", "none", "--k1", "-0.1"], "OUTPUT 'none' writes no video"),
    (["-", "none", "--camera", "--sensor", "2/3-inch", "--send", "127.0.0.1:9", "--k1", "-0.1"], "give no lens"),
    (["-", "none", "--camera", "--sensor", "2/3-inch"], "give --send HOST:PORT or --opentrackio"),
    (["-", "none", "--camera", "--send", "127.0.0.1:9"], "--sensor-width-mm"),
    (["-", "none", "--camera", "--sensor", "2/3-inch", "--focal-mm", "9", "--send", "127.0.0.1:9"], "measures the focal length"),
])
def test_camera_options_are_checked_before_the_input(capsys, argv, message):
    from glradial.cli import main

    assert main(["live", *argv]) == 2
    assert message in capsys.readouterr().err
