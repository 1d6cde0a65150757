"""Reading and writing still images with OpenCV, atomically, with explicit channel order (videos and
image sequences: :mod:`glradial.media.video_io`).

Convention:

* Arrays are ``H x W`` (grey), ``H x W x 3`` or ``H x W x 4``; ``order="rgb"`` (default) means the
  colour channels are R, G, B(, A), ``order="bgr"`` means OpenCV's B, G, R(, A). Nothing is flipped:
  row 0 is the top of the picture.
* Bit depth is kept: 8-bit (uint8), 16-bit (uint16, PNG and TIFF) and 32-bit float (float32, TIFF)
  are read and written unchanged. JPEG stores uint8 only; writing anything else to a JPEG raises.
  OpenEXR (``.exr``, :mod:`glradial.media.exr_io`): float16 (HALF) and float32 (FLOAT) arrays with the
  channel sets Y, RGB, RGBA (:data:`EXR_CHANNEL_SETS`); values beyond [0, 1] are kept. Other
  channel sets (layers, depth): :func:`glradial.media.exr_io.read_exr`.
* Every output is written to a temporary file in the target's folder and renamed into place when it
  is complete (:mod:`glradial.media.atomic`): an error or Ctrl-C leaves no partial file.
* Errors name the path: ``FileNotFoundError`` for a missing input, ``ValueError`` for an unknown
  extension or a file that cannot be decoded, ``OSError`` when the encoder fails.
* An existing output is replaced only with ``overwrite=True`` (``FileExistsError`` otherwise), as
  ``ffmpeg -y``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

import cv2
import numpy as np

from .atomic import atomic_write_bytes, check_output_folder, check_overwrite
from .native_stderr import silenced

__all__ = [
    "IMAGE_EXTENSIONS",
    "check_input_file",
    "is_image_path",
    "media_kind",
    "read_image",
    "write_image",
]

ChannelOrder = Literal["rgb", "bgr"]

#: image extension -> dtypes the format stores
IMAGE_EXTENSIONS: dict[str, tuple[str, ...]] = {
    ".png": ("uint8", "uint16"),
    ".jpg": ("uint8",),
    ".jpeg": ("uint8",),
    ".tif": ("uint8", "uint16", "float32"),
    ".tiff": ("uint8", "uint16", "float32"),
    ".exr": ("float16", "float32"),
}
#: channel names of an EXR written from an H×W×C array, by C (reading takes the same sets)
EXR_CHANNEL_SETS = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}

def _extension(path: str | os.PathLike) -> str:
    return Path(path).suffix.lower()


def is_image_path(path: str | os.PathLike) -> bool:
    """True for a single still image (a :data:`IMAGE_EXTENSIONS` name without a ``%d`` frame-number
    pattern); everything else is a video or an image sequence for FFmpeg (:mod:`glradial.media.video_io`)."""
    return _extension(path) in IMAGE_EXTENSIONS and "%" not in Path(path).name


def media_kind(path: str | os.PathLike) -> Literal["image", "video"]:
    """``"image"`` for a still image (:func:`is_image_path`), ``"video"`` for anything else: any file
    FFmpeg reads, and image sequences such as ``frame_%04d.png``."""
    return "image" if is_image_path(path) else "video"


def check_input_file(path: str | os.PathLike) -> Path:
    """``path`` as a ``Path`` after checking that it names an existing file (``FileNotFoundError`` or
    ``IsADirectoryError`` naming it otherwise)."""
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
    """RGB(A) <-> BGR(A) with OpenCV (one pass, SIMD); grey images pass through."""
    if array.dtype == np.float16 and array.ndim == 3 and array.shape[2] in (3, 4):
        return array[:, :, [2, 1, 0, 3][: array.shape[2]]]  # OpenCV converts no half floats
    if array.ndim == 3 and array.shape[2] == 3:
        return cv2.cvtColor(array, cv2.COLOR_RGB2BGR)
    if array.ndim == 3 and array.shape[2] == 4:
        return cv2.cvtColor(array, cv2.COLOR_RGBA2BGRA)
    return array


# -- images ---------------------------------------------------------------------------------------
def read_image(path: str | os.PathLike, order: ChannelOrder = "rgb") -> np.ndarray:
    """Read a PNG, JPEG or TIFF keeping its bit depth and alpha; channels in ``order``."""
    _check_order(order)
    source = check_input_file(path)
    if not is_image_path(source):
        known = ", ".join(sorted(IMAGE_EXTENSIONS))
        raise ValueError(f"{str(source)!r} is not a still image ({known}); videos: glradial.media.video_io")
    if _extension(source) == ".exr":
        return _read_exr_array(source, order)
    data = np.fromfile(source, dtype=np.uint8)
    with silenced():  # libpng/libjpeg chatter on a corrupt file: the ValueError below says it
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        raise ValueError(f"cannot decode image {str(source)!r}: the file is corrupt or not a {source.suffix} image")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.dtype not in (np.uint8, np.uint16, np.float32):
        raise ValueError(f"image {str(source)!r} has unsupported sample type {image.dtype}")
    return _swap_rb(image) if order == "rgb" else image


def write_image(
    path: str | os.PathLike, image: np.ndarray, order: ChannelOrder = "rgb", *, jpeg_quality: int = 95, overwrite: bool = True
) -> Path:
    """Write ``image`` atomically as PNG/JPEG/TIFF (from the extension), bit depth unchanged.
    ``overwrite=False`` refuses an existing ``path`` (``FileExistsError``)."""
    _check_order(order)
    target = check_output_folder(path)
    if not is_image_path(target):
        known = ", ".join(sorted(IMAGE_EXTENSIONS))
        raise ValueError(f"{str(target)!r} is not a still-image name ({known}); videos: glradial.media.video_io")
    check_overwrite(target, overwrite)
    image = np.asarray(image)
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (1, 3, 4)) or image.size == 0:
        raise ValueError(f"image must be H×W or H×W×C with C in (1, 3, 4), got shape {image.shape}")
    allowed = IMAGE_EXTENSIONS[_extension(target)]
    if image.dtype.name not in allowed:
        able = sorted({ext for ext, kinds in IMAGE_EXTENSIONS.items() if image.dtype.name in kinds} - {".jpeg", ".tiff"})
        hint = f"; write {' or '.join(able)} to keep it" if able else ""
        raise ValueError(f"{_extension(target)} cannot store {image.dtype} samples (it stores {', '.join(allowed)}){hint}")
    pixels = _swap_rb(image) if order == "rgb" else image
    if _extension(target) == ".exr":
        return _write_exr_array(target, image if order == "rgb" else _swap_rb(image))
    params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)] if _extension(target) in (".jpg", ".jpeg") else []
    with silenced():
        ok, encoded = cv2.imencode(_extension(target), pixels, params)
    if not ok:
        raise OSError(f"OpenCV could not encode {str(target)!r}")
    # through a file object, not ndarray.tofile: a short write (full disk) then raises with its errno
    atomic_write_bytes(target, encoded.tobytes())
    return target


def _read_exr_array(source: Path, order: ChannelOrder) -> np.ndarray:
    """An EXR of one of :data:`EXR_CHANNEL_SETS` as ``H x W(x C)`` float32 (HALF widened exactly)."""
    from .exr_io import read_exr

    exr = read_exr(source)
    names = tuple(exr.channels)
    for wanted in EXR_CHANNEL_SETS.values():
        if sorted(names) == sorted(wanted):
            stack = np.stack([exr.channels[name].astype(np.float32) for name in wanted], axis=-1)
            image = stack[:, :, 0] if stack.shape[2] == 1 else stack
            return _swap_rb(image) if order == "bgr" else image
    raise ValueError(f"OpenEXR image {str(source)!r} has channels {', '.join(sorted(names))}, not one of "
                     "Y, RGB, RGBA: read it with glradial.media.exr_io.read_exr")


def _write_exr_array(target: Path, image: np.ndarray) -> Path:
    """``image`` (RGB order) as an EXR with the :data:`EXR_CHANNEL_SETS` names, its dtype kept."""
    from .exr_io import ExrImage, write_exr

    planes = image[:, :, None] if image.ndim == 2 else image
    names = EXR_CHANNEL_SETS[planes.shape[2]]
    return write_exr(target, ExrImage({name: planes[:, :, i] for i, name in enumerate(names)}))
