"""Reading and writing images and videos with OpenCV, atomically, with explicit channel order.

Convention:

* Arrays are ``H x W`` (grey), ``H x W x 3`` or ``H x W x 4``; ``order="rgb"`` (default) means the
  colour channels are R, G, B(, A), ``order="bgr"`` means OpenCV's B, G, R(, A). Nothing is flipped:
  row 0 is the top of the picture.
* Bit depth is kept: 8-bit (uint8), 16-bit (uint16, PNG and TIFF) and 32-bit float (float32, TIFF)
  are read and written unchanged. JPEG stores uint8 only; writing anything else to a JPEG raises.
* Videos: the container and codec follow the output extension (:data:`VIDEO_CODECS`); the frame
  rate and frame size are those the caller gives (normally the input's), and every frame written is
  one frame in the file. Audio is not carried (OpenCV does not read it).
* Every output is written to a temporary file in the target's folder and renamed into place when it
  is complete (:mod:`glradial.atomic`): an error or Ctrl-C leaves no partial file.
* Errors name the path: ``FileNotFoundError`` for a missing input, ``ValueError`` for an unknown
  extension or a file that cannot be decoded, ``OSError`` when the encoder fails.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Iterator, Literal

import cv2
import numpy as np

from .atomic import atomic_path, atomic_write_bytes, check_output_folder
from .native_stderr import silenced

__all__ = [
    "IMAGE_EXTENSIONS",
    "VIDEO_CODECS",
    "VideoInfo",
    "VideoReader",
    "VideoWriter",
    "media_kind",
    "read_image",
    "write_image",
    "probe_video",
]

ChannelOrder = Literal["rgb", "bgr"]

#: image extension -> dtypes the format stores
IMAGE_EXTENSIONS: dict[str, tuple[str, ...]] = {
    ".png": ("uint8", "uint16"),
    ".jpg": ("uint8",),
    ".jpeg": ("uint8",),
    ".tif": ("uint8", "uint16", "float32"),
    ".tiff": ("uint8", "uint16", "float32"),
}

#: video extension -> FourCC of the codec written (all available in opencv-python's FFmpeg build)
VIDEO_CODECS: dict[str, str] = {
    ".mp4": "mp4v",  # MPEG-4 part 2 in MP4
    ".m4v": "mp4v",
    ".mov": "mp4v",  # MPEG-4 part 2 in QuickTime
    ".avi": "MJPG",  # Motion JPEG in AVI
    ".mkv": "FFV1",  # lossless FFV1 in Matroska
}

#: frame rate used when a video does not report one (frames per second)
DEFAULT_FPS = 25.0


def _extension(path: str | os.PathLike) -> str:
    return Path(path).suffix.lower()


def media_kind(path: str | os.PathLike) -> Literal["image", "video"]:
    """``"image"`` or ``"video"`` from the file extension; ``ValueError`` for any other extension."""
    ext = _extension(path)
    if ext in IMAGE_EXTENSIONS:
        return "image"
    if ext in VIDEO_CODECS:
        return "video"
    known = ", ".join(sorted(IMAGE_EXTENSIONS) + sorted(VIDEO_CODECS))
    raise ValueError(f"unknown file extension {ext or '(none)'!r} of {str(path)!r}; known: {known}")


def _check_input(path: str | os.PathLike) -> Path:
    source = Path(path)
    if not source.exists():
        raise FileNotFoundError(f"input file {str(source)!r} does not exist")
    if source.is_dir():
        raise IsADirectoryError(f"input {str(source)!r} is a folder, expected a file")
    return source


def _check_order(order: str) -> None:
    if order not in ("rgb", "bgr"):
        raise ValueError(f"order must be 'rgb' or 'bgr', got {order!r}")


def _swap_rb(array: np.ndarray) -> np.ndarray:
    """RGB(A) <-> BGR(A); grey images pass through."""
    if array.ndim == 3 and array.shape[2] in (3, 4):
        return np.ascontiguousarray(array[:, :, [2, 1, 0] + ([3] if array.shape[2] == 4 else [])])
    return array


# -- images ---------------------------------------------------------------------------------------
def read_image(path: str | os.PathLike, order: ChannelOrder = "rgb") -> np.ndarray:
    """Read a PNG, JPEG or TIFF keeping its bit depth and alpha; channels in ``order``."""
    _check_order(order)
    source = _check_input(path)
    if media_kind(source) != "image":
        raise ValueError(f"{str(source)!r} is a video, expected an image")
    data = np.fromfile(source, dtype=np.uint8)
    with silenced():
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        raise ValueError(f"cannot decode image {str(source)!r}: the file is corrupt or not a {source.suffix} image")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.dtype not in (np.uint8, np.uint16, np.float32):
        raise ValueError(f"image {str(source)!r} has unsupported sample type {image.dtype}")
    return _swap_rb(image) if order == "rgb" else image


def write_image(path: str | os.PathLike, image: np.ndarray, order: ChannelOrder = "rgb", *, jpeg_quality: int = 95) -> Path:
    """Write ``image`` atomically as PNG/JPEG/TIFF (from the extension), bit depth unchanged."""
    _check_order(order)
    target = check_output_folder(path)
    if media_kind(target) != "image":
        raise ValueError(f"{str(target)!r} has a video extension, expected an image file")
    image = np.asarray(image)
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)) or image.size == 0:
        raise ValueError(f"image must be H×W or H×W×C with C in (1, 3, 4), got shape {image.shape}")
    allowed = IMAGE_EXTENSIONS[_extension(target)]
    if image.dtype.name not in allowed:
        able = sorted({ext for ext, kinds in IMAGE_EXTENSIONS.items() if image.dtype.name in kinds} - {".jpeg", ".tiff"})
        hint = f"; write {' or '.join(able)} to keep it" if able else ""
        raise ValueError(f"{_extension(target)} cannot store {image.dtype} samples (it stores {', '.join(allowed)}){hint}")
    pixels = _swap_rb(image) if order == "rgb" else image
    params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if _extension(target) in (".jpg", ".jpeg") else []
    with silenced():
        ok, encoded = cv2.imencode(_extension(target), pixels, params)
    if not ok:
        raise OSError(f"OpenCV could not encode {str(target)!r}")
    # through a file object, not ndarray.tofile: a short write (full disk) then raises with its errno
    atomic_write_bytes(target, encoded.tobytes())
    return target


# -- videos ---------------------------------------------------------------------------------------
class VideoInfo:
    """Frame size ``(W, H)``, frame rate (fps) and the frame count the container reports."""

    def __init__(self, size: tuple[int, int], fps: float, frame_count: int) -> None:
        self.size = size
        self.fps = fps
        self.frame_count = frame_count

    def __repr__(self) -> str:
        return f"VideoInfo(size={self.size}, fps={self.fps:g}, frame_count={self.frame_count})"


class VideoReader:
    """Iterate over the frames of a video file (``H x W x 3`` uint8 in ``order``).

    ``info`` holds the size, fps (:data:`DEFAULT_FPS` when the file reports none) and the frame count
    the container reports (``-1`` if unknown; iterate for the true count). Use as a context manager or
    call :meth:`close`. A file that exists but cannot be opened, or whose first frame cannot be
    decoded, raises ``ValueError`` naming it.
    """

    def __init__(self, path: str | os.PathLike, order: ChannelOrder = "rgb") -> None:
        _check_order(order)
        self.path = _check_input(path)
        if media_kind(self.path) != "video":
            raise ValueError(f"{str(self.path)!r} is an image, expected a video")
        self.order = order
        with silenced():
            self._cap = cv2.VideoCapture(str(self.path))
            ok, first = (self._cap.read() if self._cap.isOpened() else (False, None))
        if not ok or first is None:
            self._cap.release()
            raise ValueError(f"cannot read video {str(self.path)!r}: the file is corrupt or its codec is not supported")
        fps = float(self._cap.get(cv2.CAP_PROP_FPS))
        count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        self.info = VideoInfo(
            (int(first.shape[1]), int(first.shape[0])),
            fps if math.isfinite(fps) and fps > 0 else DEFAULT_FPS,
            count if count > 0 else -1,
        )
        self._first: np.ndarray | None = first
        self.frames_read = 0

    def __iter__(self) -> Iterator[np.ndarray]:
        return self

    def __next__(self) -> np.ndarray:
        if self._first is not None:
            frame, self._first = self._first, None
        else:
            with silenced():
                ok, frame = self._cap.read()
            if not ok or frame is None:
                raise StopIteration
        self.frames_read += 1
        return _swap_rb(frame) if self.order == "rgb" else frame

    def close(self) -> None:
        self._cap.release()

    def __enter__(self) -> "VideoReader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def probe_video(path: str | os.PathLike) -> VideoInfo:
    """Size, fps and the frame count of a video, counted by decoding (exact, slower than the header)."""
    with VideoReader(path, order="bgr") as reader:
        count = sum(1 for _ in reader)
        info = reader.info
    return VideoInfo(info.size, info.fps, count)


class VideoWriter:
    """Write frames to a video atomically; codec from the extension (:data:`VIDEO_CODECS`).

    ``size`` is ``(W, H)``, ``fps`` frames per second. Frames must be ``H x W x 3`` uint8 in
    ``order``. The file appears at ``path`` only after :meth:`close` (or a clean ``with`` exit);
    :meth:`abort`, an exception inside ``with`` or Ctrl-C removes the temporary file.
    """

    def __init__(self, path: str | os.PathLike, size: tuple[int, int], fps: float, order: ChannelOrder = "rgb") -> None:
        _check_order(order)
        target = check_output_folder(path)
        ext = _extension(target)
        if ext not in VIDEO_CODECS:
            if ext in IMAGE_EXTENSIONS:
                raise ValueError(f"{str(target)!r} has an image extension, expected a video ({', '.join(sorted(VIDEO_CODECS))})")
            media_kind(target)  # raises the unknown-extension error
        width, height = (int(size[0]), int(size[1]))
        if width <= 0 or height <= 0:
            raise ValueError(f"video size must be positive, got {size!r}")
        if not (math.isfinite(float(fps)) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.path, self.size, self.fps, self.order = target, (width, height), float(fps), order
        self.frames_written = 0
        self._open = False
        self._writer = None
        self._context = atomic_path(target)
        self._tmp = self._context.__enter__()
        with silenced():
            self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*VIDEO_CODECS[ext]), self.fps, self.size)
        if not self._writer.isOpened():
            self.abort()
            raise OSError(f"OpenCV cannot open a {VIDEO_CODECS[ext]} video writer for {str(target)!r}")
        self._open = True

    def write(self, frame: np.ndarray) -> None:
        frame = np.asarray(frame)
        if frame.shape != (self.size[1], self.size[0], 3) or frame.dtype != np.uint8:
            raise ValueError(
                f"video frames must be {self.size[1]}×{self.size[0]}×3 uint8, got shape {frame.shape} {frame.dtype}"
            )
        self._writer.write(_swap_rb(frame) if self.order == "rgb" else np.ascontiguousarray(frame))
        self.frames_written += 1

    def close(self) -> Path:
        """Finish the file and move it into place; returns the final path."""
        if self._context is not None:
            context, self._context, self._open = self._context, None, False
            self._writer.release()
            context.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        """Drop everything written so far; the target is left untouched. No-op once finished."""
        if self._context is None:
            return
        context, self._context, self._open = self._context, None, False
        if self._writer is not None:
            self._writer.release()
        try:
            context.__exit__(KeyboardInterrupt, KeyboardInterrupt(), None)
        except KeyboardInterrupt:
            pass

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
