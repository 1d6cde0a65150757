"""``glradial.calibrate`` on rendered pitch views whose camera is known exactly (the markings drawn
through the camera, the lens applied with exact maps), frames that see too little, bad input, and the
``glradial calibrate`` command (JSON, overlay, top view, OpenTrackIO samples checked by the schema)."""

from __future__ import annotations

import json
from functools import lru_cache

import cv2
import numpy as np
import pytest

import glradial
from glradial import Lens
from glradial.camera.model import Camera
from glradial.camera.views import render_view
from glradial.cli import main
from glradial.export.opentrackio import validate_sample
from glradial.lens.metrics import max_displacement_px
from glradial.pitch import PitchTemplate

KEYPOINTS = PitchTemplate().keypoints()
#: The main camera at the halfway line, 30 m behind the touchline and 18 m up, seeing a penalty area
#: and the centre circle with a barrel lens.
TRUTH = Camera.look_at((3.0, -64.0, 18.0), (-25.0, 2.0), 48.0, (1280, 720), Lens(-0.18, 0.0187))


@lru_cache(maxsize=1)
def _view() -> np.ndarray:
    return render_view(TRUTH, seed=5).frame


def _keypoint_rms(est, truth: Camera) -> float:
    t = truth.project(KEYPOINTS)
    w, h = truth.size
    inside = np.isfinite(t).all(1) & (t[:, 0] >= 0) & (t[:, 0] < w) & (t[:, 1] >= 0) & (t[:, 1] < h)
    assert inside.sum() >= 6
    return float(np.sqrt(np.mean(np.sum((est.project(KEYPOINTS)[inside] - t[inside]) ** 2, axis=1))))


def _check_close(est, truth: Camera) -> None:
    assert not est.doubtful and est.reason == "ok"
    # sub-pixel keypoints (the fit's evidence is sub-pixel ridge points of anti-aliased lines)
    assert _keypoint_rms(est, truth) < 1.0
    assert est.focal == pytest.approx(truth.focal, rel=0.01)
    assert max_displacement_px(np.array([est.lens.k1, est.lens.k2]), np.array([truth.lens.k1, truth.lens.k2])) < 2.0
    np.testing.assert_allclose(est.position, truth.position, atol=1.5)  # metres, 70 m away
    assert est.uncertainty_px > 0 and {"halfway_line", "left_box_front", "centre_circle"} <= set(est.markings)


def test_calibrate_finds_the_exact_camera_with_its_own_first_guess():
    _check_close(glradial.calibrate(_view()), TRUTH)


def test_calibrate_from_a_given_first_guess_and_from_the_previous_frame():
    rng = np.random.default_rng(0)
    h = TRUTH.homography @ np.array([[1.0, 0.01, 0.8], [-0.01, 1.0, -0.5], [0.0, 0.0, 1.0]])  # ~1 m and 0.6 deg off
    est = glradial.calibrate(_view(), first_guess=[h])
    _check_close(est, TRUTH)
    moved = Camera(TRUTH.rotation, TRUTH.position + rng.normal(0, 0.5, 3), TRUTH.focal * 1.01, TRUTH.size, Lens(-0.15, 0.0))
    _check_close(glradial.calibrate(_view(), previous=moved), TRUTH)


def test_the_estimate_reports_a_consistent_camera():
    est = glradial.calibrate(_view())
    # the homography and its inverse are the undistorted view of the pitch plane
    p = np.column_stack([KEYPOINTS[:, :2], np.ones(32)]) @ est.homography.T
    back = (p / p[:, 2:]) @ est.homography_inverse.T
    np.testing.assert_allclose(back[:, :2] / back[:, 2:], KEYPOINTS[:, :2], atol=1e-6)
    assert est.hfov_deg == pytest.approx(TRUTH.hfov_deg, rel=0.01)
    d = est.as_dict()
    json.dumps(d)
    assert d["focal_px"] == pytest.approx(est.focal * 1280)


def _grass(size=(1280, 720)) -> np.ndarray:
    rng = np.random.default_rng(1)
    img = np.full((size[1], size[0], 3), (40, 110, 40), np.float64) + rng.normal(0, 3, (size[1], size[0], 3))
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("what", ["blank", "one_line", "noise"])
def test_frames_that_see_too_little_are_doubtful(what):
    if what == "blank":
        frame = _grass()
    elif what == "one_line":  # a single touchline: no crossing structure, the camera is not fixed
        frame = _grass()
        cv2.line(frame, (0, 500), (1279, 430), (235, 235, 235), 3, cv2.LINE_AA)
    else:
        frame = np.random.default_rng(2).integers(0, 256, (720, 1280, 3), dtype=np.uint8)
    est = glradial.calibrate(frame)
    assert est.doubtful and est.reason != "ok"
    if est.camera is None:
        with pytest.raises(ValueError, match="no camera"):
            est.project(KEYPOINTS)


def test_bad_input_names_the_argument():
    with pytest.raises(TypeError, match="frame"):
        glradial.calibrate("frame.png")
    with pytest.raises(ValueError, match="frame"):
        glradial.calibrate(np.zeros((4, 4, 5), np.uint8))
    with pytest.raises(TypeError, match="pitch"):
        glradial.calibrate(_grass(), pitch=(105, 68))
    with pytest.raises(ValueError, match=r"first_guess\[0\]"):
        glradial.calibrate(_grass(), first_guess=[np.eye(2)])


def test_cli_json_overlay_topview_and_opentrackio(tmp_path, capsys):
    src = tmp_path / "view.png"
    cv2.imwrite(str(src), _view()[:, :, ::-1])
    out = {n: tmp_path / n for n in ("overlay.png", "top.png", "samples.jsonl")}
    assert main(["calibrate", str(src), "--json", "--overlay", str(out["overlay.png"]), "--topview", str(out["top.png"]),
                 "--opentrackio", str(out["samples.jsonl"]), "--sensor-width-mm", "9.59"]) == 0
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert row["reason"] == "ok" and row["focal"] == pytest.approx(TRUTH.focal, rel=0.01)
    overlay = cv2.imread(str(out["overlay.png"]))
    assert overlay.shape == (720, 1280, 3) and np.any(overlay != cv2.imread(str(src)))
    top = cv2.imread(str(out["top.png"]))
    assert top.shape == (int(round(78 * 8)), int(round(115 * 8)), 3)
    sample = json.loads(out["samples.jsonl"].read_text().splitlines()[0])
    validate_sample(sample)
    assert sample["lens"]["pinholeFocalLength"] == pytest.approx(row["focal"] * 9.59)
    t = sample["transforms"][0]["translation"]
    assert [t["x"], t["y"], t["z"]] == pytest.approx(row["position_m"])


def test_cli_errors(tmp_path, capsys):
    src = tmp_path / "view.png"
    cv2.imwrite(str(src), _grass()[:, :, ::-1])
    assert main(["calibrate", str(tmp_path / "missing.png")]) != 0
    assert main(["calibrate", str(src), "--opentrackio", str(tmp_path / "s.jsonl")]) != 0
    assert "sensor" in capsys.readouterr().err
    assert main(["calibrate", str(src), "--overlay", str(tmp_path / "o.png")]) != 0  # no camera: nothing drawn
    assert not (tmp_path / "o.png").exists()
    capsys.readouterr()
    # calibrate measures the focal length: --focal-mm is neither listed nor taken
    assert main(["calibrate", "--help"]) == 0
    helped = capsys.readouterr().out
    assert "--sensor-width-mm" in helped and "--focal-mm" not in helped
    assert main(["calibrate", str(src), "--opentrackio", str(tmp_path / "s.jsonl"), "--sensor", "2/3-inch",
                 "--focal-mm", "20"]) != 0
    assert "unrecognized arguments: --focal-mm" in capsys.readouterr().err
    assert not (tmp_path / "s.jsonl").exists()


def test_cli_streams_the_samples(tmp_path):
    import socket

    src = tmp_path / "view.png"
    cv2.imwrite(str(src), _view()[:, :, ::-1])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(30)
        port = sock.getsockname()[1]
        assert main(["calibrate", str(src), "--send", f"127.0.0.1:{port}", "--sensor", "2/3-inch"]) == 0
        packet = sock.recv(65536)
    from glradial.export.opentrackio_udp import parse_packet

    parsed = parse_packet(packet)  # checksum and length checked; one sample fits one packet
    assert parsed.last
    payload = json.loads(parsed.payload.decode())
    validate_sample(payload)
    assert payload["transforms"][0]["id"] == "camera"


def test_cli_video_tracks_the_camera_frame_to_frame(tmp_path, capsys):
    from glradial.media.video_io import VideoInfo, VideoWriter

    # a slow pan: three frames, the camera turning 0.3 degrees a frame (lossless RGB)
    cams = [Camera.look_at(TRUTH.position, (-25.0 + 0.35 * i, 2.0), TRUTH.hfov_deg, TRUTH.size, TRUTH.lens) for i in range(3)]
    source = tmp_path / "pan.mkv"
    with VideoWriter(source, VideoInfo.of(TRUTH.size, 25, codec="ffv1", pix_fmt="gbrp")) as writer:
        for cam in cams:
            writer.write(render_view(cam, seed=5).frame)
    assert main(["calibrate", str(source), "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.strip().splitlines()]
    assert [r["frame"] for r in rows] == [0, 1, 2]
    for row, cam in zip(rows, cams):
        assert row["reason"] == "ok"
        assert row["focal"] == pytest.approx(cam.focal, rel=0.01)
        assert row["pan_deg"] == pytest.approx(cam.pan_tilt_roll[0], abs=0.1)
