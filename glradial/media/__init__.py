"""Files in and out: still images and videos (PyAV), atomic writes, frame normalisation to RGB8,
native stderr silencing and the progress bar."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .atomic import atomic_path, atomic_write_bytes, atomic_write_text, check_output_folder, check_overwrite, temporary_folder
    from .frames import to_rgb8
    from .image_io import IMAGE_EXTENSIONS, is_image_path, media_kind, read_image, write_image
    from .native_stderr import silenced
    from .progress import Progress
    from .video_io import CopiedPacket, EncodeOptions, VideoFrame, VideoReader, VideoWriter, check_video_overwrite, is_sequence

__getattr__, __dir__, __all__ = attach(__name__, __file__)
