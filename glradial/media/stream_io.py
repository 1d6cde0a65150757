"""Live video in and out through FFmpeg's libraries (PyAV): a stream that arrives as it is made,
and an output that goes as the frames are made.

Sources (:class:`LiveSource`), by the text given:

* ``-``: standard input, a pipe of MPEG-TS or NUT (FFmpeg probes which; ``pipe:0``);
* ``udp://``, ``rtp://``, ``srt://`` (where the FFmpeg build has it), ``tcp://``, ``rtsp://``,
  ``rtmp://``, ``http(s)://``: a network stream; :data:`NETWORK_SCHEMES`;
* ``/dev/video*``: a V4L2 capture device (Linux);
* anything else: a file, read as fast as it decodes or, with ``realtime``, at its own frame rate
  (each frame handed out when its timestamp is due, as a live source would).

A network source ends after ``idle_timeout`` seconds without data (FFmpeg's interrupt callback,
PyAV's ``timeout``); a pipe or a file ends at EOF. Frames are handed out as decoded, each as soon
as its packet is in (slice threads, no frame threads, which would hold frames back for later
packets: their periods added to every frame's latency) (``av.VideoFrame``, the source's pix_fmt), with their presentation timestamps in the stream's time
base; :attr:`LiveSource.info` is the :class:`~glradial.media.video_io.VideoInfo` of the stream, read
from its header and first decoded frame (colour tags), ``frame_count`` -1 (a live stream has none).

Outputs (:func:`open_live_output`): a file (written atomically as every glradial output:
:class:`~glradial.media.video_io.VideoWriter`, the file appears complete when the stream ends,
also on Ctrl-C, never half-written), ``-`` (MPEG-TS on standard output) or a ``udp://`` URL
(MPEG-TS in 1316-byte datagrams unless the URL says ``pkt_size``; the frames leave at the pace they
are made, which is the input's): :class:`StreamWriter`.
"""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Iterator

import av

from .srt_relay import SrtRelay, is_srt, srt_route
from .video_io import EncodeOptions, VideoInfo, VideoWriter, ffmpeg_error, frame_tags, stream_info

__all__ = ["LiveSource", "StreamWriter", "open_live_output", "open_live_source", "check_live_output", "source_kind", "NETWORK_SCHEMES", "STREAM_OUTPUT_FORMAT"]

#: URL schemes read as network streams (ended by ``idle_timeout``)
NETWORK_SCHEMES = ("udp", "rtp", "srt", "tcp", "rtsp", "rtmp", "http", "https")
#: the container written to standard output and to a ``udp://`` URL
STREAM_OUTPUT_FORMAT = "mpegts"
#: datagram size of a ``udp://`` output: 7 MPEG-TS packets of 188 bytes (the usual IPTV size)
UDP_PACKET_SIZE = 1316
#: how long (microseconds) and how many bytes FFmpeg reads a network stream or a pipe before the first frame
#: is handed out (its defaults, 5 s and 5 MB, would hold back seconds of frames and then release
#: them at once): enough for a key frame of a stream with a 1 s GOP at up to 32 Mb/s
PROBE_US = 100_000
PROBE_BYTES = 500_000
#: FFmpeg's input FIFO for a UDP source (packets of 188 bytes): about 2 s of a 20 Mb/s stream, so
#: that a short stall of the reader loses nothing
UDP_FIFO_PACKETS = 50_000


def source_kind(source: str) -> str:
    """``"stdin"``, ``"network"``, ``"ndi"``, ``"device"`` or ``"file"`` for an INPUT text (module docstring)."""
    if source == "-":
        return "stdin"
    scheme, sep, _ = source.partition("://")
    if sep:
        if scheme.lower() in NETWORK_SCHEMES:
            return "network"
        if scheme.lower() == "ndi":
            return "ndi"
        raise ValueError(f"input {source!r}: unknown URL scheme {scheme!r}; live inputs take {', '.join(NETWORK_SCHEMES)}, "
                         "ndi, '-' (stdin), a V4L2 device or a file")
    return "device" if source.startswith("/dev/video") else "file"


def _open_arguments(source: str, kind: str, idle_timeout: float) -> tuple[str, dict]:
    """The URL and the keywords of ``av.open`` for ``source`` of ``kind``."""
    probe = {"analyzeduration": str(PROBE_US), "probesize": str(PROBE_BYTES)}
    if kind == "stdin":
        return "pipe:0", {"container_options": probe}
    if kind == "device":
        return source, {"format": "v4l2"}
    if kind == "file":
        if not Path(source).is_file():
            raise FileNotFoundError(f"input {source!r} does not exist (live inputs: '-', a URL, a V4L2 device or a file)")
        return source, {}
    options = dict(probe)
    if source.lower().startswith("udp://"):
        options.update(overrun_nonfatal="1", fifo_size=str(UDP_FIFO_PACKETS))
    return source, {"container_options": options, "timeout": (idle_timeout, idle_timeout)}


class LiveSource:
    """A live video source (module docstring). Iterate :meth:`frames` on one thread; :attr:`ended`
    then says why it stopped: ``"eof"`` or ``"idle"`` (no data for ``idle_timeout`` s).

    ``ValueError`` naming the source when it cannot be opened (nothing arrives within
    ``idle_timeout``, or what arrives is no stream FFmpeg knows: e.g. garbage bytes on a pipe) or
    holds no video; midway, a demuxing error ends :meth:`frames` with a ``ValueError`` that counts
    the frames decoded before it (a decoder's own complaint about a damaged packet, which FFmpeg
    conceals, is not an error)."""

    def __init__(self, source: str, *, idle_timeout: float = 5.0, realtime: bool = False) -> None:
        if not idle_timeout > 0:
            raise ValueError(f"idle_timeout must be > 0 seconds, got {idle_timeout!r}")
        self.source, self.kind, self.realtime = source, source_kind(source), bool(realtime)
        self.idle_timeout = float(idle_timeout)
        self.relay = None
        url, keywords = _open_arguments(source, self.kind, self.idle_timeout)
        if is_srt(source) and srt_route() == "ffmpeg":  # PyAV's wheels have no SRT: the system's FFmpeg relays it
            self.relay = SrtRelay(source, "in", idle_timeout=self.idle_timeout)
            url, keywords = self.relay.url, {"format": STREAM_OUTPUT_FORMAT, **_open_arguments(source, "stdin", 0)[1]}
        try:
            self._container = av.open(url, "r", **keywords)
        except av.ExitError:
            self._close_relay()
            raise ValueError(f"live input {source!r}: no data within {self.idle_timeout:g} s") from None
        except (av.FFmpegError, UnicodeDecodeError) as err:
            why = (self.relay.error() if self.relay is not None else "") or "not a stream FFmpeg knows, or no video in it"
            self._close_relay()
            raise ValueError(f"cannot read live input {ffmpeg_error(source, err)} ({why})") from None
        try:
            self._start()
        except BaseException:
            self.close()
            raise

    def _start(self) -> None:
        """The stream, its first frames and its :attr:`info` (``ValueError`` for none)."""
        if not self._container.streams.video:
            raise ValueError(f"live input {self.source!r} holds no video stream")
        self.stream = self._container.streams.video[0]
        # slice threads only: frame threads would hold each frame back until (threads - 1) later
        # packets came (2-3 frame periods more latency, and the stream's last frames until it ends)
        self.stream.thread_type = "SLICE"
        self.frames_read = 0
        self.ended = ""
        self._flushed = False
        self._packets = self._container.demux(self.stream)
        self._pending = self._first_frames()
        #: the first decoded frame (also the first :meth:`frames` hands out): what the stream's frames are like
        self.first_frame = self._pending[0]
        first = self.first_frame
        self.info = stream_info(self._container, self.stream, frame_tags(first), size=(first.width, first.height),
                                pix_fmt=first.format.name)

    def _decode_next(self) -> list[av.VideoFrame]:
        """The frames of the next packet ([] for none); StopIteration at the end of the input."""
        try:
            packet = next(self._packets)
            return list(packet.decode())
        except StopIteration:
            self.ended = self.ended or "eof"
            raise
        except (av.ExitError, av.EOFError) as end:
            self.ended = "idle" if isinstance(end, av.ExitError) else "eof"
            return self._flush()
        except (av.FFmpegError, UnicodeDecodeError) as err:
            raise ValueError(f"live input {ffmpeg_error(self.source, err)} (after {self.frames_read} decoded frames)") from None

    def _flush(self) -> list[av.VideoFrame]:
        """The frames the decoder still holds (its threads keep a few) once no packet will come,
        then StopIteration on the next call."""
        if self._flushed:
            raise StopIteration
        self._flushed = True
        try:
            return list(self.stream.codec_context.decode(None))
        except (av.FFmpegError, ValueError):
            return []

    def _first_frames(self) -> list[av.VideoFrame]:
        while True:
            try:
                frames = self._decode_next()
            except StopIteration:
                self._container.close()
                why = f"no data within {self.idle_timeout:g} s" if self.ended == "idle" else "no frame could be decoded"
                why = (self.relay.error() if self.relay is not None else "") or why
                raise ValueError(f"live input {self.source!r}: {why}") from None
            if frames:
                return frames

    def frames(self) -> Iterator[av.VideoFrame]:
        """The decoded frames, as they arrive (paced at their timestamps with ``realtime``)."""
        start = origin = None
        while True:
            if not self._pending:
                try:
                    self._pending = self._decode_next()
                except StopIteration:
                    return
                continue
            frame = self._pending.pop(0)
            if self.realtime and frame.pts is not None:
                due = float(frame.pts * self.stream.time_base)
                if start is None:
                    start, origin = time.monotonic(), due
                wait = start + (due - origin) - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            self.frames_read += 1
            yield frame

    def timestamp(self, frame: av.VideoFrame) -> float | None:
        """The frame's presentation time (seconds on the input's clock), None without a timestamp."""
        return None if frame.pts is None else float(frame.pts * self.stream.time_base)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._container.close()
        self._close_relay()

    def _close_relay(self) -> None:
        if self.relay is not None:
            self.relay.close()


class StreamWriter(VideoWriter):
    """:class:`~glradial.media.video_io.VideoWriter` into MPEG-TS on standard output (``target``
    ``-``), a ``udp://`` or an ``srt://`` URL (:mod:`glradial.media.srt_relay`): written as it goes,
    not atomically (there is no file to rename); :meth:`close` flushes the encoder and ends the
    stream, :meth:`abort` stops it where it is."""

    container_format = STREAM_OUTPUT_FORMAT
    thread_type = "SLICE"  # live: no frame-threaded encoder delay

    def __init__(self, target: str, info: VideoInfo, *, options: EncodeOptions = EncodeOptions(), order: str = "rgb") -> None:
        if order not in ("rgb", "bgr"):
            raise ValueError(f"order must be 'rgb' or 'bgr', got {order!r}")
        url = "pipe:1" if target == "-" else target
        if url.lower().startswith("udp://") and "pkt_size=" not in url:
            url += ("&" if "?" in url else "?") + f"pkt_size={UDP_PACKET_SIZE}"
        self.relay = None
        if is_srt(target) and srt_route() == "ffmpeg":  # PyAV's wheels have no SRT: the system's FFmpeg relays it
            self.relay = SrtRelay(target, "out")
            url = self.relay.url
        self.path = target
        self.info, self.order, self.options = info, order, options
        self.sequence, self.frames_written, self._closed = False, 0, False
        self._tmpdir, self._atomic = None, contextlib.nullcontext()
        try:
            self._open(url, [])
            if url.startswith("pipe:"):  # stdout or the SRT relay: each frame's packets go at once, not in 32 KB bursts
                self._container.flags |= av.container.Flags.flush_packets.value
        except BaseException:
            self.abort()
            raise

    def close(self) -> Path:
        """Flush the encoder and end the stream (an SRT relay flushed and ended too)."""
        try:
            return super().close()
        finally:
            if self.relay is not None:
                self.relay.close()

    def abort(self) -> None:
        super().abort()
        if getattr(self, "relay", None) is not None:
            self.relay.close(wait=1.0)


def check_live_output(target: str) -> str:
    """``"stdout"``, ``"udp"``, ``"srt"``, ``"ndi"`` or ``"file"`` for an OUTPUT text; ``ValueError``
    for another URL, or for srt:// where no FFmpeg has SRT (:func:`glradial.media.srt_relay.srt_route`);
    ``RuntimeError`` for ndi:// without the NDI extra."""
    if target == "-":
        return "stdout"
    scheme, sep, _ = target.partition("://")
    if not sep:
        return "file"
    if scheme.lower() == "ndi":
        from .ndi_io import require_ndi

        require_ndi()
        return "ndi"
    if scheme.lower() not in ("udp", "srt"):
        raise ValueError(f"output {target!r}: a live output URL must be udp://HOST:PORT or srt://HOST:PORT (MPEG-TS), "
                         "ndi://NAME, or give a file or '-'")
    if scheme.lower() == "srt":
        srt_route()
    return scheme.lower()


def open_live_output(target: str, info: VideoInfo, *, options: EncodeOptions = EncodeOptions(),
                     overwrite: bool = False) -> VideoWriter:
    """The writer of OUTPUT ``target`` (module docstring) for frames like ``info``."""
    kind = check_live_output(target)
    if kind == "file":
        return VideoWriter(target, info, options=options, overwrite=overwrite, low_delay=True)
    if kind == "ndi":
        from .ndi_io import NdiWriter

        return NdiWriter(target, info)
    return StreamWriter(target, info, options=options)


def open_live_source(source: str, *, idle_timeout: float = 5.0, realtime: bool = False):
    """The live input ``source``: an :class:`~glradial.media.ndi_io.NdiSource` for ``ndi://NAME``,
    else a :class:`LiveSource` (module docstring)."""
    if source_kind(source) == "ndi":
        from .ndi_io import NdiSource

        return NdiSource(source, idle_timeout=idle_timeout)
    return LiveSource(source, idle_timeout=idle_timeout, realtime=realtime)
