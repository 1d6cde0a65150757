"""``glradial live`` in real time on this machine: frames written, delay, samples, picture, lens.

Content: the real broadcast frame shipped in the package (glradial/data/usl_broadcast_0195.jpg)
with its own lens removed (``correct(fit="crop")``, as ``glradial demo`` does), panned slowly (8 %
of its width over the clip) and zoomed slightly (crop 92 % -> 84 % of its width), then a known lens
(``--k1 --k2``, default -0.2, 0.03) applied (``distort(fit="crop")``: every pixel has a source; the
lens in the frame's own width-normalised coordinates is exactly the one applied); H.264 (x264
veryfast, crf 18, a key frame every second) in MPEG-TS. Clips are cached in ``--work``.

Runs (each reported with the command it is):

1. **fixed lens over UDP in real time**, ``--rate`` (default 50) fps: ``ffmpeg -re -i clip.ts -c copy
   -f mpegts udp://127.0.0.1:P`` into ``glradial live udp://127.0.0.1:P out.ts --k1 K1 --k2 K2 --send
   127.0.0.1:Q ...``; a socket on Q receives the samples. Figures: frames written / frames sent,
   samples received / frames written, the delay from a frame's arrival (decoded) to its leaving
   (encoded, its sample sent) at p50/p95/max in frame periods (glradial's own report), and the
   PSNR (RGB, dB) of every 10th output frame against OpenCV's undistortion of the same input frame
   (``cv2.undistort`` with fx = fy = W and the principal point at the centre of the pixel grid:
   the width-normalised lens in OpenCV's terms, an independent correction).
2. **capacity** (flat out, in this process): the same clip from the file as fast as it decodes
   through the same reader/corrector/writer threads (:func:`glradial.video.live_stream.run_live`);
   frames corrected and encoded per second, and that over the stream rate (>= 1: real time).
3. **--auto through stdin in real time**, ``--auto-rate`` (default 25) fps: ``ffmpeg -re ... -f
   mpegts - | glradial live - out.ts --auto --opentrackio samples.jsonl``. Figures: frames written,
   delay percentiles, and the samples' lens against the applied one after the first second: the
   maximum displacement (px at 1920 wide, :func:`glradial.lens.metrics.max_displacement_px`),
   median, p95 and the share within 8 px; plus the share of frames the lens was applied to (not
   doubtful).

Run: ``python bench/bench_live.py [--size 1280x720] [--seconds 10] [--rate 50] [--auto-rate 25]
[--repeat 4] [--skip fixed,capacity,auto]``; the fixed-lens run alone, four times:
``python bench/bench_live.py --skip capacity,auto`` (docs/figures/live_start.json).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import av
import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from figures import write_figure  # noqa: E402

from glradial.commands import parse_size  # noqa: E402


def make_clip(path: Path, size: tuple[int, int], rate: int, seconds: float, k1: float, k2: float) -> Path:
    """The content (module docstring), cached at ``path``."""
    if path.is_file():
        return path
    from importlib import resources

    import glradial
    from glradial.lens.lens import Lens
    from glradial.media.image_io import read_image
    from glradial.media.video_io import EncodeOptions, VideoInfo, VideoWriter

    data = resources.files("glradial.data")
    own = json.loads(data.joinpath("usl_broadcast_0195.json").read_text())["own_lens"]
    flat = glradial.correct(read_image(Path(str(data.joinpath("usl_broadcast_0195.jpg"))), order="rgb"),
                            Lens(own["k1"], own["k2"]), fit="crop", backend="cpu")
    height, width = flat.shape[:2]
    lens = Lens(k1, k2)
    scale = lens.fit_scale(size, "crop", "distort")
    frames = int(round(seconds * rate))
    info = VideoInfo.of(size, rate, codec="libx264")
    made = path.with_name("made_" + path.name)
    with VideoWriter(made, info, options=EncodeOptions(crf=18, preset="veryfast"), overwrite=True) as writer:
        for i in range(frames):
            t = i / max(frames - 1, 1)
            crop_w = int(width * (0.92 - 0.08 * t))
            crop_h = crop_w * size[1] // size[0]
            x0 = int((width - crop_w) * (0.3 + 0.5 * t)) if crop_w < width else 0
            y0 = (height - crop_h) // 2
            view = cv2.resize(flat[y0:y0 + crop_h, x0:x0 + crop_w], size, interpolation=cv2.INTER_AREA)
            writer.write(glradial.distort(view, lens, fit=scale, backend="cpu"))
    # remuxed once by ffmpeg as its sender will: its timestamps then stay those of the file (ffmpeg
    # shifts a stream that starts at 0), so output frames are matched to input frames by pts
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(made), "-c", "copy", "-f", "mpegts", str(path)], check=True)
    made.unlink()
    return path


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _report(stderr: str) -> dict:
    """glradial live's closing line: frames read/written, dropped, late, delay p50/p95/max."""
    line = next(line for line in stderr.splitlines() if "frames read" in line)
    words = line.replace(",", "").replace(";", "").split()
    pick = lambda key, after=1: float(words[words.index(key) + after])  # noqa: E731
    where = next((line.split(": ")[-1] for line in stderr.splitlines() if "dropped frames (numbers" in line), "")
    return {"read": int(words[words.index("frames") - 1]), "written": int(words[words.index("written") - 1]),
            "dropped": int(pick("dropped")), "late": int(pick("late")), "p50": pick("p50"), "p95": pick("p95"),
            "max": pick("max", 1), "dropped_at": where}


def _live(args: list[str], **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "glradial", "live", *args], cwd=ROOT, env=env, stderr=subprocess.PIPE,
                            text=True, **kwargs)


def _opencv_undistort(image: np.ndarray, k1: float, k2: float) -> np.ndarray:
    height, width = image.shape[:2]
    camera = np.array([[width, 0, (width - 1) / 2], [0, width, (height - 1) / 2], [0, 0, 1]], np.float64)
    return cv2.undistort(image, camera, np.array([k1, k2, 0, 0, 0], np.float64))


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    error = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0**2 / max(error, 1e-12)))


def picture_psnr(clip: Path, out: Path, k1: float, k2: float, every: int = 10) -> list[float]:
    """PSNR (RGB) of every ``every``-th output frame against cv2.undistort of the input frame with its pts."""
    with av.open(str(out)) as container:
        wanted = {f.pts: f.to_ndarray(format="rgb24") for i, f in enumerate(container.decode(video=0)) if i % every == 0}
    values = []
    with av.open(str(clip)) as container:
        for frame in container.decode(video=0):
            if frame.pts in wanted:
                values.append(_psnr(wanted[frame.pts], _opencv_undistort(frame.to_ndarray(format="rgb24"), k1, k2)))
    return values


def udp_receive_errors() -> int:
    """The machine's UDP datagrams lost so far for want of room in a receive buffer (``RcvbufErrors``
    of /proc/net/snmp; -1 where it cannot be read): packets of the stream lost at the socket."""
    try:
        rows = [line.split() for line in Path("/proc/net/snmp").read_text().splitlines() if line.startswith("Udp:")]
        return int(rows[1][rows[0].index("RcvbufErrors")])
    except (OSError, ValueError, IndexError):
        return -1


def load_now() -> dict:
    """The machine's load as a run starts: the 1-, 5- and 15-minute load averages (``uptime``'s)."""
    one, five, fifteen = os.getloadavg()
    return {"load_1min": one, "uptime_load": f"{one:.2f}, {five:.2f}, {fifteen:.2f}"}


def stream_over_udp(clip: Path, arguments) -> tuple[str, list[bytes], dict]:
    """``clip`` sent over UDP in real time (``ffmpeg -re``) to ``glradial live`` run with
    ``arguments(video_port, sample_port)``, its OpenTrackIO packets received on ``sample_port``:
    ``(its stderr, the packets, conditions)``, conditions being the load as sending starts
    (:func:`load_now`) and ``udp_receive_errors``, the datagrams the machine lost at full receive
    buffers meanwhile (:func:`udp_receive_errors`: the video's, or another program's); RuntimeError
    when glradial fails."""
    from glradial.export.opentrackio_udp import SampleReceiver

    video_port = _free_port()
    with SampleReceiver() as receiver:
        command = arguments(video_port, receiver.address[1])
        print("  glradial live " + " ".join(command), flush=True)
        process = _live(command)
        lines: list[str] = []
        reader = threading.Thread(target=lambda: lines.extend(iter(process.stderr.readline, "")), daemon=True)
        reader.start()
        while not any("waiting for" in line for line in lines):
            if process.poll() is not None:
                raise RuntimeError("".join(lines))
            time.sleep(0.05)
        time.sleep(1.0)  # av.open binds the socket just after the line
        conditions, lost = load_now(), udp_receive_errors()
        subprocess.run(["ffmpeg", "-v", "error", "-re", "-i", str(clip), "-c", "copy", "-f", "mpegts",
                        f"udp://127.0.0.1:{video_port}?pkt_size=1316"], check=True)
        process.wait(timeout=120)
        reader.join(timeout=5)
        time.sleep(0.3)
    conditions["udp_receive_errors"] = udp_receive_errors() - lost if lost >= 0 else -1
    stderr = "".join(lines)
    if process.returncode != 0:
        raise RuntimeError(stderr)
    return stderr, receiver.datagrams, conditions


def run_fixed_udp(clip: Path, work: Path, k1: float, k2: float, frames: int) -> dict:
    out = work / f"fixed_{clip.stem}.ts"
    stderr, received, conditions = stream_over_udp(clip, lambda video_port, sample_port: [
        f"udp://127.0.0.1:{video_port}", str(out), "-y", "--k1", str(k1), "--k2", str(k2), "--idle-timeout", "3",
        "--send", f"127.0.0.1:{sample_port}", "--sensor", "2/3-inch", "--focal-mm", "10"])
    report = _report(stderr)
    from glradial.export.opentrackio_udp import parse_packet

    samples = [json.loads(parse_packet(p).payload) for p in received]
    psnr = picture_psnr(clip, out, k1, k2)
    return {**report, **conditions, "sent": frames, "samples": len(samples), "psnr_min": min(psnr),
            "psnr_median": float(np.median(psnr)), "psnr_below_30db": int(np.sum(np.array(psnr) < 30.0)),
            "psnr_checked": len(psnr)}


def run_capacity(clip: Path, work: Path, k1: float, k2: float, backend: str = "cpu", frames: int = 150) -> dict:
    """Flat out, in this process: the clip's first ``frames`` frames decoded beforehand, then pushed
    into the corrector as soon as fewer than 2 are in flight (nothing dropped), corrected on its
    worker thread, encoded (x264 ultrafast) on this one: frames out per second."""
    from itertools import islice

    from glradial.lens.lens import Lens
    from glradial.media.stream_io import LiveSource, open_live_output
    from glradial.media.video_io import EncodeOptions
    from glradial.video.live import LiveCorrector

    source = LiveSource(str(clip))
    info = source.info
    decoded = list(islice(source.frames(), frames))
    time_base = source.stream.time_base
    source.close()
    writer = open_live_output(str(work / "capacity.ts"), info, options=EncodeOptions(preset="ultrafast"), overwrite=True)
    corrector = LiveCorrector(Lens(k1, k2), info.size, info.rate, max_delay=10**6, codec=info.codec, frames=writer,
                              backend=backend)

    def feed() -> None:
        try:
            push_all()
        finally:
            corrector.finish()

    def push_all() -> None:
        for frame in decoded:
            while corrector.stats.pushed - corrector.stats.left >= 2:
                time.sleep(0.0005)
            corrector.push(frame, float(frame.pts * time_base))

    start = time.perf_counter()
    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    while (item := corrector.pull(None, leave=False)) is not None:
        writer.write(item.image, item.pts)
        corrector.left(item)
    elapsed = time.perf_counter() - start
    corrector.close()
    writer.close()
    written = writer.frames_written
    return {"read": len(decoded), "written": written, "fps": written / elapsed, "ratio": written / elapsed / float(info.rate)}


def run_auto_stdin(clip: Path, work: Path, k1: float, k2: float, size: tuple[int, int]) -> dict:
    from glradial.lens.metrics import max_displacement_px

    out, samples_path = work / f"auto_{clip.stem}.ts", work / f"auto_{clip.stem}.jsonl"
    command = ["-", str(out), "-y", "--auto", "--opentrackio", str(samples_path), "--sensor", "2/3-inch", "--focal-mm", "10"]
    print(f"  ffmpeg -re -i {clip.name} -c copy -f mpegts - | glradial live " + " ".join(command), flush=True)
    read_end, write_end = os.pipe()
    process = _live(command, stdin=read_end)
    os.close(read_end)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(process.stderr.readline, "")), daemon=True)
    reader.start()
    while not any("waiting for" in line for line in lines):  # its worker is ready: send from now on
        if process.poll() is not None:
            break
        time.sleep(0.05)
    conditions = load_now()
    sender = subprocess.Popen(["ffmpeg", "-v", "error", "-re", "-i", str(clip), "-c", "copy", "-f", "mpegts", "-"],
                              stdout=write_end)
    os.close(write_end)
    sender.wait()
    process.wait(timeout=300)
    reader.join(timeout=5)
    stderr = "".join(lines)
    if process.returncode != 0:
        raise RuntimeError(stderr)
    report = _report(stderr)
    samples = [json.loads(line) for line in samples_path.read_text().splitlines()]
    stamps = np.array([s["timing"]["sampleTimestamp"]["seconds"] + s["timing"]["sampleTimestamp"]["nanoseconds"] * 1e-9 for s in samples])
    late = stamps >= stamps[0] + 1.0
    lenses = np.array([[s["custom"]["glradial"]["k1"], s["custom"]["glradial"]["k2"]] for s in samples])
    errors = np.atleast_1d(max_displacement_px(lenses[late], np.array([k1, k2])))
    doubtful = np.array([s["custom"]["glradial"].get("doubtful", True) for s in samples])[late]
    return {**report, **conditions, "samples": len(samples), "err_median": float(np.median(errors)), "err_p95": float(np.percentile(errors, 95)),
            "within_8px": float(np.mean(errors <= 8.0)), "sure": float(np.mean(~doubtful))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", type=parse_size, default=(1280, 720))
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=int, default=50, help="frame rate of the fixed-lens runs")
    parser.add_argument("--auto-rate", type=int, default=25, help="frame rate of the --auto run")
    parser.add_argument("--k1", type=float, default=-0.2)
    parser.add_argument("--k2", type=float, default=0.03)
    parser.add_argument("--backends", default="cpu", help="capacity runs: cpu (planar YUV), gl (RGB through GLSL; llvmpipe here)")
    parser.add_argument("--repeat", type=int, default=4, help="fixed-lens runs (each reported with its load)")
    parser.add_argument("--skip", default="", help="comma-separated runs to skip: fixed, capacity, auto")
    parser.add_argument("--work", type=Path, default=Path("/tmp/glradial_bench_live"))
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    skip = set(filter(None, args.skip.split(",")))
    figures: dict = {"load_1min_at_start": os.getloadavg()[0]}
    size, (k1, k2) = args.size, (args.k1, args.k2)
    tag = f"{size[0]}x{size[1]}"
    print(f"bench_live: {tag}, {args.seconds:g} s, lens k1={k1} k2={k2}, {os.cpu_count()} CPU cores", flush=True)
    results: dict[str, dict] = {}
    if not {"fixed", "capacity"} <= skip:
        clip = make_clip(args.work / f"clip_{tag}_{args.rate}p.ts", size, args.rate, args.seconds, k1, k2)
        frames = int(round(args.seconds * args.rate))
        if "fixed" not in skip:
            runs = figures[f"fixed_udp_{args.rate}p"] = [run_fixed_udp(clip, args.work, k1, k2, frames) for _ in range(args.repeat)]
            for r in runs:
                r["written_share_of_sent"] = r["written"] / r["sent"]
                print(f"fixed lens, UDP, {args.rate}p (load {r['uptime_load']}): written {r['written']}/{r['sent']} = "
                      f"{r['written'] / r['sent']:.1%} (read {r['read']}, dropped {r['dropped']} at [{r['dropped_at']}], late "
                      f"{r['late']}; UDP receive errors {r['udp_receive_errors']}); samples received {r['samples']}/{r['written']}; "
                      f"delay p50 {r['p50']:.2f} p95 {r['p95']:.2f} max {r['max']:.2f} frames; PSNR vs cv2.undistort min "
                      f"{r['psnr_min']:.1f} median {r['psnr_median']:.1f} dB ({r['psnr_below_30db']} of {r['psnr_checked']} "
                      "below 30 dB)", flush=True)
        for backend in ([] if "capacity" in skip else args.backends.split(",")):
            r = results[f"capacity, fixed lens, {args.rate}p, {backend}"] = run_capacity(clip, args.work, k1, k2, backend)
            print(f"capacity, fixed lens, {args.rate}p, backend {backend}: {r['fps']:.1f} fps flat out = {r['ratio']:.2f} x "
                  f"the stream rate ({r['written']} of {r['read']} frames)", flush=True)
    if "auto" not in skip:
        clip = make_clip(args.work / f"clip_{tag}_{args.auto_rate}p.ts", size, args.auto_rate, args.seconds, k1, k2)
        frames = int(round(args.seconds * args.auto_rate))
        r = run_auto_stdin(clip, args.work, k1, k2, size)
        figures[f"auto_stdin_{args.auto_rate}p"] = {**r, "sent": frames, "written_share_of_sent": r["written"] / frames}
        print(f"--auto, stdin, {args.auto_rate}p: written {r['written']}/{frames} = {r['written'] / frames:.1%} (dropped "
              f"{r['dropped']}, late {r['late']}); delay p50 {r['p50']:.2f} p95 {r['p95']:.2f} max {r['max']:.2f} frames; "
              f"samples' lens after 1 s vs applied: median {r['err_median']:.1f} px, p95 {r['err_p95']:.1f} px at 1920, "
              f"{r['within_8px']:.0%} within 8 px; {r['sure']:.0%} of frames sure (lens applied)", flush=True)
    if results:
        write_figure(f"bench_live_{tag}", results)
    if {"fixed", "auto"} - skip:
        write_figure("live_start" if tag == "1280x720" else f"live_start_{tag}", figures)


if __name__ == "__main__":
    main()
