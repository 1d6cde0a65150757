"""``glradial convert``: translate (k1, k2) between coefficient conventions."""

from __future__ import annotations

import argparse
import json

from . import UsageError, finite_float, parse_size, positive_float

CONVENTIONS = ("glradial", "width", "opencv", "ffmpeg", "lensfun", "pixel", "height")

DESCRIPTION = """\
Convert radial coefficients between conventions (all exact; a WxH frame size is needed):

  glradial, width  r = distance from the centre / image width (glradial's own, unitless)
  height           r / image height (the paper authors' released code)
  pixel            r in pixels ("apparent" coefficients; k1 in px^-2, k2 in px^-4)
  lensfun          poly5: r / half the shorter image side
  ffmpeg           lenscorrection filter: r / half the image diagonal (k1, k2 in [-1, 1])
  opencv           r / focal length: cv2 dist_coeffs (k1, k2[, p1, p2[, k3]]) with
                   K = [[f, 0, (W-1)/2], [0, f, (H-1)/2], [0, 0, 1]]; give --focal f (pixels)

VALUES are K1 K2 (for --from opencv: K1 K2 [P1 P2 [K3]]; p1, p2, k3 must be 0 unless
--approximate, which drops them). All conventions use the same model r_d = r_u (1 + k1 r_u^2 +
k2 r_u^4) centred on the frame. Prints 'K1 K2' (or JSON with --json)."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "convert", help="convert k1, k2 between OpenCV, ffmpeg, lensfun, pixel, height and width units",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--from", dest="source", choices=CONVENTIONS, required=True, help="convention of VALUES")
    parser.add_argument("--to", dest="target", choices=CONVENTIONS, required=True, help="convention to print")
    parser.add_argument("--size", type=parse_size, required=True, metavar="WxH", help="frame size in pixels, e.g. 1920x1080")
    parser.add_argument("--focal", type=positive_float, metavar="PX",
                        help="OpenCV focal length f in pixels (needed with --from opencv; with --to opencv default W)")
    parser.add_argument("--approximate", action="store_true",
                        help="--from opencv: drop p1, p2, k3 instead of refusing them")
    parser.add_argument("--json", action="store_true", help="print JSON with the glradial lens and the result")
    parser.add_argument("values", nargs="+", type=finite_float, metavar="VALUE", help="coefficients in the --from convention")
    return parser


def _canonical(name: str) -> str:
    return "glradial" if name == "width" else name


def to_lens(source: str, values: list[float], size: tuple[int, int], focal: float | None, approximate: bool):
    """Lens from VALUES in convention ``source``."""
    from ..lens.lens import Lens

    given, source = source, _canonical(source)
    if source == "opencv":
        if focal is None:
            raise UsageError("--from opencv needs --focal (the focal length in pixels)")
        if len(values) not in (2, 4, 5):
            raise UsageError(f"--from opencv takes K1 K2 [P1 P2 [K3]], got {len(values)} values")
        import numpy as np

        width, height = size
        camera = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
        dist = list(values) + [0.0] * (5 - len(values))
        return Lens.from_opencv(camera, dist, size, approximate=approximate)
    if len(values) != 2:
        raise UsageError(f"--from {given} takes two values K1 K2, got {len(values)}")
    k1, k2 = values
    if source == "glradial":
        return Lens(k1, k2)
    if source == "height":
        return Lens.from_height_normalised(k1, k2, size)
    if source == "pixel":
        return Lens.from_pixel(k1, k2, size)
    if source == "lensfun":
        return Lens.from_lensfun_poly5(k1, k2, size)
    if source == "ffmpeg":
        return Lens.from_ffmpeg(k1, k2, size)
    raise UsageError(f"unknown convention {source!r}")


def from_lens(lens, target: str, size: tuple[int, int], focal: float | None) -> tuple[float, float]:
    """(k1, k2) of ``lens`` in convention ``target``."""
    target = _canonical(target)
    if target == "glradial":
        return lens.k1, lens.k2
    if target == "height":
        return lens.to_height_normalised(size)
    if target == "pixel":
        return lens.to_pixel(size)
    if target == "lensfun":
        return lens.to_lensfun_poly5(size)
    if target == "ffmpeg":
        return lens.to_ffmpeg(size)
    if target == "opencv":
        _, dist = lens.to_opencv(size, focal)
        return float(dist[0]), float(dist[1])
    raise UsageError(f"unknown convention {target!r}")


def run(args: argparse.Namespace) -> int:
    if args.approximate and _canonical(args.source) != "opencv":
        raise UsageError("--approximate applies to --from opencv only")
    lens = to_lens(args.source, args.values, args.size, args.focal, args.approximate)
    focal_out = args.focal if _canonical(args.target) == "opencv" else None
    k1, k2 = from_lens(lens, args.target, args.size, focal_out)
    if args.json:
        document = {"from": args.source, "to": args.target, "size": list(args.size), "glradial": [lens.k1, lens.k2],
                    "k1": k1, "k2": k2}
        if _canonical(args.target) == "opencv":
            camera, dist = lens.to_opencv(args.size, focal_out)
            document["camera_matrix"] = camera.tolist()
            document["dist_coeffs"] = dist.tolist()
        print(json.dumps(document))
    else:
        print(f"{k1:.12g} {k2:.12g}")
    return 0
