"""``glradial live``: correct a live stream causally and send the lens to a graphics engine every frame."""

from __future__ import annotations

import argparse
import signal
import sys
from pathlib import Path

from ..lens.options import METHODS, UNTIL_SURE
from . import MODEL_HELP, UsageError, lens_from_args, lens_given, positive_float, positive_int
from .engine_options import add_opentrackio_options, camera_from_args, check_opentrackio_output, opentrackio_wanted
from .remapping import (
    add_encode_options,
    add_render_options,
    add_shot_lens_options,
    check_encode_options,
    refuse_same_file,
    reject_for,
    same_file,
)

DESCRIPTION = """\
Correct a live stream as it arrives and hand the lens to a graphics engine with every frame.
INPUT: a network stream FFmpeg reads (udp://, rtp://, srt:// (the system's ffmpeg relays it where
PyAV's lacks it; ?mode=listener waits for a caller), tcp://, rtsp://), ndi://NAME (the NDI source
whose name holds NAME; pip install 'glradial[ndi]'),
'-' for standard input (MPEG-TS or NUT), a V4L2 device (/dev/video0) or a file (--realtime plays it
at its own frame rate). OUTPUT: a file (it appears, complete and playable, when the stream ends: also
on Ctrl-C/SIGTERM or an input error midway), '-' for MPEG-TS on standard output, udp://HOST:PORT or
srt://HOST:PORT (MPEG-TS), ndi://NAME (an NDI source), or none (--camera only). The run ends at the input's EOF, after --idle-timeout seconds without data from a network
input, or on SIGINT/SIGTERM.

Causal: every frame is corrected with what is known when it arrives and leaves within --max-delay
frames; when the input outruns the correction, frames are dropped (never the delay let grow) and
counted, and frames that leave later than --max-delay are counted as late; the counts, the output
rate and the delay's percentiles are shown on a status line (stderr; -q hides it) and reported at
the end. The lens is given (--k1/--k2 width-normalised, or --lens FILE) or --auto: cuts detected
on the fly, each shot's lens fitted from its frames so far (line chains, frame-to-frame motion,
the bundled estimator on sampled frames) and refined as the shot goes on; a shot not yet sure
passes through uncorrected, flagged doubtful (--until-sure last keeps the last sure lens instead;
--apply-doubtful applies a doubtful shot's own lens). With --send HOST:PORT each frame's
OpenTrackIO sample (lens distortion, the input's timecode and timestamp, custom.glradial k1, k2,
uncertainty, doubt) goes out as UDP packets as soon as the frame is out; --opentrackio FILE keeps
them. H.264/HEVC output defaults to the ultrafast preset (a live encoder must keep up).

--camera: the whole camera of every frame, tracked from the pitch markings (a fit of the newest
frame whenever the last is done, carried frame to frame by the image motion: docs/CLI.md, "live
--camera"), sent as OpenTrackIO samples with the transform (pitch metres, pan/tilt/roll), the
measured focal length (give --sensor or --sensor-width-mm), the lens and the timecode; a frame
without a sure camera is flagged doubtful with a reason; custom.glradial holds the frame's fields
as 'calibrate --json' writes them. OUTPUT 'none': no video out, only the samples (no lens options)."""

#: OUTPUT that writes no video (``--camera``: the samples only)
NO_OUTPUT = "none"
#: options only --auto takes
AUTO_OPTIONS = ("model", "method", "every", "max_uncertainty", "apply_doubtful", "until_sure")
#: encoders whose presets take ``ultrafast`` (the default preset of a live run)
FAST_PRESET_CODECS = ("h264", "libx264", "hevc", "libx265")


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from . import add_lens_options

    parser = subparsers.add_parser("live", help="correct a live stream causally, send the lens per frame (OpenTrackIO)",
                                   description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("input", metavar="INPUT", help="udp://HOST:PORT, rtp://, srt://, '-' (stdin: MPEG-TS or NUT), /dev/videoN or a file")
    parser.add_argument("output", metavar="OUTPUT", help="a file (its extension picks the format), '-' (MPEG-TS on stdout) or udp://HOST:PORT")
    parser.add_argument("-y", "--overwrite", action="store_true", help="replace OUTPUT (and --opentrackio FILE) if it exists")
    lens = parser.add_argument_group("lens (give --k1 [--k2 --cx --cy --pixel-aspect], --lens FILE or --auto)")
    add_lens_options(lens)
    lens.add_argument("--auto", action="store_true", help="estimate each shot's lens from its frames so far")
    lens.add_argument("--model", metavar="ONNX", help=f"with --auto: {MODEL_HELP}")
    lens.add_argument("--method", choices=METHODS, help="with --auto: the per-frame estimator's method (default auto)")
    live = parser.add_argument_group("live")
    live.add_argument("--max-delay", type=positive_int, default=2, metavar="FRAMES",
                      help="a frame leaves within this many frame periods of its arrival, or is dropped (default 2)")
    live.add_argument("--idle-timeout", type=positive_float, default=5.0, metavar="S",
                      help="a network input ends after this many seconds without data (default 5)")
    live.add_argument("--realtime", action="store_true", help="hand out the frames of a file (or stdin) INPUT at their own rate (timestamps), as a live source would")
    live.add_argument("--camera", action="store_true",
                      help="track the whole camera from the pitch and send it per frame (OpenTrackIO: transform, focal length, lens)")
    auto = parser.add_argument_group("with --auto")
    add_shot_lens_options(auto)
    auto.add_argument("--until-sure", choices=UNTIL_SURE, default=None,
                      help="a shot not (yet) sure passes through (pass, default) or keeps the last sure lens (last); flagged doubtful either way")
    add_render_options(parser, "output scale: same = centre scale kept (as cv2.undistort), crop = zoom in until every "
                       "output pixel has a source, full = zoom out until the whole input is visible (default: same)")
    add_encode_options(parser)
    add_opentrackio_options(parser)
    return parser


def _check_options(args: argparse.Namespace) -> None:
    """The options fit together (before the input is opened)."""
    given = lens_given(args)
    _check_camera(args, given)
    if args.output == NO_OUTPUT:
        return
    if given and args.auto:
        raise UsageError("--k1/--k2/--cx/--cy/--pixel-aspect/--lens and --auto cannot be combined: give the lens one way")
    if not given and not args.auto:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE, or --auto to estimate it")
    for name in AUTO_OPTIONS:
        if getattr(args, name) is not None and not args.auto:
            raise UsageError(f"--{name.replace('_', '-')} needs --auto")
    reject_for(args, ("rate", "field_order"), "files ('glradial correct'); a live stream keeps its own rate and fields")
    if args.alpha != "auto":
        raise UsageError("--alpha is for files ('glradial correct')")
    check_encode_options(args)
    check_opentrackio_output(args, focal_measured=args.camera)
    _check_ends(args)


def _check_camera(args: argparse.Namespace, lens_given_: bool) -> None:
    """``--camera`` and OUTPUT ``none``: what they need and refuse."""
    if args.camera:
        from .engine_options import sensor_mm

        if not opentrackio_wanted(args):
            raise UsageError("--camera sends the camera as OpenTrackIO samples: give --send HOST:PORT or --opentrackio FILE")
        if args.focal_mm is not None:
            raise UsageError("--camera measures the focal length: --focal-mm is not used")
        if sensor_mm(args)[0] is None:
            raise UsageError("--camera: give --sensor-width-mm MM (or --sensor 2/3-inch) for the focal length in mm")
    if args.output != NO_OUTPUT:
        return
    if not args.camera:
        raise UsageError("OUTPUT 'none' writes no video: it is for --camera (the samples only)")
    if lens_given_ or args.auto or any(getattr(args, n) is not None for n in AUTO_OPTIONS):
        raise UsageError("OUTPUT 'none': nothing is corrected, give no lens (--k1/--k2/--lens/--auto and their options)")
    check_opentrackio_output(args, focal_measured=True)
    _check_ends(args)


def _check_ends(args: argparse.Namespace) -> None:
    """INPUT and OUTPUT before anything waits for the input: a kind of input glradial reads, an
    input file that exists, an output URL it writes, an output file that may be written and is not INPUT."""
    from ..media.stream_io import check_live_output, source_kind

    if source_kind(args.input) == "file" and not Path(args.input).is_file():
        raise FileNotFoundError(f"input {args.input!r} does not exist (live inputs: '-', a URL, a V4L2 device or a file)")
    if args.output != NO_OUTPUT and check_live_output(args.output) == "file":
        from ..media.atomic import check_output_folder
        from ..media.video_io import check_video_overwrite

        check_video_overwrite(check_output_folder(args.output), args.overwrite)
        if source_kind(args.input) == "file" and same_file(Path(args.input), Path(args.output)):
            raise UsageError(f"OUTPUT {args.output!r} is INPUT: write the corrected stream elsewhere")
    if args.opentrackio:
        refuse_same_file(args.opentrackio, "--opentrackio", *[p for p in (args.input, args.output) if p != "-" and "://" not in p])


def _encode_options(args: argparse.Namespace, info, default_preset: bool):
    from ..media.video_io import EncodeOptions

    codec = args.codec or info.codec
    preset = args.preset or ("ultrafast" if default_preset and codec in FAST_PRESET_CODECS and args.crf is None else None)
    return EncodeOptions(codec=args.codec, crf=args.crf, bitrate=args.bitrate, preset=preset, pix_fmt=args.pix_fmt)


def _open_output(args: argparse.Namespace, info):
    """The writer of OUTPUT: the live preset first; without it where the container's codec has none."""
    from ..media.stream_io import open_live_output

    try:
        return open_live_output(args.output, info, options=_encode_options(args, info, True), overwrite=args.overwrite)
    except ValueError as err:
        if args.preset is not None or "preset" not in str(err):
            raise
    return open_live_output(args.output, info, options=_encode_options(args, info, False), overwrite=args.overwrite)


def _online_lens(args: argparse.Namespace):
    """``--auto``'s online lens, its worker started and its estimator loaded before the input is
    opened (the model's session and the first call's set-up would otherwise hold up the first shot)."""
    from ..video.live_lens import BundledEstimator, OnlineShotLens

    auto = {name: getattr(args, name) for name in ("every", "apply_doubtful", "until_sure") if getattr(args, name) is not None}
    if args.max_uncertainty is not None:
        auto["doubtful_px"] = args.max_uncertainty
    return OnlineShotLens.started(BundledEstimator(args.model, args.method), **auto)


def _corrector(args: argparse.Namespace, info, writer, camera, online=None, tracker=None):
    from ..export.engines import MODEL_NAMES
    from ..video.live import LiveCorrector

    lens = online if online is not None else None if writer is None else lens_from_args(args, info.size)
    backend = "cpu" if lens is None else args.backend  # nothing is drawn: no GL context to make for "auto"
    return LiveCorrector(lens, info.size, info.rate, max_delay=args.max_delay, camera=camera,
                         model=MODEL_NAMES[args.distortion_model], fit=args.fit, interpolation=args.interpolation,
                         backend=backend, codec=info.codec, frames=writer, tracker=tracker)


def _warm_imports(args: argparse.Namespace) -> None:
    """What the set-up after the first frame would otherwise import or build while the stream's
    frames pile up behind it (measured: 0.5 s, 13 frames of a 25p stream lost at the start): the
    corrector, the stream loop, the encoders' module, the remapping modules and ``--backend auto``'s
    choice (an EGL context made and read: 0.2-0.4 s, 10-20 frames of a 50p stream dropped at the
    start when it was made after the input opened) and, with samples, the OpenTrackIO schema's
    validator."""
    from ..media import video_io  # noqa: F401
    from ..remapping import planes  # noqa: F401
    from ..remapping.remap import auto_backend
    from ..video import live, live_stream  # noqa: F401

    if args.backend == "auto" and args.output != NO_OUTPUT:
        auto_backend()  # cached for this process: the corrector reads it

    if opentrackio_wanted(args):
        from ..export.opentrackio import validate_sample

        try:
            validate_sample({})
        except ValueError:
            pass


def _warm_tracker(args: argparse.Namespace):
    """``--camera``'s tracker, its worker started and warmed up before the input is opened (the
    stream is given to it once open: :meth:`~glradial.tracking.live_camera.LiveCameraTracker.for_stream`)."""
    if not args.camera:
        return None
    from ..tracking.live_camera import camera_tracker

    return camera_tracker()


def _start_tracking(warm, source):
    """The warmed tracker given the stream, its first fit started on the first decoded frame at once
    (before the outputs are set up and the frames flow); None without ``--camera``."""
    if warm is None:
        return None
    tracker = warm.for_stream(source.info.size, source.info.rate)
    tracker.start_on(source.first_frame, 0.0)  # frame 0 on the corrector's clock (number / rate)
    return tracker


def _sample_camera(args: argparse.Namespace, info):
    """The sensor, rate and timecode of the samples; with ``--camera`` the focal length is measured
    per frame (the 1 mm here is replaced in every sample that has a camera)."""
    if not args.camera:
        return camera_from_args(args, info.size, info.rate, info.timecode)
    from ..export.opentrackio import TrackingCamera
    from .engine_options import sensor_mm

    width_mm, height_mm = sensor_mm(args)
    return TrackingCamera(info.size, width_mm, 1.0, height_mm, rate=info.rate, timecode=info.timecode)


def _status_printer(quiet: bool):
    """The status line's sink: stderr, rewritten in place on a terminal; None with -q."""
    if quiet:
        return None
    tty = sys.stderr.isatty()
    return lambda line: sys.stderr.write(("\r" + line + "\033[K") if tty else f"glradial live: {line}\n")


def run(args: argparse.Namespace) -> int:
    """SIGINT/SIGTERM/SIGHUP end the stream (the CLI makes SIGINT stop it even when inherited ignored), its outputs closed playable."""
    from ..video.live_stream import run_live

    _check_options(args)
    opened: list = []  # what to close if the set-up fails: (object, how)
    try:
        online = _online_lens(args) if args.auto else None
        opened.append((online, "close"))
        warm = _warm_tracker(args)  # the camera search warmed up before the input is opened
        opened.append((warm, "close"))
        _warm_imports(args)
        source = _open_source(args)
        opened.append((source, "close"))
        info = source.info
        tracker = _start_tracking(warm, source)
        camera = _sample_camera(args, info) if opentrackio_wanted(args) else None
        writer = None if args.output == NO_OUTPUT else _open_output(args, info)
        opened.append((writer, "abort"))
        corrector = _corrector(args, info, writer, camera, online, tracker)
        opened.append((corrector, "close"))
        corrector.warm_up(source.first_frame)
        sender, samples = _sample_outputs(args)
    except BaseException:
        for thing, how in reversed(opened):
            if thing is not None:
                getattr(thing, how)()
        raise
    return _stream(args, source, writer, corrector, sender, samples, run_live)


def _open_source(args: argparse.Namespace):
    from ..media.stream_io import open_live_source

    if not getattr(args, "quiet", False):  # the set-up is done: a sender may start now
        wait = f" (up to {args.idle_timeout:g} s)" if "://" in args.input else ""
        sys.stderr.write(f"glradial live: waiting for {'stdin' if args.input == '-' else args.input}{wait}\n")
        sys.stderr.flush()
    return open_live_source(args.input, idle_timeout=args.idle_timeout, realtime=args.realtime)


def _sample_outputs(args: argparse.Namespace):
    """The UDP sender of ``--send`` and the file of ``--opentrackio`` (None where not asked for)."""
    from ..video.live_stream import SampleFile

    sender = None
    if args.send:
        from ..export.opentrackio_udp import ENCODING_CBOR, ENCODING_JSON, SampleSender, parse_address

        sender = SampleSender(parse_address(args.send), ENCODING_CBOR if args.cbor else ENCODING_JSON)
    try:
        return sender, SampleFile(args.opentrackio, args.cbor) if args.opentrackio else None
    except BaseException:
        if sender is not None:
            sender.close()
        raise


def _stream(args, source, writer, corrector, sender, samples, run_live) -> int:
    """Run the stream, then close every output playable, whatever ended it; report the counts."""
    failure, ended = None, "eof"
    status = _status_printer(getattr(args, "quiet", False))
    try:
        ended = run_live(source, writer, corrector, sender=sender, samples=samples, cbor=args.cbor, status=status)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM/SIGHUP (the CLI raises them as this)
        ended = signal.Signals(stop.signum).name if hasattr(stop, "signum") else "SIGINT"
    except Exception as err:  # the input broke off midway, an encoder or network error: close what was written
        failure, ended = err, "error"
    finally:
        corrector.close()
        if sender is not None:
            sender.close()
    stats = corrector.stats
    written = _close_outputs(writer, samples, stats)
    if status is not None and sys.stderr.isatty():
        sys.stderr.write("\n")
    _report(args, ended, stats, written, source.frames_read, sender, samples)
    if failure is not None:
        raise failure
    if written == 0:
        raise ValueError(f"live input {args.input!r}: no frame was written ({ended})")
    return 0


def _close_outputs(writer, samples, stats) -> int:
    """Close the video (None: OUTPUT none) and the samples file complete, or abort both when no frame
    went out; returns the frames out."""
    written = stats.left if writer is None else writer.frames_written
    if written == 0:
        if writer is not None:
            writer.abort()
        if samples is not None:
            samples.abort()
        return 0
    try:
        if writer is not None:
            writer.close()
    except BaseException:
        if samples is not None:
            samples.abort()
        raise
    if samples is not None:
        samples.close()
    return written


def _report(args, ended: str, stats, written: int, read: int, sender, samples) -> None:
    """The closing lines (stderr, also with -q: a short output is never silent)."""
    why = {"eof": "end of input", "idle": f"no data for {args.idle_timeout:g} s", "error": "input error"}.get(ended, ended)
    target = {"-": "stdout", NO_OUTPUT: "no video (OUTPUT none)"}.get(args.output, args.output)
    lines = [f"glradial live: {why}: {read} frames read, {written} written to {target}, dropped {stats.dropped}, "
             f"late {stats.late} (over {stats.max_delay} frames); delay p50 {stats.delay_percentile(50):.2f} "
             f"p95 {stats.delay_percentile(95):.2f} max {max(stats.delays, default=float('nan')):.2f} frames"]
    if stats.dropped:
        lines.append(f"glradial live: dropped frames (numbers from the first): {stats.dropped_ranges()}")
    if sender is not None:
        lines.append(f"glradial live: sent {sender.sent} OpenTrackIO sample(s) in {sender.datagrams} UDP packet(s) to {args.send}")
    if samples is not None and written:
        lines.append(f"glradial live: wrote {samples.path}: {samples.count} OpenTrackIO sample(s)")
    sys.stderr.write("\n".join(lines) + "\n")
    sys.stderr.flush()
