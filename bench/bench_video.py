"""Video throughput of ``glradial correct`` against FFmpeg transcoding the same clip, in one run.

Makes one clip in a temporary folder (``--size``, ``--frames`` at 25 fps, H.264 crf 18 + AAC tone):
``--clip pan`` (default) a broadcast camera panning across a real USL match frame
(the one shipped in the package, glradial/data/usl_broadcast_0195.jpg, or ``--frame``) through a constant lens (k1 -0.2, k2 0.03), the
common case; ``--clip zoom`` the same frame zooming in (hfov -25 %) while the lens goes from
k1 -0.30 to -0.18, so the shot's lens, and the maps, change on every frame; ``--clip cuts`` what users
bring, several shots cut together (:data:`CUT_SHOTS`, 6 s each; ``--frames 750``: 30 s, five shots). Then it times, each ``--repeats`` times taking turns (so that load
from other processes on a shared machine falls on all alike; the order reversed every other round), keeping the best run of each
and every round's time (the target ratios are also given round by round, :func:`per_round`: their median and range):

* ``ffmpeg``       the ffmpeg command transcoding the clip with the same codec settings and no
                   filter (``-c:v libx264 -crf C -preset P -c:a copy``)
* ``pyav``         the same transcode in this process through PyAV (decode + encode, no RGB)
* ``fixed lens``   :func:`glradial.video.video_pipeline.correct_video` with one lens (k1 -0.25, k2 0.05)
* ``--auto``       pass 1 (:func:`~glradial.video.video_pipeline.track_video` with the bundled
                   estimator: the frames other frames refer to decoded, cuts on them, the shot
                   evidence on every 10th frame, one lens fit per shot) + pass 2 with the per-frame
                   lens (doubtful shots applied too, so both runs correct every frame)
* ``fixed, RGB``   the fixed lens forced through RGB (decode to RGB, correct, convert back), the
                   path pass 2 takes for anything but planar YUV (``correction_space``)
* ``pass 1, all``  pass 1 decoding every frame (``sparse=False``)
* ``pass 2``       pass 2 alone with the lens track of one earlier pass 1 (taking turns with the
                   fixed lens: what the per-frame lens costs against one lens)
* ``fixed, 1/32-px maps``  the fixed lens with the planes remapped from OpenCV's fixed-point maps
                   (``cpu_maps(..., float_maps=False)``, as before 2026-11-25's float maps)

and prints frames per second and the ratios the issue sets targets for: fixed lens / ffmpeg
(>= 0.8) and --auto / fixed lens (>= 0.8), in wall-clock time and in CPU time (every thread of
this process, and ffmpeg's: :func:`cpu_seconds`; on a shared machine the wall clock measures the
load, and where the cores are few pass 1's threads and pass 2's encoder share them). First it times the maps of a new lens at the clip's
size: ``Lens.maps`` (float32, OpenCV) against the float64 NumPy reference, and the CPU path's whole
``cpu_maps`` (maps + fixed-point conversion + source-less pixels; or float maps, the planar
YUV path's) of the frame and of a 4:2:0 chroma plane, each a new lens every call.

Run: ``python3 bench/bench_video.py [--size 1920x1080] [--frames 150] [--preset medium] [--crf 23]
[--backend auto] [--repeats 2] [--paths 'ffmpeg,fixed lens,--auto,pass 2']`` (``--paths``: only those, taking
turns faster, for a machine whose load changes; ``pass 2`` then checks it: the same work as the fixed lens).
"""

from __future__ import annotations

import argparse
import math
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import av
from figures import write_figure

from glradial.media.video_io import EncodeOptions
from glradial.video import video_pipeline
from glradial.video.video_pipeline import correct_video, default_estimator, track_video

K1, K2 = -0.25, 0.05


def bundled_frame_path() -> Path:
    """The real broadcast frame shipped in the package (the one ``glradial demo-real`` uses)."""
    from importlib import resources

    from glradial.commands.demo import FRAME_NAME

    return Path(str(resources.files("glradial.data").joinpath(FRAME_NAME)))


def make_clip(path: Path, size: tuple[int, int], frames: int, kind: str, source: Path) -> None:
    """Render the clip's frames (crop of the real frame, resized, distorted) into H.264, then mux
    a 440 Hz AAC tone with the ffmpeg command."""
    import cv2

    import glradial
    from glradial.media.image_io import read_image
    from glradial.media.video_io import VideoInfo, VideoWriter

    picture = read_image(source)
    height, width = picture.shape[:2]
    video = path.with_name("video_only.mp4")
    with VideoWriter(video, VideoInfo.of(size, 25, codec="libx264"), options=EncodeOptions(crf=18), overwrite=True) as writer:
        for i in range(frames):
            crop_w, x0, k1 = _view(kind, i, frames, width)
            crop_h = crop_w * size[1] // size[0]
            y0 = (height - crop_h) // 2
            frame = cv2.resize(picture[y0 : y0 + crop_h, x0 : x0 + crop_w], size, interpolation=cv2.INTER_CUBIC)
            writer.write(glradial.distort(frame, k1, 0.019 * k1 + 0.805 * k1 * k1, backend="cpu"))
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(video), "-f", "lavfi", "-i", "sine=frequency=440:sample_rate=48000",
                    "-c:v", "copy", "-c:a", "aac", "-shortest", str(path)], check=True)


#: ``--clip cuts``: frames per shot (6 s at 25 fps) and each shot's (kind, lens k1): a pan, a
#: zoom, a static shot, a pan back, a tighter static shot, then again
CUT_SHOT_FRAMES = 150
CUT_SHOTS = (("pan", -0.2), ("zoom", 0.0), ("static", -0.12), ("pan back", -0.28), ("static tight", -0.06))


def _view(kind: str, i: int, frames: int, width: int) -> tuple[int, int, float]:
    """Frame ``i``'s crop of the picture (width, left edge, px) and lens k1 for clip ``kind``."""
    k1 = -0.2  # the pan's lens
    if kind == "cuts":
        kind, k1 = CUT_SHOTS[(i // CUT_SHOT_FRAMES) % len(CUT_SHOTS)]
        frames, i = CUT_SHOT_FRAMES, i % CUT_SHOT_FRAMES
    t = i / max(frames - 1, 1)
    if kind in ("pan", "pan back"):
        crop_w = int(width * 0.8)
        return crop_w, int((t if kind == "pan" else 1.0 - t) * (width - crop_w)), k1
    if kind == "zoom":
        crop_w = int(width * (0.9 - 0.25 * t))
        return crop_w, (width - crop_w) // 2, -0.30 + 0.12 * t
    crop_w = int(width * (0.55 if kind == "static tight" else 0.85))
    return crop_w, (width - crop_w) // 3, k1


def pyav_transcode(source: Path, target: Path, crf: float, preset: str) -> None:
    with av.open(str(source)) as inp, av.open(str(target), "w") as out:
        vin = inp.streams.video[0]
        vin.thread_type = "AUTO"
        ain = inp.streams.audio[0]
        vout = out.add_stream("libx264", rate=vin.average_rate)
        vout.width, vout.height, vout.pix_fmt = vin.codec_context.width, vin.codec_context.height, "yuv420p"
        vout.time_base = vin.time_base
        vout.codec_context.time_base = vin.time_base
        vout.codec_context.options = {"crf": f"{crf:g}", "preset": preset}
        vout.codec_context.thread_type = "AUTO"  # frame threads, as the ffmpeg command and glradial's file outputs
        aout = out.add_stream_from_template(ain)
        for packet in inp.demux(vin, ain):
            if packet.stream is ain:
                if packet.dts is not None:
                    packet.stream = aout
                    out.mux(packet)
                continue
            for frame in packet.decode():
                frame.pict_type = av.video.frame.PictureType.NONE
                out.mux(vout.encode(frame))
        out.mux(vout.encode(None))


def map_times(size: tuple[int, int], calls: int = 20) -> dict[str, float]:
    """Median ms per call of each way to build the maps of a lens never seen before."""
    import numpy as np

    from glradial.lens.lens import Lens
    from glradial.remapping.planes import yuv_planes
    from glradial.remapping.remap import cpu_maps

    chroma = yuv_planes(size, (1, 1))[1]
    ways = {
        "Lens.maps (float32)": lambda lens: lens.maps(size),
        "Lens.maps (float64 reference)": lambda lens: lens.maps(size, dtype=np.float64),
        "cpu_maps (all of it)": lambda lens: cpu_maps(lens, size, "undistort", 1.0, "exact", False),
        "cpu_maps (4:2:0 chroma plane)": lambda lens: cpu_maps(lens, size, "undistort", 1.0, "exact", False, chroma),
        "cpu_maps float (all of it)": lambda lens: cpu_maps(lens, size, "undistort", 1.0, "exact", False, float_maps=True),
        "cpu_maps float (4:2:0 chroma)": lambda lens: cpu_maps(lens, size, "undistort", 1.0, "exact", False, chroma,
                                                               float_maps=True),
    }
    times: dict[str, list[float]] = {name: [] for name in ways}
    for i in range(calls):
        for name, build in ways.items():
            lens = Lens(K1 + 1e-7 * (i + 1) * (1 + len(times[name])), K2)
            start = time.perf_counter()
            build(lens)
            times[name].append(1e3 * (time.perf_counter() - start))
    return {name: float(np.median(values)) for name, values in times.items()}


def fixed_point_maps():
    """A context in which :func:`glradial.remapping.planes.remap_planes` remaps from OpenCV's
    fixed-point maps (1/32 px), as before the float maps."""
    import contextlib

    from glradial.remapping import planes

    @contextlib.contextmanager
    def forced():
        maps = planes.cpu_maps
        planes.cpu_maps = lambda *args, **kwargs: maps(*args, **{**kwargs, "float_maps": False})
        try:
            yield
        finally:
            planes.cpu_maps = maps

    return forced()


def stage_times(clip: Path, folder: Path, frames: int = 24) -> dict[str, float]:
    """Median ms per frame of pass 2's correction stage alone (no decoding, no encoding), the three
    ways taking turns frame by frame: RGB (convert to RGB, ``cv2.remap`` of 3 channels, convert back
    to the encoder's YUV), YUV (the planes remapped in place from float maps, no conversion) and
    YUV from fixed-point maps."""
    import numpy as np

    from glradial.lens.lens import Lens
    from glradial.media.video_io import VideoReader, VideoWriter, frame_planes, yuv_layout
    from glradial.remapping.planes import black, chroma_siting, remap_planes, yuv_planes
    from glradial.remapping.remap import correct

    lens = Lens(K1, K2)
    with VideoReader(clip, keep_decoded=True) as reader:
        info = reader.info
        decoded = [item.decoded for _, item in zip(range(frames), reader.items())]
    writer = VideoWriter(folder / "stage.mp4", info, overwrite=True)
    lattices = yuv_planes(info.size, yuv_layout(info.pix_fmt)[:2], chroma_siting(info.codec))
    fill = black(yuv_layout(info.pix_fmt)[2], writer.full_range)
    times: dict[str, list[float]] = {"RGB": [], "YUV": [], "YUV 1/32": []}
    try:
        for frame in decoded:
            start = time.perf_counter()
            writer.frame(correct(reader.convert(frame), lens, backend="cpu"), frame.pts)
            middle = time.perf_counter()
            target, planes = writer.planar_frame()
            remap_planes(frame_planes(frame), lens, lattices, planes, fill=fill)
            writer.stamp(target, frame.pts)
            end = time.perf_counter()
            with fixed_point_maps():
                target, planes = writer.planar_frame()
                remap_planes(frame_planes(frame), lens, lattices, planes, fill=fill)
                writer.stamp(target, frame.pts)
            times["RGB"].append(middle - start)
            times["YUV"].append(end - middle)
            times["YUV 1/32"].append(time.perf_counter() - end)
    finally:
        writer.abort()
    return {name: 1e3 * float(np.median(values[1:])) for name, values in times.items()}  # the first builds the maps


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", default="1920x1080")
    parser.add_argument("--clip", choices=("pan", "zoom", "cuts"), default="pan")
    parser.add_argument("--frame", type=Path, default=None,
                        help="picture the clip is made from (default: the frame shipped in glradial/data)")
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--preset", default="medium")
    parser.add_argument("--crf", type=float, default=23.0)
    parser.add_argument("--backend", default="auto", choices=("auto", "cpu", "gl"))
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--paths", default=None,
                        help="comma-separated paths to time (default all), e.g. 'ffmpeg,fixed lens,--auto,pass 2': "
                             "fewer paths take turns faster, so a changing load falls on them more alike")
    args = parser.parse_args(argv)
    if args.frame is None:
        args.frame = bundled_frame_path()
    return args


def timed_paths(args: argparse.Namespace, size: tuple[int, int], tmp: Path, clip: Path) -> tuple[dict, dict, dict, dict, dict]:
    """``(best, passes, stages, cpu, turns)``: the best time (s) of each path over ``args.repeats``
    rounds, the best times of ``--auto``'s two passes (s), the correction stage alone (ms/frame),
    the least CPU time (s, :func:`cpu_seconds`) of each path and pass, and every round's time (s)
    of each path (:func:`per_round`). Each round runs every path once, in the order given on even
    rounds and reversed on odd ones, so that neither of two neighbours always goes first."""
    options = EncodeOptions(codec="libx264", crf=args.crf, preset=args.preset)
    estimator = default_estimator()

    def ffmpeg() -> None:
        subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(clip), "-c:v", "libx264", "-crf", f"{args.crf:g}",
                        "-preset", args.preset, "-pix_fmt", "yuv420p", "-c:a", "copy", str(tmp / "ffmpeg.mp4")], check=True)

    def fixed() -> None:
        correct_video(clip, tmp / "fixed.mp4", lambda _i: (K1, K2), backend=args.backend, progress=False,
                      options=options, overwrite=True)

    def fixed_rgb() -> None:  # the same, forced through RGB (the path before pass 2 worked in YUV)
        space = video_pipeline.correction_space
        video_pipeline.correction_space = lambda *_args: ("rgb", "forced by the bench")
        try:
            fixed()
        finally:
            video_pipeline.correction_space = space

    passes: dict[str, float] = {"pass 1": float("inf"), "pass 2": float("inf")}
    passes_cpu: dict[str, float] = dict(passes)

    def auto() -> None:
        start, start_cpu = time.perf_counter(), cpu_seconds()
        # doubtful shots applied too: the correction pass does the same work as the fixed lens
        track = track_video(clip, estimator, progress=False, apply_doubtful=True)
        middle, middle_cpu = time.perf_counter(), cpu_seconds()
        correct_video(clip, tmp / "auto.mp4", track.lens_for, backend=args.backend, progress=False,
                      options=options, overwrite=True, frames_expected=track.n_frames)
        passes["pass 1"] = min(passes["pass 1"], middle - start)
        passes["pass 2"] = min(passes["pass 2"], time.perf_counter() - middle)
        passes_cpu["pass 1"] = min(passes_cpu["pass 1"], middle_cpu - start_cpu)
        passes_cpu["pass 2"] = min(passes_cpu["pass 2"], cpu_seconds() - middle_cpu)

    def fixed_32() -> None:  # the planes from fixed-point maps (as before the float maps)
        with fixed_point_maps():
            fixed()

    track = track_video(clip, estimator, progress=False, apply_doubtful=True)
    stages = stage_times(clip, tmp)
    paths = {"ffmpeg": ffmpeg, "pyav": lambda: pyav_transcode(clip, tmp / "pyav.mp4", args.crf, args.preset),
             "fixed lens": fixed, "--auto": auto, "fixed, RGB": fixed_rgb,
             # pass 1 decoding every frame (as before the sparse decode)
             "pass 1, all": lambda: track_video(clip, estimator, progress=False, apply_doubtful=True, sparse=False),
             # pass 2 alone, the per-frame lens of one earlier pass 1
             "pass 2": lambda: correct_video(clip, tmp / "pass2.mp4", track.lens_for, backend=args.backend, progress=False,
                                             options=options, overwrite=True, frames_expected=track.n_frames),
             "fixed, 1/32-px maps": fixed_32}
    if args.paths:
        wanted = [name.strip() for name in args.paths.split(",")]
        unknown = sorted(set(wanted) - set(paths))
        if unknown:
            raise SystemExit(f"--paths: unknown {unknown}; choose from {sorted(paths)}")
        paths = {name: run for name, run in paths.items() if name in wanted}
    best = {name: float("inf") for name in paths}
    cpu = dict(best)
    turns: dict[str, list[float]] = {name: [] for name in paths}
    for round_ in range(args.repeats):
        for name, run in list(paths.items())[:: 1 if round_ % 2 == 0 else -1]:
            start, start_cpu = time.perf_counter(), cpu_seconds()
            run()
            turns[name].append(time.perf_counter() - start)
            best[name] = min(best[name], turns[name][-1])
            cpu[name] = min(cpu[name], cpu_seconds() - start_cpu)
    return best, passes, stages, {**cpu, **passes_cpu}, turns


#: the ratios the issue sets targets for (>= 0.8), as (path, peer): the peer's time over the path's
TARGETS = {"fixed / ffmpeg": ("fixed lens", "ffmpeg"), "--auto / fixed": ("--auto", "fixed lens")}


def per_round(turns: dict[str, list[float]]) -> dict[str, list[float]]:
    """Each target ratio (:data:`TARGETS`) round by round: the two paths' times of one round, run
    next to each other (the best-of ratios compare each path's best round, which a machine whose
    speed drifts may give to the two at different speeds)."""
    return {name: [t_peer / t_path for t_path, t_peer in zip(turns[path], turns[peer])]
            for name, (path, peer) in TARGETS.items() if path in turns and peer in turns}


def cpu_seconds() -> float:
    """CPU time (s, user + system, every thread) of this process and of its waited-for children
    (the ffmpeg command): the measure of work that a shared machine's load does not inflate much."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def report(args: argparse.Namespace, best: dict, passes: dict, stages: dict, cpu: dict, turns: dict) -> dict:
    """Print the figures and return them (frames/s, ms/frame and the ratios the targets name, in
    wall-clock time and in CPU time: ``cpu`` (s) per path and pass, :func:`cpu_seconds`; and the
    target ratios round by round, :func:`per_round` of ``turns``: their median and range)."""
    fps = {name: args.frames / seconds for name, seconds in best.items()}
    ms = {name: 1e3 * seconds / args.frames for name, seconds in {**best, **passes}.items()}
    pairs = {**TARGETS, "fixed / pyav": ("fixed lens", "pyav"), "fixed RGB / ffmpeg": ("fixed, RGB", "ffmpeg"),
             "fixed YUV / fixed RGB": ("fixed lens", "fixed, RGB")}
    times = {"fixed / fixed 1/32-px maps (time)": ("fixed lens", "fixed, 1/32-px maps"),
             "pass 2 / fixed (time)": ("pass 2", "fixed lens")}
    ratios = {name: fps[a] / fps[b] for name, (a, b) in pairs.items() if a in fps and b in fps}
    ratios.update({name: best[a] / best[b] for name, (a, b) in times.items() if a in best and b in best})
    if "pass 1, all" in best:
        ratios["pass 1 sparse / all (time)"] = passes["pass 1"] / best["pass 1, all"]
    cpu_ms = {name: 1e3 * seconds / args.frames for name, seconds in cpu.items()}
    ratios.update({f"{name} (CPU)": cpu[b] / cpu[a] for name, (a, b) in pairs.items() if a in cpu and b in cpu})
    print(f"clip: {args.clip} over {args.frame.name}, {args.size}, {args.frames} frames, H.264 + AAC; encoder libx264 crf {args.crf:g} preset {args.preset}; "
          f"backend {args.backend}; {os.cpu_count()} CPU cores; best of {args.repeats}; load average {os.getloadavg()[0]:.1f}")
    for name, value in fps.items():
        print(f"  {name:19s} {value:6.1f} frames/s")
    print(f"  --auto pass 1 (decode, cuts, shot evidence and fit) {ms['pass 1']:.1f} ms/frame, pass 2 (correct + encode) "
          f"{ms['pass 2']:.1f} ms/frame; fixed lens {ms.get('fixed lens', math.nan):.1f} ms/frame")
    print("  CPU ms/frame (every thread, ffmpeg's process too): "
          + ", ".join(f"{name} {value:.1f}" for name, value in cpu_ms.items()))
    print(f"  pass 2 correction stage alone (taking turns per frame): RGB {stages['RGB']:.1f} ms/frame, "
          f"YUV {stages['YUV']:.1f} ms/frame, YUV from 1/32-px maps {stages['YUV 1/32']:.1f} ms/frame")
    rounds = per_round(turns)
    ratios.update({f"{name} (median of rounds)": statistics.median(values) for name, values in rounds.items()})
    for name, value in ratios.items():
        pair, _, kind = name.partition(" (")
        spread = f", rounds {min(rounds[pair]):.2f}-{max(rounds[pair]):.2f}" if kind == "median of rounds)" else ""
        target = f"  (target >= 0.8{spread})" if pair in TARGETS else ""
        print(f"{name:34s}: {value:.2f}{target}")
    return {"per_round_ratios": rounds, "fps": fps, "ms_per_frame": ms, "cpu_ms_per_frame": cpu_ms, "correction_stage_ms_per_frame": stages, "ratios": ratios,
            "clip": args.clip, "size": args.size, "frames": args.frames, "preset": args.preset, "crf": args.crf,
            "backend": args.backend, "repeats": args.repeats, "paths": list(best),
            "load_average_1_5_15": [round(v, 1) for v in os.getloadavg()]}


def main() -> int:
    args = parse_args()
    if shutil.which("ffmpeg") is None:
        sys.exit("bench_video needs the ffmpeg command (make setup installs it)")
    size = tuple(int(v) for v in args.size.split("x"))
    maps = map_times(size)
    for name, ms in maps.items():
        print(f"new-lens maps at {args.size}: {name:30s} {ms:6.1f} ms")
    with tempfile.TemporaryDirectory() as folder:
        clip = Path(folder) / "clip.mp4"
        make_clip(clip, size, args.frames, args.clip, args.frame)
        best, passes, stages, cpu, turns = timed_paths(args, size, Path(folder), clip)
    results = report(args, best, passes, stages, cpu, turns)
    write_figure(f"bench_video_{args.clip}_{args.size}", {**results, "new_lens_maps_ms": maps})
    return 0

if __name__ == "__main__":
    sys.exit(main())
