"""What ``glradial correct`` and ``glradial distort`` share: their options (input and output,
rendering, video encoding) and the work on images, folders of images and videos once the lens is
known. Not a command itself (``glradial/cli.py`` lists the commands).

A *transform* is ``transform(image, lens, alpha) -> image``: :func:`glradial.correct` or
:func:`glradial.distort` with the command's fit, interpolation and backend bound. Videos go through
:func:`glradial.video.video_pipeline.correct_video` with the command's direction.
"""

from __future__ import annotations

import argparse
import os
from fractions import Fraction
from pathlib import Path
from typing import Callable

import numpy as np

from ..lens.options import ALPHAS, BACKENDS, FIELD_ORDERS, FITS, INTERPOLATIONS
from . import UsageError, finite_float, note

__all__ = [
    "bitrate", "frame_rate", "add_remap_parser", "add_io_arguments", "add_render_options", "add_encode_options", "check_paths",
    "reject_for", "check_encode_options", "image_transform", "run_with_lens", "remap_image_file", "remap_folder",
    "remap_video", "same_file", "summary", "video_alpha", "folder_images", "ALPHA_CHOICES",
    "VIDEO_OPTIONS", "RemapHook", "add_shot_lens_options",
]

#: ``--alpha``: auto = premultiplied for OpenEXR (its convention), straight for everything else
ALPHA_CHOICES = ("auto",) + ALPHAS
#: options that only a video (or image sequence) takes
VIDEO_OPTIONS = ("lens_track", "codec", "crf", "bitrate", "preset", "pix_fmt", "rate", "field_order")

Transform = Callable[[np.ndarray, object, str], np.ndarray]


class RemapHook:
    """What a command adds to :func:`run_with_lens`'s work on an image or a video (e.g. ``correct
    --opentrackio``, :class:`glradial.commands.engine_options.OpenTrackIOHook`); each method is
    called once, and does nothing here."""

    def lens_known(self, size: tuple[int, int], lens=None, *, track=None, info=None) -> None:
        """The lens (or a video's lens ``track``) of a ``(W, H)`` INPUT is known and no frame is
        decoded yet; ``info``: the video's ``VideoInfo`` (None for an image)."""

    def written(self, frames: int) -> None:
        """OUTPUT is complete: ``frames`` written (1 for an image)."""


def bitrate(text: str) -> int:
    """argparse type for a bit rate in bits per second, with an optional k/M/G suffix (8M, 2500k)."""
    scale = {"k": 1e3, "m": 1e6, "g": 1e9}.get(text[-1:].lower(), 1.0)
    number = text[:-1] if scale != 1.0 else text
    try:
        value = float(number) * scale
    except ValueError:
        value = -1.0
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"bit rate must be a positive number of bits per second (e.g. 8M, 2500k), got {text!r}")
    return int(round(value))


def frame_rate(text: str) -> Fraction:
    """argparse type for a frame rate: a positive number or fraction (25, 29.97, 30000/1001)."""
    try:
        value = Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        value = Fraction(0)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"frame rate must be a positive number or fraction such as 30000/1001, got {text!r}")
    return value.limit_denominator(1001) if "/" not in text else value


# -- options ----------------------------------------------------------------------------------------
def add_remap_parser(subparsers: argparse._SubParsersAction, name: str, summary_help: str, description: str,
                     lens_title: str, track_help: str) -> tuple[argparse.ArgumentParser, argparse._ArgumentGroup]:
    """The subparser of ``correct``/``distort`` (``name``) with INPUT, OUTPUT, ``-y`` and the lens
    group (``--k1 --k2 --cx --cy --pixel-aspect --lens --lens-track``), returned with that group."""
    from . import add_lens_options

    parser = subparsers.add_parser(name, help=summary_help, description=description,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    add_io_arguments(parser, name)
    lens = parser.add_argument_group(lens_title)
    add_lens_options(lens)
    lens.add_argument("--lens-track", metavar="CSV", help=track_help)
    return parser, lens


def add_io_arguments(parser: argparse.ArgumentParser, verb: str) -> None:
    """INPUT, OUTPUT and ``-y``; ``verb`` ("correct", "distort") words the help."""
    from . import InputPaths

    parser.add_argument("paths", metavar="INPUT OUTPUT", nargs="+", action=InputPaths,
                        help=f"INPUT: image, folder of images, video or image sequence (frame_%%04d.png) to {verb}; OUTPUT: file, "
                             "folder or image sequence, a file's extension picks the format. With --out-dir DIR: INPUT [INPUT ...], "
                             "each a file, folder, glob or @LIST, every output in DIR under its input's name")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace OUTPUT (and a sidecar) if it exists")


def add_render_options(parser: argparse.ArgumentParser, fit_help: str) -> argparse._ArgumentGroup:
    """``--fit --interpolation --backend --alpha`` in a "rendering" group (returned)."""
    render = parser.add_argument_group("rendering")
    render.add_argument("--fit", choices=FITS, default="same", help=fit_help)
    render.add_argument("--interpolation", choices=INTERPOLATIONS, default="linear",
                        help="resampling filter (default: linear)")
    render.add_argument("--backend", choices=BACKENDS, default="auto",
                        help="gl = GLSL shaders through EGL, cpu = the same maps through cv2.remap, auto = the faster "
                        "one on this machine (default: auto)")
    render.add_argument("--alpha", choices=ALPHA_CHOICES, default="auto",
                        help="how the input's alpha is stored: straight (PNG, TIFF, ProRes 4444, VP9) or premultiplied "
                        "(OpenEXR); auto = premultiplied for .exr, else straight. Either way the picture is interpolated "
                        "premultiplied (no fringe at a key's edge) and written in the input's convention")
    return render


def add_encode_options(parser: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The "video encoding" group (read by :func:`check_encode_options` and :func:`remap_video`)."""
    encode = parser.add_argument_group("video encoding")
    encode.add_argument("--codec", metavar="NAME", help="FFmpeg encoder or codec: h264, hevc, prores, ffv1, ... (default: the input's)")
    encode.add_argument("--crf", type=finite_float, metavar="Q", help="constant quality for x264/x265/VPx/AV1 (lower = better)")
    encode.add_argument("--bitrate", type=bitrate, metavar="BPS", help="target bit rate in bits/s, k/M suffix (default for codecs without --crf: the input's)")
    encode.add_argument("--preset", metavar="NAME", help="encoder speed preset, e.g. ultrafast ... veryslow for x264/x265")
    encode.add_argument("--rate", type=frame_rate, metavar="FPS",
                        help="frame rate of an image-sequence INPUT, e.g. 25 or 30000/1001 (default 25; videos keep theirs)")
    encode.add_argument("--pix-fmt", metavar="FMT", help="output pixel format, e.g. yuv420p, yuv422p10le (default: the input's where the encoder takes it)")
    encode.add_argument("--field-order", choices=FIELD_ORDERS, default=None,
                        help="interlaced video: auto = the stream's (its field order, else a frame flagged interlaced "
                        "is taken as top field first); tff/bff = interlaced, that field first; progressive = whole "
                        "frames. Interlaced frames are remapped field by field (each field on its own half-height "
                        "geometry) and written with the same field order and flags (default: auto)")
    return encode


def add_shot_lens_options(group: argparse._ArgumentGroup) -> None:
    """``--every --max-uncertainty --apply-doubtful``: how ``--auto`` reads a video's shots and its
    doubt policy (``correct --auto``, ``live --auto``)."""
    from . import positive_float, positive_int

    group.add_argument("--every", type=positive_int, default=None, metavar="N",
                       help="read the evidence of every N-th frame of each shot, plus each shot's first frame (frames; default 10)")
    group.add_argument("--max-uncertainty", type=positive_float, default=None, metavar="PX",
                       help="a shot whose lens is less sure than this is doubtful, unless even its bound leaves the frame better "
                            "than uncorrected (px at 1920 wide, ~p90; default 10)")
    group.add_argument("--apply-doubtful", action="store_const", const=True, default=None,
                       help="correct a doubtful image or shot too (default: it passes through uncorrected and is reported)")


def reject_for(args: argparse.Namespace, names: tuple[str, ...], what: str) -> None:
    """``UsageError`` for the first of ``names`` given (``--name is for <what>``)."""
    for name in names:
        if getattr(args, name, None) is not None:
            raise UsageError(f"--{name.replace('_', '-')} is for {what}")


def check_encode_options(args: argparse.Namespace) -> None:
    """The encoding options that conflict, before any work."""
    if args.crf is not None and args.bitrate is not None:
        raise UsageError("give --crf or --bitrate, not both")


# -- paths --------------------------------------------------------------------------------------------
def same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` name the same file: the same absolute path, or both exist and are one
    file (hard links, symbolic links)."""
    if os.path.abspath(a) == os.path.abspath(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def refuse_same_file(path: str | os.PathLike, option: str, *others: str | os.PathLike) -> None:
    """``UsageError`` when the file ``option`` names (``path``) is one of ``others`` (INPUT, OUTPUT):
    glradial never writes a side output over its input or its main output."""
    if any(same_file(Path(path), Path(other)) for other in others):
        raise UsageError(f"{option} {str(path)!r} must differ from INPUT and OUTPUT")


def _article(kind: str) -> str:
    return "an" if kind == "image" else "a"


def check_paths(args: argparse.Namespace) -> str:
    """``"image"``, ``"folder"`` or ``"video"``: what INPUT is, after checking that OUTPUT is the
    same kind, differs from INPUT and may be written (``-y``)."""
    from ..media.atomic import check_output_folder
    from ..media.image_io import media_kind
    from ..media.video_io import check_video_overwrite, is_sequence

    source, target = Path(args.input), Path(args.output)
    if not is_sequence(source) and not source.exists():
        raise FileNotFoundError(f"input file {str(source)!r} does not exist")
    if same_file(source, target):
        raise UsageError("OUTPUT must differ from INPUT (glradial never writes over its input)")
    if source.is_dir():
        return _check_folder_output(source, target)
    for path in (source, target):
        _refuse_float_sequence(path)
    kind_in, kind_out = media_kind(source), media_kind(target)
    if target.is_dir():
        raise UsageError(f"INPUT is {_article(kind_in)} {kind_in} but OUTPUT {str(target)!r} is a folder")
    if kind_in != kind_out:
        raise UsageError(f"INPUT is {_article(kind_in)} {kind_in} but OUTPUT {str(target)!r} is "
                         f"{_article(kind_out)} {kind_out} name")
    check_output_folder(target)
    check_video_overwrite(target, args.overwrite)
    return kind_in


def _refuse_float_sequence(path: Path) -> None:
    """A float image sequence (EXR, float TIFF) would go through FFmpeg, which clips values beyond 1:
    ``UsageError`` pointing to folders, where each frame is read as an image."""
    from ..media.video_io import is_sequence, sequence_files

    if not is_sequence(path):
        return
    suffix = path.suffix.lower()
    floating = suffix == ".exr"
    if suffix in (".tif", ".tiff"):
        from ..media.image_io import read_image

        first = sequence_files(path)[:1]
        floating = bool(first) and read_image(first[0]).dtype.kind == "f"
    if floating:
        raise UsageError(f"{str(path)!r}: a float image sequence would go through FFmpeg, which clips values beyond 1; "
                         "put the frames in a folder and give the folder (each frame is then read as an image)")


def _check_folder_output(source: Path, target: Path) -> str:
    from ..media.image_io import media_kind

    if target.exists() and not target.is_dir():
        raise UsageError(f"INPUT {str(source)!r} is a folder but OUTPUT {str(target)!r} is a file: give a folder")
    if not target.exists():
        if media_kind(target) == "image" or "%" in target.name:
            kind = "an image" if media_kind(target) == "image" else "an image-sequence"
            raise UsageError(f"INPUT {str(source)!r} is a folder but OUTPUT {str(target)!r} is {kind} name: give a folder")
        if not (target.parent if str(target.parent) else Path(".")).is_dir():
            raise FileNotFoundError(f"cannot write {str(target)!r}: its folder {str(target.parent)!r} does not exist")
    if not folder_images(source):
        raise ValueError(f"folder {str(source)!r} holds no still image (.png, .jpg, .tif, .exr)")
    return "folder"


def folder_images(folder: Path) -> list[Path]:
    """The still images directly in ``folder`` (not in sub-folders), in name order."""
    from ..media.image_io import is_image_path

    return sorted(p for p in folder.iterdir() if p.is_file() and is_image_path(p) and not p.name.startswith("."))


# -- images ---------------------------------------------------------------------------------------------
def image_transform(args: argparse.Namespace, direction: str, **extra: object) -> Transform:
    """``transform(image, lens, alpha)`` with the command's fit, interpolation and backend (and
    ``extra`` keywords, e.g. ``inverse``), for :func:`remap_image_file`."""
    from ..remapping import remap

    function = remap.correct if direction == "undistort" else remap.distort
    options = dict(fit=args.fit, interpolation=args.interpolation, backend=args.backend, **extra)
    return lambda image, lens, alpha: function(image, lens, alpha=alpha, **options)


def _alpha_for(choice: str, path: Path) -> str:
    if choice != "auto":
        return choice
    return "premultiplied" if path.suffix.lower() == ".exr" else "straight"


def remap_image_file(source: Path, target: Path, lens_for: Callable[[tuple[int, int]], object], transform: Transform,
                     *, alpha: str = "auto", overwrite: bool = False, image: np.ndarray | None = None) -> None:
    """Read ``source`` (or take ``image``, the caller's decode of it, as RGB), apply ``transform`` with
    ``lens_for((W, H))`` and write ``target`` (atomic, depth kept). EXR to EXR goes channel by channel
    (:func:`glradial.media.exr_io.channel_groups`), every channel and its HALF/FLOAT type kept."""
    from ..media.atomic import check_overwrite
    from ..media.image_io import read_image, write_image

    check_overwrite(target, overwrite)
    convention = _alpha_for(alpha, source)
    if source.suffix.lower() == ".exr" and target.suffix.lower() == ".exr":
        _remap_exr(source, target, lens_for, transform, convention, overwrite)
        return
    image = read_image(source, order="rgb") if image is None else image
    lens = lens_for((image.shape[1], image.shape[0]))
    write_image(target, transform(image, lens, convention), order="rgb", overwrite=overwrite)


def _remap_exr(source: Path, target: Path, lens_for, transform: Transform, alpha: str, overwrite: bool) -> None:
    from ..media.exr_io import channel_groups, read_exr, write_exr

    exr = read_exr(source)
    lens = lens_for(exr.size)
    result: dict[str, np.ndarray] = {}
    for group in channel_groups(list(exr.channels)):
        stack = np.stack([exr.channels[name].astype(np.float32) for name in group], axis=-1)
        done = transform(stack if len(group) > 1 else stack[:, :, 0], lens, alpha)
        result.update({name: (done[:, :, i] if len(group) > 1 else done) for i, name in enumerate(group)})
    write_exr(target, exr.replaced(result), overwrite=overwrite)


def remap_folder(args: argparse.Namespace, lens_for, transform: Transform, progress: bool | None, label: str) -> int:
    """Every still image of the folder INPUT into the folder OUTPUT (made if missing), same names;
    existing outputs are refused before any work unless ``-y``. Returns the number written."""
    from ..media.atomic import check_overwrite
    from ..media.progress import Progress

    source, target = Path(args.input), Path(args.output)
    images = folder_images(source)
    for image in images:
        check_overwrite(target / image.name, args.overwrite)
    target.mkdir(exist_ok=True)
    with Progress(len(images), label, enabled=progress) as bar:
        for image in images:
            remap_image_file(image, target / image.name, lens_for, transform, alpha=args.alpha, overwrite=args.overwrite)
            bar.update()
    print(f"wrote {len(images)} image(s) into {target}", flush=True)
    return len(images)


def run_with_lens(args: argparse.Namespace, direction: str, kind: str, lens_for=None, *,
                  video_only: tuple[str, ...] = (), hook: RemapHook | None = None, transform: Transform | None = None,
                  lens: object = None, image: np.ndarray | None = None, **extra: object) -> int:
    """The work of ``correct``/``distort`` once INPUT's ``kind`` (:func:`check_paths`) and the lens
    are known: ``lens_for((W, H))`` (default: the command line's, :func:`lens_from_args`) or, for a
    video, ``--lens-track``. Images and folders refuse the video options (and ``video_only``).
    ``hook``: told the lens and the end of an image's or a video's work (not a folder's).
    ``transform``: an image's remap (default: :func:`image_transform` of ``direction``; a video's
    is always that). ``lens``: the lens already decided for an image INPUT (instead of ``lens_for``);
    ``image``: that INPUT already decoded (RGB), not read again. ``extra``: keywords of the remap
    (``inverse=`` for distort)."""
    from . import lens_from_args, show_progress

    if lens is not None:
        lens_for = lambda _size: lens  # noqa: E731  (decided before: no call back into the command)
    lens_for = lens_for or (lambda size: lens_from_args(args, size))
    hook = hook or RemapHook()
    progress = show_progress(args)
    if kind == "video":
        remap_video(args, direction, lens_for, progress, hook=hook, alpha=video_alpha(args), **extra)
        return 0
    reject_for(args, VIDEO_OPTIONS + video_only, "videos")
    transform = transform or image_transform(args, direction, **extra)
    label = "correct" if direction == "undistort" else "distort"
    if kind == "folder":
        remap_folder(args, lens_for, transform, progress, label)
        return 0
    remap_image_file(Path(args.input), Path(args.output), _told(lens_for, hook, args), transform, alpha=args.alpha,
                     overwrite=args.overwrite, image=image)
    note(args, frames=1)
    hook.written(1)
    return 0


def _told(lens_for, hook: RemapHook, args: argparse.Namespace):
    """``lens_for`` that also tells ``hook`` (and a job's report, :func:`note`) the lens it gives."""
    def told(size: tuple[int, int]):
        lens = lens_for(size)
        hook.lens_known(size, lens)
        note(args, replace=False, k1=lens.k1, k2=lens.k2)
        return lens

    return told


# -- videos ---------------------------------------------------------------------------------------------
def remap_video(args: argparse.Namespace, direction: str, lens_for, progress: bool | None, *,
                hook: RemapHook | None = None, **extra: object) -> int:
    """A video or image sequence with a lens given (``lens_for((W, H))`` -> Lens, checked before any
    frame is decoded) or, with ``--lens-track``, one per frame; ends with :func:`summary`, then
    ``hook.written``."""
    from ..media.video_io import EncodeOptions, VideoReader, is_sequence
    from ..video.video_pipeline import correct_video

    if args.rate is not None and not is_sequence(args.input):
        raise UsageError("--rate is for image-sequence inputs (videos keep their own frame rate)")
    encode = EncodeOptions(codec=args.codec, crf=args.crf, bitrate=args.bitrate, preset=args.preset, pix_fmt=args.pix_fmt)
    with VideoReader(args.input, rate=args.rate) as reader:
        info = reader.info
    video = dict(fit=args.fit, interpolation=args.interpolation, backend=args.backend, progress=progress,
                 options=encode, overwrite=args.overwrite, rate=args.rate, direction=direction,
                 field_order=args.field_order or "auto", **extra)
    hook = hook or RemapHook()
    if getattr(args, "lens_track", None):
        from ..video.lens_track import load_lens_track

        track = load_lens_track(args.lens_track, info.rate, info.size)
        hook.lens_known(info.size, track=track, info=info)
        written = correct_video(args.input, args.output, track.lens_for, frames_expected=track.n_frames, **video)
    else:
        lens = lens_for(info.size)
        hook.lens_known(info.size, lens, info=info)
        written = correct_video(args.input, args.output, lambda _i: lens, **video)
    summary(args.output, written, info.frame_count)
    note(args, frames=written, **({} if getattr(args, "lens_track", None) else {"k1": lens.k1, "k2": lens.k2}))
    hook.written(written)
    return written


def video_alpha(args: argparse.Namespace) -> str:
    """The alpha convention of a video input: ``--alpha``, or straight for ``auto`` (what FFmpeg
    decodes ProRes 4444, VP9 and PNG-in-MOV alpha as)."""
    return "straight" if args.alpha == "auto" else args.alpha


def summary(output: str, written: int, header: int) -> None:
    """The line every video run ends with (stdout, also with -q): frames read and written, and the
    count the input's header states (-1: none), so that a short output is never silent."""
    stated = f"{header} frames" if header > 0 else "unknown"
    print(f"wrote {output}: {written} frames read and written (input header: {stated})", flush=True)
