"""``glradial correct``: undistort an image or a video with a given or estimated lens."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from . import UsageError, add_lens_options, lens_from_args, lens_given, positive_float, positive_int, show_progress

DESCRIPTION = """\
Undistort INPUT into OUTPUT. Images: PNG, JPEG, TIFF (8- and 16-bit and float32 TIFF kept, alpha
kept). Videos: .mp4/.m4v/.mov (MPEG-4), .avi (Motion JPEG), .mkv (lossless FFV1): the container and
codec follow OUTPUT's extension, frame rate, frame size and frame count are kept, audio is dropped.
The lens is given (--k1/--k2, width-normalised: image width = 1, origin at the image centre,
p_d = p_u (1 + k1 r^2 + k2 r^4); negative k1 = barrel; --cx/--cy/--pixel-aspect for an off-centre
principal point and non-square pixels; or --lens FILE, e.g. an OpenCV calibration) or estimated by
the bundled CNN (--auto, centred model).
For a video, --auto estimates every Nth frame, detects shot cuts, smooths the lens within each
shot and writes the per-frame lens to a sidecar (OUTPUT.lens.csv by default). Outputs appear only
when complete."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "correct",
        help="undistort an image or a video (given lens or --auto)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("input", metavar="INPUT", help="image or video to correct")
    parser.add_argument("output", metavar="OUTPUT", help="corrected file; its extension picks the format")
    lens = parser.add_argument_group("lens (give --k1 [--k2 --cx --cy --pixel-aspect], --lens FILE or --auto)")
    add_lens_options(lens)
    lens.add_argument("--auto", action="store_true", help="estimate the lens with the bundled CNN")
    lens.add_argument("--model", metavar="ONNX", help="with --auto: use this ONNX model instead of the bundled one")
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
    video = parser.add_argument_group("video with --auto")
    video.add_argument("--every", type=positive_int, default=5, metavar="N",
                       help="estimate every N-th frame of each shot, plus each shot's first frame (frames; default 5)")
    video.add_argument("--window", type=positive_float, default=2.0, metavar="SECONDS",
                       help="half width of the per-shot smoothing window (seconds; default 2.0)")
    video.add_argument("--sidecar", metavar="PATH",
                       help="per-frame lens file: .csv or .json (default: OUTPUT.lens.csv)")
    return parser


def _check_paths(args: argparse.Namespace) -> tuple[str, str]:
    from ..media_io import media_kind

    source, target = Path(args.input), Path(args.output)
    if not source.exists():
        raise FileNotFoundError(f"input file {str(source)!r} does not exist")
    kind_in, kind_out = media_kind(source), media_kind(target)
    if kind_in != kind_out:
        raise UsageError(f"INPUT is {'an' if kind_in == 'image' else 'a'} {kind_in} but OUTPUT {str(target)!r} has {'an' if kind_out == 'image' else 'a'} {kind_out} extension")
    if target.exists() and os.path.samefile(source, target):
        raise UsageError("OUTPUT must differ from INPUT")
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"output folder {str(folder)!r} does not exist")
    return kind_in, kind_out


def run(args: argparse.Namespace) -> int:
    given = lens_given(args)
    if args.auto and given:
        raise UsageError("--auto cannot be combined with --k1/--k2/--cx/--cy/--pixel-aspect/--lens")
    if not args.auto and not given:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE, or --auto to estimate it")
    if args.model is not None and not args.auto:
        raise UsageError("--model needs --auto")
    if args.sidecar is not None and not args.auto:
        raise UsageError("--sidecar needs --auto")
    kind, _ = _check_paths(args)
    progress = show_progress(args)
    options = dict(fit=args.fit, interpolation=args.interpolation, backend=args.backend)

    if kind == "image":
        from ..remap import correct
        from ..media_io import read_image, write_image

        if args.sidecar is not None:
            raise UsageError("--sidecar is for videos")
        from ..lens import Lens

        image = read_image(args.input, order="rgb")
        if args.auto:
            from ..video_pipeline import default_estimator, rgb8_for_estimator

            k1, k2 = _pair(default_estimator(args.model)(rgb8_for_estimator(image)))
            print(f"{args.input}: estimated k1={k1:.6f} k2={k2:.6f}")
            lens = Lens(k1, k2)
        else:
            lens = lens_from_args(args, (image.shape[1], image.shape[0]))
        write_image(args.output, correct(image, lens, **options), order="rgb")
        return 0

    from ..video_pipeline import correct_video

    if not args.auto:
        from ..media_io import VideoReader

        with VideoReader(args.input) as reader:
            size = reader.info.size
        lens = lens_from_args(args, size)  # validated before any frame is decoded
        correct_video(args.input, args.output, lambda _i: lens, progress=progress, **options)
        return 0

    from ..video_pipeline import default_estimator, rgb8_for_estimator, track_video
    from ..atomic import check_output_folder

    sidecar = Path(args.sidecar) if args.sidecar else Path(f"{args.output}.lens.csv")
    check_output_folder(sidecar)
    estimator = default_estimator(args.model)
    track = track_video(args.input, lambda frame: estimator(rgb8_for_estimator(frame)), every=args.every,
                        window_s=args.window, progress=progress)
    correct_video(args.input, args.output, lambda i: tuple(track.lens[min(i, track.n_frames - 1)]),
                  progress=progress, **options)
    try:
        track.save(sidecar)
    except BaseException:
        Path(args.output).unlink(missing_ok=True)  # both outputs or neither
        raise
    shots = track.per_shot()
    print(f"{args.input}: {track.n_frames} frames, {len(shots)} shot(s); per-frame lens in {sidecar}")
    for shot in shots:
        print(f"  shot {shot['shot']}: frames {shot['first_frame']}-{shot['last_frame']} k1={shot['k1']:.6f} k2={shot['k2']:.6f}")
    return 0


def _pair(value: object) -> tuple[float, float]:
    k1 = getattr(value, "k1", None)
    if k1 is not None:
        return float(k1), float(value.k2)  # type: ignore[attr-defined]
    a, b = value  # type: ignore[misc]
    return float(a), float(b)

