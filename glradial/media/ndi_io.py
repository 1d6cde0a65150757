"""NDI in and out (``ndi://SOURCE NAME``) through cyndilib, an optional extra
(``pip install 'glradial[ndi]'``) whose wheels carry the NDI runtime (libndi).

* :class:`NdiSource`: the frames of the NDI source whose name contains the text after ``ndi://``
  (NDI names read ``MACHINE (NAME)``), found by NDI's discovery (mDNS; where that does not reach,
  an NDI configuration with ``networks.ips``, e.g. ``NDI_CONFIG_DIR``), received as RGBA and handed
  out as ``H x W x 3`` uint8 RGB with the sender's timestamps; the same interface as
  :class:`glradial.media.stream_io.LiveSource` (``frames``, ``timestamp``, ``info``, ``first_frame``,
  ``frames_read``, ``ended``, ``close``), ended after ``idle_timeout`` s without a frame.
* :class:`NdiWriter`: corrected frames sent as the NDI source ``NAME`` (RGBA, the stream's rate),
  with :class:`~glradial.media.video_io.VideoWriter`'s ``write``/``close``/``abort``/``frames_written``.

NDI is lossy (SpeedHQ): a frame comes back within a few code values of what was sent.
"""

from __future__ import annotations

import time
from fractions import Fraction
from typing import Iterator

import cv2
import numpy as np

from .video_io import VideoInfo

__all__ = ["NDI_SCHEME", "is_ndi", "require_ndi", "NdiSource", "NdiWriter"]

NDI_SCHEME = "ndi://"
#: cyndilib's receive holds the interpreter's lock while it waits: it waits at most this long
#: (milliseconds), and the thread sleeps POLL_S seconds (letting the others run) between two tries
RECEIVE_MS, POLL_S = 5, 0.003


def is_ndi(url: str) -> bool:
    """Whether ``url`` names an NDI source or output (``ndi://NAME``)."""
    return url.lower().startswith(NDI_SCHEME)


def require_ndi():
    """The ``cyndilib`` module, or ``RuntimeError`` saying what to install."""
    try:
        import cyndilib
    except ImportError:
        raise RuntimeError("NDI (ndi://) needs the optional extra: pip install 'glradial[ndi]' (cyndilib, whose "
                           "wheels carry the NDI runtime)") from None
    return cyndilib


def _name(url: str) -> str:
    name = url[len(NDI_SCHEME):]
    if not name:
        raise ValueError(f"an NDI URL names its source: ndi://NAME, got {url!r}")
    return name


class NdiSource:
    """An NDI source as a live input (module docstring)."""

    kind = "ndi"

    def __init__(self, source: str, *, idle_timeout: float = 5.0) -> None:
        ndi = require_ndi()
        from cyndilib.receiver import ReceiveFrameType

        self.source, self.idle_timeout, self.wanted = source, float(idle_timeout), _name(source)
        self.frames_read, self.ended, self._video_type = 0, "", ReceiveFrameType.recv_video
        self._finder = ndi.Finder()
        self._finder.open()
        self._receiver = None
        try:
            found = self._find()
            self._receiver = ndi.Receiver(color_format=ndi.RecvColorFormat.RGBX_RGBA)
            self._frame = ndi.VideoRecvFrame()
            self._receiver.set_video_frame(self._frame)
            self._receiver.set_source(found)
            self._origin: float | None = None
            self.first_frame = self._next()
            if self.first_frame is None:
                raise ValueError(f"live input {source!r}: no frame within {self.idle_timeout:g} s")
            self._pending: list = [self.first_frame]
            rate = Fraction(self._frame.get_frame_rate()).limit_denominator(1001)
            self.info = VideoInfo.of((self.first_frame.shape[1], self.first_frame.shape[0]), rate)
        except BaseException:
            self.close()
            raise

    def _find(self):
        end = time.monotonic() + self.idle_timeout
        while time.monotonic() < end:
            self._finder.wait_for_sources(min(0.5, max(0.0, end - time.monotonic())))
            for found in self._finder.iter_sources():
                if self.wanted in found.name:
                    return found
        names = ", ".join(self._finder.get_source_names()) or "none"
        raise ValueError(f"live input {self.source!r}: no NDI source named {self.wanted!r} within {self.idle_timeout:g} s "
                         f"(sources seen: {names})")

    def _next(self) -> np.ndarray | None:
        """The next frame (RGB), or None after ``idle_timeout`` s without one."""
        end = time.monotonic() + self.idle_timeout
        while time.monotonic() < end:
            if not self._receiver.receive(self._video_type, RECEIVE_MS) & self._video_type:
                time.sleep(POLL_S)
            else:
                width, height = self._frame.get_resolution()
                data = np.empty(self._frame.get_buffer_size(), np.uint8)
                self._frame.fill_p_data(data)
                stride = self._frame.get_line_stride()
                rows = data[: stride * height].reshape(height, stride)[:, : width * 4].reshape(height, width, 4)
                self._stamp = float(self._frame.get_timestamp_posix())
                return np.ascontiguousarray(rows[..., :3])
        return None

    def frames(self) -> Iterator[np.ndarray]:
        """The frames as they arrive, until ``idle_timeout`` s pass without one (``ended`` "idle")."""
        while True:
            frame = self._pending.pop(0) if self._pending else self._next()
            if frame is None:
                self.ended = "idle"
                return
            self.frames_read += 1
            yield frame

    def timestamp(self, frame: np.ndarray) -> float | None:
        """The latest frame's sender timestamp (s, from the first frame's)."""
        if self._origin is None:
            self._origin = self._stamp
        return max(0.0, self._stamp - self._origin)

    def close(self) -> None:
        if self._receiver is not None:
            self._receiver.disconnect()
            self._receiver = None
        if self._finder is not None:
            self._finder.close()
            self._finder = None


class NdiWriter:
    """Frames sent as the NDI source ``NAME`` of ``ndi://NAME`` (module docstring): RGB arrays (H x W x 3
    uint8, the stream's size); planar frames are not taken (:meth:`takes_planes_of`)."""

    def __init__(self, target: str, info: VideoInfo) -> None:
        ndi = require_ndi()
        self.path, self.info, self.frames_written = target, info, 0
        self._sender = ndi.Sender(_name(target), clock_video=False)
        frame = ndi.VideoSendFrame()
        frame.set_resolution(*info.size)
        rate = Fraction(info.rate)
        frame.set_frame_rate(rate)
        frame.set_fourcc(ndi.FourCC.RGBA)
        self._sender.set_video_frame(frame)
        self._sender.open()
        self._rgba = np.empty((info.size[1], info.size[0], 4), np.uint8)

    def takes_planes_of(self, pix_fmt: str) -> bool:
        return False

    def write(self, image: np.ndarray, pts: int | None = None) -> None:
        """Send one RGB frame (``pts`` unused: NDI stamps frames as they are sent)."""
        if image.shape[:2] != self._rgba.shape[:2] or image.dtype != np.uint8:
            raise ValueError(f"image must be {self.info.size[0]}x{self.info.size[1]} uint8 RGB, got {image.dtype} {image.shape}")
        cv2.cvtColor(image, cv2.COLOR_RGB2RGBA, dst=self._rgba)
        self._sender.write_video(self._rgba.ravel())
        self.frames_written += 1

    def close(self) -> str:
        self._sender.close()
        return self.path

    def abort(self) -> None:
        self._sender.close()
