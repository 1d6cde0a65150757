"""``glradial calibrate``: the whole camera (lens, focal length, pose) of images and videos from the
pitch markings."""

from __future__ import annotations

import argparse
import json
import math
import uuid

from ..media.image_io import media_kind, read_image
from . import UsageError, show_progress
from .engine_options import add_opentrackio_options, check_opentrackio_output, opentrackio_wanted, sensor_mm

DESCRIPTION = """\
Calibrate the whole camera of each INPUT from the pitch markings (a 105 x 68 m pitch by default):
the lens (width-normalised k1, k2, as 'estimate'), the focal length (image widths, px and the
horizontal field of view), the pose (camera position in pitch metres: origin at the centre spot, x
toward the goal on the right of the main camera, y toward the far touchline, z up; pan, tilt, roll in
degrees) and the pitch->frame homography. Each answer states a 90 % bound on the reprojection error of
the markings (px of a 1280-wide frame) and a doubt verdict (doubtful=0/1 and its reason: ok,
no_markings, too_few_markings, weak_geometry, poor_fit); a doubtful frame's numbers must not be used.
Videos: one camera per frame, each frame starting from the previous sure frame's camera of its shot
(tracking); per shot (cuts detected), one lens as a function of the measured focal length (the zoom),
and each sure frame's pose and focal length refit with that lens at its zoom (lens_from=shot; a frame
whose refit is doubtful keeps its own lens, lens_from=frame). A video's rows come at each shot's end.
docs/CAMERA.md says what it can and cannot do."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser("calibrate", help="the whole camera (lens, focal length, pose) from the pitch markings",
                                   description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", metavar="IMG|VIDEO", help="an image (PNG, JPEG, TIFF) or a video")
    parser.add_argument("--json", action="store_true", help="one JSON object per frame instead of text")
    parser.add_argument("--overlay", metavar="OUT", help="write the frame with the projected markings (an image; a video's last frame)")
    parser.add_argument("--topview", metavar="OUT", help="write the frame warped onto the pitch plane (8 px per metre)")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace output files that exist")
    add_opentrackio_options(parser)
    return parser


def _frames(path: str, kind: str, progress):
    if kind == "image":
        yield read_image(path)
        return
    from ..media.progress import Progress
    from ..media.video_io import VideoReader

    with VideoReader(path) as reader, Progress(reader.info.frame_count, "calibrate", enabled=progress) as bar:
        for frame in reader:
            yield frame
            bar.update(1)


def _line(path: str, index: int, est, more: dict) -> str:
    d = est.as_dict()
    shot = "".join(f"\t{k}={more[k]}" for k in ("shot", "lens_from") if k in more)
    if est.camera is None:
        return f"{path}\tframe={index}{shot}\tdoubtful=1\treason={est.reason}"
    x, y, z = d["position_m"]
    return (f"{path}\tframe={index}\tk1={d['k1']:.6f}\tk2={d['k2']:.6f}\tfocal={d['focal']:.5f}\t"
            f"focal_px={d['focal_px']:.1f}\thfov={d['hfov_deg']:.3f}deg\tposition=({x:.2f},{y:.2f},{z:.2f})m\t"
            f"pan={d['pan_deg']:.3f}\ttilt={d['tilt_deg']:.3f}\troll={d['roll_deg']:.3f}\t"
            f"uncertainty={est.uncertainty_px:.2f}px\tmarkings={len(est.markings)}{shot}\tdoubtful={int(est.doubtful)}\treason={est.reason}")


def _check(args: argparse.Namespace) -> str:
    from ..media.atomic import check_output_folder, check_overwrite

    kind = media_kind(args.input)
    for out in (args.overlay, args.topview):
        if out:
            check_overwrite(check_output_folder(out), args.overwrite)
    if args.focal_mm is not None:
        raise UsageError("calibrate measures the focal length: --focal-mm is not used")
    if opentrackio_wanted(args):
        if sensor_mm(args)[0] is None:
            raise UsageError("OpenTrackIO samples: give --sensor-width-mm MM (or --sensor 2/3-inch); the focal "
                             "length is measured")
        check_opentrackio_output(args, focal_measured=True)
    return kind


def _video_estimates(frames, emit):
    """Calibrate a video's frames shot by shot (cuts: :class:`glradial.video.cuts.ShotDetector`), each
    shot with its lens as a function of the zoom (:class:`glradial.camera.shot_lens.ShotCalibrator`);
    ``emit(index, estimate, shot, from_shot)`` per frame at each shot's end. Yields each frame (RGB)."""
    from ..camera.shot_lens import ShotCalibrator
    from ..video.cuts import ShotDetector

    detector, calibrator, shot, first = ShotDetector(), ShotCalibrator(), 0, 0

    def flush() -> None:
        done = calibrator.finish()
        for i, (est, from_shot) in enumerate(zip(done.estimates, done.from_shot)):
            emit(first + i, est, shot, from_shot, done.lens_model)

    for index, frame in enumerate(frames):
        if detector.update(frame) and index > 0:
            flush()
            shot, first = shot + 1, index
        calibrator.add(frame)
        yield frame
    flush()


def run(args: argparse.Namespace) -> int:
    from ..camera.calibrate import calibrate
    from ..camera.views import overlay, top_view
    from ..media.frames import to_rgb8
    from ..media.image_io import write_image

    kind = _check(args)
    estimates, extra, last = [], [], None

    def emit(index: int, est, shot: int | None = None, from_shot: bool = False, model=None) -> None:
        estimates.append(est)
        more = {} if shot is None else {"shot": shot, "lens_from": "shot" if from_shot else "frame",
                                        "shot_lens": None if model is None else model.as_dict()}
        extra.append(more)
        print(json.dumps({"path": args.input, "frame": index, **more, **est.as_dict()}) if args.json
              else _line(args.input, index, est, more), flush=True)

    frames = (to_rgb8(f) for f in _frames(args.input, kind, show_progress(args)))
    if kind == "image":
        for index, last in enumerate(frames):
            emit(index, calibrate(last))
    else:
        for last in _video_estimates(frames, emit):
            pass
    if not estimates:
        raise UsageError(f"{args.input!r} holds no frame")
    final = estimates[-1]
    for out, draw in ((args.overlay, overlay), (args.topview, top_view)):
        if out:
            if final.camera is None:
                raise UsageError(f"no camera in the last frame ({final.reason}): nothing to draw for {out!r}")
            write_image(out, draw(last, final.camera))
    if opentrackio_wanted(args):
        _write_opentrackio(args, estimates, extra, (last.shape[1], last.shape[0]))
    return 0


def _write_opentrackio(args: argparse.Namespace, estimates, extra, size: tuple[int, int]) -> None:
    """One OpenTrackIO sample per frame with the measured focal length (mm, from the sensor width) and
    the camera's transform (pitch metres; OpenTrackIO pan/tilt/roll); a frame with no camera is left
    out, a doubtful one is flagged."""
    from ..export.engines import MODEL_NAMES
    from ..export.opentrackio import TrackingCamera as OtioCamera
    from ..export.opentrackio import track_samples, validate_sample, write_samples
    from ..lens.lens import Lens

    width_mm, height_mm = sensor_mm(args)
    rows = [(i, e) for i, e in enumerate(estimates) if e.camera is not None]
    if not rows:
        raise UsageError("no frame has a camera: no OpenTrackIO samples written")
    source = uuid.uuid4().urn
    samples = []
    for i, e in rows:
        otio = OtioCamera(size, width_mm, e.focal * width_mm, height_mm)
        sample = track_samples([Lens(e.lens.k1, e.lens.k2)], otio, model=MODEL_NAMES[args.distortion_model],
                               uncertainty_px=[math.nan], doubtful=[e.doubtful], source_id=source)[0]
        pan, tilt, roll = e.pan_tilt_roll
        x, y, z = (float(v) for v in e.position)
        # OpenTrackIO: Z up, Y forward at pan = tilt = roll = 0, pan counter-clockwise seen from above,
        # tilt up: glradial's pan (toward +x) and tilt (down) change sign
        sample["transforms"] = [{"translation": {"x": x, "y": y, "z": z},
                                 "rotation": {"pan": -pan, "tilt": -tilt, "roll": roll}, "id": "camera"}]
        sample["custom"]["glradial"].update({"frame": i, "calibration_uncertainty_px_1280": e.uncertainty_px,
                                             "calibration_reason": e.reason,
                                             **{k: extra[i][k] for k in ("shot", "lens_from") if k in extra[i]}})
        validate_sample(sample)
        samples.append(sample)
    if args.opentrackio:
        write_samples(args.opentrackio, samples, cbor=args.cbor)
    if args.send:
        from ..export.opentrackio import encode_sample
        from ..export.opentrackio_udp import ENCODING_CBOR, ENCODING_JSON, parse_address, send_payloads

        send_payloads((encode_sample(s, args.cbor) for s in samples), parse_address(args.send),
                      encoding=ENCODING_CBOR if args.cbor else ENCODING_JSON, rate=None)
