"""Reading and writing videos and image sequences through FFmpeg's own libraries (PyAV).

Why PyAV: its wheels carry FFmpeg's libraries (libavformat/libavcodec/libswscale), so whatever
FFmpeg demuxes and decodes is read (MXF, TS, WebM, ProRes, DNxHD, 10/12-bit H.264/HEVC, image
sequences ...), packets of other streams can be copied untouched, and the exact rational frame rate,
timestamps and colour tags are available, with no external process and every error raised as a
Python exception (unlike a pipe to the ``ffmpeg`` command, whose failures arrive as exit codes and
text, or OpenCV's ``VideoCapture``/``VideoWriter``, which drop audio, timing and depth).

Conventions:

* Frames reach the caller as ``H x W x 3`` arrays in ``order`` (``"rgb"`` default, or ``"bgr"``):
  ``uint8`` for sources of 8 bits per component or less, ``uint16`` (full 0..65535 scale) for deeper
  ones (10-bit, 12-bit), which are written back at the output pixel format's depth. Alpha is dropped.
  YUV <-> RGB conversions use the stream's matrix (BT.601/709/2020) and range (limited/full) both
  ways (libswscale); an untagged stream is read as BT.709 from 720 lines up, BT.601 below.
* Timing: the video stream's time base, every frame's presentation timestamp and the average frame
  rate (a :class:`fractions.Fraction`, e.g. 30000/1001) are copied to the output; the timecode
  (``timecode`` tag), colour tags (primaries, transfer, matrix, range) and field order as well.
* Audio, subtitle and data streams are copied packet by packet (no re-encoding). A QuickTime
  timecode track (``tmcd``) is not copied: the muxer rebuilds it from the video's timecode tag.
* Outputs are written to a temporary name next to the target and renamed into place when complete
  (:mod:`glradial.media.atomic`); an image sequence (``frame_%04d.png``) is written into a hidden
  temporary folder and its files moved into place at the end. An existing output is replaced only
  with ``overwrite=True``. Any FFmpeg error (full disk, encoder failure, unsupported codec) raises
  ``OSError`` naming the path and the cause, and leaves nothing behind.
"""

from __future__ import annotations

import functools
import glob
import os
import re
import shutil
import threading
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Iterator, Literal, Union

import av
import numpy as np

from ..threads import thread_budget
from .atomic import atomic_path, check_output_folder, check_overwrite, temporary_folder
from .image_io import check_input_file
from .native_stderr import silenced

__all__ = [
    "EncodeOptions",
    "VideoInfo",
    "VideoFrame",
    "VideoReader",
    "VideoWriter",
    "check_video_overwrite",
    "frame_timestamps",
    "frame_planes",
    "has_alpha",
    "is_sequence",
    "probe_video",
    "sequence_files",
    "yuv_layout",
]

ChannelOrder = Literal["rgb", "bgr"]

#: frame rate given to an image sequence read without one (frames per second; FFmpeg's default)
SEQUENCE_RATE = Fraction(25)

#: a video whose frames end more than this (seconds) before the duration its header states is
#: reported as truncated (decoders and muxers round durations to a frame or so, never by this much)
TRUNCATION_TOLERANCE_S = 0.5

#: encoders that take a constant-rate-factor quality (``--crf``) instead of a bit rate
CRF_ENCODERS = frozenset({"libx264", "libx264rgb", "libx265", "libvpx", "libvpx-vp9", "libaom-av1", "libsvtav1"})

#: x264's and x265's presets, fastest first: their FFmpeg 'preset' option is a free string that the
#: library itself checks when the encoder opens (FFmpeg cannot list them)
X26X_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow", "placebo")
_LIBRARY_PRESETS = {"libx264": X26X_PRESETS, "libx264rgb": X26X_PRESETS, "libx265": X26X_PRESETS}

_PATTERN = re.compile(r"%(0?\d*)d")

#: a conversion whose output has at most this many pixels (a cut detector's thumbnail, a 640 x 360
#: copy) runs on the calling thread alone: FFmpeg's slice threads cost it more CPU than they save
#: (a 960 x 540 frame to 64 x 36 RGB: 0.41 ms of CPU on one thread, 0.68 with the automatic count)
SINGLE_THREAD_PIXELS = 640 * 360

# AVColorSpace (stream tag) -> libswscale matrix; BT470BG and SMPTE170M are both BT.601
_SWS_MATRIX = {1: 1, 4: 4, 5: 5, 6: 5, 7: 7, 9: 9, 10: 9}
_UNSPECIFIED = 2


def is_sequence(path: str | os.PathLike) -> bool:
    """True when ``path``'s file name holds a printf frame-number pattern (``%d``, ``%04d``)."""
    return bool(_PATTERN.search(Path(path).name))


def sequence_files(pattern: str | os.PathLike) -> list[Path]:
    """Existing files that an image-sequence ``pattern`` names, sorted."""
    pattern = Path(pattern)
    regex = re.compile("^" + _PATTERN.sub(r"\\d+", re.escape(pattern.name).replace(r"\%", "%")) + "$")
    folder = pattern.parent if str(pattern.parent) else Path(".")
    wildcard = _PATTERN.sub("*", glob.escape(pattern.name))
    return sorted(p for p in folder.glob(wildcard) if regex.match(p.name))


def check_video_overwrite(path: str | os.PathLike, overwrite: bool) -> None:
    """:func:`~glradial.media.atomic.check_overwrite` for an output file or an image-sequence pattern
    (``FileExistsError`` when any file of the sequence exists and ``overwrite`` is false)."""
    if not is_sequence(path):
        check_overwrite(path, overwrite)
    elif not overwrite and sequence_files(path):
        raise FileExistsError(f"output files {str(path)!r} already exist (overwrite them with -y/--overwrite)")


def ffmpeg_error(path: object, err: BaseException) -> str:
    """``'PATH': what FFmpeg said`` on one line (its strerror where it has one), for error messages."""
    text = " ".join(str(getattr(err, "strerror", None) or err).split())
    return f"{str(path)!r}: {text}"


@dataclass(frozen=True)
class VideoInfo:
    """What a video stream is: ``size`` (W, H) in pixels, ``rate`` (exact frames per second),
    ``frame_count`` from the container (-1 if unknown), the decoder ``codec`` name, the source
    ``pix_fmt`` and its ``bit_depth`` (bits per component), the stream ``time_base`` (seconds per
    timestamp tick), the ``timecode`` tag, the colour tags (FFmpeg enum values) and field order."""

    size: tuple[int, int]
    rate: Fraction
    frame_count: int
    codec: str
    pix_fmt: str
    bit_depth: int
    time_base: Fraction
    timecode: str | None = None
    color_primaries: int = _UNSPECIFIED
    color_trc: int = _UNSPECIFIED
    colorspace: int = _UNSPECIFIED
    color_range: int = 0
    field_order: int = 0
    bit_rate: int = 0
    interlaced: bool = False

    @property
    def fields(self) -> str:
        """``"tff"``, ``"bff"`` or ``"progressive"``: the stream's field order (FFmpeg's
        AVFieldOrder: TT/TB = top field first, BB/BT = bottom first); a stream that states none but
        whose first frame is flagged interlaced is taken as TFF (the HD broadcast order)."""
        if self.field_order in (FIELD_TT, FIELD_TB):
            return "tff"
        if self.field_order in (FIELD_BB, FIELD_BT):
            return "bff"
        return "tff" if self.interlaced and self.field_order != FIELD_PROGRESSIVE else "progressive"

    @property
    def fps(self) -> float:
        return float(self.rate)

    @classmethod
    def of(cls, size: tuple[int, int], rate: float | Fraction, *, codec: str = "", pix_fmt: str = "yuv420p") -> "VideoInfo":
        """A description for new frames (no source file): ``rate`` frames per second (a float is
        turned into the nearest fraction with a denominator up to 1001), time base ``1/rate``-exact,
        ``codec`` "" = the container's default encoder."""
        rate = Fraction(rate).limit_denominator(1001) if not isinstance(rate, Fraction) else rate
        if not rate > 0:
            raise ValueError(f"rate must be positive (frames per second), got {rate}")
        width, height = int(size[0]), int(size[1])
        if width <= 0 or height <= 0:
            raise ValueError(f"video size must be positive, got {size!r}")
        return cls((width, height), rate, -1, codec, pix_fmt, _bit_depth(pix_fmt), 1 / rate)

    @property
    def dtype(self) -> np.dtype:
        """Sample type of the frames handed out: uint8 up to 8 bits per component, else uint16."""
        return np.dtype(np.uint8 if self.bit_depth <= 8 else np.uint16)


@dataclass
class VideoFrame:
    """One decoded frame: its ``index`` (0 = first), the ``image`` (see the module conventions),
    its presentation timestamp ``pts`` in the stream's time base (None if the source has none) and
    the decoded frame itself (``decoded``, for :meth:`VideoReader.convert` at another size)."""

    index: int
    image: np.ndarray
    pts: int | None
    decoded: av.VideoFrame | None = field(default=None, repr=False)


@dataclass
class CopiedPacket:
    """A packet of a stream copied untouched (audio, subtitles, data)."""

    packet: av.Packet = field(repr=False)


def _bit_depth(pix_fmt: str) -> int:
    try:
        return max(c.bits for c in av.VideoFormat(pix_fmt).components)
    except Exception:  # hardware or unknown formats: assume 8 bits
        return 8


#: FFmpeg's AVFieldOrder values
FIELD_UNKNOWN, FIELD_PROGRESSIVE, FIELD_TT, FIELD_BB, FIELD_TB, FIELD_BT = range(6)
#: ``VideoInfo.fields`` name -> the AVFieldOrder written
FIELD_ORDER_CODES = {"progressive": FIELD_PROGRESSIVE, "tff": FIELD_TT, "bff": FIELD_BB}


def _rgb_format(depth: int, order: str, alpha: bool = False) -> str:
    if alpha:
        return f"{order}a" if depth <= 8 else f"{order}a64le"
    return f"{order}24" if depth <= 8 else f"{order}48le"


def has_alpha(pix_fmt: str) -> bool:
    """Whether FFmpeg's pixel format ``pix_fmt`` stores an alpha plane (yuva444p12le, rgba, gbrap ...)."""
    try:
        return any(component.is_alpha for component in av.VideoFormat(pix_fmt).components)
    except (ValueError, av.FFmpegError):
        return False


def yuv_layout(pix_fmt: str) -> tuple[int, int, int] | None:
    """``(shift_x, shift_y, bits)`` of a planar YUV pixel format with three planes and no alpha
    (chroma subsampled by ``2^shift`` across and down; ``bits`` per sample, stored in uint8 up to 8
    bits, else in native-endian uint16), e.g. ``(1, 1, 8)`` for yuv420p, ``(1, 0, 10)`` for
    yuv422p10le; None for anything else (RGB, packed, semi-planar NV12/P010, alpha, big-endian)."""
    try:
        fmt = av.VideoFormat(pix_fmt, 64, 64)
    except (ValueError, av.FFmpegError):
        return None
    parts = fmt.components
    if (fmt.is_rgb or not fmt.is_planar or fmt.is_bit_stream or fmt.has_palette or len(parts) != 3
            or [c.plane for c in parts] != [0, 1, 2] or any(c.is_alpha for c in parts) or not parts[0].is_luma
            or len({c.bits for c in parts}) != 1 or parts[0].bits > 16
            or (parts[0].bits > 8 and fmt.is_big_endian != (np.dtype(np.uint16).byteorder == ">"))):
        return None
    shift_x, shift_y = (64 // parts[1].width).bit_length() - 1, (64 // parts[1].height).bit_length() - 1
    return shift_x, shift_y, parts[0].bits


#: codecs whose decoders skip non-reference frames on request and whose container packets carry
#: one frame each (so that the packets' timestamps number the frames): :meth:`VideoReader.skip_nonreference`
SKIPPABLE_CODECS = frozenset({"h264", "hevc", "mpeg2video", "mpeg1video", "mpeg4"})


def frame_timestamps(path: str | os.PathLike) -> np.ndarray | None:
    """The presentation timestamps (``VideoInfo.time_base`` ticks) of every frame of the video at
    ``path``, in display order, read from its packets without decoding (a fraction of a second for
    a long file); None where they cannot number the frames: an image sequence, a codec outside
    :data:`SKIPPABLE_CODECS`, or a packet without a timestamp or with a repeated one. (An
    interlaced stream may hold a field per packet: the caller checks ``VideoInfo.fields``.)"""
    if is_sequence(path):
        return None
    stamps: list[int] = []
    try:
        with av.open(str(path), "r") as container:
            stream = container.streams.video[0]
            if stream.codec_context.name not in SKIPPABLE_CODECS:
                return None
            for packet in container.demux(stream):
                if packet.size == 0:
                    continue
                if packet.pts is None:
                    return None
                stamps.append(int(packet.pts))
    except (av.FFmpegError, IndexError, OSError, UnicodeDecodeError):
        return None
    order = np.sort(np.asarray(stamps, np.int64))
    if len(order) == 0 or np.any(np.diff(order) == 0):
        return None
    return order


def frame_planes(frame: av.VideoFrame) -> list[np.ndarray]:
    """The planes of a planar ``frame`` (:func:`yuv_layout`) as 2-D arrays viewing its memory
    (writable: a new frame's planes are filled in place), uint8 or uint16."""
    dtype = np.dtype(np.uint8) if frame.format.components[0].bits <= 8 else np.dtype(np.uint16)
    views = []
    for plane in frame.planes:
        data = np.frombuffer(plane, dtype)
        views.append(data[: plane.height * (plane.line_size // dtype.itemsize)]
                     .reshape(plane.height, plane.line_size // dtype.itemsize)[:, : plane.width])
    return views


def _matrix(colorspace: int, height: int) -> int:
    return _SWS_MATRIX.get(colorspace, 1 if height >= 720 else 5)


def _check_input(path: str | os.PathLike) -> str:
    source = Path(path)
    if is_sequence(source):
        if not sequence_files(source):
            raise FileNotFoundError(f"input image sequence {str(source)!r} matches no file")
        return str(source)
    return str(check_input_file(source))


class VideoReader:
    """Decode the first video stream of anything FFmpeg reads, frame by frame.

    Iterating yields the frames as arrays (module conventions); :meth:`items` yields
    :class:`VideoFrame` and, with ``copy_streams=True``, the packets of every other stream
    (:class:`CopiedPacket`) in file order, for :class:`VideoWriter`. ``max_width`` downsizes frames
    wider than it in the conversion (area filter), e.g. for an estimator; ``keep_decoded`` hands
    each decoded frame along too, for :meth:`convert` at another size. ``info`` describes the
    stream. A file that cannot be opened or has no video raises ``ValueError`` naming it; a decoding
    error midway raises ``ValueError`` with the number of frames decoded before it. ``alpha=True``:
    frames of a source with alpha (ProRes 4444, PNG or QuickTime RLE with alpha, FFV1 yuva ...) are
    ``H x W x 4``, alpha last, straight (as FFmpeg decodes them); other sources stay 3 channels.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        order: ChannelOrder = "rgb",
        *,
        copy_streams: bool = False,
        max_width: int | None = None,
        rate: Fraction | None = None,
        keep_decoded: bool = False,
        alpha: bool = False,
    ) -> None:
        if order not in ("rgb", "bgr"):
            raise ValueError(f"order must be 'rgb' or 'bgr', got {order!r}")
        self.path = Path(_check_input(path))
        self.order = order
        options = {"framerate": str(rate or SEQUENCE_RATE)} if is_sequence(self.path) else {}
        try:
            self._container = av.open(str(self.path), "r", options=options)
        except (av.FFmpegError, UnicodeDecodeError) as err:
            raise ValueError(f"cannot read video {ffmpeg_error(self.path, err)}") from None
        if not self._container.streams.video:
            self._container.close()
            raise ValueError(f"{str(self.path)!r} holds no video stream")
        stream = self._container.streams.video[0]
        stream.thread_type = "AUTO"
        stream.thread_count = thread_budget() or 0  # 0: FFmpeg's automatic count (about one per core)
        self.stream = stream
        self.info = stream_info(self._container, stream, _first_frame_tags(self.path, options))
        if self.info.size[0] <= 0 or self.info.size[1] <= 0:
            self._container.close()
            raise ValueError(f"cannot read video {str(self.path)!r}: its video stream has no frame size")
        self.copied = [s for s in self._container.streams if s is not stream and copy_streams and _copyable(s)]
        self.max_width = max_width
        self.keep_decoded = keep_decoded
        #: set True before :meth:`items` to get frames as decoded (``image`` None, ``decoded`` the
        #: frame in the source's pix_fmt), for a caller that works on its planes (no conversion)
        self.planar = False
        self.frames_read = 0
        self._last_pts: int | None = None
        self._take_alpha(alpha)

    def _take_alpha(self, wanted: bool) -> None:
        """Set :attr:`alpha` (frames carry the source's alpha as a 4th channel: ``alpha=True`` and a
        pix_fmt with alpha) and the conversion format; VP8/VP9 with an alpha plane get libvpx's
        decoder, which returns it (yuva420p)."""
        self._decoder = _alpha_decoder(self.stream) if wanted else None
        if self._decoder is not None:
            self.info = VideoInfo(**{**self.info.__dict__, "pix_fmt": self._decoder.pix_fmt or "yuva420p"})
        self.alpha = bool(wanted) and has_alpha(self.info.pix_fmt)
        self._format = _rgb_format(self.info.bit_depth, self.order, self.alpha)

    # -- frames --------------------------------------------------------------------------------
    def skip_nonreference(self) -> None:
        """Have the decoder drop the frames no other frame refers to (B-frames mostly: about half
        of a typical H.264 stream, two thirds of MPEG-2), which it then does not decode at all.
        The frames handed out are then a subsample: number them by their ``pts``
        (:func:`frame_timestamps`), not by ``index``, which counts the frames decoded."""
        self.stream.codec_context.skip_frame = "NONREF"

    def seek(self, pts: int) -> None:
        """Continue from the key frame at or before ``pts`` (stream time base); ``index`` then
        counts from there."""
        self._container.seek(int(pts), stream=self.stream, backward=True, any_frame=False)

    def convert(self, frame: av.VideoFrame, max_width: int | None = None) -> np.ndarray:
        """A decoded frame as an array (module conventions), at most ``max_width`` px wide (area
        filter; None = full size)."""
        width, height = frame.width, frame.height
        if max_width is not None and width > max_width:
            width, height = max_width, max(1, round(height * max_width / width))
        rgb = frame.reformat(
            width=width, height=height, format=self._format, interpolation="AREA",
            src_colorspace=_matrix(frame.colorspace, frame.height), src_color_range=frame.color_range or 1,
            dst_color_range=2, threads=1 if width * height <= SINGLE_THREAD_PIXELS else thread_budget() or 0,
        )
        return rgb.to_ndarray()

    def items(self) -> Iterator[VideoFrame | CopiedPacket]:
        """Frames (:class:`VideoFrame`) and copied packets in demuxing order."""
        wanted = [self.stream, *self.copied]
        try:
            for packet in self._container.demux(wanted):
                if packet.stream is not self.stream:
                    if packet.dts is not None:
                        yield CopiedPacket(packet)
                    continue
                for frame in (self._decoder.decode(packet) if self._decoder is not None else packet.decode()):
                    image = None if self.planar else self.convert(frame, self.max_width)
                    self.frames_read += 1
                    if frame.pts is not None:
                        self._last_pts = frame.pts
                    yield VideoFrame(self.frames_read - 1, image, frame.pts,
                                     frame if self.keep_decoded or self.planar else None)
        except av.FFmpegError as err:
            raise ValueError(
                f"input {ffmpeg_error(self.path, err)} (truncated or corrupt after {self.frames_read} decoded frames)"
            ) from None
        if self.frames_read == 0:
            raise ValueError(f"cannot read video {str(self.path)!r}: no frame could be decoded")
        self._check_complete()

    def _check_complete(self) -> None:
        """``ValueError`` when the frames stop well before the duration the header states (a
        truncated file): more than :data:`TRUNCATION_TOLERANCE_S` or two frames short."""
        stream, info = self.stream, self.info
        if stream.duration:
            stated = float(stream.duration * stream.time_base)
        elif self._container.duration:
            stated = self._container.duration / 1e6
        else:
            return
        start = float(stream.start_time * stream.time_base) if stream.start_time is not None else 0.0
        if self._last_pts is None:
            return
        reached = float(self._last_pts * stream.time_base) - start + 1.0 / info.fps
        if reached < stated - max(TRUNCATION_TOLERANCE_S, 2.0 / info.fps):
            raise ValueError(
                f"input {str(self.path)!r} is truncated: its header says {stated:.2f} s but its frames end at "
                f"{reached:.2f} s, after {self.frames_read} frames"
            )

    def __iter__(self) -> Iterator[np.ndarray]:
        for item in self.items():
            if isinstance(item, VideoFrame):
                yield item.image

    def close(self) -> None:
        self._container.close()

    def __enter__(self) -> "VideoReader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


FrameTags = tuple[int, int, int, int, bool]


def frame_tags(frame: av.VideoFrame) -> FrameTags:
    """A decoded frame's colour tags (primaries, transfer, matrix, range: FFmpeg's enum values) and
    its interlaced flag: what the bitstream says (the decoder context may report defaults before
    anything is decoded)."""
    return (int(frame.color_primaries), int(frame.color_trc), int(frame.colorspace), int(frame.color_range),
            bool(frame.interlaced_frame))


def stream_info(container: av.container.InputContainer, stream: av.VideoStream, tags: FrameTags, *,
                size: tuple[int, int] | None = None, pix_fmt: str | None = None) -> VideoInfo:
    """The :class:`VideoInfo` of an opened video ``stream`` of ``container``, with the first frame's
    ``tags`` (:func:`frame_tags`); ``size`` and ``pix_fmt`` default to the decoder's (a live source
    passes its first frame's). The rate falls back to :data:`SEQUENCE_RATE` where the stream states
    none; ``frame_count`` is -1 where the header does not give it (a live stream has none)."""
    context = stream.codec_context
    rate = stream.average_rate or stream.guessed_rate or stream.base_rate
    timecode = stream.metadata.get("timecode") or container.metadata.get("timecode")
    for other in container.streams:
        timecode = timecode or other.metadata.get("timecode")
    pix_fmt = pix_fmt or context.pix_fmt or "yuv420p"
    return VideoInfo(
        size=size or (int(context.width), int(context.height)),
        rate=Fraction(rate) if rate else SEQUENCE_RATE,
        frame_count=int(stream.frames) if stream.frames and stream.frames > 0 else -1,
        codec=context.name,
        pix_fmt=pix_fmt,
        bit_depth=_bit_depth(pix_fmt),
        time_base=Fraction(stream.time_base) if stream.time_base else Fraction(1, 90000),
        timecode=timecode,
        color_primaries=tags[0],
        color_trc=tags[1],
        colorspace=tags[2],
        color_range=tags[3],
        interlaced=tags[4],
        field_order=int(getattr(context, "field_order", 0) or 0),
        bit_rate=int(context.bit_rate or getattr(stream, "bit_rate", 0) or 0),
    )


def _first_frame_tags(path: Path, options: dict) -> FrameTags:
    """:func:`frame_tags` of the file's first decoded frame (unspecified where none decodes): read
    once per version of a file (path, size, modification time, inode) and kept, since a command
    opens its input several times (``correct --auto``: the check, pass 1, pass 2), and decoding
    the first frame again takes 18 ms at 960 x 540, 50 at 1920 x 1080."""
    key = str(path), tuple(sorted(options.items()))
    try:
        stat = path.stat()
    except OSError:  # an image sequence's pattern: read each time
        return _read_first_frame_tags.__wrapped__(*key, None)
    return _read_first_frame_tags(*key, (stat.st_size, stat.st_mtime_ns, stat.st_ino))


@functools.lru_cache(maxsize=8)
def _read_first_frame_tags(path: str, options: tuple, version: tuple | None) -> FrameTags:
    """:func:`_first_frame_tags` of one version of a file (``version`` only keys the cache)."""
    try:
        with av.open(path, "r", options=dict(options)) as container:
            return frame_tags(next(container.decode(video=0)))
    except (av.FFmpegError, StopIteration, UnicodeDecodeError):
        return _UNSPECIFIED, _UNSPECIFIED, _UNSPECIFIED, 0, False


def _copyable(stream: av.stream.Stream) -> bool:
    if stream.type not in ("audio", "subtitle", "data"):
        return False
    tag = getattr(stream.codec_context, "codec_tag", "") if stream.codec_context else ""
    return not (stream.type == "data" and (tag == "tmcd" or "timecode" in stream.metadata))


class _FieldFlags:
    """Marks frames interlaced with a field order (FFmpeg's ``setfield`` filter: PyAV cannot set a
    frame's flags), which the encoders (libx264, prores_ks, mpeg2video ...) follow."""

    def __init__(self, fields: str) -> None:
        self.fields = fields
        self._graph: av.filter.Graph | None = None
        self._lock = threading.Lock()

    def __call__(self, frame: av.VideoFrame) -> av.VideoFrame:
        with self._lock:
            if self._graph is None:
                graph = av.filter.Graph()
                source = graph.add_buffer(width=frame.width, height=frame.height, format=frame.format.name,
                                          time_base=frame.time_base)
                mark, sink = graph.add("setfield", self.fields), graph.add("buffersink")
                source.link_to(mark)
                mark.link_to(sink)
                graph.configure()
                self._graph = graph
            self._graph.push(frame)
            marked = self._graph.pull()
        marked.pts, marked.time_base = frame.pts, frame.time_base
        return marked


#: FFmpeg's native VP8/VP9 decoders drop the alpha a WebM file stores beside the picture
#: (Matroska AlphaMode, BlockAdditional); libvpx's decoders return it
_ALPHA_DECODERS = {"vp8": "libvpx", "vp9": "libvpx-vp9"}


def _alpha_decoder(stream: av.video.stream.VideoStream) -> "av.codec.context.CodecContext | None":
    """A libvpx decoder for a VP8/VP9 stream that states an alpha plane (``alpha_mode`` = 1); None
    otherwise (or when this FFmpeg has no libvpx decoder)."""
    name = _ALPHA_DECODERS.get(stream.codec_context.name)
    if name is None or stream.metadata.get("alpha_mode") != "1":
        return None
    try:
        decoder = av.CodecContext.create(name, "r")
    except (av.FFmpegError, ValueError):
        return None
    decoder.extradata = stream.codec_context.extradata
    decoder.pix_fmt = "yuva420p"
    return decoder


def _interlace_encoder(context: av.codec.context.CodecContext, info: VideoInfo) -> "_FieldFlags | None":
    """For an interlaced ``info`` (:attr:`VideoInfo.fields`), ask the encoder for interlaced coding
    (field DCT and motion estimation) and return the frame marker; None for progressive."""
    if info.fields == "progressive":
        return None
    context.flags |= av.codec.context.Flags.interlaced_dct | av.codec.context.Flags.interlaced_me
    if info.field_order in (FIELD_UNKNOWN, FIELD_PROGRESSIVE):  # frames flagged interlaced, stream silent
        context.field_order = FIELD_ORDER_CODES[info.fields]
    return _FieldFlags(info.fields)


def probe_video(path: str | os.PathLike) -> VideoInfo:
    """:class:`VideoInfo` with the frame count counted by decoding (exact, slower than the header)."""
    with VideoReader(path, max_width=16) as reader:
        count = sum(1 for _ in reader)
        info = reader.info
    return VideoInfo(**{**info.__dict__, "frame_count": count})


# -- writing ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class EncodeOptions:
    """Output encoding: ``codec`` (an FFmpeg encoder or codec name: h264, hevc, prores, ffv1 ...;
    None = the input's codec where an encoder exists and the container takes it, else the
    container's default), ``crf`` (quality for x264/x265/VPx/AV1 encoders), ``bitrate`` (bits per
    second; default for encoders without a CRF: the input's bit rate), ``preset`` (encoder speed
    preset), ``pix_fmt`` (None = the input's where the encoder takes it, else the encoder's format
    closest in depth and chroma)."""

    codec: str | None = None
    crf: float | None = None
    bitrate: int | None = None
    preset: str | None = None
    pix_fmt: str | None = None

    def __post_init__(self) -> None:
        if self.crf is not None and self.bitrate is not None:
            raise ValueError("give crf or bitrate, not both")
        if self.crf is not None and not (0 <= self.crf <= 63):
            raise ValueError(f"crf must lie in [0, 63], got {self.crf}")
        if self.bitrate is not None and self.bitrate <= 0:
            raise ValueError(f"bitrate must be positive (bits per second), got {self.bitrate}")


def _encoder(name: str) -> av.Codec:
    try:
        return av.Codec(name, "w")
    except Exception:
        raise ValueError(f"no FFmpeg encoder {name!r} in this build (see 'ffmpeg -encoders')") from None


def _check_preset(encoder: str, context: av.CodecContext, preset: str) -> None:
    """``ValueError`` when ``encoder`` has no ``preset`` option or ``preset`` is not one of its presets
    (FFmpeg's list of the option's named values, else :data:`X26X_PRESETS` for x264/x265; an
    encoder whose presets neither knows is left to refuse it when it opens)."""
    supported = getattr(context, "supported_options", None)
    if supported is None:  # a PyAV without option introspection
        return
    option = next((o for o in supported.private if o.name == "preset"), None)
    if option is None:
        raise ValueError(f"--preset {preset!r}: encoder {encoder} has no presets")
    presets = [choice.name for choice in (option.choices or [])] or list(_LIBRARY_PRESETS.get(encoder, ()))
    if presets and preset not in presets:
        raise ValueError(f"--preset {preset!r} is not a preset of {encoder} ({' '.join(presets)})")


def _pick_pix_fmt(codec: av.Codec, wanted: str | None, source: str) -> str:
    formats = [f.name for f in (codec.video_formats or [])]
    if wanted is not None:
        if formats and wanted not in formats:
            raise ValueError(f"encoder {codec.name} cannot write pix_fmt {wanted!r}; it takes {', '.join(formats)}")
        return wanted
    if not formats or source in formats:
        return source
    depth = _bit_depth(source)

    def layout(name: str) -> tuple:
        fmt = av.VideoFormat(name, 64, 64)  # a size, so that the chroma planes have one
        return (fmt.is_rgb, tuple(c.width for c in fmt.components[:3]), tuple(c.height for c in fmt.components[:3]),
                has_alpha(name))

    wanted_layout = layout(source)

    def distance(name: str) -> tuple[int, int, int]:
        bits = _bit_depth(name)
        alpha_lost = 1000 if has_alpha(source) and not has_alpha(name) else 0  # a key is never dropped by default
        return (abs(bits - depth) + (100 if bits < depth else 0) + alpha_lost, 0 if layout(name) == wanted_layout else 1,
                formats.index(name))

    return min(formats, key=distance)


class VideoWriter:
    """Encode frames into a video (or an image sequence) like the source described by ``info``.

    ``streams`` are input streams to copy (:attr:`VideoReader.copied`); their packets go through
    :meth:`mux`. :meth:`write` takes an image (module conventions, the ``info`` size; uint8 or uint16)
    and the frame's ``pts`` in ``info.time_base`` (None: numbered from 0 at the frame rate). The file
    appears at ``path`` only on :meth:`close`; :meth:`abort` (or an exception inside ``with``)
    removes everything. ``low_delay``: every frame's packets leave as it is encoded (slice threads
    only; a live output), not a few frames later (:attr:`thread_type`). Errors: ``ValueError`` for
    options the encoder or container refuses, ``FileExistsError`` for an existing output without
    ``overwrite``, ``OSError`` naming the path for anything FFmpeg fails to write (full disk ...).
    """

    #: the container format to write (None: FFmpeg's choice by the name's extension)
    container_format: str | None = None
    #: the encoder's threads: "AUTO" (frame and slice threads, what the ffmpeg command uses: x264
    #: then encodes some frames ahead, about 20 % less time at 960x540 than PyAV's default of slice
    #: threads) for files; "SLICE" for a live output (``low_delay``), where a frame must leave at once
    thread_type = "AUTO"

    def __init__(
        self,
        path: str | os.PathLike,
        info: VideoInfo,
        *,
        options: EncodeOptions = EncodeOptions(),
        streams: list = (),  # type: ignore[assignment]
        order: ChannelOrder = "rgb",
        overwrite: bool = False,
        low_delay: bool = False,
    ) -> None:
        if order not in ("rgb", "bgr"):
            raise ValueError(f"order must be 'rgb' or 'bgr', got {order!r}")
        if low_delay:
            self.thread_type = "SLICE"
        self.path = check_output_folder(path)
        self.info, self.order, self.options = info, order, options
        self.sequence = is_sequence(self.path)
        check_video_overwrite(self.path, overwrite)
        self.frames_written = 0
        self._closed = False
        self._atomic = None
        if self.sequence:
            self._tmpdir: Path | None = temporary_folder(self.path, self.path.name.split('%')[0])
            tmp = self._tmpdir / self.path.name
        else:
            self._tmpdir = None
            self._atomic = atomic_path(self.path)
            tmp = self._atomic.__enter__()
        self._tmp = tmp
        try:
            self._open(str(tmp), streams)
        except ValueError as err:
            self.abort()
            if str(self.path) in str(err):
                raise
            raise ValueError(f"cannot write {str(self.path)!r}: {err}") from None
        except BaseException:
            self.abort()
            raise

    def _open(self, tmp: str, streams) -> None:
        info = self.info
        try:
            self._container = av.open(tmp, "w", format="image2" if self.sequence else self.container_format)
        except (av.FFmpegError, ValueError) as err:
            raise ValueError(f"FFmpeg cannot write {ffmpeg_error(self.path, err)} (unknown or unsupported output format)") from None
        codec = _encoder(self._codec_choice())
        stream = self._add_video_stream(codec)
        self._stream = stream
        self._codec_name, self._pix_fmt = stream.codec_context.name, stream.pix_fmt
        self._depth = _bit_depth(stream.pix_fmt)
        self._matrix = _matrix(info.colorspace, info.size[1])
        self._range = info.color_range or (2 if stream.pix_fmt.startswith("yuvj") else 1)
        self._copies = {}
        for source in streams:
            try:
                self._copies[source.index] = self._container.add_stream_from_template(source)
            except (av.FFmpegError, ValueError) as err:
                raise ValueError(
                    f"cannot copy the {source.type} stream #{source.index} ({source.codec_context.name if source.codec_context else '?'}) "
                    f"into {str(self.path)!r}: {err}; choose a container that holds it (.mkv, .mov)"
                ) from None
        self._start_encoding(codec)

    def _codec_choice(self) -> str:
        """The encoder's name: the one asked for, else by the sequence's extension, else the input's
        codec where FFmpeg has an encoder for it and the container takes it, else the container's default."""
        name = self.options.codec
        if name is not None:
            return name
        if self.sequence:
            return {".png": "png", ".tif": "tiff", ".tiff": "tiff", ".jpg": "mjpeg", ".jpeg": "mjpeg"}.get(
                self.path.suffix.lower(), self._container.default_video_codec)
        # the input's codec where FFmpeg has an encoder for it and the container is not
        # known to refuse it (avformat's list is authoritative only where it is long)
        supported = self._container.supported_codecs
        name = self.info.codec
        try:
            encoder_ok = bool(name) and av.Codec(name, "w") is not None
        except Exception:
            encoder_ok = False
        if not encoder_ok or (len(supported) > 20 and name not in supported):
            name = self._container.default_video_codec
        return name

    def _add_video_stream(self, codec):
        """The output video stream: size, pixel format, timing, colour tags, field order, encoder
        options (crf, preset, bitrate) and timecode."""
        info, options = self.info, self.options
        stream = self._container.add_stream(codec.name, rate=info.rate)
        stream.width, stream.height = info.size
        stream.pix_fmt = _pick_pix_fmt(codec, options.pix_fmt, info.pix_fmt)
        stream.time_base = info.time_base
        stream.codec_context.time_base = info.time_base
        context = stream.codec_context
        context.color_primaries = info.color_primaries
        context.color_trc = info.color_trc
        context.colorspace = info.colorspace
        context.color_range = info.color_range
        if info.field_order:
            try:
                context.field_order = info.field_order
            except (AttributeError, TypeError, ValueError):
                pass
        self._fields = _interlace_encoder(context, info)
        context.thread_type = self.thread_type
        context.thread_count = thread_budget() or 0  # the process's budget (glradial.threads); 0: FFmpeg's automatic count
        codec_options: dict[str, str] = {}
        if options.crf is not None:
            if codec.name not in CRF_ENCODERS:
                raise ValueError(f"--crf is for {', '.join(sorted(CRF_ENCODERS))}; use --bitrate with {codec.name}")
            codec_options["crf"] = f"{options.crf:g}"
        if options.preset is not None:
            _check_preset(codec.name, context, options.preset)
            codec_options["preset"] = options.preset
        bitrate = options.bitrate
        if bitrate is None and options.crf is None and codec.name not in CRF_ENCODERS and info.bit_rate > 0:
            bitrate = info.bit_rate
        if bitrate:
            context.bit_rate = int(bitrate)
        context.options = codec_options
        if info.timecode and not self.sequence:
            stream.metadata["timecode"] = info.timecode
        return stream

    def _start_encoding(self, codec) -> None:
        """Open the encoder and start the container; a refusal is a ``ValueError`` naming the codec."""
        try:
            with silenced():  # the encoder's own log lines on a refusal: the ValueError below says it
                try:
                    self._stream.codec_context.open()
                except av.FFmpegError:
                    # some encoders (MPEG-1/2) take only a standard frame-rate time base
                    self._stream.codec_context.time_base = 1 / self.info.rate
                    self._stream.codec_context.open()
                self._container.start_encoding()
        except av.FFmpegError as err:
            preset = f", preset {self.options.preset!r}" if self.options.preset is not None else ""
            raise ValueError(f"cannot encode {ffmpeg_error(self.path, err)} (codec {codec.name}, pix_fmt {self._stream.pix_fmt}{preset})") from None

    @property
    def codec(self) -> str:
        return self._codec_name

    @property
    def pix_fmt(self) -> str:
        return self._pix_fmt

    def frame(self, image: np.ndarray, pts: int | None = None) -> av.VideoFrame:
        """The encoder-ready frame for ``image`` (RGB -> the output pix_fmt); thread-safe, so a
        worker thread can convert while the caller encodes."""
        image = np.asarray(image)
        width, height = self.info.size
        if image.shape not in ((height, width, 3), (height, width, 4)) or image.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"video frames must be {height}×{width}×3 (or ×4 with alpha) uint8 or uint16, got shape "
                             f"{image.shape} {image.dtype}")
        if image.shape[2] == 4 and not has_alpha(self._pix_fmt):
            image = image[:, :, :3]  # an output format without alpha, chosen with pix_fmt (check_alpha_kept)
        depth = 8 if image.dtype == np.uint8 else 16
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format=_rgb_format(depth, self.order, image.shape[2] == 4))
        frame = frame.reformat(format=self._pix_fmt, dst_colorspace=self._matrix, src_color_range=2,
                               dst_color_range=self._range, interpolation="BILINEAR", threads=thread_budget() or 0)
        return self._stamp(frame, pts)

    def _stamp(self, frame: av.VideoFrame, pts: int | None) -> av.VideoFrame:
        # the source's tags, not those of the conversion (which names its matrix even when untagged)
        frame.colorspace, frame.color_range = self.info.colorspace, self.info.color_range
        frame.color_primaries, frame.color_trc = self.info.color_primaries, self.info.color_trc
        frame.pts = pts
        frame.time_base = self.info.time_base  # the muxer may give the stream another time base
        return self._fields(frame) if self._fields is not None else frame

    @property
    def full_range(self) -> bool:
        """Whether the output's YUV samples are full range (JPEG) rather than limited (video)."""
        return self._range == 2

    def takes_planes_of(self, source_pix_fmt: str) -> bool:
        """Whether frames in ``source_pix_fmt`` can be written plane for plane (:meth:`planar_frame`):
        the output is that same planar YUV format (:func:`yuv_layout`), progressive."""
        return source_pix_fmt == self._pix_fmt and yuv_layout(self._pix_fmt) is not None and self._fields is None

    def planar_frame(self) -> tuple[av.VideoFrame, list[np.ndarray]]:
        """A new frame in the output pix_fmt (planar YUV: :meth:`takes_planes_of`) and writable
        views of its planes (:func:`frame_planes`); fill them, then :meth:`stamp` it."""
        width, height = self.info.size
        frame = av.VideoFrame(width, height, self._pix_fmt)
        return frame, frame_planes(frame)

    def stamp(self, frame: av.VideoFrame, pts: int | None) -> av.VideoFrame:
        """A frame of :meth:`planar_frame`, filled, made ready to encode: the source's colour tags,
        ``pts`` (in ``info.time_base``) and time base."""
        return self._stamp(frame, pts)

    def check_alpha_kept(self) -> None:
        """``ValueError`` when the source has alpha (``info.pix_fmt``) and the output format has none,
        unless that format was chosen (``options.pix_fmt``): a key is never dropped silently."""
        if has_alpha(self.info.pix_fmt) and not has_alpha(self._pix_fmt) and self.options.pix_fmt is None:
            raise ValueError(
                f"the input has alpha ({self.info.pix_fmt}) but {str(self.path)!r} would be written as {self._pix_fmt} "
                f"({self._codec_name}), which stores none: write ProRes 4444 (.mov, --codec prores), FFV1 (.mkv), VP9 in "
                f".webm or a PNG sequence to keep it, or give --pix-fmt (e.g. {self._pix_fmt}) to drop it"
            )

    def write(self, image: np.ndarray | av.VideoFrame, pts: int | None = None) -> None:
        frame = image if isinstance(image, av.VideoFrame) else self.frame(image, pts)
        if frame.pts is None:  # number the frames at the frame rate
            frame.pts = round(Fraction(self.frames_written) / self.info.rate / self.info.time_base)
            frame.time_base = self.info.time_base
        try:
            packets = self._stream.encode(frame)
        except av.FFmpegError as err:
            raise OSError(f"cannot write {ffmpeg_error(self.path, err)}") from None
        try:  # the encoder has the frame, and close() writes it out: counted even if a signal stops us here
            self._container.mux(packets)
        except av.FFmpegError as err:
            raise OSError(f"cannot write {ffmpeg_error(self.path, err)}") from None
        finally:
            self.frames_written += 1

    def mux(self, item: CopiedPacket) -> None:
        """Copy a packet of a copied stream into the output."""
        packet = item.packet
        target = self._copies.get(packet.stream.index)
        if target is None:
            return
        packet.stream = target
        try:
            self._container.mux(packet)
        except av.FFmpegError as err:
            raise OSError(f"cannot write {ffmpeg_error(self.path, err)}") from None

    def close(self) -> Path:
        """Flush the encoder, finish the file and move it into place; returns the target path."""
        if self._closed:
            return self.path
        try:
            with silenced():  # x265 prints its statistics when its context is freed: free it here
                self._container.mux(self._stream.encode(None))
                self._container.close()
                self._container = self._stream = None
                self._copies = {}
        except av.FFmpegError as err:
            self.abort()
            raise OSError(f"cannot write {ffmpeg_error(self.path, err)}") from None
        except BaseException:
            self.abort()
            raise
        self._closed = True
        if self.sequence:
            self._publish_sequence()
        else:
            context, self._atomic = self._atomic, None
            context.__exit__(None, None, None)
        return self.path

    def _publish_sequence(self) -> None:
        folder = self.path.parent if str(self.path.parent) else Path(".")
        try:
            for produced in sorted(self._tmpdir.iterdir()):
                os.replace(produced, folder / produced.name)
        finally:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None

    def abort(self) -> None:
        """Drop everything written so far; the target is left untouched. No-op once finished."""
        container = getattr(self, "_container", None)
        if container is not None and not self._closed:
            with silenced():  # the encoder's statistics, printed when its context is freed
                try:
                    container.close()
                except Exception:
                    pass
                del container
                self._container = self._stream = None
        self._closed = True
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None
        if self._atomic is not None:
            context, self._atomic = self._atomic, None
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


MediaItem = Union[VideoFrame, CopiedPacket]
