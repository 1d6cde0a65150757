"""``glradial convert``: translate (k1, k2) between coefficient conventions."""

from __future__ import annotations

import argparse
import json
import sys

from ..lens.options import DISTORTION_MODELS
from . import OPENCV_API_HINT, UsageError, finite_float, parse_size, positive_float
from .engine_options import add_camera_options, camera_from_args, sensor_mm

CONVENTIONS = ("glradial", "width", "opencv", "ffmpeg", "lensfun", "pixel", "height", "opentrackio")
#: graphics-engine conventions (output only, except opentrackio U-D, which converts back exactly)
ENGINES = ("opentrackio", "unreal", "3de4-radial-deg4")

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
k2 r_u^4) centred on the frame. Prints 'K1 K2' (or JSON with --json).

Graphics engines (--to; docs/CLI.md gives the sources):

  opentrackio      OpenTrackIO / OpenLensIO v1.0 (SMPTE RIS-OSVP): mm from the sensor centre, y down;
                   radial = [k1..k6], R = (1 + k1 r^2 + k3 r^4 + k5 r^6) / (1 + k2 r^2 + k4 r^4 +
                   k6 r^6), r in mm. --distortion-model U-D (default): undistorted -> distorted,
                   exact: k1 = K1 / w^2, k3 = K2 / w^4 (w = sensor width, mm). D-U: distorted ->
                   undistorted, a least-squares fit (its error in px is printed). Needs
                   --sensor-width-mm (or --sensor) and --focal-mm; --json prints the sample's "lens"
                   object (distortion with overscan, pinholeFocalLength, offsets), else the six
                   radial numbers. --from opentrackio reads U-D radial VALUES back (--sensor-width-mm).
  unreal           Unreal Engine lens file, spherical model (OpenCV's): K1 K2 K3 P1 P2 with radii
                   in focal lengths, undistorted -> distorted (exact), FxFy = focal / (W, H),
                   PrincipalPoint in fractions of the frame (0.5 = centre). Needs the focal length:
                   --focal PX, or --focal-mm with --sensor-width-mm (or --sensor). Prints JSON.
  3de4-radial-deg4 3DEqualizer "Radial - Standard, Degree 4": x_u = x_d (1 + c2 r^2 + c4 r^4), r
                   normalised by half the frame diagonal from the lens centre, distorted ->
                   undistorted: c2, c4 are a least-squares fit over the frame, its largest and RMS
                   error in px printed with them. Prints 'C2 C4' (or JSON with --json)."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "convert", help="convert k1, k2 between OpenCV, ffmpeg, lensfun, pixel, height and width units",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--from", dest="source", choices=CONVENTIONS, required=True, help="convention of VALUES")
    parser.add_argument("--to", dest="target", choices=CONVENTIONS + ENGINES[1:], required=True, help="convention to print")
    parser.add_argument("--size", type=parse_size, required=True, metavar="WxH", help="frame size in pixels, e.g. 1920x1080")
    parser.add_argument("--focal", type=positive_float, metavar="PX",
                        help="OpenCV focal length f in pixels (needed with --from opencv; with --to opencv default W)")
    parser.add_argument("--approximate", action="store_true",
                        help="--from opencv: drop p1, p2, k3 instead of refusing them")
    parser.add_argument("--json", action="store_true", help="print JSON with the glradial lens and the result")
    parser.add_argument("values", nargs="+", type=finite_float, metavar="VALUE", help="coefficients in the --from convention")
    engine = parser.add_argument_group("graphics engines (--to opentrackio, unreal, 3de4-radial-deg4)")
    engine.add_argument("--distortion-model", choices=DISTORTION_MODELS, default="U-D",
                        help="--to opentrackio: U-D (exact, default) or D-U (fitted)")
    add_camera_options(engine)
    return parser


def _canonical(name: str) -> str:
    return "glradial" if name == "width" else name


def to_lens(source: str, values: list[float], size: tuple[int, int], focal: float | None, approximate: bool,
            sensor_width_mm: float | None = None):
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
        try:
            return Lens.from_opencv(camera, dist, size, approximate=approximate)
        except ValueError as err:  # the Python API's advice, in this command's terms
            raise ValueError(str(err).replace(OPENCV_API_HINT, "Give --approximate to keep K1, K2 only.")) from None
    if source == "opentrackio":
        return _from_opentrackio(values, sensor_width_mm)
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


def _from_opentrackio(values: list[float], sensor_width_mm: float | None):
    from ..export.engines import lens_from_openlensio

    if sensor_width_mm is None:
        raise UsageError("--from opentrackio needs --sensor-width-mm MM (or --sensor 2/3-inch): its coefficients are in mm")
    if not 1 <= len(values) <= 6:
        raise UsageError(f"--from opentrackio takes 1 to 6 radial values (Brown-Conrady U-D k1..k6), got {len(values)}")
    return lens_from_openlensio(values, sensor_width_mm)


def _engine(lens, args: argparse.Namespace) -> tuple[dict, str]:
    """(JSON document, text line) of ``lens`` in engine convention ``args.target``."""
    from ..export import engines

    if args.target == "3de4-radial-deg4":
        document = engines.tde4_radial_deg4(lens, args.size)
        c2, c4 = document["Distortion - Degree 2"], document["Quartic Distortion - Degree 4"]
        print(f"glradial: 3DE4 Radial - Standard, Degree 4 fit over the {args.size[0]}x{args.size[1]} frame: largest error "
              f"{document['fit_max_error_px']:.3g} px, RMS {document['fit_rms_error_px']:.3g} px", file=sys.stderr)
        return document, f"{c2:.12g} {c4:.12g}"
    if args.target == "unreal":
        focal = args.focal
        if focal is None:
            if args.focal_mm is None:
                raise UsageError("--to unreal needs the focal length: --focal PX, or --focal-mm MM with --sensor-width-mm MM "
                                 "(or --sensor 2/3-inch)")
            camera = camera_from_args(args, args.size, what="--to unreal with --focal-mm")
            focal = camera.focal_mm / camera.sensor_width_mm * args.size[0]
        document = engines.unreal_spherical(lens, args.size, focal)
        return document, " ".join(f"{document[k]:.12g}" for k in ("K1", "K2", "K3", "P1", "P2"))
    from ..export.engines import MODEL_NAMES
    from ..export.opentrackio import lens_object

    camera = camera_from_args(args, args.size, what="--to opentrackio")
    document, error = lens_object(lens, camera, model=MODEL_NAMES[args.distortion_model])
    if error is not None:
        print(f"glradial: D-U fit over the {args.size[0]}x{args.size[1]} frame: largest error {error:.3g} px", file=sys.stderr)
    return document, " ".join(f"{v:.12g}" for v in document["distortion"][0]["radial"])


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
    width_mm, _height_mm = sensor_mm(args)
    lens = to_lens(args.source, args.values, args.size, args.focal, args.approximate, width_mm)
    if args.target in ENGINES:
        document, text = _engine(lens, args)
        print(json.dumps(document) if args.json or args.target == "unreal" else text)
        return 0
    if args.target == "opentrackio" or args.distortion_model != "U-D":
        raise UsageError("--distortion-model is for --to opentrackio")
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
