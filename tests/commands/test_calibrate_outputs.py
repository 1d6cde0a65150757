"""What ``glradial calibrate`` says, line by line (issue 44): pitch positions of a detector's boxes
(MOTChallenge CSV) against the exact rendered camera, bad detections refused with nothing written,
folders, the JSON rows' time and units, OpenTrackIO samples timed as live's and without a transform
when doubtful, the overlay of a doubtful camera."""

from __future__ import annotations

import argparse
import csv
import json

import cv2
import numpy as np
import pytest

from glradial.camera.estimate import CameraEstimate
from glradial.camera.model import Camera
from glradial.camera.views import DOUBT_RGB, OVERLAY_RGB, overlay, render_view
from glradial.cli import main
from glradial.commands.calibrate import _Outputs
from glradial.export.opentrackio import validate_sample
from glradial.lens.lens import Lens

TRUTH = Camera.look_at((3.0, -64.0, 18.0), (-25.0, 2.0), 48.0, (1280, 720), Lens(-0.18, 0.0187))
#: Players' feet on the pitch (metres) in view of TRUTH.
FEET = np.array([[-30.0, 5.0], [-20.0, -10.0], [-40.0, 12.0], [-10.0, 0.0]])


@pytest.fixture(scope="module")
def view(tmp_path_factory):
    path = tmp_path_factory.mktemp("view") / "view.png"
    cv2.imwrite(str(path), render_view(TRUTH, seed=5).frame[:, :, ::-1])
    return path


def _mot(path, rows) -> None:
    path.write_text("".join(",".join(str(v) for v in r) + "\n" for r in rows))


def _boxes(frame: int = 1) -> list[tuple]:
    px = TRUTH.project(FEET)
    return [(frame, i + 1, x - 10, y - 60, 20, 60, 0.9, -1, -1, -1) for i, (x, y) in enumerate(px)]


def test_points_map_box_feet_to_pitch_metres(tmp_path, view, capsys):
    det, out = tmp_path / "det.txt", tmp_path / "pos.csv"
    _mot(det, _boxes())
    assert main(["calibrate", str(view), "--points", str(det), "--positions", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [int(r["id"]) for r in rows] == [1, 2, 3, 4] and all(r["camera_doubtful"] == "0" for r in rows)
    got = np.array([[float(r["x_m"]), float(r["y_m"])] for r in rows])
    # the fitted camera is sub-pixel on the keypoints (test_calibrate): ~0.1 m at 40-70 m
    assert np.max(np.linalg.norm(got - FEET, axis=1)) < 0.3


def test_points_of_a_video_frame_by_frame(tmp_path, capsys):
    from glradial.media.video_io import VideoInfo, VideoWriter

    cam = TRUTH.with_size((640, 360))
    source = tmp_path / "still.mkv"
    frame = render_view(cam, seed=5).frame
    with VideoWriter(source, VideoInfo.of((640, 360), 25, codec="ffv1", pix_fmt="gbrp")) as writer:
        for i in range(4):
            writer.write(np.clip(frame + np.random.default_rng(i).normal(0, 2, frame.shape), 0, 255).astype(np.uint8))
    px = cam.project(FEET)
    det, out = tmp_path / "det.txt", tmp_path / "pos.csv"
    _mot(det, [(f, i + 1, x - 5, y - 30, 10, 30, 0.8) for f in (2, 4) for i, (x, y) in enumerate(px)])
    assert main(["calibrate", str(source), "--points", str(det), "--positions", str(out)]) == 0
    rows = list(csv.DictReader(out.open()))
    assert [int(r["frame"]) for r in rows] == [2] * 4 + [4] * 4
    got = np.array([[float(r["x_m"]), float(r["y_m"])] for r in rows])
    assert np.max(np.linalg.norm(got - np.vstack([FEET, FEET]), axis=1)) < 0.5  # 640 wide: twice 1280's 0.3 m, about
    _mot(det, [(5, 1, 10, 10, 10, 30, 0.8)])
    out.unlink()
    assert main(["calibrate", str(source), "--points", str(det), "--positions", str(out)]) != 0
    assert "boxes in frame 5 but" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("rows, message", [
    ([(1, 1, 10, 10, 20)], "line 1: expected frame,id,left,top,width,height,conf"),
    ([(1, 1, "a", 10, 20, 60, 0.9)], "line 1: not numbers"),
    ([(0, 1, 10, 10, 20, 60, 0.9)], "counts from 1"),
    ([(1, 1, 10, 10, -20, 60, 0.9)], "positive width"),
    ([(1, 1, 3000, 10, 20, 60, 0.9)], "line 1: the box's bottom centre (3010.0, 70.0) lies outside the 1280x720 frame"),
    ([(2, 1, 10, 10, 20, 60, 0.9)], "boxes in frame 2 but"),
])
def test_bad_detections_are_refused_with_nothing_written(tmp_path, view, capsys, rows, message):
    det, out = tmp_path / "det.txt", tmp_path / "pos.csv"
    _mot(det, rows)
    assert main(["calibrate", str(view), "--points", str(det), "--positions", str(out)]) != 0
    assert message in capsys.readouterr().err
    assert not out.exists() and list(tmp_path.iterdir()) == [det]


def test_a_frame_with_no_camera_leaves_its_positions_empty_and_says_so(tmp_path, capsys):
    grass = tmp_path / "grass.png"
    cv2.imwrite(str(grass), np.full((720, 1280, 3), (40, 120, 50), np.uint8))
    det, out = tmp_path / "det.txt", tmp_path / "pos.csv"
    _mot(det, _boxes())
    assert main(["calibrate", str(grass), "--points", str(det), "--positions", str(out)]) == 0
    assert "no sure camera in 1 frame(s) with boxes" in capsys.readouterr().err
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 4 and all(r["x_m"] == "" and r["camera_doubtful"] == "1" for r in rows)


def test_points_and_positions_go_together(view, capsys):
    assert main(["calibrate", str(view), "--points", "det.txt"]) != 0
    assert "--points DETECTIONS and --positions OUT go together" in capsys.readouterr().err


def test_a_folder_is_calibrated_image_by_image(tmp_path, view, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for name in ("a.png", "b.png"):
        (folder / name).write_bytes(view.read_bytes())
    (folder / "notes.txt").write_text("not an image")
    assert main(["calibrate", str(folder), "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["path"] for r in rows] == [str(folder / "a.png"), str(folder / "b.png")]
    assert all(not r["doubtful"] and r["units"]["uncertainty_px"].startswith("px at 1280") for r in rows)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["calibrate", str(empty)]) != 0
    assert "holds no still image" in capsys.readouterr().err


def _args(**more) -> argparse.Namespace:
    base = dict(json=False, opentrackio="x.jsonl", send=None, sensor="2/3-inch", sensor_width_mm=None,
                sensor_height_mm=None, distortion_model="U-D", doubtful_transforms=False, cbor=False)
    return argparse.Namespace(**{**base, **more})


def test_opentrackio_samples_are_timed_as_live_and_doubtful_ones_carry_no_transform():
    from fractions import Fraction

    sure = CameraEstimate(TRUTH, 2.0, False, "ok", ("a", "b"), 0.5, 500, 0.95, 0.01)
    doubtful = CameraEstimate(TRUTH, 9.0, True, "poor_fit", ("a", "b"), 0.5, 500, 0.6, 0.01)
    for asked in (False, True):
        out = _Outputs(_args(doubtful_transforms=asked), None)
        out.rate = Fraction(25)
        samples = [out._sample(7, sure, 0.28, 1), out._sample(8, doubtful, 0.32, 1)]
        for sample, index, time_s in zip(samples, (7, 8), (0.28, 0.32)):
            validate_sample(sample)
            timing = sample["timing"]
            assert timing["sequenceNumber"] == index and timing["sampleRate"] == {"num": 25, "denom": 1}
            assert sample["static"]["camera"]["captureFrameRate"] == {"num": 25, "denom": 1}
            assert timing["sampleTimestamp"]["seconds"] + timing["sampleTimestamp"]["nanoseconds"] * 1e-9 == pytest.approx(time_s)
        assert "transforms" in samples[0]
        assert ("transforms" in samples[1]) == asked and samples[1]["custom"]["glradial"]["doubtful"]


def test_the_overlay_of_a_doubtful_camera_says_so():
    frame = np.zeros((720, 1280, 3), np.int32)
    sure = overlay(frame.astype(np.uint8), TRUTH).astype(np.int32)[40:]
    doubtful = overlay(frame.astype(np.uint8), TRUTH, doubt="support 0.73 < 0.83").astype(np.int32)
    banner, doubtful = doubtful[:30], doubtful[40:]
    # the colours as drawn (anti-aliased on black): magenta (blue over green) and orange (green over blue)
    magenta = lambda im: (im[..., 2] > im[..., 1] + 20).sum()  # noqa: E731
    orange = lambda im: (im[..., 1] > im[..., 2] + 20).sum()  # noqa: E731
    assert OVERLAY_RGB[2] > OVERLAY_RGB[1] and DOUBT_RGB[1] > DOUBT_RGB[2]
    assert magenta(sure) > 1000 and orange(sure) == 0
    assert orange(doubtful) > 300 and magenta(doubtful) == 0
    assert orange(doubtful) < 0.7 * magenta(sure)  # dashed
    assert orange(banner) > 50  # the DOUBTFUL banner's text
