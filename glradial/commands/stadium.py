"""``glradial stadium``: render one procedural football-stadium panorama to an image file."""

from __future__ import annotations

import argparse

from . import non_negative_int, parse_size, positive_int

DESCRIPTION = """\
Render the procedural football-stadium panorama of SEED as an equirectangular RGB image
(longitude 0 at the centre column, + to the right; latitude +90 deg at the top row; W = 2 H is
usual). The seed decides everything: stadium shape, colours, lighting, mowing stripes, camera
position (main broadcast platform, other tribune positions, behind a goal, pitch side). Seeds
split into train / val / test by SEED % 10: 0-7 train, 8 val, 9 test. Formats: .png, .jpg, .jpeg,
.tif, .tiff or .npy (H x W x 3 uint8 array). An existing --out is replaced only with -y."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "stadium", help="render a procedural football-stadium panorama (equirectangular)",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--seed", type=non_negative_int, required=True, help="stadium seed (integer >= 0)")
    parser.add_argument("--size", type=parse_size, default=(8192, 4096), metavar="WxH",
                        help="panorama size in pixels (default 8192x4096)")
    parser.add_argument("--supersample", type=positive_int, default=None, metavar="N",
                        help="N x N samples on geometric edges, 1..4 (default: the seed's style, 2)")
    parser.add_argument("--lighting", choices=("day", "overcast", "night"), default=None,
                        help="override the seed's lighting")
    parser.add_argument("--out", required=True, metavar="FILE", help="output image (.png, .jpg, .jpeg, .tif, .tiff) or .npy")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace --out if it exists")
    parser.add_argument("--info", action="store_true", help="also print the seed's style (camera, lighting, split)")
    return parser


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from ..media.atomic import atomic_path, check_output_folder, check_overwrite
    from ..media.image_io import IMAGE_EXTENSIONS, is_image_path, write_image
    from ..synthesis.stadium import stadium_panorama
    from ..synthesis.stadium_style import sample_style, stadium_split

    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {args.seed}")
    overrides = {}
    if args.supersample is not None:
        overrides["supersample"] = args.supersample
    if args.lighting is not None:
        overrides["lighting"] = args.lighting
    from ..media.progress import Progress
    from . import show_progress

    target = check_output_folder(args.out)  # everything about --out is checked before the render
    npy = target.suffix.lower() == ".npy"
    known = ", ".join(sorted(ext for ext, dtypes in IMAGE_EXTENSIONS.items() if "uint8" in dtypes))  # 8-bit RGB formats
    if not npy and not is_image_path(target):
        raise ValueError(f"--out {str(target)!r}: unknown image extension {target.suffix or '(none)'!r}; use {known} or .npy")
    if not npy and "uint8" not in IMAGE_EXTENSIONS[target.suffix.lower()]:
        raise ValueError(f"--out {str(target)!r}: {target.suffix} cannot store the panorama's 8-bit RGB samples; "
                         f"use {known} or .npy")
    check_overwrite(target, args.overwrite)
    with Progress(1, "stadium", unit="panoramas", enabled=show_progress(args)) as bar:
        image = stadium_panorama(args.seed, tuple(args.size), **overrides)
        bar.update()
    if npy:
        with atomic_path(target) as tmp:
            with open(tmp, "wb") as handle:
                np.save(handle, image)
    else:
        write_image(target, image)
    width, height = args.size
    style = sample_style(args.seed)
    print(f"wrote {args.out}: {width}x{height} stadium panorama, seed {args.seed} ({stadium_split(args.seed)})")
    if args.info:
        print(f"camera {style.camera_kind} at ({style.camera[0]:.1f}, {style.camera[1]:.1f}, {style.camera[2]:.1f}) m, "
              f"lighting {overrides.get('lighting', style.lighting)}, stripes {style.stripe_pattern}")
    return 0
