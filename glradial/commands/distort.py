"""``glradial distort``: put a lens into an undistorted image, folder of images or video, the exact
inverse of ``glradial correct`` (graphics rendered for a straight camera, made to sit in its lens)."""

from __future__ import annotations

import argparse

from ..lens.options import INVERSES
from . import UsageError, lens_from_args, lens_given, parse_size
from . import remapping as shared
from .engine_options import add_overscan_option, overscan_value

DESCRIPTION = """\
Apply a lens to INPUT (undistorted: graphics, a virtual set, a clean plate) and write OUTPUT as the
camera would see it; 'glradial correct' with the same lens and framing undoes it (the round trip
keeps a picture within interpolation error, docs/CLI.md). INPUT: an image (PNG, JPEG, TIFF, OpenEXR;
8/16-bit and float kept, EXR HALF/FLOAT and every channel kept, values beyond 1 kept), a folder of
images (each written into the folder OUTPUT under its own name), a video or an image sequence (as
'glradial correct': streams, timing, colour tags, depth kept; alpha kept where the codec stores it,
e.g. ProRes 4444). The lens is given (--k1/--k2, width-normalised: image width = 1, origin at the
image centre, p_d = p_u (1 + k1 r^2 + k2 r^4); negative k1 = barrel; --cx/--cy/--pixel-aspect; or
--lens FILE) or, for a video, read per frame from a lens track (--lens-track, e.g. the sidecar of
'glradial correct --auto'). An RGBA picture is interpolated premultiplied (no fringe on a key's edge)
and written in the convention it came in (--alpha). --overscan [FACTOR]: INPUT is an overscanned
render (a graphics engine's undistorted render whose field is FACTOR times the frame's, about its
centre; OpenLensIO's overscan) and OUTPUT the distorted frame, which it fills with no empty pixel
when FACTOR is at least the lens's own overscan (the default when no FACTOR is given). Outputs
appear only when complete; an existing OUTPUT is replaced only with -y."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser, _lens = shared.add_remap_parser(
        subparsers, "distort",
        "apply a lens to an image, folder or video (the inverse of correct: graphics into a camera's lens)", DESCRIPTION,
        "lens (give --k1 [--k2 --cx --cy --pixel-aspect], --lens FILE or --lens-track)",
        "videos: per-frame lens file (the sidecar of 'correct --auto'; .csv or .json)",
    )
    render = shared.add_render_options(
        parser, "output scale, the same numbers as 'correct': same = centre scale kept, crop = zoom in until every "
        "output pixel has a source (undone by 'correct --fit full'), full = the whole input stays visible "
        "(undone by 'correct --fit crop') (default: same)",
    )
    render.add_argument("--inverse", choices=INVERSES, default="exact",
                        help="inverse of the lens: exact (bounded Newton, to float precision) or drap (the Drap-Lefevre "
                        "polynomial, up to ~0.002 lens units off at the extremes of its k1 range) (default: exact)")
    add_overscan_option(render, "images: INPUT is an overscanned undistorted render whose field is FACTOR (>= 1) times the "
                        "frame's; without FACTOR the lens's own overscan (OpenLensIO), the smallest that leaves no "
                        "empty pixel. Rendered with cv2.remap (replaces --fit)")
    render.add_argument("--size", type=parse_size, metavar="WxH",
                        help="with --overscan: the distorted frame's size in pixels (default: INPUT's)")
    shared.add_encode_options(parser)
    return parser


def run(args: argparse.Namespace) -> int:
    given = lens_given(args)
    if given and args.lens_track:
        raise UsageError("--k1/--k2/--cx/--cy/--pixel-aspect/--lens and --lens-track cannot be combined: give the lens one way")
    if not (given or args.lens_track):
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect), --lens FILE or --lens-track")
    shared.check_encode_options(args)
    kind = shared.check_paths(args)
    if args.overscan is not None:
        return _run_overscanned(args, kind)
    if args.size is not None:
        raise UsageError("--size is for --overscan (without it OUTPUT has INPUT's size)")
    return shared.run_with_lens(args, "distort", kind, inverse=args.inverse)


def _run_overscanned(args: argparse.Namespace, kind: str) -> int:
    """``--overscan``: each image distorted from an overscanned render by
    :func:`glradial.export.overscan.distort_overscanned`, alpha interpolated premultiplied."""
    for wrong, why in ((kind == "video", "images and folders of images (a video: give its frames as a folder)"),
                       (args.fit != "same", "the frame itself: it replaces --fit"),
                       (args.backend == "gl", "cv2.remap: give --backend cpu or auto"),
                       (args.inverse != "exact", "the exact inverse: it replaces --inverse")):
        if wrong:
            raise UsageError(f"--overscan renders {why}")
    factor, frame = overscan_value(args.overscan), args.size
    return shared.run_with_lens(args, "distort", kind, lambda size: lens_from_args(args, frame or size),
                                transform=_overscanned_transform(args, factor, frame))


def _overscanned_transform(args: argparse.Namespace, factor: float | None, frame: tuple[int, int] | None):
    """``transform(render, lens, alpha)`` of ``--overscan``: ``factor`` None = the lens's own on the
    frame (stated once per lens and size)."""
    from ..export.overscan import distort_overscanned, overscan_factor
    from ..remapping.alpha import remap_with_alpha

    stated: dict = {}

    def transform(render, lens, alpha):
        size = frame or (render.shape[1], render.shape[0])
        scale = factor
        if scale is None:
            key = (lens.k1, lens.k2, lens.cx, lens.cy, lens.pixel_aspect, size)
            if key not in stated:
                stated[key] = overscan_factor(lens, size)
                print(f"overscan {stated[key]:.6f} (OpenLensIO: the smallest that leaves no empty pixel)", flush=True)
            scale = stated[key]
        return remap_with_alpha(render, 0.0, alpha, lambda work, _fill: distort_overscanned(  # the fill is 0
            work, lens, size, scale, interpolation=args.interpolation))

    return transform
