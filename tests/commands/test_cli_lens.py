"""The command line's lens options: --cx/--cy/--pixel-aspect and --lens FILE (glradial numbers, an
estimate's JSON line, convert's JSON, an OpenCV calibration) for correct (images and videos) and
stmap; oracles: cv2.undistort with the calibration's K, and the library called directly."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from conftest import DATA

import glradial
from glradial import Lens
from glradial.cli import main
from glradial.export.stmap import lens_stmap, read_stmap
from glradial.media.image_io import read_image, write_image
from glradial.media.video_io import VideoInfo, VideoReader, VideoWriter

#: a 1280×720 calibration with its principal point 200 px right of and 60 px above the centre
K_OFF = [[1100.0, 0.0, 839.5], [0.0, 1078.0, 299.5], [0.0, 0.0, 1.0]]
DIST = [-0.28, 0.08, 0.0, 0.0, 0.0]
SMALL = (320, 180)


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("glradial: error: ") and "Traceback" not in err, err
    return lines[0]


@pytest.fixture()
def small_photo(tmp_path):
    image = cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), SMALL, interpolation=cv2.INTER_AREA)
    path = tmp_path / "road.png"
    write_image(path, image)
    return path, image


def test_correct_with_an_opencv_calibration_file(tmp_path, small_photo):
    """The calibration of the 1280×720 camera corrects a 320×180 copy of its frame: the lens is
    resolution independent, so the result equals cv2.undistort with K scaled to 320×180."""
    source, image = small_photo
    calibration = tmp_path / "calib.json"
    calibration.write_text(json.dumps({"camera_matrix": K_OFF, "dist_coeffs": DIST, "size": [1280, 720]}))
    out = tmp_path / "out.png"
    assert main(["correct", str(source), str(out), "-y", "--lens", str(calibration), "--backend", "cpu"]) == 0
    camera = np.array(K_OFF)
    camera[:2, :2] /= 4.0
    camera[:2, 2] = (camera[:2, 2] + 0.5) / 4.0 - 0.5
    expected = cv2.undistort(image, camera, np.array(DIST), newCameraMatrix=camera)
    inner = (slice(10, -10), slice(10, -10))
    diff = np.abs(read_image(out)[inner].astype(float) - expected[inner])
    assert diff.mean() < 0.3, diff.mean()


def test_correct_with_principal_point_options_and_lens_files(tmp_path, small_photo):
    source, image = small_photo
    lens = Lens(-0.3, 0.05, 0.05, -0.02, 0.98)
    expected = glradial.correct(image, lens, fit="crop", backend="cpu")
    out = tmp_path / "a.png"
    assert main(["correct", str(source), str(out), "-y", "--k1", "-0.3", "--k2", "0.05", "--cx", "0.05", "--cy", "-0.02",
                 "--pixel-aspect", "0.98", "--fit", "crop", "--backend", "cpu"]) == 0
    np.testing.assert_array_equal(read_image(out), expected)
    own = tmp_path / "lens.json"  # glradial's own numbers
    own.write_text(json.dumps({"k1": -0.3, "k2": 0.05, "cx": 0.05, "cy": -0.02, "pixel_aspect": 0.98}))
    assert main(["correct", str(source), str(out), "-y", "--lens", str(own), "--fit", "crop", "--backend", "cpu"]) == 0
    np.testing.assert_array_equal(read_image(out), expected)
    estimate = tmp_path / "estimate.json"  # a line of 'glradial estimate --json'
    estimate.write_text(json.dumps({"path": "frame.png", "k1": -0.3, "k2": 0.05, "method": "net", "uncertainty_px": 3.2,
                                    "chains": 2, "source": "frame.png"}))
    assert main(["correct", str(source), str(out), "-y", "--lens", str(estimate), "--backend", "cpu"]) == 0
    np.testing.assert_array_equal(read_image(out), glradial.correct(image, -0.3, 0.05, backend="cpu"))


@pytest.mark.parametrize("target", ["ffmpeg", "opencv"])
def test_lens_file_from_convert_json(tmp_path, small_photo, capsys, target):
    """'glradial convert --json' output: its k1, k2 are in the --to convention, the glradial pair
    is what --lens uses (also with --to opencv, whose output holds camera_matrix and dist_coeffs)."""
    source, image = small_photo
    assert main(["convert", "--from", "width", "--to", target, "--size", "320x180", "--json", "-0.2", "0.04"]) == 0
    converted = tmp_path / "converted.json"
    converted.write_text(capsys.readouterr().out)
    out = tmp_path / "b.png"
    assert main(["correct", str(source), str(out), "-y", "--lens", str(converted), "--backend", "cpu"]) == 0
    np.testing.assert_array_equal(read_image(out), glradial.correct(image, -0.2, 0.04, backend="cpu"))


def test_correct_video_with_a_lens_file(tmp_path):
    frames = [np.full((36, 64, 3), 40 * i, np.uint8) for i in range(4)]
    for i, frame in enumerate(frames):
        frame[:, 8 * i : 8 * i + 8] = 250
    source, out, lens_file = tmp_path / "in.mkv", tmp_path / "out.mkv", tmp_path / "lens.json"
    with VideoWriter(source, VideoInfo.of((64, 36), 10, codec="ffv1", pix_fmt="gbrp")) as writer:  # lossless RGB
        for frame in frames:
            writer.write(frame)
    lens_file.write_text(json.dumps({"camera_matrix": [[60.0, 0, 40.0], [0, 61.0, 15.0], [0, 0, 1]],
                                     "dist_coeffs": [-0.2, 0.03, 0, 0]}))  # size: the video's
    assert main(["correct", str(source), str(out), "-y", "--lens", str(lens_file), "--backend", "cpu"]) == 0
    lens = Lens.from_opencv([[60.0, 0, 40.0], [0, 61.0, 15.0], [0, 0, 1]], [-0.2, 0.03, 0, 0], (64, 36))
    with VideoReader(source) as a, VideoReader(out) as b:
        pairs = list(zip(a, b))
    assert len(pairs) == 4
    for frame_in, frame_out in pairs:  # FFV1 in planar RGB is lossless
        np.testing.assert_array_equal(frame_out, glradial.correct(frame_in, lens, backend="cpu"))


def test_stmap_with_principal_point(tmp_path):
    out = tmp_path / "map.npy"
    assert main(["stmap", "--k1", "-0.2", "--cx", "0.03", "--cy", "0.01", "--pixel-aspect", "1.02", "--size", "64x36",
                 "--out", str(out)]) == 0
    expected = lens_stmap(Lens(-0.2, 0.0, 0.03, 0.01, 1.02), (64, 36))
    np.testing.assert_array_equal(read_stmap(out), expected)
    calibration = tmp_path / "calib.json"
    calibration.write_text(json.dumps({"camera_matrix": K_OFF, "dist_coeffs": DIST, "size": [1280, 720]}))
    assert main(["stmap", "--lens", str(calibration), "--size", "128x72", "--out", str(out), "-y"]) == 0
    np.testing.assert_allclose(read_stmap(out), lens_stmap(Lens.from_opencv(K_OFF, DIST, (1280, 720)), (128, 72)))


@pytest.mark.parametrize(
    "args, contents, words, status",
    [
        (["--lens", "{lens}", "--k1", "0.1"], {"k1": 0.1}, "--lens cannot be combined with --k1", 2),
        (["--auto", "--cx", "0.1"], None, "--auto cannot be combined", 2),
        (["--cx", "0.1"], None, "give the lens with --k1", 2),
        (["--lens", "{lens}"], "not json", "is not JSON", 1),
        (["--lens", "{lens}"], [0.1, 0.0], "must hold a JSON object, got list", 1),
        (["--lens", "{lens}"], {"k2": 0.1}, "has neither \"k1\" nor an OpenCV", 1),
        (["--lens", "{lens}"], {"camera_matrix": K_OFF}, "needs both camera_matrix and dist_coeffs", 1),
        (["--lens", "{lens}"], {"camera_matrix": K_OFF, "dist_coeffs": [-0.2, 0, 0.01, 0], "size": [1280, 720]},
         "p1=0.01", 1),
        (["--lens", "{lens}"], {"k1": 0.1, "pixel_aspect": -1}, "pixel_aspect must be positive", 1),
        (["--lens", "{missing}"], None, "lens file .* does not exist", 1),
        # a misspelt key must not silently become k2 = 0: the error names it and the accepted keys
        (["--lens", "{lens}"], {"k1": -0.2, "k_2": 0.05}, "unknown key\\(s\\) 'k_2'; accepted: .*k2, method, path, pixel_aspect", 1),
        (["--lens", "{lens}"], {"camera_matrix": K_OFF, "dist_coeffs": DIST, "size": [1280, 720], "rms": 0.3},
         "OpenCV calibration\\) has unknown key\\(s\\) 'rms'; accepted: camera_matrix, dist_coeffs, size", 1),
        (["--lens", "{lens}"], {"glradial": [-0.2, 0.0], "k3": 0.1}, "convert --json' output\\) has unknown key\\(s\\) 'k3'", 1),
        # the lens_file schema: a value of the wrong type is named with its field
        (["--lens", "{lens}"], {"k1": "-0.2"}, "\\(glradial's numbers\\): k1: '-0.2' is not of type 'number'", 1),
        (["--lens", "{lens}"], {"glradial": [-0.2]}, "output\\): glradial: \\[-0.2\\] is too short", 1),
        # the CLI has no approximate=True: say what to do on the command line
        (["--lens", "{lens}"], {"camera_matrix": K_OFF, "dist_coeffs": [-0.2, 0, 0, 0, 0.02], "size": [1280, 720]},
         "k3=0.02. Set p1, p2, k3 ... to 0 in the file .* 'glradial convert --from opencv .*--approximate", 1),
        (["--k1", "-0.1", "--pixel-aspect", "0"], None, "expected a positive number", 2),
    ],
)
def test_lens_option_errors(tmp_path, small_photo, capsys, args, contents, words, status):
    source, _ = small_photo
    lens_file = tmp_path / "lens.json"
    if contents is not None:
        lens_file.write_text(contents if isinstance(contents, str) else json.dumps(contents))
    argv = [a.format(lens=lens_file, missing=tmp_path / "none.json") for a in args]
    out = tmp_path / "out.png"
    assert main(["correct", str(source), str(out), "-y", *argv]) == status
    import re

    line = _error_line(capsys)
    assert re.search(words, line), (words, line)
    assert "approximate=True" not in line
    assert not out.exists()
