"""``glradial stmap``: export a lens as a 32-bit float STMap for compositing tools."""

from __future__ import annotations

import argparse

from ..lens.options import DIRECTIONS, FITS, INVERSES
from . import add_lens_options, lens_from_args, parse_size

DESCRIPTION = """\
Write the STMap of the lens (--k1 --k2 [--cx --cy --pixel-aspect], or --lens FILE) on a WxH frame: a
32-bit float RGB image whose red (S) and green (T) channels give, for each output pixel, the source
position to sample, with Nuke's convention: S = (x + 0.5) / W, T = 1 - (y + 0.5) / H (origin at the
bottom-left corner of the source, x right, y down in pixels, row 0 at the top), blue = 0. Pixels
with no source hold S = T = -1. --direction undistort: apply the map to the distorted footage to
correct it (as 'glradial correct'); distort: apply it to an undistorted render to add the lens.
Formats: .exr (float32 R, G, B, ZIP-compressed: what Nuke and Gyroflow load), .tif or .tiff
(uncompressed float32 RGB TIFF), .npy (H x W x 3 float32 array). An existing --out is replaced only
with -y."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "stmap", help="export a lens as a 32-bit float STMap (Nuke convention)",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_lens_options(parser.add_argument_group("lens (give --k1 [--k2 --cx --cy --pixel-aspect] or --lens FILE)"))
    parser.add_argument("--size", type=parse_size, required=True, metavar="WxH", help="frame size in pixels, e.g. 1920x1080")
    parser.add_argument("--direction", choices=DIRECTIONS, default="undistort",
                        help="undistort = map that corrects distorted footage, distort = map that adds the lens (default: undistort)")
    parser.add_argument("--fit", choices=FITS, default="same",
                        help="output scale, as in 'glradial correct' (default: same)")
    parser.add_argument("--inverse", choices=INVERSES, default="exact",
                        help="with --direction distort: exact inverse (Newton) or the paper's Drap-Lefevre polynomial (default: exact)")
    parser.add_argument("--out", required=True, metavar="FILE", help="output .exr (recommended), .tif/.tiff or .npy")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace --out if it exists")
    return parser


def run(args: argparse.Namespace) -> int:
    from ..export.stmap import check_stmap_path, lens_stmap, write_stmap
    from ..media.atomic import check_output_folder
    from ..media.image_io import check_overwrite

    check_overwrite(check_output_folder(check_stmap_path(args.out)), args.overwrite)  # before any work
    lens = lens_from_args(args, args.size)
    stmap = lens_stmap(lens, args.size, direction=args.direction, fit=args.fit, inverse=args.inverse)
    write_stmap(args.out, stmap)
    width, height = args.size
    extra = "" if lens.is_centred else f", cx={lens.cx:g}, cy={lens.cy:g}, pixel_aspect={lens.pixel_aspect:g}"
    print(f"wrote {args.out}: {width}x{height} float32 STMap ({args.direction}, fit={args.fit}, "
          f"k1={lens.k1:g}, k2={lens.k2:g}{extra})")
    return 0
