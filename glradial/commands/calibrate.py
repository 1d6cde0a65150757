"""``glradial calibrate``: the whole camera (lens, focal length, pose) of images and videos from the
pitch markings, and pixels (a detector's boxes) to pitch metres."""

from __future__ import annotations

import argparse
import json
import math
import sys
import uuid
from fractions import Fraction
from pathlib import Path

from ..media.image_io import media_kind, read_image
from . import UsageError, show_progress
from .engine_options import add_opentrackio_options, check_opentrackio_output, opentrackio_wanted, sensor_mm

DESCRIPTION = """\
Calibrate the whole camera of each INPUT from the pitch markings (a 105 x 68 m pitch by default):
the lens (width-normalised k1, k2, as 'estimate'), the focal length (image widths, px and the
horizontal field of view), the pose (camera position in pitch metres: origin at the centre spot, x
toward the goal on the right of the main camera, y toward the far touchline, z up; pan, tilt, roll in
degrees) and the pitch->frame homography (pitch metres -> the frame's own undistorted pixels). Each
answer states a 90 % bound on the reprojection error of the markings (uncertainty, px of a 1280-wide
frame, as rms) and a doubt verdict (doubtful=0/1, its reason: ok, no_markings, too_few_markings,
weak_geometry, poor_fit, track_lost, and why in numbers); a doubtful frame's numbers must not be used.
INPUT: an image, a folder of images (each calibrated on its own) or a video.
Videos: the camera is followed through each shot (cuts detected): the motion between frames carries
it, the markings are measured on every 5th frame and correct it, a frame that alone would be
declined takes the camera carried from its sure neighbours (carried=N frames, a growing bound), and
the track is smoothed forward and backward; rows are written in blocks, each 25-50 frames after its frame is read.
--points DETECTIONS (MOTChallenge CSV: frame,id,left,top,width,height,conf,..., frames from 1) maps
each box's bottom centre to pitch metres, written to --positions OUT.csv (empty where the frame's
camera is doubtful). docs/CAMERA.md says what it can and cannot do."""

#: A video's rows wait for 25-50 later frames (the backward pass of the track, once per block).
ROW_LAG = 25
#: What the numbers of a --json row are in.
UNITS = {"time_s": "seconds from the first frame", "homography": "pitch (x, y, 1) metres -> undistorted px of the frame",
         "uncertainty_px": "px at 1280 wide (90 % bound)", "rms_px": "px at 1280 wide", "position_m": "pitch metres",
         "focal": "image widths", "k1, k2": "width-normalised", "angles": "degrees"}


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("calibrate", help="the whole camera (lens, focal length, pose) from the pitch markings",
                                   description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    from . import InputPaths

    parser.add_argument("paths", metavar="IMG|FOLDER|VIDEO", nargs="+", action=InputPaths,
                        help="an image (PNG, JPEG, TIFF), a folder of images or a video; with --out-dir DIR: many (files, "
                             "folders, globs, @LIST), each calibration in DIR/NAME.json")
    parser.add_argument("--json", action="store_true", help="one JSON object per frame instead of text (with its time and units)")
    parser.add_argument("--overlay", metavar="OUT", help="write the frame with the projected markings (an image; a video's "
                        "last frame; dashed under a DOUBTFUL banner when the camera is doubtful)")
    parser.add_argument("--topview", metavar="OUT", help="write the frame warped onto the pitch plane (8 px per metre)")
    parser.add_argument("--points", metavar="DETECTIONS", help="MOTChallenge CSV boxes (frame,id,left,top,width,height,conf,...; "
                        "frames from 1): each box's bottom centre mapped to pitch metres (needs --positions)")
    parser.add_argument("--positions", metavar="OUT", help="the CSV file --points writes (frame,id,pixel_x,pixel_y,conf,x_m,y_m,"
                        "camera_doubtful,camera_reason,camera_uncertainty_px_1280)")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace output files that exist")
    group = add_opentrackio_options(parser, focal=False)
    group.add_argument("--doubtful-transforms", action="store_true",
                       help="also give doubtful frames' samples the camera transform (default: only the lens, flagged)")
    return parser


def _check(args: argparse.Namespace):
    """The input's kind ("image", "folder", "video") and its detections (or None), every option
    checked before any work."""
    from ..media.atomic import check_output_folder, check_overwrite

    source = Path(args.input)
    kind = "folder" if source.is_dir() else media_kind(args.input)
    if kind == "folder":
        from .remapping import folder_images

        if not folder_images(source):
            raise UsageError(f"folder {args.input!r} holds no still image (.png, .jpg, .tif, .exr)")
    for out in (args.overlay, args.topview, args.positions):
        if out:
            check_overwrite(check_output_folder(out), args.overwrite)
    if bool(args.points) != bool(args.positions):
        raise UsageError("--points DETECTIONS and --positions OUT go together")
    if opentrackio_wanted(args):
        if sensor_mm(args)[0] is None:
            raise UsageError("OpenTrackIO samples: give --sensor-width-mm MM (or --sensor 2/3-inch); the focal "
                             "length is measured")
        check_opentrackio_output(args, focal_measured=True)
    elif args.doubtful_transforms:
        raise UsageError("--doubtful-transforms needs --opentrackio FILE or --send HOST:PORT")
    detections = None
    if args.points:
        from ..media.detections import read_mot

        detections = read_mot(args.points)
    return kind, detections


def _line(path: str, index: int, est, more: dict) -> str:
    d = est.as_dict()
    extra = "".join(f"\t{k}={more[k]}" for k in ("time_s", "shot") if more.get(k) is not None)
    if est.camera is None:
        return f"{path}\tframe={index}{extra}\tdoubtful=1\treason={est.reason}\twhy={est.why}"
    x, y, z = d["position_m"]
    why = f"\twhy={est.why}" if est.doubtful else ""
    return (f"{path}\tframe={index}{extra}\tk1={d['k1']:.6f}\tk2={d['k2']:.6f}\tfocal={d['focal']:.5f}\t"
            f"focal_px={d['focal_px']:.1f}\thfov={d['hfov_deg']:.3f}deg\tposition=({x:.2f},{y:.2f},{z:.2f})m\t"
            f"pan={d['pan_deg']:.3f}\ttilt={d['tilt_deg']:.3f}\troll={d['roll_deg']:.3f}\t"
            f"uncertainty={est.uncertainty_px:.2f}px\tmarkings={len(est.markings)}\tcarried={est.carried}"
            f"\tdoubtful={int(est.doubtful)}\treason={est.reason}{why}")


class _Outputs:
    """Where each decided frame goes: its row (text or JSON, printed at once), its OpenTrackIO sample,
    its detections' positions; the last frame for the pictures."""

    def __init__(self, args: argparse.Namespace, detections) -> None:
        self.args, self.detections = args, detections
        self.samples: list[dict] = []
        self.positions: list[tuple] = []
        self.count, self.last, self.last_frame = 0, None, None
        self.source_id, self.rate, self.timecode = uuid.uuid4().urn, None, None

    def emit(self, path: str, index: int, est, time_s: float | None = None, shot: int | None = None) -> None:
        more = {"time_s": None if time_s is None else round(time_s, 6), "shot": shot}
        if self.args.json:
            row = {"path": path, "frame": index, **{k: v for k, v in more.items() if v is not None}, **est.as_dict(),
                   "units": UNITS}
            print(json.dumps(row), flush=True)
        else:
            print(_line(path, index, est, more), flush=True)
        self.count, self.last = self.count + 1, est
        if opentrackio_wanted(self.args) and est.camera is not None:
            self.samples.append(self._sample(index, est, time_s, shot))
        if self.detections is not None:
            self._positions(index, est)

    def _positions(self, index: int, est) -> None:
        d = self.detections
        mine = d.frame == index + 1  # MOTChallenge counts frames from 1
        if not mine.any():
            return
        feet = d.feet[mine]
        sure = est.camera is not None and not est.doubtful
        xy = est.to_pitch(feet) if sure else [(math.nan, math.nan)] * len(feet)
        for ident, foot, conf, (x, y) in zip(d.ids[mine], feet, d.conf[mine], xy):
            self.positions.append((index + 1, int(ident), float(foot[0]), float(foot[1]), float(conf), float(x), float(y),
                                   int(est.doubtful), est.reason, float(est.uncertainty_px)))

    def _sample(self, index: int, est, time_s: float | None, shot: int | None) -> dict:
        """The frame's OpenTrackIO sample, timed as ``glradial live``'s (sequence number = frame, sample
        rate, capture frame rate, timestamp, the source's timecode); the camera transform (pitch metres; OpenTrackIO pan/tilt/roll) only where
        the camera is sure, or with --doubtful-transforms."""
        from ..export.engines import MODEL_NAMES
        from ..export.opentrackio import TrackingCamera as OtioCamera
        from ..export.opentrackio import camera_transform, frame_sample, validate_sample
        from ..lens.lens import Lens

        width_mm, height_mm = sensor_mm(self.args)
        otio = OtioCamera(est.camera.size, width_mm, est.focal * width_mm, height_mm, rate=self.rate,
                          timecode=self.timecode if self.rate is not None else None)
        sample = frame_sample(Lens(est.lens.k1, est.lens.k2), otio, index, self.source_id,
                              model=MODEL_NAMES[self.args.distortion_model], uncertainty_px=math.nan,
                              doubtful=est.doubtful, shot=shot, timestamp_s=time_s)
        if not est.doubtful or self.args.doubtful_transforms:
            sample["transforms"] = [camera_transform(est.position, est.pan_tilt_roll)]
        sample["custom"]["glradial"].update({"frame": index, "calibration_uncertainty_px_1280": est.uncertainty_px,
                                             "calibration_reason": est.reason, "calibration_carried": est.carried})
        validate_sample(sample)
        return sample


def _images(args: argparse.Namespace, kind: str, out: _Outputs) -> None:
    from ..camera.calibrate import calibrate
    from ..media.frames import to_rgb8

    if kind == "folder":
        from .remapping import folder_images

        paths = [str(p) for p in folder_images(Path(args.input))]
    else:
        paths = [args.input]
    for path in paths:
        out.last_frame = to_rgb8(read_image(path))
        if out.detections is not None:
            out.detections.check_inside(out.last_frame.shape[1::-1], args.points)
        out.emit(path, 0, calibrate(out.last_frame))


def _video(args: argparse.Namespace, out: _Outputs) -> None:
    """A video's frames followed shot by shot (:func:`glradial.tracking.camera_track.track_cameras`),
    rows emitted in blocks, each :data:`ROW_LAG` to twice that many frames after its frame is read."""
    from ..media.frames import to_rgb8
    from ..media.progress import Progress
    from ..media.video_io import VideoReader
    from ..tracking.camera_track import track_cameras
    from ..video.cuts import ShotDetector

    detector, starts, reading = ShotDetector(), [0], [0]

    with VideoReader(args.input) as reader, Progress(reader.info.frame_count, "calibrate", enabled=show_progress(args)) as bar:
        out.rate, out.timecode, fps = Fraction(reader.info.rate), reader.info.timecode, reader.info.fps

        def frames():
            for index, frame in enumerate(reader):
                rgb = to_rgb8(frame)
                if index == 0 and out.detections is not None:
                    out.detections.check_inside(rgb.shape[1::-1], args.points)
                out.last_frame, reading[0] = rgb, index
                yield rgb
                bar.update(1)

        def is_cut(frame) -> bool:
            cut = detector.update(frame)
            if cut and reading[0] > 0:
                starts.append(reading[0])
            return cut

        for index, est in track_cameras(frames(), lag=ROW_LAG, is_cut=is_cut):
            shot = sum(1 for s in starts if s <= index) - 1
            out.emit(args.input, index, est, index / fps, shot)


def run(args: argparse.Namespace) -> int:
    kind, detections = _check(args)
    out = _Outputs(args, detections)
    if kind == "video":
        _video(args, out)
    else:
        _images(args, kind, out)
    if out.count == 0:
        raise UsageError(f"{args.input!r} holds no frame")
    frames = 1 if kind == "folder" else out.count  # a folder's images are each frame 1
    if detections is not None and int(detections.frame.max()) > frames:
        raise UsageError(f"{args.points!r} has boxes in frame {int(detections.frame.max())} but {args.input!r} holds "
                         f"{frames} frame(s) (MOTChallenge counts frames from 1): no positions written")
    _write(args, out)
    return 0


def _write(args: argparse.Namespace, out: _Outputs) -> None:
    """The files asked for, each written whole (atomically) once every frame is decided."""
    from ..camera.views import overlay, top_view
    from ..media.image_io import write_image

    final = out.last
    for path, draw in ((args.overlay, lambda f, c: overlay(f, c, doubt=final.why)), (args.topview, top_view)):
        if path:
            if final.camera is None:
                raise UsageError(f"no camera in the last frame ({final.reason}: {final.why}): nothing to draw for {path!r}")
            write_image(path, draw(out.last_frame, final.camera))
    if args.positions:
        from ..media.detections import write_positions

        missing = sorted({r[0] for r in out.positions if not math.isfinite(r[5])})
        if missing:
            print(f"calibrate: no sure camera in {len(missing)} frame(s) with boxes (frames {missing[0]}..{missing[-1]}, "
                  "counted from 1): their positions are left empty", file=sys.stderr)
        write_positions(args.positions, out.positions)
    if opentrackio_wanted(args):
        _write_opentrackio(args, out.samples)


def _write_opentrackio(args: argparse.Namespace, samples: list[dict]) -> None:
    """One OpenTrackIO sample per frame with a camera (module :class:`_Outputs`), written and/or sent."""
    from ..export.opentrackio import write_samples

    if not samples:
        raise UsageError("no frame has a camera: no OpenTrackIO samples written")
    if args.opentrackio:
        write_samples(args.opentrackio, samples, cbor=args.cbor)
    if args.send:
        from ..export.opentrackio import encode_sample
        from ..export.opentrackio_udp import ENCODING_CBOR, ENCODING_JSON, parse_address, send_payloads

        send_payloads((encode_sample(s, args.cbor) for s in samples), parse_address(args.send),
                      encoding=ENCODING_CBOR if args.cbor else ENCODING_JSON, rate=None)
