"""``glradial distort``: put a lens into an undistorted image, folder of images or video, the exact
inverse of ``glradial correct`` (graphics rendered for a straight camera, made to sit in its lens)."""

from __future__ import annotations

import argparse

from ..lens.options import INVERSES
from . import UsageError, lens_given
from . import remapping as shared

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
and written in the convention it came in (--alpha). Outputs appear only when complete; an existing
OUTPUT is replaced only with -y."""


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
    shared.add_encode_options(parser)
    return parser


def run(args: argparse.Namespace) -> int:
    given = lens_given(args)
    if given and args.lens_track:
        raise UsageError("--k1/--k2/--cx/--cy/--pixel-aspect/--lens and --lens-track cannot be combined: give the lens one way")
    if not (given or args.lens_track):
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect), --lens FILE or --lens-track")
    shared.check_encode_options(args)
    return shared.run_with_lens(args, "distort", shared.check_paths(args), inverse=args.inverse)
