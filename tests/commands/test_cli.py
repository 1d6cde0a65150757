"""The glradial command: correct (images, videos, --auto on video with a stand-in estimator),
convert, help texts, and the handling of every kind of bad input (one line on stderr, non-zero exit,
no output left behind)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import DATA

import glradial
from glradial import Lens
from glradial.cli import build_parser, main
from glradial.media.image_io import read_image, write_image
from glradial.media.video_io import EncodeOptions, VideoInfo, VideoReader, VideoWriter, probe_video

K1, K2 = -0.25, 0.05


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("glradial: error: "), err
    assert "Traceback" not in err
    return lines[0]


# -- correct: images ------------------------------------------------------------------------------
def test_correct_real_jpeg_matches_library_and_opencv(tmp_path):
    out = tmp_path / "road_corrected.png"
    assert main(["correct", str(DATA / "road_straight_lines1.jpg"), str(out), "--k1", str(K1), "--k2", str(K2),
                 "--backend", "cpu"]) == 0
    image = read_image(DATA / "road_straight_lines1.jpg")
    result = read_image(out)
    np.testing.assert_array_equal(result, glradial.correct(image, K1, K2, backend="cpu"))
    # independent oracle (docs/DESIGN.md): cv2.undistort with f = W; equal up to fixed-point rounding
    h, w = image.shape[:2]
    camera = np.array([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1]], np.float64)
    expected = cv2.undistort(image, camera, np.array([K1, K2, 0, 0], np.float64))
    assert np.abs(result.astype(int) - expected.astype(int)).mean() < 0.1


def test_correct_16bit_tiff_keeps_depth_and_options(tmp_path):
    rng = np.random.default_rng(4)
    base = cv2.resize(read_image(DATA / "chessboard_calibration2.jpg"), (160, 90), interpolation=cv2.INTER_AREA)
    image16 = base.astype(np.uint16) * 257 + rng.integers(0, 257, base.shape, dtype=np.uint16)
    source, out = tmp_path / "in16.tif", tmp_path / "out16.tif"
    write_image(source, image16)
    assert main(["correct", str(source), str(out), "--k1", "0.15", "--k2", "0.02", "--fit", "crop",
                 "--interpolation", "cubic", "--backend", "cpu"]) == 0
    result = read_image(out)
    assert result.dtype == np.uint16 and result.shape == image16.shape
    np.testing.assert_array_equal(result, glradial.correct(image16, 0.15, 0.02, fit="crop", interpolation="cubic", backend="cpu"))
    # the low byte survived: a 16-bit result, not an 8-bit one scaled up
    assert np.any(result % 257 != 0)


def test_correct_k2_defaults_to_zero(tmp_path):
    source, out = tmp_path / "in.png", tmp_path / "out.png"
    write_image(source, cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), (64, 36)))
    assert main(["-q", "correct", str(source), str(out), "--k1", "-0.2", "--backend", "cpu"]) == 0
    np.testing.assert_array_equal(read_image(out), glradial.correct(read_image(source), -0.2, 0.0, backend="cpu"))


# -- correct: videos --------------------------------------------------------------------------------
def _pan_video(path: Path, panorama: np.ndarray, n: int = 30, fps: float = 12.5, cut: int | None = None,
               marker: bool = False, lenses: np.ndarray | None = None) -> None:
    """160×90 frames panning over the real field panorama; optional cut to another area; optional
    frame index written into pixel (0, 0) (lossless .mkv only: FFV1 in planar RGB); optional
    per-frame lens applied."""
    lossless = dict(codec="ffv1", pix_fmt="gbrp") if path.suffix == ".mkv" else {}
    with VideoWriter(path, VideoInfo.of((160, 90), fps, **lossless)) as writer:
        for i in range(n):
            x0, y0, step = (200, 420, 4) if cut is None or i < cut else (1100, 380, -3)
            j = i if cut is None or i < cut else i - cut
            crop = panorama[y0 : y0 + 270, x0 + j * step : x0 + j * step + 480]
            frame = cv2.resize(crop, (160, 90), interpolation=cv2.INTER_AREA)
            if lenses is not None:
                frame = glradial.distort(frame, *lenses[i], backend="cpu")
            if marker:
                frame[0, 0] = (i, 255 - i, 0)
            writer.write(frame)


def test_correct_video_keeps_count_fps_size(tmp_path, field_panorama):
    source, out = tmp_path / "in.mp4", tmp_path / "out.mov"
    _pan_video(source, field_panorama, n=30, fps=12.5)
    assert main(["correct", str(source), str(out), "--k1", str(K1), "--k2", str(K2), "--backend", "cpu"]) == 0
    info = probe_video(out)
    assert (info.size, info.frame_count) == ((160, 90), 30)
    assert info.fps == pytest.approx(12.5, rel=1e-3)
    with VideoReader(source) as a, VideoReader(out) as b:
        for i, (frame_in, frame_out) in enumerate(zip(a, b)):
            if i % 10 == 0:
                expected = glradial.correct(frame_in, K1, K2, backend="cpu")
                # H.264 re-encoding at its default quality (crf 23): a few levels on average
                assert np.abs(frame_out.astype(int) - expected.astype(int)).mean() < 4.0
    assert _names(tmp_path) == ["in.mp4", "out.mov"]


def _decoded_frames(path: Path) -> int:
    """Frames FFmpeg decodes from ``path``, counted with PyAV directly (not glradial's reader)."""
    import av

    with av.open(str(path)) as container:
        return sum(1 for _ in container.decode(video=0))


def test_correct_video_says_frames_read_and_written_even_when_quiet(tmp_path, capsys):
    """An MPEG-TS has no frame count in its header: cut short, it decodes without error, so the
    one summary line (stdout, kept with -q) is what tells the user that the output is short."""
    rng = np.random.default_rng(0)
    whole, cut, out = tmp_path / "whole.ts", tmp_path / "cut.ts", tmp_path / "out.mp4"
    with VideoWriter(whole, VideoInfo.of((64, 36), 25), options=EncodeOptions(codec="libx264")) as writer:
        for _ in range(100):
            writer.write(rng.integers(0, 256, (36, 64, 3), dtype=np.uint8))  # noise: ~equal bytes per frame
    data = whole.read_bytes()
    cut.write_bytes(data[: len(data) // 2 // 188 * 188])  # whole TS packets: a clean cut, no decoding error
    decodable = _decoded_frames(cut)
    assert 20 < decodable < 80
    assert main(["-q", "correct", str(cut), str(out), "--k1", "-0.2", "--backend", "cpu"]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"wrote {out}: {decodable} frames read and written (input header: unknown)"]
    assert _decoded_frames(out) == decodable
    assert main(["correct", str(whole), str(out), "--k1", "-0.2", "--backend", "cpu", "-y", "-q"]) == 0
    assert capsys.readouterr().out.splitlines() == [f"wrote {out}: 100 frames read and written (input header: unknown)"]
    mp4 = tmp_path / "again.mp4"
    assert main(["correct", str(out), str(mp4), "--k1", "0.1", "--backend", "cpu", "-q"]) == 0  # an MP4 states its count
    assert capsys.readouterr().out.splitlines() == [f"wrote {mp4}: 100 frames read and written (input header: 100 frames)"]


def test_correct_auto_checks_the_encoder_before_estimating(tmp_path, capfd, monkeypatch):
    source, out = tmp_path / "in.mp4", tmp_path / "out.mp4"
    with VideoWriter(source, VideoInfo.of((64, 36), 25), options=EncodeOptions(codec="libx264")) as writer:
        for value in (0, 100, 200):
            writer.write(np.full((36, 64, 3), value, np.uint8))
    monkeypatch.setattr("glradial.video.video_pipeline.track_video", lambda *a, **k: pytest.fail("estimation started"))
    assert main(["correct", str(source), str(out), "--auto", "--preset", "ludicrous"]) == 1
    lines = [line for line in capfd.readouterr().err.splitlines() if line.strip()]
    assert lines == [f"glradial: error: cannot write {str(out)!r}: --preset 'ludicrous' is not a preset of libx264 "
                     "(ultrafast superfast veryfast faster fast medium slow slower veryslow placebo)"]
    assert _names(tmp_path) == ["in.mp4"]


def test_correct_video_auto_per_shot_and_doubt_policy(tmp_path, field_panorama, monkeypatch):
    """--auto on a small lossless clip with a cut, with a stand-in estimator keyed on the frame
    index stored in pixel (0, 0): the cut is found, the estimator runs on the shots' sampled frames
    only (every 2nd frame), once each, on every 4th sample at least (and on samples with few line
    chains: these 160 px frames show few), the sidecar has one row per frame with the shot, its
    doubt, reason and whether it was applied; a doubtful shot passes through untouched (lossless:
    identical pixels), and with --apply-doubtful every frame is corrected with its track lens."""
    n, cut = 24, 14
    k1 = np.where(np.arange(n) < cut, -0.3, -0.1)
    truth = np.stack([k1, 0.019 * k1 + 0.805 * k1**2], 1)
    calls = []

    def fake_estimator(_model=None, _method=None):
        def estimate(frame):
            assert frame.dtype == np.uint8 and frame.shape == (90, 160, 3)
            calls.append(int(frame[0, 0, 0]))
            return tuple(truth[int(frame[0, 0, 0])])

        return estimate

    monkeypatch.setattr("glradial.video.video_pipeline.default_estimator", fake_estimator)
    source = tmp_path / "in.mkv"
    _pan_video(source, field_panorama, n=n, fps=25, cut=cut, marker=True, lenses=truth)
    for extra in ([], ["--apply-doubtful"]):
        out = tmp_path / f"out{len(extra)}.mkv"
        calls.clear()
        assert main(["correct", str(source), str(out), "--auto", "--every", "2", "--backend", "cpu", *extra]) == 0
        sampled = set(range(0, cut, 2)) | set(range(cut, n, 2))
        # once each; not in frame order: a due sample's estimate runs ahead of an earlier sample's own
        # (few chains), on pass 1's estimator thread (glradial.video.shot_track._Shots)
        assert len(calls) == len(set(calls)) and {0, 8, 14, 22} <= set(calls) <= sampled, calls
        rows = np.genfromtxt(f"{out}.lens.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
        assert len(rows) == n
        assert np.all(rows["shot"][:cut] == 0) and np.all(rows["shot"][cut:] == 1)
        assert np.array_equal(rows["applied"], 1 - rows["doubtful"] if not extra else np.ones(n, int))
        assert all(bool(r) == bool(d) for r, d in zip(rows["reason"], rows["doubtful"]))
        with VideoReader(source) as a, VideoReader(out) as b:
            pairs = list(zip(a, b))
        assert len(pairs) == n
        for i in (3, cut + 1):
            if rows["applied"][i]:
                expected = glradial.correct(pairs[i][0], rows["k1"][i], rows["k2"][i], backend="cpu")
                difference = np.abs(pairs[i][1].astype(int) - expected.astype(int))
                assert difference.max() <= 8 and difference.mean() < 0.1, (difference.max(), difference.mean())
            else:
                assert np.array_equal(pairs[i][1], pairs[i][0])


def test_correct_image_auto_uses_estimator(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr("glradial.camera.estimator.Estimator.estimate", lambda self, frame, method="auto", pixel_aspect=1.0, pitch=False: Lens(-0.2, 0.03))
    source, out = tmp_path / "in.png", tmp_path / "out.png"
    write_image(source, cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), (64, 36)))
    assert main(["correct", str(source), str(out), "--auto", "--backend", "cpu"]) == 0
    assert "k1=-0.200000 k2=0.030000" in capsys.readouterr().out
    np.testing.assert_array_equal(read_image(out), glradial.correct(read_image(source), -0.2, 0.03, backend="cpu"))


def test_ctrl_c_leaves_no_output(tmp_path, field_panorama, monkeypatch):
    source, out = tmp_path / "in.mp4", tmp_path / "out.mp4"
    _pan_video(source, field_panorama, n=12)
    import glradial.remapping.planes

    count = {"n": 0}

    def interrupting(real):
        def interrupted(*args, **kwargs):
            count["n"] += 1
            if count["n"] == 5:
                raise KeyboardInterrupt
            return real(*args, **kwargs)
        return interrupted

    # the 5th frame corrected, in RGB or (yuv420p here) plane by plane
    monkeypatch.setattr("glradial.remapping.remap.correct", interrupting(glradial.remapping.remap.correct))
    monkeypatch.setattr("glradial.remapping.planes.remap_planes", interrupting(glradial.remapping.planes.remap_planes))
    assert main(["correct", str(source), str(out), "--k1", "-0.1", "--backend", "cpu"]) == 130
    assert _names(tmp_path) == ["in.mp4"]


# -- bad input --------------------------------------------------------------------------------------
def _bad_cases(tmp: Path) -> list[tuple[list[str], str, int]]:
    road = str(DATA / "road_straight_lines1.jpg")
    (tmp / "broken.mp4").write_bytes(bytes(range(256)) * 20)
    (tmp / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n but then nothing")
    return [
        (["correct", str(tmp / "missing.jpg"), str(tmp / "o.png"), "--k1", "0.1"], "does not exist", 1),
        (["correct", str(tmp / "broken.mp4"), str(tmp / "o.mp4"), "--k1", "0.1"], "cannot read video", 1),
        (["correct", str(tmp / "broken.png"), str(tmp / "o.png"), "--k1", "0.1"], "cannot decode image", 1),
        (["correct", road, str(tmp / "o.xyz"), "--k1", "0.1"], "INPUT is an image but OUTPUT", 2),
        (["correct", road, road, "--k1", "0.1", "-y"], "OUTPUT must differ from INPUT", 2),
        (["correct", road, str(tmp / "broken.png"), "--k1", "0.1"], "already exists (overwrite it with -y", 1),
        (["correct", road, str(tmp / "o.png"), "--k1", "0.1", "--codec", "h264"], "--codec is for videos", 2),
        (["correct", str(tmp / "broken.mp4"), str(tmp / "o.mp4"), "--k1", "0.1", "--crf", "20", "--bitrate", "2M"], "--crf or --bitrate", 2),
        (["correct", str(tmp / "broken.mp4"), str(tmp / "o.mp4"), "--k1", "0.1", "--bitrate", "fast"], "bit rate must be", 2),
        (["correct", str(tmp / "broken.mp4"), str(tmp / "o.mp4"), "--auto", "--lens-track", "t.csv"], "cannot be combined", 2),
        (["correct", str(tmp / "broken.mp4"), str(tmp / "o.mp4"), "--auto", "--sidecar", str(tmp / "o.mp4")], "must end in .csv or .json", 2),
        (["correct", road, str(tmp / "o.png"), "--k1", "0.1", "--auto"], "--k1/--k2/--cx/--cy/--pixel-aspect/--lens and --auto cannot be combined", 2),
        (["correct", road, str(tmp / "o.png")], "give the lens with --k1", 2),
        (["correct", road, str(tmp / "o.mp4"), "--k1", "0.1"], "INPUT is an image but OUTPUT", 2),
        (["correct", road, str(tmp / "nofolder" / "o.png"), "--k1", "0.1"], "output folder", 1),
        (["correct", road, str(tmp / "o.png"), "--k1", "-3"], "folds over", 1),
        (["correct", road, str(tmp / "o.png"), "--k1", "abc"], "expected a number", 2),
        (["correct", road, str(tmp / "o.png"), "--k1", "0.1", "--fit", "zoom"], "invalid choice: 'zoom'", 2),
        (["correct", road, str(tmp / "o.png"), "--k1", "0.1", "--sidecar", str(tmp / "s.csv")], "--sidecar needs --auto", 2),
        (["correct", road, str(tmp / "o.jpg"), "--k1", "0.1", "--every", "0"], "positive integer", 2),
        (["convert", "--from", "opencv", "--to", "width", "--size", "1920x1080", "-0.1", "0.01"], "needs --focal", 2),
        (["convert", "--from", "opencv", "--to", "width", "--size", "1920x1080", "--focal", "900", "-0.1", "0.01", "0.001", "0"],
         "cannot represent: p1=0.001", 1),
        (["convert", "--from", "width", "--to", "ffmpeg", "--size", "1920x1080", "-4", "0"], "accepts k1 in [-1, 1]", 1),
        (["frobnicate"], "invalid choice: 'frobnicate'", 2),
    ]


def test_every_bad_input_gets_one_clear_line_and_no_output(tmp_path, capsys):
    for argv, message, status in _bad_cases(tmp_path):
        before = _names(tmp_path)
        assert main(argv) == status, argv
        line = _error_line(capsys)
        assert message in line, (argv, line)
        assert _names(tmp_path) == before, argv  # nothing written, no temporary file left


def test_same_input_and_output_is_refused(tmp_path, capsys):
    source = tmp_path / "a.png"
    write_image(source, np.zeros((8, 8, 3), np.uint8))
    assert main(["correct", str(source), str(source), "--k1", "0.1"]) == 2
    assert "OUTPUT must differ from INPUT" in _error_line(capsys)


# -- convert ---------------------------------------------------------------------------------------
def _convert(capsys, *argv: str) -> tuple[float, float]:
    assert main(["convert", *argv]) == 0
    k1, k2 = capsys.readouterr().out.split()
    return float(k1), float(k2)


def test_convert_known_answers(capsys):
    w, h = 1920, 1080
    # OpenCV with f = W: the same numbers (docs/DESIGN.md); with f = W/2: k1 (W/f)^2 = 4 k1, k2 (W/f)^4 = 16 k2
    assert _convert(capsys, "--from", "opencv", "--to", "width", "--size", "1920x1080", "--focal", "1920", "-0.1", "0.01") == pytest.approx((-0.1, 0.01))
    assert _convert(capsys, "--from", "opencv", "--to", "width", "--size", "1920x1080", "--focal", "960", "-0.1", "0.01") == pytest.approx((-0.4, 0.16))
    # pixel units: k1 / W^2, k2 / W^4
    assert _convert(capsys, "--from", "width", "--to", "pixel", "--size", "1920x1080", "-0.2", "0.05") == pytest.approx((-0.2 / w**2, 0.05 / w**4))
    # height-normalised: r' = r W / H -> k1 (H/W)^2
    assert _convert(capsys, "--from", "glradial", "--to", "height", "--size", "1920x1080", "-0.2", "0.05") == pytest.approx((-0.2 * (h / w) ** 2, 0.05 * (h / w) ** 4))
    # ffmpeg: radius / half diagonal; lensfun: radius / half the shorter side
    corner = 0.5 * np.hypot(1, h / w)
    assert _convert(capsys, "--from", "width", "--to", "ffmpeg", "--size", "1920x1080", "-0.2", "0.05") == pytest.approx((-0.2 * corner**2, 0.05 * corner**4))
    half_short = 0.5 * h / w
    assert _convert(capsys, "--from", "width", "--to", "lensfun", "--size", "1920x1080", "-0.2", "0.05") == pytest.approx((-0.2 * half_short**2, 0.05 * half_short**4))


@pytest.mark.parametrize("convention", ["opencv", "ffmpeg", "lensfun", "pixel", "height", "width"])
def test_convert_round_trips(capsys, convention):
    extra = ["--focal", "1500"] if convention == "opencv" else []
    there = _convert(capsys, "--from", "width", "--to", convention, "--size", "1280x720", *extra, "-0.31", "0.07")
    back = _convert(capsys, "--from", convention, "--to", "width", "--size", "1280x720", *extra, repr(there[0]), repr(there[1]))
    assert back == pytest.approx((-0.31, 0.07), rel=1e-10)


def test_convert_json_and_opencv_matrix(capsys):
    assert main(["convert", "--from", "width", "--to", "opencv", "--size", "1280x720", "--json", "-0.2", "0.04"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert document["camera_matrix"] == [[1280.0, 0.0, 639.5], [0.0, 1280.0, 359.5], [0.0, 0.0, 1.0]]
    assert document["dist_coeffs"][:2] == pytest.approx([-0.2, 0.04])



def test_convert_opencv_extra_terms_point_to_the_option(capsys):
    """p1, p2, k3 that glradial cannot represent are refused with the command line's advice
    (--approximate), not the Python API's (approximate=True); with --approximate, k1, k2 are kept
    (f = W: the same numbers, docs/DESIGN.md)."""
    argv = ["convert", "--from", "opencv", "--to", "width", "--size", "1920x1080", "--focal", "1920", "--", "-0.1", "0.01", "0.001", "0", "0"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "p1=0.001" in err and "--approximate" in err and "approximate=True" not in err, err
    assert main(argv[:9] + ["--approximate"] + argv[9:]) == 0
    assert [float(v) for v in capsys.readouterr().out.split()] == pytest.approx([-0.1, 0.01])

# -- help --------------------------------------------------------------------------------------------
def test_every_option_is_documented():
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, sub in subparsers.choices.items():
        for action in sub._actions:
            assert action.help and action.help != argparse.SUPPRESS or action.dest == "help", (name, action.dest)
    correct_help = subparsers.choices["correct"].format_help()
    for unit in ("frames", "width-normalised", "px at 1920"):
        assert unit in correct_help


def test_every_command_is_installed():
    parser = build_parser()
    subparsers = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(subparsers.choices) == {"correct", "distort", "live", "estimate", "calibrate", "convert", "stmap", "crops", "stadium", "demo", "evaluate"}
    for name, sub in subparsers.choices.items():
        assert "unavailable" not in (sub.description or ""), (name, sub.description)


def test_parser_imports_nothing_heavy():
    """'glradial --help' builds every subparser without importing torch, moderngl or onnxruntime."""
    probe = ("import sys\nfrom glradial.cli import build_parser\nbuild_parser()\n"
             "print([m for m in ('torch', 'moderngl', 'onnxruntime') if m in sys.modules])")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr


def test_python_dash_m_runs():
    done = subprocess.run([sys.executable, "-m", "glradial", "--help"], capture_output=True, text=True, timeout=60,
                          cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0 and "correct" in done.stdout and "stmap" in done.stdout
    done = subprocess.run([sys.executable, "-m", "glradial", "correct", "x.png", "y.png", "--k1", "1", "--auto"],
                          capture_output=True, text=True, timeout=60, cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 2 and done.stderr.count("\n") == 1 and done.stderr.startswith("glradial: error:")


# -- with a real ONNX file (a stand-in model that always answers the same lens) -----------------------
def constant_model(path: Path, k1: float, k2: float, size: tuple[int, int] = (192, 108)) -> Path:
    """An ONNX graph with the bundled model's interface (uint8 N×H×W×3 RGB in, float N×2 out)
    whose output is (k1, k2) for every image (it still reads the input: mean × 0 + constant)."""
    import onnx
    from onnx import TensorProto, helper

    width, height = size
    nodes = [
        helper.make_node("Cast", ["images"], ["x"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["x"], ["m"], axes=[1, 2, 3], keepdims=1),
        helper.make_node("Reshape", ["m", "shape"], ["m2"]),
        helper.make_node("Mul", ["m2", "zero"], ["z"]),
        helper.make_node("Add", ["z", "lens"], ["k"]),
    ]
    graph = helper.make_graph(
        nodes, "constant_lens",
        [helper.make_tensor_value_info("images", TensorProto.UINT8, ["N", height, width, 3])],
        [helper.make_tensor_value_info("k", TensorProto.FLOAT, ["N", 2])],
        initializer=[
            helper.make_tensor("shape", TensorProto.INT64, [2], [-1, 1]),
            helper.make_tensor("zero", TensorProto.FLOAT, [1, 2], [0.0, 0.0]),
            helper.make_tensor("lens", TensorProto.FLOAT, [1, 2], [k1, k2]),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
    return path


def test_correct_auto_with_an_onnx_model(tmp_path, capsys):
    model = constant_model(tmp_path / "const.onnx", -0.21, 0.04)
    source, out = tmp_path / "in.png", tmp_path / "out.png"
    write_image(source, cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), (128, 72)))
    # a small road photo is no pitch (doubtful): applied only when asked
    assert main(["correct", str(source), str(out), "--auto", "--model", str(model), "--backend", "cpu", "--apply-doubtful"]) == 0
    captured = capsys.readouterr()
    assert "k1=-0.210000 k2=0.040000" in captured.out and "is doubtful (" in captured.err and "applied anyway" in captured.err
    expected = glradial.correct(read_image(source), np.float32(-0.21), np.float32(0.04), backend="cpu")
    np.testing.assert_array_equal(read_image(out), expected)
    # a model file that is not a model: one clear line, no output
    (tmp_path / "junk.onnx").write_bytes(b"junk")
    assert main(["correct", str(source), str(tmp_path / "o2.png"), "--auto", "--model", str(tmp_path / "junk.onnx")]) == 1
    assert "cannot load ONNX model" in _error_line(capsys)
    assert not (tmp_path / "o2.png").exists()


def test_estimate_video_per_shot_with_an_onnx_model(tmp_path, field_panorama):
    """The video hook of 'glradial estimate' (glradial.video.video_pipeline.estimate_video): shots found,
    one lens per shot on every frame of it (the model's where the shot has no geometry of its own),
    JSON and CSV sidecars agree."""
    from glradial.video.lens_track import load_lens_track
    from glradial.video.video_pipeline import estimate_video, track_report

    model = constant_model(tmp_path / "const.onnx", -0.21, 0.04)
    source = tmp_path / "cut.mp4"
    _pan_video(source, field_panorama, n=20, fps=25, cut=12)
    track = estimate_video(source, model=model, every=3)
    assert track.n_frames == 20 and track.per_shot()[1]["first_frame"] == 12
    for first, end in ((0, 12), (12, 20)):
        np.testing.assert_array_equal(track.lens[first:end], np.tile(track.lens[first], (end - first, 1)))
        if track.reason[first] == "no_geometry":
            np.testing.assert_allclose(track.lens[first], [-0.21, 0.04], atol=1e-6)
    text = track_report(track, "cut.mp4")
    shots = text.splitlines()  # the shot's lens, then the uncertainty and the per-frame methods
    assert len(shots) == 2 and all("method=net" in line and "uncertainty=" in line for line in shots)
    assert shots[0].startswith(f"cut.mp4: shot 0 frames 0-11 k1={track.lens[0, 0]:.6f} k2={track.lens[0, 1]:.6f} ")
    assert shots[1].startswith(f"cut.mp4: shot 1 frames 12-19 k1={track.lens[12, 0]:.6f} k2={track.lens[12, 1]:.6f} ")
    document = json.loads(track_report(track, "cut.mp4", per_frame=True, as_json=True))
    assert len(document["frames"]) == 20 and document["fps"] == pytest.approx(25)
    # samples at least 3 frames apart in each shot (0, 3, 6, 9 | 12, ...: the sparse decode numbers
    # what it decodes); the estimator runs on every 4th sample of a shot
    # (glradial.video.shot_track.ESTIMATE_EVERY): frames 0 and 12 (shot 0 ends before its 5th
    # sample), and on the samples whose line detection finds few chains (shot_evidence.FEW_CHAINS),
    # on no other frame
    estimated = sorted(r["frame"] for r in document["frames"] if r["k1_raw"] is not None)
    assert {0, 12} <= set(estimated) and len(estimated) <= 7, estimated
    assert all(b - a >= 3 for shot in ([f for f in estimated if f < 12], [f for f in estimated if f >= 12])
               for a, b in zip(shot, shot[1:])), estimated
    track.save(tmp_path / "t.json")
    track.save(tmp_path / "t.csv")
    for name in ("t.csv", "t.json"):
        back = load_lens_track(tmp_path / name, track.rate, track.size)
        np.testing.assert_allclose(back.lens, track.lens, rtol=1e-7)
        np.testing.assert_array_equal(back.shot, track.shot)
    assert json.loads((tmp_path / "t.json").read_text())["shots"] == track.per_shot()


def test_estimate_command_on_a_video_prints_shots(tmp_path, field_panorama, capsys):
    """'glradial estimate VIDEO': one line per detected shot with the model's lens; --json gives one
    document with per-frame rows when --per-frame is set; images and videos mix in one call."""
    model = constant_model(tmp_path / "const.onnx", -0.21, 0.04)
    video = tmp_path / "cut.mp4"
    _pan_video(video, field_panorama, n=20, fps=25, cut=12)
    image = tmp_path / "frame.png"
    write_image(image, cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), (128, 72)))
    assert main(["estimate", str(video), str(image), "--model", str(model), "--every", "4"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"{video}: shot 0 frames 0-11 k1=-0.210000 k2=0.040000 ") and "method=net" in lines[0]
    assert lines[1].startswith(f"{video}: shot 1 frames 12-19 k1=-0.210000 k2=0.040000 ") and "method=net" in lines[1]
    assert lines[2].startswith(f"{image}\tk1=-0.210000")
    assert main(["estimate", str(video), "--model", str(model), "--json", "--per-frame"]) == 0
    document = json.loads(capsys.readouterr().out)
    assert len(document["frames"]) == 20 and [s["first_frame"] for s in document["shots"]] == [0, 12]


def test_estimate_command_bad_images_get_one_line(tmp_path, capsys):
    """Missing and corrupt images (read by glradial.media.image_io.read_image) get one named error line."""
    model = constant_model(tmp_path / "const.onnx", -0.21, 0.04)
    assert main(["estimate", str(tmp_path / "missing.png"), "--model", str(model)]) == 1
    assert "missing.png" in _error_line(capsys)
    (tmp_path / "junk.jpg").write_bytes(b"not a jpeg")
    assert main(["estimate", str(tmp_path / "junk.jpg"), "--model", str(model)]) == 1
    line = _error_line(capsys)
    assert "junk.jpg" in line and "corrupt" in line
    gray16 = tmp_path / "gray16.png"
    write_image(gray16, np.full((36, 64), 40000, np.uint16))
    assert main(["estimate", str(gray16), "--model", str(model)]) == 0
    assert "k1=-0.210000" in capsys.readouterr().out


def test_quiet_anywhere_and_progress_on_stderr(tmp_path, capsys):
    """-q before or after the command silences the bars; without it, an enabled bar (tqdm) draws on
    its stream with the count, a disabled one draws nothing."""
    import io

    from glradial.commands import show_progress
    from glradial.media.progress import Progress

    parser = build_parser()
    base = ["correct", "a.png", "b.png", "--k1", "0.1"]
    assert show_progress(parser.parse_args(["-q", *base])) is False
    assert show_progress(parser.parse_args([*base, "-q"])) is False
    assert show_progress(parser.parse_args(base[:3] + ["--quiet"] + base[3:])) is False
    assert show_progress(parser.parse_args(base)) is None  # auto: only on a terminal
    drawn, silent = io.StringIO(), io.StringIO()
    for stream, enabled in ((drawn, True), (silent, False)):
        with Progress(7, "work", unit="frames", enabled=enabled, stream=stream) as bar:
            for _ in range(7):
                bar.update()
    assert "work" in drawn.getvalue() and "7/7" in drawn.getvalue()
    assert silent.getvalue() == ""


def test_correct_image_auto_decodes_the_image_once(tmp_path, monkeypatch, capsys):
    """Decide, then apply: ``correct --auto`` on an image decodes it once (the estimate and the
    correction share that decode), and the doubt policy is one function (glradial.lens.doubt)."""
    import glradial.lens.doubt
    import glradial.media.image_io as image_io

    source, out = tmp_path / "in.png", tmp_path / "out.png"
    write_image(source, cv2.resize(read_image(DATA / "road_straight_lines1.jpg"), (64, 36)))
    decodes, decisions = [], []
    real_read, real_applies = image_io.read_image, glradial.lens.doubt.applies
    monkeypatch.setattr(image_io, "read_image", lambda *a, **k: decodes.append(a[0]) or real_read(*a, **k))
    monkeypatch.setattr(glradial.lens.doubt, "applies", lambda *a: decisions.append(a) or real_applies(*a))
    doubtful = glradial.LensEstimate(-0.2, 0.03, uncertainty_px=30.0, method="net", doubtful=True, reason="weak_geometry")
    monkeypatch.setattr("glradial.camera.estimator.Estimator.estimate", lambda self, frame, **kw: doubtful)
    assert main(["correct", str(source), str(out), "--auto", "--backend", "cpu"]) == 0
    assert [str(p) for p in decodes] == [str(source)]
    assert decisions[0] == (True, "weak_geometry", False)  # decided once, here; the identity lens then applied
    real = real_read(source)
    np.testing.assert_array_equal(real_read(out), real)  # doubtful: the image passes through
    assert main(["correct", str(source), str(out), "--auto", "--backend", "cpu", "--apply-doubtful", "-y"]) == 0
    np.testing.assert_array_equal(real_read(out), glradial.correct(real, -0.2, 0.03, backend="cpu"))
