"""glradial.media.image_io and glradial.media.atomic: bit depth, channel order, atomic writes, overwrite,
clear errors on bad files."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from glradial.media.atomic import atomic_path, atomic_write_text
from glradial.media.image_io import media_kind, read_image, write_image


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
    # a still image by its extension, everything else (any FFmpeg format, image sequences) a video
    assert [media_kind(name) for name in ("a.PNG", "a.xyz", "a.mxf", "f_%04d.png")] == ["image", "video", "video", "video"]
    with pytest.raises(ValueError, match="not a still-image name"):
        write_image(tmp_path / "a.mp4", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(ValueError, match=r"\.jpg cannot store uint16"):
        write_image(tmp_path / "deep.jpg", np.zeros((4, 4, 3), np.uint16))
    with pytest.raises(FileNotFoundError, match="output folder"):
        write_image(tmp_path / "no" / "such.png", np.zeros((4, 4, 3), np.uint8))
    assert _files(tmp_path) == ["bad.png"]


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


def test_overwrite_is_refused_unless_asked(tmp_path):
    write_image(tmp_path / "a.png", np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(FileExistsError, match="a.png' already exists"):
        write_image(tmp_path / "a.png", np.ones((4, 4, 3), np.uint8), overwrite=False)
    assert read_image(tmp_path / "a.png").max() == 0 and _files(tmp_path) == ["a.png"]
    write_image(tmp_path / "a.png", np.ones((4, 4, 3), np.uint8), overwrite=True)
    assert read_image(tmp_path / "a.png").max() == 1


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
