"""``glradial estimate``: estimate the lens (k1, k2) of images and videos (pitch-line fit and bundled CNN)."""

from __future__ import annotations

import argparse
import json

from ..lens.options import METHODS
from ..media.image_io import media_kind, read_image
from . import MODEL_HELP, PITCH_HELP, UsageError, cached_estimator, positive_float, positive_int, show_progress
from .engine_options import add_opentrackio_options, check_opentrackio_output, opentrackio_wanted, write_image_opentrackio, write_track_opentrackio

DESCRIPTION = """\
Estimate the radial lens of each INPUT. --method auto (default): the pitch-line fit where it is
surer than the CNN; on images combined with the lens of the whole-camera fit to the pitch template
where that fits (--no-pitch to skip it, docs/CAMERA.md); where no pitch line is found it falls back
on the CNN, doubtful. --method net: the bundled CNN alone (ONNX on onnxruntime); --method lines: the
line fit whenever a frame has usable lines. How well each does (maximum displacement error, px of a 1920-wide frame, per source):
README.md ("What it can and cannot do"), docs/LINES.md, docs/eval/real.md, docs/eval/trust.md. Each image is
read as RGB; the network sees its centred 16:9 view (the whole frame when it is 16:9), resized with
area interpolation, and its answer is converted to the image's own width-normalised lens; with auto
or lines, the lens that straightens the frame's pitch lines and straight edges is fitted too. Prints one line per image: the path, k1 and
k2 (width-normalised: image width = 1, origin at the image centre, p_d = p_u (1 + k1 r^2 + k2 r^4);
negative k1 = barrel), the method that produced them (net, lines, or pitch where the camera fit took part), the uncertainty (a 90 % bound
on the maximum displacement error, px of a 1920-wide frame), the line chains used and the doubt
verdict (doubtful=0/1 and its reason: ok, blank_frame, noise_frame, not_a_pitch, too_few_lines,
evidence_disagrees, weak_geometry; docs/LINES.md), or with --json one JSON object per line {"path",
"k1", "k2", "pixel_aspect", "method", "uncertainty_px", "chains", "doubtful", "reason"}. Videos (anything FFmpeg reads that is not a still image; image sequences as
frame_%04d.png): shot cuts are detected and one lens is fitted per shot from the evidence of every
--every-th frame, as 'glradial correct --auto' does (without the camera fit, which would cost
0.2-0.3 s a frame); prints one line per shot (first and last frame,
median k1, k2, the uncertainty in px at 1920 wide, the per-frame methods, and for a doubtful shot
DOUBTFUL(reason) and not-applied), or per frame with --per-frame, or one JSON document per video
with --json."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "estimate", help="estimate the lens (k1, k2) of images and videos: pitch-line fit and CNN, with a stated uncertainty", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("inputs", metavar="INPUT", nargs="+", help="image (PNG, JPEG, TIFF) or video files")
    parser.add_argument("--json", action="store_true", help="one JSON object per line instead of text")
    parser.add_argument("--model", metavar="ONNX", help=MODEL_HELP)
    parser.add_argument("--threads", type=positive_int, help="onnxruntime threads (default: all cores)")
    parser.add_argument("--every", type=positive_int, default=None, metavar="N",
                        help="videos: read the evidence of every N-th frame of each shot (frames; default 10, as correct --auto)")
    parser.add_argument("--per-frame", action="store_true", help="videos: one line (or JSON row) per frame")
    parser.add_argument("--method", choices=METHODS, default="auto",
                        help="auto (default: the line fit when it is surer than the CNN), net (the CNN alone) or "
                             "lines (the pitch-line fit; the CNN when a frame has no usable lines); videos too")
    parser.add_argument("--pitch", action=argparse.BooleanOptionalAction, default=True,
                        help=f"images, with --method auto (default on): {PITCH_HELP} (videos always)")
    parser.add_argument("--pixel-aspect", type=positive_float, metavar="FY/FX",
                        help="images: the pixel aspect fy / fx of a frame stored squashed (e.g. 16/9 for a 16:9 "
                             "picture stored 640x640; default 1: square pixels); the lens printed applies to the "
                             "stored frame")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace the --opentrackio FILE if it exists")
    add_opentrackio_options(parser)
    return parser


def run(args: argparse.Namespace) -> int:
    from ..media.frames import to_rgb8

    if opentrackio_wanted(args) and len(args.inputs) != 1:
        raise UsageError(f"--opentrackio/--send take one INPUT (its samples), got {len(args.inputs)}")
    check_opentrackio_output(args)
    kinds = [media_kind(path) for path in args.inputs]
    if args.pixel_aspect is not None and "video" in kinds:
        raise UsageError(f"--pixel-aspect is for images; {args.inputs[kinds.index('video')]!r} is a video")
    estimator = cached_estimator(args.model, args.threads)
    for path, kind in zip(args.inputs, kinds):
        if kind == "video":
            from ..video.video_pipeline import track_report, track_video

            # the estimator loaded above (its --threads), not a second one per video
            stride = {"every": args.every} if args.every is not None else {}
            # per-frame video estimates skip the pitch camera fit (200-400 ms a frame; docs/CAMERA.md)
            track = track_video(path, lambda frame: estimator.estimate(frame, method=args.method, pitch=False),
                                progress=show_progress(args), **stride)
            print(track_report(track, path, per_frame=args.per_frame, as_json=args.json), flush=True)
            if opentrackio_wanted(args):
                from ..media.video_io import VideoReader

                with VideoReader(path) as reader:
                    info = reader.info
                write_track_opentrackio(args, track, info)
            continue
        image = to_rgb8(read_image(path))
        lens = estimator.estimate(image, method=args.method, pixel_aspect=args.pixel_aspect or 1.0, pitch=args.pitch)
        if args.json:
            print(json.dumps({"path": path, **lens.as_dict()}), flush=True)
        else:
            print(f"{path}\tk1={lens.k1:.6f}\tk2={lens.k2:.6f}\tmethod={lens.method}\t"
                  f"uncertainty={lens.uncertainty_px:.1f}px\tchains={lens.chains}\tdoubtful={int(lens.doubtful)}\t"
                  f"reason={lens.reason}", flush=True)
        if opentrackio_wanted(args):
            write_image_opentrackio(args, (image.shape[1], image.shape[0]), lens)
    return 0

