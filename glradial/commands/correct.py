"""``glradial correct``: undistort an image or a video with a given or estimated lens."""

from __future__ import annotations

import argparse
import os
import sys
from fractions import Fraction
from pathlib import Path

from ..lens.options import BACKENDS, FITS, INTERPOLATIONS, METHODS
from . import UsageError, add_lens_options, finite_float, lens_from_args, lens_given, positive_float, positive_int, show_progress
from .engine_options import (
    add_opentrackio_options,
    camera_from_args,
    check_opentrackio_output,
    opentrackio_wanted,
    write_image_opentrackio,
    write_opentrackio,
    write_track_opentrackio,
)

DESCRIPTION = """\
Undistort INPUT into OUTPUT. Images: PNG, JPEG, TIFF (8- and 16-bit and float32 TIFF kept, alpha
kept). Videos: anything FFmpeg reads (MP4, MOV, MXF, TS, MKV, WebM ...; image sequences as
frame_%04d.png), written through FFmpeg (PyAV): audio, subtitle and data streams are copied
untouched; frame rate, timestamps, timecode, colour tags and field order are kept; 10- and 12-bit
sources are processed at 16 bits and written back at their depth. The output codec is the input's
where an encoder exists (else the container's default); --codec, --crf/--bitrate, --preset and
--pix-fmt choose another. The lens is given (--k1/--k2, width-normalised: image width = 1, origin
at the image centre, p_d = p_u (1 + k1 r^2 + k2 r^4); negative k1 = barrel; --cx/--cy/--pixel-aspect
for an off-centre principal point and non-square pixels; or --lens FILE, e.g. an OpenCV
calibration), read per frame from a lens track (--lens-track) or estimated (--auto, centred model). For a video, --auto estimates every Nth frame,
detects shot cuts, smooths the lens within each shot weighting each estimate by its stated
confidence, warns about every shot whose lens is doubtful (uncertainty above --max-uncertainty)
and writes the per-frame lens to a sidecar (OUTPUT.lens.csv by default; format in docs/CLI.md),
which can be edited and fed back with --lens-track. Outputs appear only when complete; an existing
OUTPUT is replaced only with -y."""


def _bitrate(text: str) -> int:
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


def _rate(text: str) -> Fraction:
    """argparse type for a frame rate: a positive number or fraction (25, 29.97, 30000/1001)."""
    try:
        value = Fraction(text.strip())
    except (ValueError, ZeroDivisionError):
        value = Fraction(0)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"frame rate must be a positive number or fraction such as 30000/1001, got {text!r}")
    return value.limit_denominator(1001) if "/" not in text else value


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "correct",
        help="undistort an image or a video (given lens, lens track or --auto)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("input", metavar="INPUT", help="image, video or image sequence (frame_%%04d.png) to correct")
    parser.add_argument("output", metavar="OUTPUT", help="corrected file or image sequence; its extension picks the format")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace OUTPUT (and the sidecar) if it exists")
    lens = parser.add_argument_group("lens (give --k1 [--k2 --cx --cy --pixel-aspect], --lens FILE, --lens-track or --auto)")
    add_lens_options(lens)
    lens.add_argument("--auto", action="store_true", help="estimate the lens with the bundled estimator")
    lens.add_argument("--model", metavar="ONNX", help="with --auto: use this ONNX model instead of the bundled one")
    lens.add_argument("--method", choices=METHODS,
                      help="with --auto: auto (default: the pitch-line fit when it is surer than the CNN), net or lines")
    lens.add_argument("--lens-track", metavar="CSV", help="videos: per-frame lens file (a sidecar of --auto, edited or not; .csv or .json)")
    render = parser.add_argument_group("rendering")
    render.add_argument(
        "--fit", choices=FITS, default="same",
        help="output scale: same = centre scale kept (as cv2.undistort), crop = zoom in until every "
        "output pixel has a source, full = zoom out until the whole input is visible (default: same)",
    )
    render.add_argument(
        "--interpolation", choices=INTERPOLATIONS, default="linear",
        help="resampling filter (default: linear)",
    )
    render.add_argument(
        "--backend", choices=BACKENDS, default="auto",
        help="gl = GLSL shaders through EGL, cpu = the same maps through cv2.remap, auto = the faster "
        "one on this machine (default: auto)",
    )
    encode = parser.add_argument_group("video encoding")
    encode.add_argument("--codec", metavar="NAME", help="FFmpeg encoder or codec: h264, hevc, prores, ffv1, ... (default: the input's)")
    encode.add_argument("--crf", type=finite_float, metavar="Q", help="constant quality for x264/x265/VPx/AV1 (lower = better)")
    encode.add_argument("--bitrate", type=_bitrate, metavar="BPS", help="target bit rate in bits/s, k/M suffix (default for codecs without --crf: the input's)")
    encode.add_argument("--preset", metavar="NAME", help="encoder speed preset, e.g. ultrafast ... veryslow for x264/x265")
    encode.add_argument("--rate", type=_rate, metavar="FPS",
                        help="frame rate of an image-sequence INPUT, e.g. 25 or 30000/1001 (default 25; videos keep theirs)")
    encode.add_argument("--pix-fmt", metavar="FMT", help="output pixel format, e.g. yuv420p, yuv422p10le (default: the input's where the encoder takes it)")
    video = parser.add_argument_group("video with --auto")
    video.add_argument("--every", type=positive_int, default=None, metavar="N",
                       help="estimate every N-th frame of each shot, plus each shot's first frame (frames; default 5)")
    video.add_argument("--window", type=positive_float, default=None, metavar="SECONDS",
                       help="half width of the per-shot smoothing window (seconds; default 2.0)")
    video.add_argument("--max-uncertainty", type=positive_float, default=None, metavar="PX",
                       help="warn about shots whose smoothed lens is less sure than this (px at 1920 wide, ~p90; default 10)")
    video.add_argument("--sidecar", metavar="PATH",
                       help="per-frame lens file: .csv or .json (default: OUTPUT.lens.csv)")
    add_opentrackio_options(parser)
    return parser


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _check_paths(args: argparse.Namespace) -> str:
    from ..media.atomic import check_output_folder
    from ..media.image_io import media_kind
    from ..media.video_io import check_video_overwrite, is_sequence

    source, target = Path(args.input), Path(args.output)
    if not is_sequence(source) and not source.exists():
        raise FileNotFoundError(f"input file {str(source)!r} does not exist")
    kind_in, kind_out = media_kind(source), media_kind(target)
    if kind_in != kind_out:
        raise UsageError(f"INPUT is {'an' if kind_in == 'image' else 'a'} {kind_in} but OUTPUT {str(target)!r} is {'an' if kind_out == 'image' else 'a'} {kind_out} name")
    if _same_file(source, target) or os.path.abspath(source) == os.path.abspath(target):
        raise UsageError("OUTPUT must differ from INPUT (glradial never writes over its input)")
    check_output_folder(target)
    check_video_overwrite(target, args.overwrite)
    return kind_in


def _check_lens_options(args: argparse.Namespace) -> bool:
    """The lens is given one way and the options fit it; returns whether it is given by numbers."""
    given = lens_given(args)
    sources = [name for name, used in (("--k1/--k2/--cx/--cy/--pixel-aspect/--lens", given), ("--auto", args.auto),
                                       ("--lens-track", args.lens_track)) if used]
    if len(sources) > 1:
        raise UsageError(f"{' and '.join(sources)} cannot be combined: give the lens one way")
    if not sources:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE, --lens-track, "
                         "or --auto to estimate it")
    for name in ("model", "method", "sidecar", "max_uncertainty", "every", "window"):
        if getattr(args, name) is not None and not args.auto:
            raise UsageError(f"--{name.replace('_', '-')} needs --auto")
    if args.sidecar is not None and Path(args.sidecar).suffix.lower() not in (".csv", ".json"):
        raise UsageError(f"--sidecar {args.sidecar!r} must end in .csv or .json (its format)")
    if args.crf is not None and args.bitrate is not None:
        raise UsageError("give --crf or --bitrate, not both")
    return given


def run(args: argparse.Namespace) -> int:
    given = _check_lens_options(args)
    kind = _check_paths(args)
    check_opentrackio_output(args)
    if args.opentrackio and os.path.abspath(args.opentrackio) in (os.path.abspath(args.input), os.path.abspath(args.output)):
        raise UsageError("--opentrackio must differ from INPUT and OUTPUT")
    options = dict(fit=args.fit, interpolation=args.interpolation, backend=args.backend)
    if kind == "image":
        return _run_image(args, options)
    from ..media.video_io import EncodeOptions, is_sequence

    encode = EncodeOptions(codec=args.codec, crf=args.crf, bitrate=args.bitrate, preset=args.preset, pix_fmt=args.pix_fmt)
    if args.rate is not None and not is_sequence(args.input):
        raise UsageError("--rate is for image-sequence inputs (videos keep their own frame rate)")
    video = dict(progress=show_progress(args), options=encode, overwrite=args.overwrite, rate=args.rate, **options)
    if given or args.lens_track:
        return _run_video_with_lens(args, video)
    return _run_video_auto(args, encode, video)


def _run_image(args: argparse.Namespace, options: dict) -> int:
    """One image: the lens given or estimated, corrected, written atomically."""
    from ..media.image_io import read_image, write_image
    from ..remapping.remap import correct

    for name in ("sidecar", "lens_track", "codec", "crf", "bitrate", "preset", "pix_fmt", "rate", "every", "window",
                 "max_uncertainty"):
        if getattr(args, name) is not None:
            raise UsageError(f"--{name.replace('_', '-')} is for videos")
    image = read_image(args.input, order="rgb")
    lens = _estimate_image(args, image) if args.auto else lens_from_args(args, (image.shape[1], image.shape[0]))
    write_image(args.output, correct(image, lens, **options), order="rgb", overwrite=args.overwrite)
    if opentrackio_wanted(args):
        write_image_opentrackio(args, (image.shape[1], image.shape[0]), lens)
    return 0


def _estimate_image(args: argparse.Namespace, image):
    """``--auto`` on an image: the estimate, printed with its stated uncertainty, warned if doubtful."""
    from ..lens.lens import as_lens
    from ..media.frames import to_rgb8
    from ..video.lens_track import DOUBTFUL_PX
    from ..video.video_pipeline import default_estimator

    lens = as_lens(default_estimator(args.model, args.method)(to_rgb8(image)))
    method, uncertainty = getattr(lens, "method", None), getattr(lens, "uncertainty_px", None)
    stated = f" ({method}, uncertainty {uncertainty:.1f} px at 1920)" if method and uncertainty is not None else ""
    print(f"{args.input}: estimated k1={lens.k1:.6f} k2={lens.k2:.6f}{stated}")
    if uncertainty is not None and uncertainty > DOUBTFUL_PX:
        print(f"glradial: warning: the estimate of {args.input} is doubtful (uncertainty {uncertainty:.1f} px > "
              f"{DOUBTFUL_PX:g} px at 1920 wide); check the result or give the lens", file=sys.stderr)
    return lens


def _run_video_with_lens(args: argparse.Namespace, video: dict) -> int:
    """A video with the lens given: by numbers (one lens, checked before any frame is decoded) or
    by a lens track (one lens per frame, as many frames as the video)."""
    from ..media.video_io import VideoReader
    from ..video.lens_track import load_lens_track
    from ..video.video_pipeline import correct_video

    with VideoReader(args.input, rate=args.rate) as reader:
        info = reader.info
    if args.lens_track:
        track = load_lens_track(args.lens_track, info.rate, info.size)
        written = correct_video(args.input, args.output, track.lens_at, frames_expected=track.n_frames, **video)
        _summary(args.output, written, info.frame_count)
        if opentrackio_wanted(args):
            write_track_opentrackio(args, track, info)
        return 0
    lens = lens_from_args(args, info.size)  # validated before any frame is decoded
    camera = _video_camera(args, lens, info) if opentrackio_wanted(args) else None
    written = correct_video(args.input, args.output, lambda _i: lens, **video)
    _summary(args.output, written, info.frame_count)
    if camera is not None:
        write_opentrackio(args, [lens] * written, camera)
    return 0


def _video_camera(args: argparse.Namespace, lens, info):
    """The camera of ``--opentrackio`` for a video with one lens, checked (the lens too: one the
    standard cannot carry is refused) before any frame is decoded."""
    from ..export.opentrackio import track_samples

    camera = camera_from_args(args, info.size, info.rate, info.timecode)
    track_samples([lens], camera)
    return camera


def _auto_sidecar(args: argparse.Namespace) -> Path:
    """The sidecar ``--auto`` writes, checked before anything runs."""
    from ..media.atomic import check_output_folder
    from ..media.image_io import check_overwrite

    sidecar = Path(args.sidecar) if args.sidecar else Path(f"{args.output}.lens.csv")
    check_output_folder(sidecar)
    check_overwrite(sidecar, args.overwrite)
    if _same_file(Path(args.input), sidecar) or os.path.abspath(sidecar) in (os.path.abspath(args.input), os.path.abspath(args.output)):
        raise UsageError("--sidecar must differ from INPUT and OUTPUT")
    return sidecar


def _run_video_auto(args: argparse.Namespace, encode, video: dict) -> int:
    """``--auto`` on a video: pass 1 (track), pass 2 (correct), the sidecar; both outputs or neither."""
    from ..media.video_io import VideoReader, VideoWriter
    from ..video.lens_track import DOUBTFUL_PX
    from ..video.video_pipeline import correct_video, default_estimator, doubtful_warnings, track_video

    sidecar = _auto_sidecar(args)
    with VideoReader(args.input, rate=args.rate, copy_streams=True) as reader:
        info = reader.info
        # the encoder, its options and the container are checked before the estimation pass: open and drop
        VideoWriter(args.output, info, options=encode, streams=reader.copied, overwrite=args.overwrite).abort()
    given_options = {name: value for name, value in (("every", args.every), ("window_s", args.window)) if value is not None}
    track = track_video(args.input, default_estimator(args.model, args.method), progress=video["progress"],  # its defaults: every 5, window 2 s
                        doubtful_px=args.max_uncertainty or DOUBTFUL_PX, rate=args.rate, **given_options)
    for line in doubtful_warnings(track, args.input):
        sys.stderr.write(line + "\n")
    written = correct_video(args.input, args.output, track.lens_at, frames_expected=track.n_frames, **video)
    try:
        track.save(sidecar)
    except BaseException:
        Path(args.output).unlink(missing_ok=True)  # both outputs or neither
        raise
    _summary(args.output, written, info.frame_count)
    _print_shots(args.input, track, sidecar)
    if opentrackio_wanted(args):
        write_track_opentrackio(args, track, info)
    return 0


def _print_shots(source: str, track, sidecar: Path) -> None:
    shots = track.per_shot()
    print(f"{source}: {track.n_frames} frames, {len(shots)} shot(s); per-frame lens in {sidecar}")
    for shot in shots:
        sure = f" uncertainty {shot['uncertainty_px']:.1f} px" if shot["uncertainty_px"] is not None else ""
        flag = " DOUBTFUL" if shot["doubtful"] else ""
        print(f"  shot {shot['shot']}: frames {shot['first_frame']}-{shot['last_frame']} k1={shot['k1']:.6f} k2={shot['k2']:.6f}{sure}{flag}")


def _summary(output: str, written: int, header: int) -> None:
    """The line every video run ends with (stdout, also with -q): frames read and written, and the
    count the input's header states (-1: none), so that a short output is never silent."""
    stated = f"{header} frames" if header > 0 else "unknown"
    print(f"wrote {output}: {written} frames read and written (input header: {stated})", flush=True)
