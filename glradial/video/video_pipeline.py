"""Automatic lens correction of videos: one lens per shot, then correct.

Pipeline (memory does not grow with the file's length):

1. :func:`track_video` decodes a subsample (the frames other frames refer to, where the stream
   allows: :mod:`glradial.video.shot_track`), detects cuts on 64 px thumbnails, places each cut
   seen between two decoded frames exactly by decoding that stretch again, and gathers a cheap
   subsample's evidence (line chains, frame-to-frame matches, a per-frame estimate now and
   then, on copies at most :data:`~glradial.video.shot_track.ESTIMATE_WIDTH` px wide); each shot gets one joint lens fit, a
   function of its zoom when the picture zooms (:mod:`glradial.video.shot_track`,
   :mod:`glradial.video.shot_fit`). A doubtful shot is marked and, by default, passed through
   uncorrected.
2. :func:`correct_video` decodes the file (all of it, once), corrects each frame with its lens and
   encodes it (:mod:`glradial.media.video_io`: audio and other streams copied, timing, colour tags
   and depth kept). A planar YUV stream (yuv420p, yuv422p10le ...) written in its own pix_fmt is
   corrected plane by plane in its own samples, with no conversion to RGB and back
   (:func:`correction_space`, :mod:`glradial.remapping.planes`); anything else goes through RGB.
   Decoding, correction and encoding overlap on three threads with at most ``depth`` frames
   queued between two steps; the correction runs on one worker thread, which owns its GL context
   (released when it ends) or uses the CPU path.

The result of pass 1 is a :class:`~glradial.video.lens_track.LensTrack`, written as a sidecar
(format: :mod:`glradial.video.lens_track`).

Convention: frames are ``H x W x 3`` RGB (uint8, or uint16 for deeper sources) when they reach the
RGB corrector, planes of the source's own samples on the YUV path; the estimator gets uint8 RGB; the lens is width-normalised ``(k1, k2)`` (docs/DESIGN.md).
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import replace
from fractions import Fraction
from typing import Callable

import numpy as np

from ..lens.lens import Lens, as_lens
from ..lens.metrics import max_displacement
from ..media.progress import Progress
from ..media.video_io import (
    FIELD_ORDER_CODES,
    CopiedPacket,
    EncodeOptions,
    VideoFrame,
    VideoInfo,
    VideoReader,
    VideoWriter,
    frame_planes,
    yuv_layout,
)
from .lens_track import LensTrack
from .pipelined import Pipelined
from .shot_track import EVERY, track_shots

__all__ = ["LensTrack", "track_video", "correct_video", "correction_space", "default_estimator"]

#: what the pipeline notes without failing (a header's frame count the stream does not hold);
#: ``glradial`` shows its warnings on stderr
logger = logging.getLogger(__name__)

#: estimator: RGB uint8 frame -> (k1, k2) or a Lens (a LensEstimate carries uncertainty_px and method)
EstimatorFn = Callable[[np.ndarray], "tuple[float, float] | Lens"]

#: pass 2 keeps the previous frame's lens (and so its cached maps) while the next frame's lens
#: would move no point of the frame by more than this (px of the frame): half the 1/32-px step of
#: the CPU path's fixed-point maps (RGB frames), which cannot resolve a smaller change anyway; the
#: planar YUV path's float maps could, but a 1/64-px shift moves a sample by at most 4 levels at
#: the sharpest 8-bit edge (255 levels a pixel), far less on smooth picture. A static or panning
#: camera then builds its maps once per shot instead of once per frame; a zoom still rebuilds them.
MAP_REUSE_PX = 1.0 / 64.0


def default_estimator(model: str | os.PathLike | None = None, method: str | None = None) -> EstimatorFn:
    """The bundled estimator (:class:`glradial.Estimator`), as a frame -> lens function; ``method``
    (e.g. "auto", "net", "lines") is handed to ``NetLinesEstimator.estimate`` when given."""
    from ..estimation.net_lines import NetLinesEstimator

    estimator = NetLinesEstimator(model) if model is not None else NetLinesEstimator()
    if method is None:
        return lambda frame: estimator.estimate(frame)
    return lambda frame: estimator.estimate(frame, method=method)


#: pass 1: detect cuts and fit one lens per shot while decoding (:func:`glradial.video.shot_track.track_shots`)
track_video = track_shots


class FrameCorrector:
    """Corrects frames on the pipeline's worker thread: ``backend`` "gl" makes a
    :class:`~glradial.remapping.remap.Remapper` with its own context on first use there (falling back to the
    CPU for frames beyond its texture limit) and :meth:`release` frees it on that thread."""

    def __init__(self, backend: str, fit: str, interpolation: str, direction: str = "undistort", **extra: object) -> None:
        from ..lens.options import BACKENDS, DIRECTIONS
        from ..remapping.remap import auto_backend

        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        if direction not in DIRECTIONS:
            raise ValueError(f"direction must be one of {', '.join(DIRECTIONS)}, got {direction!r}")
        self.backend = auto_backend() if backend == "auto" else backend
        self.fit, self.interpolation, self.direction = fit, interpolation, direction
        self.extra = extra  # inverse= (distort), alpha=
        self.interlaced = False  # True: each field on its own geometry (glradial.remapping.fields)
        self._remapper = None
        self._last: Lens | None = None

    def _reused(self, lens: Lens, width: int, height: int) -> Lens:
        """``lens``, or the previous frame's when no point of the frame would move by more than
        :data:`MAP_REUSE_PX` (the same maps, cached)."""
        last = self._last
        if (last is not None and (last.cx, last.cy, last.pixel_aspect) == (lens.cx, lens.cy, lens.pixel_aspect)
                and max_displacement((lens.k1, lens.k2), (last.k1, last.k2), lens.frame_radius((width, height))) * width
                <= MAP_REUSE_PX):
            return last
        self._last = lens
        return lens

    def use_planes(self, info: VideoInfo, full_range: bool) -> None:
        """Correct frames of ``info`` (planar YUV, :func:`correction_space`) plane by plane."""
        from ..remapping.planes import black, chroma_siting, yuv_planes

        shift_x, shift_y, bits = yuv_layout(info.pix_fmt)
        self.lattices = yuv_planes(info.size, (shift_x, shift_y), chroma_siting(info.codec))
        self.black = black(bits, full_range)

    def planar(self, decoded, lens: Lens | None, writer: VideoWriter, pts: int | None):
        """The encoder-ready frame of a decoded planar YUV frame corrected with ``lens`` (None: copied)."""
        from ..remapping.planes import remap_planes

        frame, out = writer.planar_frame()
        source = frame_planes(decoded)
        if lens is None:
            for plane, target in zip(source, out):
                target[...] = plane
        else:
            lens = self._reused(lens, decoded.width, decoded.height)
            remap_planes(source, lens, self.lattices, out, fill=self.black, direction=self.direction, fit=self.fit,
                         interpolation=self.interpolation, inverse=str(self.extra.get("inverse", "exact")))
        return writer.stamp(frame, pts)

    def __call__(self, image: np.ndarray, lens: Lens) -> np.ndarray:
        height, width = image.shape[:2]
        lens = self._reused(lens, width, height)
        if not self.interlaced:
            return self._remap(image, lens, self.fit)
        from ..remapping.fields import remap_fields

        return remap_fields(image, lens, lens.fit_scale((width, height), self.fit, self.direction), self._remap)

    def _remap(self, image: np.ndarray, lens: Lens, fit: object) -> np.ndarray:
        from ..remapping.remap import Remapper, correct, distort

        options = dict(fit=fit, interpolation=self.interpolation, **self.extra)
        if self.backend == "gl":
            if self._remapper is None:
                self._remapper = Remapper()
            if max(image.shape[:2]) <= self._remapper.max_texture_size:
                method = self._remapper.correct if self.direction == "undistort" else self._remapper.distort
                return method(image, lens, **options)
        return (correct if self.direction == "undistort" else distort)(image, lens, backend="cpu", **options)

    def release(self) -> None:
        if self._remapper is not None:
            self._remapper.release()
            self._remapper = None


def correction_space(info: VideoInfo, writer: VideoWriter, backend: str, remap_options: dict) -> tuple[str, str]:
    """Where pass 2 corrects the frames of a stream ``info`` written by ``writer``: ``("yuv", "")``
    plane by plane in the source's own samples (:mod:`glradial.remapping.planes`: no colour
    conversion), or ``("rgb", why)``: decoded to RGB, corrected, converted back. YUV needs the CPU
    backend, a progressive planar YUV source without alpha (:func:`~glradial.media.video_io.yuv_layout`:
    yuv420p, yuv422p10le ...) written in that same pix_fmt, and no ``fill`` of its own."""
    if backend != "cpu":
        return "rgb", f"the {backend} backend corrects RGB frames"
    if info.fields != "progressive":
        return "rgb", f"interlaced ({info.fields}): fields are remapped in RGB"
    if set(remap_options) - {"inverse", "alpha"}:
        return "rgb", f"options {sorted(set(remap_options) - {'inverse', 'alpha'})} are applied in RGB"
    if yuv_layout(info.pix_fmt) is None:
        return "rgb", f"{info.pix_fmt} is not planar YUV"
    if not writer.takes_planes_of(info.pix_fmt):
        return "rgb", f"the output is {writer.pix_fmt}, not {info.pix_fmt}"
    return "yuv", ""


def _with_fields(info: VideoInfo, field_order: str) -> VideoInfo:
    """``info`` with ``field_order`` forced (``"auto"``: unchanged)."""
    from ..remapping.fields import FIELD_ORDERS

    if field_order not in FIELD_ORDERS:
        raise ValueError(f"field_order must be one of {', '.join(FIELD_ORDERS)}, got {field_order!r}")
    if field_order == "auto":
        return info
    return replace(info, field_order=FIELD_ORDER_CODES[field_order], interlaced=field_order != "progressive")


def correct_video(
    source: str | os.PathLike,
    target: str | os.PathLike,
    lenses: Callable[[int], Lens | tuple[float, float] | None],
    *,
    fit: str = "same",
    interpolation: str = "linear",
    backend: str = "auto",
    progress: bool | None = None,
    label: str = "correct",
    options: EncodeOptions = EncodeOptions(),
    overwrite: bool = False,
    frames_expected: int | None = None,
    rate: Fraction | None = None,
    direction: str = "undistort",
    field_order: str = "auto",
    **remap_options: object,
) -> int:
    """Pass 2: correct (``direction="distort"``: distort) every frame of ``source`` with
    ``lenses(frame_index)`` (a :class:`Lens` or ``(k1, k2)``; ``None`` passes the frame through
    uncorrected) into ``target``
    (atomic; size, timing, colour, depth and the other streams kept, :mod:`glradial.media.video_io`;
    encoder from ``options``). Returns the number of frames written. ``frames_expected`` (a lens
    track's length): a video with another frame count is an error and leaves no output. A header
    frame count that differs from the frames decoded gives a warning on stderr with both counts.
    ``rate``: frame rate of an image-sequence input (default 25). ``remap_options``: ``inverse``
    (distort) and ``alpha`` of :func:`glradial.distort`. ``field_order``: ``"auto"`` (the stream's,
    :attr:`VideoInfo.fields`), or ``"progressive"``, ``"tff"``, ``"bff"`` to force one; interlaced
    frames are remapped field by field (:mod:`glradial.remapping.fields`) and written with that field order.
    Planar YUV written in its own pix_fmt is corrected in YUV (:func:`correction_space`: the CPU
    backend, progressive; source-less pixels black in the source's range), anything else in RGB."""
    corrector = FrameCorrector(backend, fit, interpolation, direction, **remap_options)
    with VideoReader(source, order="rgb", copy_streams=True, rate=rate, alpha=True) as reader:
        info = _with_fields(reader.info, field_order)
        corrector.interlaced = info.fields != "progressive"
        writer = VideoWriter(target, info, options=options, streams=reader.copied, overwrite=overwrite)
        try:
            writer.check_alpha_kept()
            if correction_space(info, writer, corrector.backend, remap_options)[0] == "yuv":
                corrector.use_planes(info, writer.full_range)
                reader.planar = True

            def work(item):
                if not isinstance(item, VideoFrame):
                    return item
                lens = lenses(item.index)
                lens = None if lens is None else as_lens(lens)  # None: passed through uncorrected (a doubtful shot)
                if reader.planar and item.decoded.format.name == info.pix_fmt:
                    return corrector.planar(item.decoded, lens, writer, item.pts)
                image = item.image if item.image is not None else reader.convert(item.decoded)
                return writer.frame(image if lens is None else corrector(image, lens), item.pts)

            with Progress(info.frame_count, label, enabled=progress) as bar, \
                    Pipelined(reader.items(), work, on_worker_exit=corrector.release) as done:
                for item in done:
                    if isinstance(item, CopiedPacket):
                        writer.mux(item)
                    else:
                        writer.write(item)
                        bar.update()
            if frames_expected is not None and writer.frames_written != frames_expected:
                raise ValueError(
                    f"the lens track has {frames_expected} frames but {source} has {writer.frames_written}: "
                    "it belongs to another video"
                )
            writer.close()
        except BaseException:
            writer.abort()
            raise
    if 0 < info.frame_count != writer.frames_written:
        logger.warning("%s reports %d frames in its header; %d could be decoded and were written",
                       source, info.frame_count, writer.frames_written)
    return writer.frames_written


def estimate_video(
    path: str | os.PathLike,
    *,
    model: str | os.PathLike | None = None,
    every: int = EVERY,
    progress: bool | None = None,
    method: str | None = None,
) -> LensTrack:
    """Per-frame and per-shot lens of a video with the bundled estimator (or ``model``, with
    ``method`` when given): the first pass of ``glradial correct --auto`` (:func:`track_video`)
    without the correction (what ``glradial estimate VIDEO`` prints, with the estimator it loaded)."""
    return track_video(path, default_estimator(model, method), every=every, progress=progress)


def track_report(track: LensTrack, source: str, *, per_frame: bool = False, as_json: bool = False) -> str:
    """Text for ``glradial estimate VIDEO``: one line per shot (or per frame with ``per_frame``),
    with the stated uncertainty (px at 1920) and the methods where the estimator states them, or one
    JSON document (``{"input", "fps", "size", "shots": [...], "frames": [...]}``)."""
    if as_json:
        document = {"input": source, "fps": track.fps, "size": list(track.size), "shots": track.per_shot()}
        if per_frame:
            document["frames"] = track.rows()
        return json.dumps(document)
    lines = []
    if per_frame:
        for row in track.rows():
            lines.append(f"{source}: frame {row['frame']} shot {row['shot']} k1={row['k1']:.6f} k2={row['k2']:.6f}"
                         + _confidence_text(row["uncertainty_px"], [row["method"]] if row["method"] else []))
    else:
        for shot in track.per_shot():
            lines.append(
                f"{source}: shot {shot['shot']} frames {shot['first_frame']}-{shot['last_frame']} "
                f"k1={shot['k1']:.6f} k2={shot['k2']:.6f}" + _confidence_text(shot["uncertainty_px"], shot["methods"])
                + (f" DOUBTFUL({shot['reason']})" if shot["doubtful"] else "")
                + ("" if shot["applied"] else " not-applied")
            )
    return "\n".join(lines)


def _confidence_text(uncertainty_px: float | None, methods: list[str]) -> str:
    text = f" uncertainty={uncertainty_px:.1f}px" if uncertainty_px is not None else ""
    return text + (f" method={'+'.join(methods)}" if methods else "")


def doubtful_warnings(track: LensTrack, source: str) -> list[str]:
    """One warning line per doubtful shot of ``track`` (for ``correct --auto``)."""
    lines = []
    for shot in track.per_shot():
        if shot["doubtful"]:
            lines.append(
                f"glradial: warning: {source}: shot {shot['shot']} (frames {shot['first_frame']}-{shot['last_frame']}) "
                f"lens k1={shot['k1']:.4f} k2={shot['k2']:.4f} is doubtful ({shot['reason']}, uncertainty "
                f"{shot['uncertainty_px'] or float('nan'):.1f} px at 1920 wide): "
                + ("passed through uncorrected (--apply-doubtful applies it)" if not shot["applied"] else "applied anyway")
            )
    return lines
