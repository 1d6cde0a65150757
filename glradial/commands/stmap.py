"""``glradial stmap``: export a lens as a 32-bit float STMap for compositing tools."""

from __future__ import annotations

import argparse

from ..lens.options import DIRECTIONS, FITS, INVERSES, LAYOUTS, ORIGINS
from . import UsageError, add_lens_options, lens_from_args, lens_given, parse_size
from .engine_options import add_overscan_option, overscan_value

DESCRIPTION = """\
Write the STMap of the lens (--k1 --k2 [--cx --cy --pixel-aspect], or --lens FILE) on a WxH frame: a
32-bit float RGB image whose red (S) and green (T) channels give, for each output pixel, the source
position to sample, with Nuke's convention: S = (x + 0.5) / W, T = 1 - (y + 0.5) / H (origin at the
bottom-left corner of the source, x right, y down in pixels, row 0 at the top), blue = 0. Pixels
with no source hold S = T = -1. --direction undistort: apply the map to the distorted footage to
correct it (as 'glradial correct'); distort: apply it to an undistorted render to add the lens.
Formats: .exr (float32 R, G, B, ZIP-compressed: what Nuke and Gyroflow load), .tif or .tiff
(uncompressed float32 RGB TIFF), .npy (H x W x 3 float32 array). An existing --out is replaced only
with -y.

--layout unreal: Unreal Engine's lens-file ST map, one RGBA float image: R, G = the undistortion map
(distorted -> undistorted), B, A = the distortion map (undistorted CG -> distorted), with the pixel
origin of T chosen by --origin (top-left: T = (y + 0.5) / H, default; bottom-left: Nuke's).
--overscan [FACTOR]: the undistorted side of the map is an overscanned render whose field is FACTOR
times the frame's (about the frame centre; OpenLensIO's overscan): the distort map samples it, the
undistort map produces it; without FACTOR, the lens's own overscan (the smallest that leaves no
empty pixel, OpenLensIO appendix A.1), printed. --lens-track CSV: one map per shot of a lens track
(its median lens; with --overscan and no FACTOR the track's largest), written to --out with
'_shotN' before the extension."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "stmap", help="export a lens as a 32-bit float STMap (Nuke or Unreal layout, overscan)",
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
    parser.add_argument("--layout", choices=LAYOUTS, default="nuke",
                        help="nuke = RGB, S T in R G (default); unreal = RGBA, undistortion in RG and distortion in BA")
    parser.add_argument("--origin", choices=ORIGINS,
                        help="--layout unreal: pixel origin of T (default top-left; Nuke's layout is always bottom-left)")
    add_overscan_option(parser, "maps for an overscanned undistorted render: FACTOR >= 1, or the lens's own overscan when "
                        "given without a value (replaces --fit)")
    parser.add_argument("--lens-track", metavar="CSV", help="write one map per shot of this lens track (.csv or .json)")
    parser.add_argument("--out", required=True, metavar="FILE", help="output .exr (recommended), .tif/.tiff or .npy")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace --out if it exists")
    return parser


def _jobs(args: argparse.Namespace) -> list[tuple[str, object, str]]:
    """(output path, lens, label) of each map to write."""
    from pathlib import Path

    if args.lens_track is None:
        return [(args.out, lens_from_args(args, args.size), "")]
    if lens_given(args):
        raise UsageError("--lens-track cannot be combined with --k1/--k2/--cx/--cy/--pixel-aspect/--lens")
    from fractions import Fraction

    from ..lens.lens import Lens
    from ..video.lens_track import load_lens_track

    track = load_lens_track(args.lens_track, Fraction(25), args.size)  # the rate only fills times, unused here
    out = Path(args.out)
    return [(str(out.with_name(f"{out.stem}_shot{shot['shot']}{out.suffix}")), Lens(shot["k1"], shot["k2"]),
             f" shot {shot['shot']} (frames {shot['first_frame']}-{shot['last_frame']})") for shot in track.per_shot()]


def run(args: argparse.Namespace) -> int:
    from ..export.stmap import check_stmap_path, lens_stmap, unreal_stmap, write_stmap
    from ..media.atomic import check_output_folder, check_overwrite

    if args.origin is not None and args.layout != "unreal":
        raise UsageError("--origin is for --layout unreal (Nuke's layout has its origin at the bottom left)")
    if args.overscan is not None and args.fit != "same":
        raise UsageError("--overscan replaces --fit: give one of them")
    factor = overscan_value(args.overscan)
    jobs = _jobs(args)
    for path, _lens, _label in jobs:
        check_overwrite(check_output_folder(check_stmap_path(path)), args.overwrite)  # before any work
    if args.overscan is not None and factor is None:
        from ..export.overscan import overscan_factor

        factor = max(overscan_factor(lens, args.size) for _path, lens, _label in jobs)
        print(f"overscan {factor:.6f} (OpenLensIO: the smallest that leaves no empty pixel)")
    width, height = args.size
    for path, lens, label in jobs:
        if args.layout == "unreal":
            stmap = unreal_stmap(lens, args.size, overscan=factor or 1.0, origin=args.origin or "top-left")
            what = f"RGBA (undistort RG, distort BA, origin {args.origin or 'top-left'}"
        else:
            stmap = lens_stmap(lens, args.size, direction=args.direction, fit=args.fit, inverse=args.inverse, overscan=factor)
            what = f"RGB ({args.direction}, fit={args.fit}" if factor is None else f"RGB ({args.direction}"
        write_stmap(path, stmap)
        extra = "" if lens.is_centred else f", cx={lens.cx:g}, cy={lens.cy:g}, pixel_aspect={lens.pixel_aspect:g}"
        scan = "" if factor is None else f", overscan={factor:g}"
        print(f"wrote {path}:{label} {width}x{height} float32 STMap {what}{scan}, k1={lens.k1:g}, k2={lens.k2:g}{extra})")
    return 0
