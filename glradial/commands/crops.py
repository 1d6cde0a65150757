"""``glradial crops``: write a training dataset of distorted crops from equirectangular panoramas."""

from __future__ import annotations

import argparse

from ..lens.metrics import PAPER_SIZE
from ..lens.options import INVERSES
from . import non_negative_int, parse_size, positive_int, show_progress

DESCRIPTION = """\
Render COUNT distorted perspective crops from equirectangular panoramas (2:1 image files) with the
paper's distribution of camera pose, field of view and lens (pan U[-35,35] deg, tilt U[-15,0],
roll U[-2,2], hfov U[15,60], k1 U[-0.7,0.3], k2 = 0.019 k1 + 0.805 k1^2 + N(0, 0.02); lenses that
fold over on the frame are redrawn). The lens (k1, k2) refers to the --size frame (width-normalised
lens units); --out-size resizes it with an area filter (the paper: 1280x720 -> 224x224).

Writes DIR/manifest.json (settings), DIR/<split>/<index>.png and DIR/labels.csv (one row per crop:
file, split, panorama id, seed, pan, tilt, roll, hfov in degrees, k1, k2, sizes, inverse). Panoramas
are assigned to train/val/test as a whole: no panorama is in two splits. Every file is written
atomically; rerunning the same command resumes an interrupted run, skipping finished files."""


def _supersample(text: str) -> int | str:
    if text == "auto":
        return text
    from ..synthesis.crops import MAX_SUPERSAMPLE

    value = positive_int(text)
    if value > MAX_SUPERSAMPLE:
        raise argparse.ArgumentTypeError(f"expected an integer in 1..{MAX_SUPERSAMPLE} or auto, got {text!r}")
    return value


def _fractions(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected TRAIN,VAL,TEST fractions, got {text!r}") from None
    if len(values) != 3 or any(v < 0 or v != v for v in values) or abs(sum(values) - 1) > 1e-6:
        raise argparse.ArgumentTypeError(f"expected three fractions >= 0 summing to 1, got {text!r}")
    return values  # type: ignore[return-value]


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "crops", help="write a dataset of distorted crops from equirectangular panoramas",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("panoramas", nargs="+", metavar="PANORAMA", help="equirectangular panorama image files (width = 2 x height)")
    parser.add_argument("--count", type=positive_int, required=True, metavar="N", help="number of crops in total (spread evenly over the panoramas)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder (created; rerun to resume)")
    parser.add_argument("--seed", type=non_negative_int, required=True, metavar="S", help="random seed: fixes every crop and the split assignment")
    parser.add_argument("--size", type=parse_size, default=PAPER_SIZE, metavar="WxH",
                        help="frame geometry the lens refers to, in pixels (default: 1280x720)")
    parser.add_argument("--out-size", type=parse_size, default=None, metavar="WxH",
                        help="size of the written images (area-filtered; default: --size)")
    parser.add_argument("--inverse", choices=INVERSES, default="exact",
                        help="lens inverse used to distort: exact (Newton) or the paper's Drap-Lefevre polynomial (default: exact)")
    parser.add_argument("--supersample", type=_supersample, default=1, metavar="N|auto",
                        help="anti-aliasing with --out-size: N x N area-averaged samples per pixel, or auto (near-square "
                             "footprints, 2x1 for 1280x720 -> 224x224); default 1: one trilinear mipmap read")
    parser.add_argument("--splits", type=_fractions, default=(0.8, 0.1, 0.1), metavar="TRAIN,VAL,TEST",
                        help="fractions of the panoramas per split (default: 0.8,0.1,0.1)")
    parser.add_argument("--format", choices=("png", "jpg"), default="png", help="image file format (default: png)")
    return parser


def run(args: argparse.Namespace) -> int:
    from ..media.progress import Progress
    from ..synthesis.dataset import write_crops_dataset

    bar = Progress(args.count, "crops", unit="crops", enabled=show_progress(args))
    try:
        summary = write_crops_dataset(
            args.panoramas, args.out, count=args.count, seed=args.seed, size=args.size, out_size=args.out_size,
            inverse=args.inverse, supersample=args.supersample, splits=args.splits, image_format=args.format, progress=bar.update,
        )
    finally:
        bar.close()
    splits = ", ".join(f"{name} {n}" for name, n in summary.per_split.items() if n)
    print(f"wrote {summary.written} crops to {args.out} ({summary.skipped} already there; {splits}); labels in {summary.labels}")
    return 0
