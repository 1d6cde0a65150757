"""Options shared by the commands that hand the lens to graphics engines (``convert --to
opentrackio|unreal``, ``estimate --opentrackio``, ``correct --opentrackio``): the camera (sensor
size, focal length) and the OpenTrackIO output (file, model, CBOR, UDP). Not a subcommand."""

from __future__ import annotations

import argparse
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..lens.options import DISTORTION_MODELS, SENSORS
from . import UsageError, positive_float
from .remapping import RemapHook, refuse_same_file

__all__ = ["add_camera_options", "add_opentrackio_options", "camera_from_args", "opentrackio_wanted",
           "check_opentrackio_output", "write_opentrackio", "write_image_opentrackio", "write_track_opentrackio",
           "OpenTrackIOHook", "opentrackio_hook", "add_overscan_option", "overscan_value", "sensor_mm"]


def add_overscan_option(group: argparse.ArgumentParser | argparse._ArgumentGroup, help_text: str) -> None:
    """``--overscan [FACTOR]`` (``distort``, ``stmap``), read by :func:`overscan_value`."""
    group.add_argument("--overscan", nargs="?", const="auto", metavar="FACTOR", help=help_text)


def overscan_value(text: str | None) -> float | None:
    """The factor of ``--overscan [FACTOR]`` (``nargs="?", const="auto"``): a number >= 1, or None
    when not given or given without a value (the lens's own overscan)."""
    if text in (None, "auto"):
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value >= 1.0 or value == float("inf"):
        raise UsageError(f"--overscan takes a factor >= 1 (or no value: the lens's own), got {text!r}")
    return value


def add_camera_options(group: argparse._ArgumentGroup, *, focal: bool = True) -> None:
    """``--sensor-width-mm --sensor-height-mm --sensor --focal-mm`` (read by :func:`camera_from_args`);
    without ``--focal-mm`` for a command that measures the focal length (``focal=False``)."""
    group.add_argument("--sensor-width-mm", type=positive_float, metavar="MM", help="width of the camera sensor's active area in mm (the frame's width)")
    group.add_argument("--sensor-height-mm", type=positive_float, metavar="MM", help="its height in mm (default: width x H / W, square photosites)")
    group.add_argument("--sensor", choices=SENSORS, help="a named sensor instead of --sensor-width-mm: 2/3-inch = 9.59 x 5.39 mm (16:9 broadcast)")
    if focal:
        group.add_argument("--focal-mm", type=positive_float, metavar="MM", help="pinhole focal length of the lens in mm (glradial measures distortion, not the field of view)")


def add_opentrackio_options(parser: argparse.ArgumentParser, *, focal: bool = True) -> argparse._ArgumentGroup:
    """The OpenTrackIO output group: ``--opentrackio FILE --distortion-model --cbor --send`` and the
    camera (``focal=False``: no ``--focal-mm``, the command measures it); returns the group."""
    group = parser.add_argument_group(
        "OpenTrackIO output (one sample per frame for a graphics engine; needs the sensor width"
        + (" and focal length)" if focal else ")"))
    group.add_argument("--opentrackio", metavar="FILE",
                       help="write one OpenTrackIO sample per frame (JSON lines; a CBOR sequence with --cbor)")
    group.add_argument("--distortion-model", choices=DISTORTION_MODELS, default="U-D",
                       help="U-D = undistorted->distorted, glradial's own direction (exact; default); D-U = "
                            "distorted->undistorted, the schema's default (a least-squares fit; error printed)")
    group.add_argument("--cbor", action="store_true", help="write CBOR instead of JSON (needs the cbor2 package)")
    group.add_argument("--send", metavar="HOST:PORT",
                       help="also stream the samples as OpenTrackIO UDP packets, paced at the frame rate "
                            "(the standard's multicast group for source 1 is 235.135.1.1:55555)")
    add_camera_options(group, focal=focal)
    return group


def opentrackio_wanted(args: argparse.Namespace) -> bool:
    """Whether samples are asked for (a file or a UDP destination)."""
    return bool(getattr(args, "opentrackio", None) or getattr(args, "send", None))


def sensor_mm(args: argparse.Namespace) -> tuple[float | None, float | None]:
    """Sensor width and height (mm) of ``--sensor``/``--sensor-width-mm``/``--sensor-height-mm`` (None where not given)."""
    if args.sensor and args.sensor_width_mm is not None:
        raise UsageError("give --sensor or --sensor-width-mm, not both")
    if args.sensor:
        from ..export.opentrackio import SENSOR_PRESETS

        width, height = SENSOR_PRESETS[args.sensor]
        return width, args.sensor_height_mm or height
    return args.sensor_width_mm, args.sensor_height_mm


def camera_from_args(args: argparse.Namespace, size: tuple[int, int], rate: Fraction | None = None,
                     timecode: str | None = None, *, what: str = "OpenTrackIO samples"):
    """The :class:`glradial.export.opentrackio.TrackingCamera` of the options; ``UsageError`` naming the
    option to give when the sensor width or the focal length is missing (never a zero)."""
    from ..export.opentrackio import TrackingCamera

    width_mm, height_mm = _camera_numbers(args, what)
    return TrackingCamera(size, width_mm, args.focal_mm, height_mm, rate=rate, timecode=timecode)


def _camera_numbers(args: argparse.Namespace, what: str, focal_measured: bool = False) -> tuple[float, float | None]:
    """Sensor width and height (mm) of the options; ``UsageError`` naming what is missing (the focal
    length too, unless ``focal_measured``: a command that measures it)."""
    width_mm, height_mm = sensor_mm(args)
    missing = []
    if width_mm is None:
        missing.append("--sensor-width-mm MM (or --sensor 2/3-inch)")
    if getattr(args, "focal_mm", None) is None and not focal_measured:
        missing.append("--focal-mm MM")
    if missing:
        raise UsageError(f"{what}: give {' and '.join(missing)} (glradial cannot know them from the picture)")
    return width_mm, height_mm


def check_opentrackio_output(args: argparse.Namespace, *, focal_measured: bool = False) -> None:
    """Before any work: the options fit together, the file can be written (``-y`` to replace);
    ``focal_measured``: the command measures the focal length, ``--focal-mm`` is not asked for."""
    from ..media.atomic import check_output_folder, check_overwrite

    given = [name for name in ("distortion_model", "cbor") if getattr(args, name) not in (None, False, "U-D")]
    if not opentrackio_wanted(args):
        camera = [n for n in ("sensor_width_mm", "sensor_height_mm", "sensor", "focal_mm") if getattr(args, n, None) is not None]
        if given or camera:
            names = ", ".join(f"--{n.replace('_', '-')}" for n in given + camera)
            raise UsageError(f"{names} need(s) --opentrackio FILE or --send HOST:PORT")
        return
    _camera_numbers(args, "OpenTrackIO samples", focal_measured)
    if args.send:
        from ..export.opentrackio_udp import parse_address

        parse_address(args.send)
    if args.cbor:
        from ..export.opentrackio import require_cbor2  # the optional dependency, checked before any work

        require_cbor2()
    if args.opentrackio:
        check_overwrite(check_output_folder(Path(args.opentrackio)), getattr(args, "overwrite", False))


def write_opentrackio(args: argparse.Namespace, lenses, camera, *, uncertainty_px=None, doubtful=None,
                      shots=None) -> None:
    """Make the samples of ``lenses`` (:class:`Lens` objects or (k1, k2) rows), write ``--opentrackio`` and stream to ``--send``."""
    from ..export.engines import MODEL_NAMES
    from ..export.opentrackio import encode_sample, track_samples, write_samples
    from ..export.opentrackio_udp import ENCODING_CBOR, ENCODING_JSON, parse_address, send_payloads

    samples = track_samples(lenses, camera, model=MODEL_NAMES[args.distortion_model], uncertainty_px=uncertainty_px,
                            doubtful=doubtful, shots=shots)
    overscan = samples[0]["static"]["lens"]["distortionOverscanMax"]
    errors = [s["custom"]["glradial"]["fit_max_error_px"] for s in samples if "fit_max_error_px" in s["custom"]["glradial"]]
    stated = f"; D-U fit error up to {max(errors):.3g} px" if errors else ""
    if args.opentrackio:
        write_samples(args.opentrackio, samples, cbor=args.cbor)
        print(f"wrote {args.opentrackio}: {len(samples)} OpenTrackIO sample(s) ({MODEL_NAMES[args.distortion_model]}, "
              f"overscan up to {overscan:.4f}{stated})", file=sys.stderr, flush=True)
    if args.send:
        address = parse_address(args.send)
        rate = float(camera.rate) if camera.rate is not None else None
        sent = send_payloads((encode_sample(s, args.cbor) for s in samples), address, encoding=ENCODING_CBOR if args.cbor else ENCODING_JSON,
                             rate=rate)
        print(f"sent {len(samples)} OpenTrackIO sample(s) in {sent} UDP packet(s) to {args.send}", file=sys.stderr)


def write_track_opentrackio(args: argparse.Namespace, track, video_info) -> None:
    """:func:`write_opentrackio` of a :class:`glradial.video.lens_track.LensTrack` (its per-frame lens,
    stated uncertainty, doubtful shots and shot ids) with the video's rate and timecode."""
    camera = camera_from_args(args, track.size, video_info.rate, video_info.timecode)
    doubtful_shots = set(track.doubtful_shots())
    known = np.isfinite(track.uncertainty_px).any()
    write_opentrackio(args, track.lenses(), camera, uncertainty_px=track.uncertainty_px if known else None,
                      doubtful=[int(s) in doubtful_shots for s in track.shot] if known else None, shots=track.shot)


def write_image_opentrackio(args: argparse.Namespace, size: tuple[int, int], lens) -> None:
    """:func:`write_opentrackio` of one image's lens; an estimate's stated uncertainty (and whether
    it is doubtful) goes in ``custom``."""
    from ..video.lens_track import DOUBTFUL_PX

    uncertainty = getattr(lens, "uncertainty_px", None)
    known = uncertainty is not None
    write_opentrackio(args, [[lens.k1, lens.k2]], camera_from_args(args, size), uncertainty_px=[uncertainty] if known else None,
                      doubtful=[uncertainty > DOUBTFUL_PX] if known else None)


class OpenTrackIOHook(RemapHook):
    """``correct --opentrackio``/``--send`` on an image or a video whose lens is given or read from a
    lens track: the camera (and a video's one lens, which the standard may refuse) checked before
    any frame is decoded, the samples written once the picture is."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.size: tuple[int, int] | None = None
        self.lens = self.track = self.info = self.camera = None

    def lens_known(self, size, lens=None, *, track=None, info=None) -> None:
        from ..export.opentrackio import track_samples

        self.size, self.lens, self.track, self.info = size, lens, track, info
        if info is not None:
            self.camera = camera_from_args(self.args, info.size, info.rate, info.timecode)
            if lens is not None:
                track_samples([lens], self.camera)  # a lens the standard cannot carry is refused now

    def written(self, frames: int) -> None:
        if self.track is not None:
            write_track_opentrackio(self.args, self.track, self.info)
        elif self.info is not None:
            write_opentrackio(self.args, [self.lens] * frames, self.camera)
        else:
            write_image_opentrackio(self.args, self.size, self.lens)


def opentrackio_hook(args: argparse.Namespace, kind: str) -> OpenTrackIOHook | None:
    """The hook of ``correct``'s OpenTrackIO options for INPUT of ``kind`` (None when no sample is
    asked for), after checking them before any work: a folder is refused (one camera per run), the
    file must differ from INPUT and OUTPUT and may be written."""
    check_opentrackio_output(args)
    if not opentrackio_wanted(args):
        return None
    if kind == "folder":
        raise UsageError("--opentrackio and --send are for an image or a video, not a folder")
    if args.opentrackio:
        refuse_same_file(args.opentrackio, "--opentrackio", args.input, args.output)
    return OpenTrackIOHook(args)
