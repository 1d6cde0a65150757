"""``glradial correct``: undistort an image or a video with a given or estimated lens."""

from __future__ import annotations

import argparse
import os
import sys
from fractions import Fraction
from pathlib import Path

from . import UsageError, add_lens_options, finite_float, lens_from_args, lens_given, positive_float, positive_int, show_progress

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
calibration), read per frame from a lens track (--lens-track) or estimated (--auto, centred model). For a video, --auto detects shot
cuts and fits one lens per shot from the pitch lines of every Nth frame and the frame-to-frame
motion between them (a zooming shot's lens follows the zoom); a doubtful shot (too little geometry,
or uncertainty above --max-uncertainty) is reported and passed through uncorrected unless
--apply-doubtful; the per-frame lens goes to a sidecar the per-frame lens to a sidecar (OUTPUT.lens.csv by default; format in docs/CLI.md),
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
    lens.add_argument("--method", choices=("auto", "net", "lines"),
                      help="with --auto: auto (default: the pitch-line fit when it is surer than the CNN), net or lines")
    lens.add_argument("--lens-track", metavar="CSV", help="videos: per-frame lens file (a sidecar of --auto, edited or not; .csv or .json)")
    render = parser.add_argument_group("rendering")
    render.add_argument(
        "--fit", choices=("same", "crop", "full"), default="same",
        help="output scale: same = centre scale kept (as cv2.undistort), crop = zoom in until every "
        "output pixel has a source, full = zoom out until the whole input is visible (default: same)",
    )
    render.add_argument(
        "--interpolation", choices=("nearest", "linear", "cubic"), default="linear",
        help="resampling filter (default: linear)",
    )
    render.add_argument(
        "--backend", choices=("auto", "gl", "cpu"), default="auto",
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
                       help="read the evidence of every N-th frame of each shot, plus each shot's first frame (frames; default 10)")
    video.add_argument("--max-uncertainty", type=positive_float, default=None, metavar="PX",
                       help="a shot whose lens is less sure than this is doubtful (px at 1920 wide, ~p90; default 10)")
    video.add_argument("--apply-doubtful", action="store_true",
                       help="correct doubtful shots too (default: they pass through uncorrected and are reported)")
    video.add_argument("--sidecar", metavar="PATH",
                       help="per-frame lens file: .csv or .json (default: OUTPUT.lens.csv)")
    return parser


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _check_paths(args: argparse.Namespace) -> str:
    from ..atomic import check_output_folder
    from ..image_io import media_kind
    from ..video_io import check_video_overwrite, is_sequence

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


def run(args: argparse.Namespace) -> int:
    given = lens_given(args)
    sources = [name for name, used in (("--k1/--k2/--cx/--cy/--pixel-aspect/--lens", given), ("--auto", args.auto),
                                       ("--lens-track", args.lens_track)) if used]
    if len(sources) > 1:
        raise UsageError(f"{' and '.join(sources)} cannot be combined: give the lens one way")
    if not sources:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE, --lens-track, "
                         "or --auto to estimate it")
    for name in ("model", "method", "sidecar", "max_uncertainty", "every", "apply_doubtful"):
        if getattr(args, name) not in (None, False) and not args.auto:
            raise UsageError(f"--{name.replace('_', '-')} needs --auto")
    if args.sidecar is not None and Path(args.sidecar).suffix.lower() not in (".csv", ".json"):
        raise UsageError(f"--sidecar {args.sidecar!r} must end in .csv or .json (its format)")
    if args.crf is not None and args.bitrate is not None:
        raise UsageError("give --crf or --bitrate, not both")
    kind = _check_paths(args)
    progress = show_progress(args)
    options = dict(fit=args.fit, interpolation=args.interpolation, backend=args.backend)

    if kind == "image":
        from ..remap import correct
        from ..image_io import read_image, write_image

        for name in ("sidecar", "lens_track", "codec", "crf", "bitrate", "preset", "pix_fmt", "rate", "every",
                     "max_uncertainty"):
            if getattr(args, name) is not None:
                raise UsageError(f"--{name.replace('_', '-')} is for videos")
        from ..lens import Lens

        image = read_image(args.input, order="rgb")
        if args.auto:
            from ..lens_track import DOUBTFUL_PX
            from ..frames import to_rgb8
            from ..video_pipeline import _as_pair, default_estimator

            estimate = default_estimator(args.model, args.method)(to_rgb8(image))
            k1, k2 = _as_pair(estimate)
            method, uncertainty = getattr(estimate, "method", None), getattr(estimate, "uncertainty_px", None)
            stated = f" ({method}, uncertainty {uncertainty:.1f} px at 1920)" if method and uncertainty is not None else ""
            print(f"{args.input}: estimated k1={k1:.6f} k2={k2:.6f}{stated}")
            if uncertainty is not None and uncertainty > DOUBTFUL_PX:
                print(f"glradial: warning: the estimate of {args.input} is doubtful (uncertainty {uncertainty:.1f} px > "
                      f"{DOUBTFUL_PX:g} px at 1920 wide); check the result or give the lens", file=sys.stderr)
            lens = Lens(k1, k2)
        else:
            lens = lens_from_args(args, (image.shape[1], image.shape[0]))
        write_image(args.output, correct(image, lens, **options), order="rgb", overwrite=args.overwrite)
        return 0

    from ..video_io import EncodeOptions, VideoReader
    from ..video_pipeline import correct_video

    encode = EncodeOptions(codec=args.codec, crf=args.crf, bitrate=args.bitrate, preset=args.preset, pix_fmt=args.pix_fmt)
    from ..video_io import is_sequence

    if args.rate is not None and not is_sequence(args.input):
        raise UsageError("--rate is for image-sequence inputs (videos keep their own frame rate)")
    video = dict(progress=progress, options=encode, overwrite=args.overwrite, rate=args.rate, **options)
    if given:
        with VideoReader(args.input, rate=args.rate) as reader:
            info = reader.info
        lens = lens_from_args(args, info.size)  # validated before any frame is decoded
        _summary(args.output, correct_video(args.input, args.output, lambda _i: lens, **video), info.frame_count)
        return 0

    if args.lens_track:
        from ..lens_track import load_lens_track

        with VideoReader(args.input, rate=args.rate) as reader:
            info = reader.info
        track = load_lens_track(args.lens_track, info.rate, info.size)
        written = correct_video(args.input, args.output, track.lens_for, frames_expected=track.n_frames, **video)
        _summary(args.output, written, info.frame_count)
        return 0

    from ..atomic import check_output_folder
    from ..image_io import check_overwrite
    from ..lens_track import DOUBTFUL_PX
    from ..video_pipeline import default_estimator, doubtful_warnings, track_video

    sidecar = Path(args.sidecar) if args.sidecar else Path(f"{args.output}.lens.csv")
    check_output_folder(sidecar)
    check_overwrite(sidecar, args.overwrite)
    if _same_file(Path(args.input), sidecar) or os.path.abspath(sidecar) in (os.path.abspath(args.input), os.path.abspath(args.output)):
        raise UsageError("--sidecar must differ from INPUT and OUTPUT")
    from ..video_io import VideoWriter

    with VideoReader(args.input, rate=args.rate, copy_streams=True) as reader:
        info = reader.info
        # the encoder, its options and the container are checked before the estimation pass: open and drop
        VideoWriter(args.output, info, options=encode, streams=reader.copied, overwrite=args.overwrite).abort()
    given_options = {"every": args.every} if args.every is not None else {}
    track = track_video(args.input, default_estimator(args.model, args.method), progress=progress,
                        doubtful_px=args.max_uncertainty or DOUBTFUL_PX, apply_doubtful=args.apply_doubtful,
                        rate=args.rate, **given_options)
    for line in doubtful_warnings(track, args.input):
        sys.stderr.write(line + "\n")
    written = correct_video(args.input, args.output, track.lens_for, frames_expected=track.n_frames, **video)
    try:
        track.save(sidecar)
    except BaseException:
        Path(args.output).unlink(missing_ok=True)  # both outputs or neither
        raise
    _summary(args.output, written, info.frame_count)
    shots = track.per_shot()
    print(f"{args.input}: {track.n_frames} frames, {len(shots)} shot(s); per-frame lens in {sidecar}")
    for shot in shots:
        sure = f" uncertainty {shot['uncertainty_px']:.1f} px" if shot["uncertainty_px"] is not None else ""
        flag = (f" DOUBTFUL ({shot['reason']}, " + ("applied)" if shot["applied"] else "not applied)")) if shot["doubtful"] else ""
        print(f"  shot {shot['shot']}: frames {shot['first_frame']}-{shot['last_frame']} k1={shot['k1']:.6f} k2={shot['k2']:.6f}{sure}{flag}")
    return 0


def _summary(output: str, written: int, header: int) -> None:
    """The line every video run ends with (stdout, also with -q): frames read and written, and the
    count the input's header states (-1: none), so that a short output is never silent."""
    stated = f"{header} frames" if header > 0 else "unknown"
    print(f"wrote {output}: {written} frames read and written (input header: {stated})", flush=True)
