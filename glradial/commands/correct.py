"""``glradial correct``: undistort an image, a folder of images or a video with a given or estimated lens."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..lens.options import METHODS
from . import MODEL_HELP, PITCH_HELP, UsageError, cached_estimator, estimators_kept, lens_given, note, show_progress
from .engine_options import add_opentrackio_options, opentrackio_hook, opentrackio_wanted, write_track_opentrackio
from .remapping import (
    VIDEO_OPTIONS,
    add_encode_options,
    add_remap_parser,
    add_render_options,
    add_shot_lens_options,
    check_encode_options,
    check_paths,
    refuse_same_file,
    reject_for,
    run_with_lens,
    summary,
    video_alpha,
)

DESCRIPTION = """\
Undistort INPUT into OUTPUT ('glradial distort' is the inverse). Images: PNG, JPEG, TIFF, OpenEXR
(8- and 16-bit and float kept; EXR: every channel, HALF/FLOAT, values beyond 1 kept); a folder of
images into a folder. Alpha (RGBA images, ProRes 4444, VP9, FFV1) kept and interpolated
premultiplied (--alpha); interlaced video corrected field by field (--field-order). Videos: anything FFmpeg reads (MP4, MOV, MXF, TS, MKV, WebM ...; image sequences as
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
or uncertainty above --max-uncertainty that also reaches the uncorrected frame) is reported and passed through uncorrected unless
--apply-doubtful; the per-frame lens goes to a sidecar (OUTPUT.lens.csv by default; format in docs/CLI.md),
which can be edited and fed back with --lens-track. Outputs appear only when complete; an existing
OUTPUT is replaced only with -y."""


#: options only ``--auto`` on a video takes (an image or folder refuses them as video options;
#: --apply-doubtful is taken by an image too)
AUTO_VIDEO_OPTIONS = ("sidecar", "every", "max_uncertainty")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser, lens = add_remap_parser(
        subparsers, "correct", "undistort an image, folder or video (given lens, lens track or --auto)", DESCRIPTION,
        "lens (give --k1 [--k2 --cx --cy --pixel-aspect], --lens FILE, --lens-track or --auto)",
        "videos: per-frame lens file (a sidecar of --auto, edited or not; .csv or .json)",
    )
    lens.add_argument("--auto", action="store_true", help="estimate the lens with the bundled estimator")
    lens.add_argument("--model", metavar="ONNX", help=f"with --auto: {MODEL_HELP}")
    lens.add_argument("--pitch", action=argparse.BooleanOptionalAction, default=None,
                      help=f"with --auto on images (the default there): {PITCH_HELP}")
    lens.add_argument("--method", choices=METHODS,
                      help="with --auto: auto (default: the pitch-line fit when it is surer than the CNN), net or lines")
    add_render_options(
        parser, "output scale: same = centre scale kept (as cv2.undistort), crop = zoom in until every "
        "output pixel has a source, full = zoom out until the whole input is visible (default: same)",
    )
    add_encode_options(parser)
    video = parser.add_argument_group("video with --auto")
    add_shot_lens_options(video)
    video.add_argument("--sidecar", metavar="PATH",
                       help="per-frame lens file: .csv or .json (default: OUTPUT.lens.csv)")
    add_opentrackio_options(parser)
    return parser


def _check_lens_options(args: argparse.Namespace) -> bool:
    """The lens is given one way and the options fit it; returns whether it is given by numbers."""
    auto_aspect = args.auto and args.pixel_aspect is not None  # --auto --pixel-aspect: the stored frame's pixels
    given = lens_given(args) and not (auto_aspect and not _numbers_besides_aspect(args))
    sources = [name for name, used in (("--k1/--k2/--cx/--cy/--pixel-aspect/--lens", given), ("--auto", args.auto),
                                       ("--lens-track", args.lens_track)) if used]
    if len(sources) > 1:
        raise UsageError(f"{' and '.join(sources)} cannot be combined: give the lens one way")
    if not sources:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE, --lens-track, "
                         "or --auto to estimate it")
    for name in ("model", "method", "pitch", "sidecar", "max_uncertainty", "every", "apply_doubtful"):
        if getattr(args, name) is not None and not args.auto:
            raise UsageError(f"--{name.replace('_', '-')} needs --auto")
    if args.sidecar is not None and Path(args.sidecar).suffix.lower() not in (".csv", ".json"):
        raise UsageError(f"--sidecar {args.sidecar!r} must end in .csv or .json (its format)")
    check_encode_options(args)
    return given


def _numbers_besides_aspect(args: argparse.Namespace) -> bool:
    """Whether a lens option other than ``--pixel-aspect`` was given."""
    return any(getattr(args, name) is not None for name in ("k1", "k2", "cx", "cy", "lens"))


def run(args: argparse.Namespace) -> int:
    given = _check_lens_options(args)
    kind = check_paths(args)
    if kind == "folder" and args.auto:
        raise UsageError("--auto on a folder is not supported: estimate each image with 'glradial estimate', or give the lens")
    if args.auto and args.pixel_aspect is not None and kind != "image":
        raise UsageError(f"--auto --pixel-aspect is for images; {args.input!r} is a {kind}")
    if args.pitch is not None and kind != "image":
        raise UsageError(f"--pitch is for images (a video's shots are read without the camera fit); {args.input!r} is a {kind}")
    hook = opentrackio_hook(args, kind)
    if kind == "image" and args.auto:
        return _correct_image_auto(args, hook)
    if kind != "video" or given or args.lens_track:
        return run_with_lens(args, "undistort", kind, video_only=AUTO_VIDEO_OPTIONS, hook=hook)
    from ..media.video_io import EncodeOptions, is_sequence

    encode = EncodeOptions(codec=args.codec, crf=args.crf, bitrate=args.bitrate, preset=args.preset, pix_fmt=args.pix_fmt)
    if args.rate is not None and not is_sequence(args.input):
        raise UsageError("--rate is for image-sequence inputs (videos keep their own frame rate)")
    video = dict(progress=show_progress(args), options=encode, overwrite=args.overwrite, rate=args.rate, fit=args.fit,
                 interpolation=args.interpolation, backend=args.backend, alpha=video_alpha(args),
                 field_order=args.field_order or "auto")
    return _run_video_auto(args, encode, video)


def _correct_image_auto(args: argparse.Namespace, hook) -> int:
    """``--auto`` on an image: decide, then apply. The image is decoded once; its lens is decided here
    (the estimate, then the doubt policy, :func:`glradial.lens.doubt.applies`) and handed to the
    apply step as a plain lens. The cheap checks (options, an existing OUTPUT) come first."""
    from ..media.atomic import check_overwrite
    from ..media.image_io import read_image

    reject_for(args, VIDEO_OPTIONS + AUTO_VIDEO_OPTIONS, "videos")
    check_overwrite(Path(args.output), args.overwrite)
    image = read_image(args.input, order="rgb")
    lens = _estimate_image(args, image)
    return run_with_lens(args, "undistort", "image", video_only=AUTO_VIDEO_OPTIONS, hook=hook, lens=lens, image=image)


def _estimate_image(args: argparse.Namespace, image):
    """The lens ``--auto`` applies to ``image`` (RGB array): the estimate, printed with its stated
    uncertainty and doubt; a doubtful one is reported in one line on stderr and, unless
    ``--apply-doubtful``, decided against (the identity lens: the image passes through)."""
    from ..lens import doubt
    from ..lens.lens import Lens
    from ..media.frames import to_rgb8

    # as 'glradial estimate IMG': auto adds the pitch camera fit's lens where the template fits; a squashed
    # frame (--pixel-aspect) is read in square pixels and the estimate carries the aspect to the stored frame
    estimator = cached_estimator(args.model)
    found = estimator.estimate(to_rgb8(image), method=args.method or "auto", pixel_aspect=args.pixel_aspect or 1.0,
                               pitch=args.pitch is not False)
    method, uncertainty = getattr(found, "method", None), getattr(found, "uncertainty_px", None)
    doubtful, reason = bool(getattr(found, "doubtful", False)), getattr(found, "reason", None)
    stated = f" ({method}, uncertainty {uncertainty:.1f} px at 1920, {reason})" if method and uncertainty is not None else ""
    print(f"{args.input}: estimated k1={found.k1:.6f} k2={found.k2:.6f}{stated}")
    note(args, k1=found.k1, k2=found.k2, method=method, uncertainty_px=uncertainty, reason=reason, doubtful=doubtful)
    applied = doubt.applies(doubtful, reason or "", bool(args.apply_doubtful))  # the one doubt policy decides
    if doubtful:
        action = "applied anyway (--apply-doubtful)" if applied else "left uncorrected (--apply-doubtful applies it)"
        print(f"glradial: warning: the estimate of {args.input} is doubtful ({reason}): {action}", file=sys.stderr)
    if not applied:
        return Lens(0.0, 0.0)
    return Lens(found.k1, found.k2, found.cx, found.cy, found.pixel_aspect)


def _auto_sidecar(args: argparse.Namespace) -> Path:
    """The sidecar ``--auto`` writes, checked before anything runs."""
    from ..media.atomic import check_output_folder, check_overwrite

    sidecar = Path(args.sidecar) if args.sidecar else Path(f"{args.output}.lens.csv")
    check_output_folder(sidecar)
    check_overwrite(sidecar, args.overwrite)
    refuse_same_file(sidecar, "--sidecar", args.input, args.output)
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
    given_options = {"every": args.every} if args.every is not None else {}
    track = track_video(args.input, _video_estimator(args, default_estimator), progress=video["progress"],
                        doubtful_px=args.max_uncertainty or DOUBTFUL_PX, apply_doubtful=bool(args.apply_doubtful),
                        rate=args.rate, **given_options)
    for line in doubtful_warnings(track, args.input):
        sys.stderr.write(line + "\n")
    written = correct_video(args.input, args.output, track.lens_for, frames_expected=track.n_frames, **video)
    try:
        track.save(sidecar)
    except BaseException:
        Path(args.output).unlink(missing_ok=True)  # both outputs or neither
        raise
    summary(args.output, written, info.frame_count)
    note(args, frames=written, shot_list=track.per_shot())
    _print_shots(args.input, track, sidecar)
    if opentrackio_wanted(args):
        write_track_opentrackio(args, track, info)
    return 0


def _video_estimator(args: argparse.Namespace, default_estimator):
    """Pass 1's frame -> lens: the estimation layer's reading without the camera fit (as 'estimate
    VIDEO'); in a job's worker its kept estimator (:func:`glradial.commands.keep_estimators`)."""
    if not estimators_kept():
        return default_estimator(args.model, args.method)
    estimator, method = cached_estimator(args.model), args.method or "auto"
    return lambda frame: estimator.estimate(frame, method=method, pitch=False)


def _print_shots(source: str, track, sidecar: Path) -> None:
    shots = track.per_shot()
    print(f"{source}: {track.n_frames} frames, {len(shots)} shot(s); per-frame lens in {sidecar}")
    for shot in shots:
        sure = f" uncertainty {shot['uncertainty_px']:.1f} px" if shot["uncertainty_px"] is not None else ""
        flag = (f" DOUBTFUL ({shot['reason']}, " + ("applied)" if shot["applied"] else "not applied)")) if shot["doubtful"] else ""
        print(f"  shot {shot['shot']}: frames {shot['first_frame']}-{shot['last_frame']} k1={shot['k1']:.6f} k2={shot['k2']:.6f}{sure}{flag}")
