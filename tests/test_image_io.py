"""glradial.media_io and glradial.atomic: bit depth, channel order, fps/size/frame count, atomic writes,
clear errors on bad files."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from glradial.atomic import atomic_path, atomic_write_text
from glradial.media_io import (
    VideoReader,
    VideoWriter,
    media_kind,
    probe_video,
    read_image,
    write_image,
)


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("ext", [".png", ".tif", ".tiff"])
def test_16bit_round_trip_is_exact(tmp_path, ext):
    rng = np.random.default_rng(1)
    image = rng.integers(0, 65536, size=(23, 31, 3), dtype=np.uint16)
    path = tmp_path / f"a{ext}"
    write_image(path, image)
    back = read_image(path)
    assert back.dtype == np.uint16 and back.shape == image.shape
    np.testing.assert_array_equal(back, image)


def test_float32_tiff_and_rgba_png_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    image = rng.random((9, 13, 3), dtype=np.float32)
    write_image(tmp_path / "f.tif", image)
    np.testing.assert_array_equal(read_image(tmp_path / "f.tif"), image)
    rgba = rng.integers(0, 256, size=(9, 13, 4), dtype=np.uint8)
    write_image(tmp_path / "a.png", rgba)
    np.testing.assert_array_equal(read_image(tmp_path / "a.png"), rgba)
    grey = rng.integers(0, 256, size=(9, 13), dtype=np.uint8)
    write_image(tmp_path / "g.png", grey)
    np.testing.assert_array_equal(read_image(tmp_path / "g.png"), grey)


def test_channel_order_is_explicit(tmp_path):
    """A pure red RGB image is stored as red: OpenCV's own reader (BGR) sees it in channel 2."""
    red = np.zeros((4, 5, 3), np.uint8)
    red[..., 0] = 200
    write_image(tmp_path / "r.png", red, order="rgb")
    opencv = cv2.imread(str(tmp_path / "r.png"), cv2.IMREAD_UNCHANGED)
    assert opencv[..., 2].min() == 200 and opencv[..., :2].max() == 0
    np.testing.assert_array_equal(read_image(tmp_path / "r.png", order="bgr"), opencv)
    np.testing.assert_array_equal(read_image(tmp_path / "r.png"), red)


def test_real_jpeg_reads_like_opencv(chessboard):
    from conftest import DATA

    image = read_image(DATA / "chessboard_calibration2.jpg")
    np.testing.assert_array_equal(image, chessboard)


def test_image_errors_are_clear_and_leave_nothing(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.png"):
        read_image(tmp_path / "missing.png")
    (tmp_path / "bad.png").write_bytes(b"not a png at all")
    with pytest.raises(ValueError, match="cannot decode image"):
        read_image(tmp_path / "bad.png")
    with pytest.raises(ValueError, match="unknown file extension '.xyz'"):
        media_kind(tmp_path / "a.xyz")
    with pytest.raises(ValueError, match=r"\.jpg cannot store uint16"):
        write_image(tmp_path / "deep.jpg", np.zeros((4, 4, 3), np.uint16))
    with pytest.raises(FileNotFoundError, match="output folder"):
        write_image(tmp_path / "no" / "such.png", np.zeros((4, 4, 3), np.uint8))
    assert _files(tmp_path) == ["bad.png"]


def _synthetic_video(path: Path, n: int = 30, size=(160, 90), fps: float = 12.5) -> np.ndarray:
    """A moving gradient + square; returns the frames written (RGB)."""
    width, height = size
    yy, xx = np.mgrid[0:height, 0:width]
    frames = []
    with VideoWriter(path, size, fps) as writer:
        for i in range(n):
            frame = np.stack([(xx * 255 // width), (yy * 255 // height), np.full_like(xx, 40)], -1).astype(np.uint8)
            frame[30:60, 10 + 3 * i : 40 + 3 * i] = (250, 250, 250)
            writer.write(frame)
            frames.append(frame)
    return np.array(frames)


@pytest.mark.parametrize("ext", [".mp4", ".avi", ".mkv"])
def test_video_round_trip_keeps_count_fps_size(tmp_path, ext):
    path = tmp_path / f"v{ext}"
    frames = _synthetic_video(path)
    info = probe_video(path)
    assert info.size == (160, 90)
    assert info.frame_count == 30
    assert info.fps == pytest.approx(12.5, rel=1e-3)
    with VideoReader(path) as reader:
        back = np.array(list(reader))
    # lossy codecs: mean error of a few grey levels (mp4v/MJPG at default quality); FFV1 is lossless
    error = np.abs(back.astype(int) - frames.astype(int)).mean()
    assert error < (0.01 if ext == ".mkv" else 6.0), error
    # channel order kept: the red channel carries the horizontal gradient
    assert np.corrcoef(back[0, 80, :, 0], np.arange(160))[0, 1] > 0.99
    assert _files(tmp_path) == [f"v{ext}"]  # no temporary file left


def test_video_writer_abort_leaves_nothing(tmp_path):
    path = tmp_path / "out.mp4"
    with pytest.raises(KeyboardInterrupt):
        with VideoWriter(path, (32, 18), 25) as writer:
            writer.write(np.zeros((18, 32, 3), np.uint8))
            raise KeyboardInterrupt
    assert _files(tmp_path) == []
    with pytest.raises(ValueError, match="18×32×3 uint8"):
        with VideoWriter(path, (32, 18), 25) as writer:
            writer.write(np.zeros((18, 30, 3), np.uint8))
    assert _files(tmp_path) == []


def test_corrupt_and_missing_videos(tmp_path):
    (tmp_path / "broken.mp4").write_bytes(os.urandom(2000))
    with pytest.raises(ValueError, match="cannot read video"):
        VideoReader(tmp_path / "broken.mp4")
    with pytest.raises(FileNotFoundError, match="nope.mp4"):
        VideoReader(tmp_path / "nope.mp4")
    with pytest.raises(ValueError, match="image extension"):
        VideoWriter(tmp_path / "x.png", (32, 18), 25)


def test_atomic_helpers(tmp_path):
    target = tmp_path / "t.txt"
    atomic_write_text(target, "one")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert target.read_text() == "one" and _files(tmp_path) == ["t.txt"]
    with pytest.raises(OSError, match="nothing was written"):
        with atomic_path(tmp_path / "empty.txt"):
            pass
    assert _files(tmp_path) == ["t.txt"]


def test_outputs_get_ordinary_permissions(tmp_path):
    """Temporary files are private (0600); the finished file gets what open() would give, or the
    mode of the file it replaces."""
    mask = os.umask(0o022)
    try:
        write_image(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
        assert (tmp_path / "a.png").stat().st_mode & 0o777 == 0o644
        os.chmod(tmp_path / "a.png", 0o640)
        write_image(tmp_path / "a.png", np.ones((4, 4, 3), np.uint8))
        assert (tmp_path / "a.png").stat().st_mode & 0o777 == 0o640
    finally:
        os.umask(mask)
