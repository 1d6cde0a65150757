"""``glradial live`` and :class:`glradial.LiveCorrector` on loopback only (127.0.0.1): ffmpeg sends a
short generated clip as MPEG-TS over UDP in real time (``-re``, stream copy); the corrected frames
are checked against OpenCV's own undistortion (``cv2.undistort`` with the camera matrix and
coefficients that the width-normalised lens is, written out here: fx = fy = W, principal point at
the centre of the pixel grid), the OpenTrackIO samples are received on a loopback UDP socket and
parsed; the stdin pipe, SIGINT mid-stream (ffprobe reads the output), garbage on the pipe and an
input faster than the correction (drops counted) are checked too. Each test lasts a few seconds."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import av
import cv2
import numpy as np
import pytest
from conftest import LIVE_RATE, LIVE_SECONDS, LIVE_SIZE

ROOT = Path(__file__).resolve().parents[2]
K1, K2 = -0.2, 0.03
SIZE, RATE, SECONDS = LIVE_SIZE, LIVE_RATE, LIVE_SECONDS
pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None,
                                reason="needs ffmpeg and ffprobe on PATH")


@pytest.fixture(scope="module")
def clip(live_clip) -> Path:
    """The live tests' clip (tests/conftest.py: SIZE, RATE, SECONDS)."""
    return live_clip


def _free_port(kind: int = socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _live(*args: str, **kwargs) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "glradial", "live", *args], cwd=ROOT, env=env, stderr=subprocess.PIPE,
                            text=True, **kwargs)


class _Lines:
    """The stderr lines of a process, read on a thread; :meth:`wait_for` a line holding a text."""

    def __init__(self, process: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=lambda: self.lines.extend(iter(process.stderr.readline, "")), daemon=True)
        self._thread.start()

    def wait_for(self, text: str, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while not any(text in line for line in self.lines):
            assert time.monotonic() < end, f"no {text!r} on stderr: {self.lines}"
            time.sleep(0.05)

    def text(self) -> str:
        self._thread.join(timeout=5)
        return "".join(self.lines)


def _luma(frame: av.VideoFrame) -> np.ndarray:
    plane = frame.planes[0]
    return np.frombuffer(plane, np.uint8).reshape(plane.height, plane.line_size)[:, : plane.width].copy()


def _frames(path: Path) -> dict[int, np.ndarray]:
    """Decoded frames by pts: their luma planes (8-bit yuv420p). The picture is compared in luma,
    the usual measure of video: the 4:2:0 chroma of the pattern's saturated colour edges, remapped
    at half resolution, differs from OpenCV's RGB resampling of the upsampled chroma by more than
    the correction could show (the bench compares RGB on a real broadcast frame)."""
    with av.open(str(path)) as container:
        return {frame.pts: _luma(frame) for frame in container.decode(video=0)}


def _opencv_undistort(image: np.ndarray) -> np.ndarray:
    """OpenCV's undistortion with the lens written in its own terms (the oracle)."""
    width, height = image.shape[1], image.shape[0]
    camera = np.array([[width, 0, (width - 1) / 2], [0, width, (height - 1) / 2], [0, 0, 1]], np.float64)
    return cv2.undistort(image, camera, np.array([K1, K2, 0, 0, 0], np.float64))


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    error = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0**2 / max(error, 1e-12)))


def _report(stderr: str) -> dict[str, int]:
    """The closing line's counts: frames read, written, dropped, late."""
    line = next(line for line in stderr.splitlines() if "frames read" in line)
    words = line.replace(",", "").split()
    return {"read": int(words[words.index("frames") - 1]), "written": int(words[words.index("written") - 1]),
            "dropped": int(words[words.index("dropped") + 1]), "late": int(words[words.index("late") + 1])}


def test_udp_in_real_time_fixed_lens(clip, tmp_path):
    from glradial.export.opentrackio_udp import SampleReceiver

    video_port = _free_port()
    out = tmp_path / "out.ts"
    with SampleReceiver() as receiver:
        process = _live(f"udp://127.0.0.1:{video_port}", str(out), "--k1", str(K1), "--k2", str(K2), "--crf", "8",
                        "--idle-timeout", "3", "--send", f"127.0.0.1:{receiver.address[1]}", "--sensor", "2/3-inch",
                        "--focal-mm", "10", "--max-delay", "8")  # the plumbing under test, not the capacity (bench_live measures that)
        lines = _Lines(process)
        lines.wait_for("waiting for")
        time.sleep(1.0)  # the socket is bound inside av.open, just after the line
        subprocess.run(["ffmpeg", "-v", "error", "-re", "-i", str(clip), "-c", "copy", "-f", "mpegts",
                        f"udp://127.0.0.1:{video_port}?pkt_size=1316"], check=True, timeout=30)
        assert process.wait(timeout=30) == 0, lines.text()
        time.sleep(0.2)
    counts = _report(lines.text())
    source, written = _frames(clip), _frames(out)
    assert counts["written"] == len(written) and counts["read"] == counts["written"] + counts["dropped"]
    assert len(written) >= 0.9 * len(source), lines.text()  # the bench measures the 98 % of the target at 720p50
    samples = [json.loads(payload) for payload in receiver.payloads()]
    assert len(samples) >= 0.95 * len(written)
    numbers = [s["timing"]["sequenceNumber"] for s in samples]
    assert numbers == sorted(set(numbers))
    # frames that came before the lens's maps were built pass through uncorrected, flagged doubtful
    pending = {s["timing"]["sequenceNumber"] for s in samples if s["custom"]["glradial"].get("doubtful")}
    assert pending == set(range(len(pending))) and len(pending) <= 5, pending
    order = {pts: i for i, pts in enumerate(sorted(source))}
    for pts, image in written.items():
        assert pts in source, f"output pts {pts} is no input frame's"
        assert _psnr(image, source[pts] if order[pts] in pending else _opencv_undistort(source[pts])) >= 30.0
    assert all(s["custom"]["glradial"]["k1"] == K1 and s["custom"]["glradial"]["k2"] == K2 for s in samples)
    assert all(s["tracker"]["status"] == "lens given" and "sampleTimestamp" in s["timing"] for s in samples)


def test_stdin_pipe_in_real_time(clip, tmp_path):
    out = tmp_path / "out.mkv"
    with open(clip, "rb") as pipe:
        process = _live("-", str(out), "--k1", str(K1), "--k2", str(K2), "--realtime", "-q", "--crf", "8", stdin=pipe)
        stderr = process.communicate(timeout=60)[1]
    assert process.returncode == 0, stderr
    counts = _report(stderr)
    assert counts["read"] == RATE * SECONDS and counts["written"] + counts["dropped"] == counts["read"]
    assert counts["written"] >= 0.9 * counts["read"]
    probed = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v", "-show_entries",
                             "stream=nb_read_frames", "-of", "csv=p=0", str(out)], capture_output=True, text=True, check=True)
    assert int(probed.stdout.strip()) == counts["written"]


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("stop, start", [(signal.SIGINT, None), (signal.SIGTERM, None), (signal.SIGINT, _ignore_sigint)],
                         ids=["SIGINT", "SIGTERM", "SIGINT-ignored-at-start"])
def test_a_signal_mid_stream_leaves_a_playable_output(clip, tmp_path, stop, start):
    """SIGINT also stops a run started with it ignored (a background job of a script, nohup, a CI
    runner): Python leaves an inherited SIG_IGN in place, and the run would go on to the input's end."""
    long_clip = tmp_path / "long.ts"
    subprocess.run(["ffmpeg", "-v", "error", "-stream_loop", "3", "-i", str(clip), "-c", "copy", str(long_clip)], check=True)
    out = tmp_path / "out.mp4"
    process = _live(str(long_clip), str(out), "--k1", str(K1), "--realtime", preexec_fn=start)
    lines = _Lines(process)
    lines.wait_for("frames out")  # the status line: frames are flowing
    process.send_signal(stop)
    assert process.wait(timeout=30) == 0, lines.text()
    stderr = lines.text()
    assert signal.Signals(stop).name in stderr
    counts = _report(stderr)
    assert 0 < counts["written"] < 4 * RATE * SECONDS
    probed = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v", "-show_entries",
                             "stream=nb_read_frames", "-of", "csv=p=0", str(out)], capture_output=True, text=True, check=True)
    assert int(probed.stdout.strip()) == counts["written"]


def test_garbage_on_the_pipe_is_a_clear_error(tmp_path):
    out = tmp_path / "out.mp4"
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(np.random.default_rng(1).integers(0, 256, 200_000, dtype=np.uint8).tobytes())
    with open(garbage, "rb") as pipe:
        process = _live("-", str(out), "--k1", str(K1), stdin=pipe)
        stderr = process.communicate(timeout=60)[1]
    assert process.returncode == 1
    assert "glradial: error:" in stderr and "'-'" in stderr and "Traceback" not in stderr
    assert not out.exists() and not list(tmp_path.glob(".out*"))  # nothing half-written


def test_an_input_faster_than_the_correction_drops_frames_counted(tmp_path):
    """1 s of 1280x720 at 50 fps piped in as fast as it decodes (no --realtime), --max-delay 1 (20 ms):
    the frames arrive far faster than they are corrected and encoded, and the ones that could not
    leave in time are dropped and counted, never silently."""
    clip, out = tmp_path / "hd.ts", tmp_path / "out.ts"
    subprocess.run(["ffmpeg", "-v", "error", "-f", "lavfi", "-i", "testsrc2=size=1280x720:rate=50:duration=1", "-c:v",
                    "libx264", "-preset", "ultrafast", "-pix_fmt", "yuv420p", "-f", "mpegts", str(clip)], check=True)
    with open(clip, "rb") as pipe:
        process = _live("-", str(out), "--k1", str(K1), "--max-delay", "1", "-q", stdin=pipe)
        stderr = process.communicate(timeout=60)[1]
    assert process.returncode == 0, stderr
    counts = _report(stderr)
    assert counts["read"] == 50 and counts["written"] + counts["dropped"] == counts["read"]
    assert counts["dropped"] > 0, stderr
    where = next(line for line in stderr.splitlines() if "dropped frames (numbers from the first)" in line).split(": ")[-1]
    if "..." not in where:  # every dropped frame named, once
        runs = [[int(v) for v in run.split("-")] for run in where.split(", ")]
        named = [i for run in runs for i in range(run[0], run[-1] + 1)]
        assert len(named) == len(set(named)) == counts["dropped"] and all(0 <= i < 50 for i in named)


def test_dropped_frames_read_as_runs():
    from glradial.video.live import LiveStats

    stats = LiveStats(25.0, 2)
    for index in (5, 3, 4, 9, 20, 21, 40):
        stats.drop(index)
    assert stats.dropped_ranges() == "3-5, 9, 20-21, 40"
    assert stats.dropped_ranges(most=2) == "3-5, 9, ..."
    assert LiveStats(25.0, 2).dropped_ranges() == ""
    assert stats.dropped == 7
    stats.delays.extend([0.5, 2.0, 2.01, 7.0])  # frame periods; late = more than max_delay (2)
    assert (stats.left, stats.late) == (4, 2)


def _image(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.resize(rng.integers(0, 256, (18, 32, 3), dtype=np.uint8), SIZE, interpolation=cv2.INTER_NEAREST)


def test_api_drops_what_waits_too_long_and_counts_it():
    from glradial import Lens, LiveCorrector

    image = _image(0)
    with LiveCorrector(Lens(K1, K2), SIZE, RATE, max_delay=2, backend="cpu") as live:
        for i in range(20):  # a burst nobody takes in time: the frames that would leave late are dropped
            live.push(image, i / RATE)
        time.sleep(0.5)
        live.finish()
        out = []
        while (item := live.pull(None)) is not None:
            out.append(item)
        stats = live.stats
    assert stats.pushed == 20 and stats.dropped > 0 and stats.left == len(out) == stats.pushed - stats.dropped
    assert [o.index for o in out] == sorted(o.index for o in out)
    with pytest.raises(ValueError, match="max_delay"):
        LiveCorrector(Lens(K1, K2), SIZE, RATE, max_delay=0)
    with pytest.raises(ValueError, match="320x180"):
        with LiveCorrector(Lens(K1, K2), SIZE, RATE) as live:
            live.push(np.zeros((10, 10, 3), np.uint8), 0.0)


def test_api_auto_passes_a_shot_through_until_it_has_a_lens():
    """The doubt policy, causally: a new shot's first frame has no lens yet (passed through,
    flagged doubtful, "pending"); a later frame of it gets the shot's lens (applied here with
    apply_doubtful: an estimator that states no bound leaves the shot doubtful); a cut opens shot 1."""
    from glradial import LiveCorrector, correct
    from glradial.export.opentrackio import TrackingCamera

    camera = TrackingCamera(SIZE, 9.59, 10.0, rate=RATE)
    images = [_image(1)] * 12 + [_image(2)] * 12
    with LiveCorrector("auto", SIZE, RATE, max_delay=20, camera=camera, estimator=lambda frame: (K1, K2),
                       auto={"every": 4, "apply_doubtful": True, "worker": "thread"}) as live:
        out = []
        for i, image in enumerate(images):
            live.push(image, i / RATE)
            out.append(live.pull(None))
            time.sleep(0.03)
    first = out[0]
    assert first.state.reason == "pending" and first.state.applied is None and np.array_equal(first.image, images[0])
    assert first.sample["custom"]["glradial"]["doubtful"] is True and "DOUBTFUL" in first.sample["tracker"]["status"]
    later = out[10]
    assert later.state.shot == 0 and later.state.applied is not None
    assert later.state.applied.k1 == pytest.approx(K1) and later.state.applied.k2 == pytest.approx(K2)
    assert _psnr(later.image, correct(images[10], later.state.applied, backend="cpu")) > 60
    assert out[12].state.shot == 1 and out[12].state.reason == "pending"


def test_auto_through_stdin_reads_the_shot_lens(tmp_path):
    """``--auto`` end to end (its worker process, the bundled estimator): a real broadcast frame
    with its own lens removed, the known lens applied, panned for 2 s at 640x360 and piped in at its
    own rate: one sample per written frame, and once the shot's first fit has landed the samples'
    lens lies within 8 px (max displacement at 1920 wide) of the applied one."""
    from importlib import resources

    import glradial
    from glradial.lens.metrics import max_displacement_px
    from glradial.media.image_io import read_image
    from glradial.media.video_io import EncodeOptions, VideoInfo, VideoWriter

    data = resources.files("glradial.data")
    own = json.loads(data.joinpath("usl_broadcast_0195.json").read_text())["own_lens"]
    flat = glradial.correct(read_image(Path(str(data.joinpath("usl_broadcast_0195.jpg"))), order="rgb"),
                            glradial.Lens(own["k1"], own["k2"]), fit="crop", backend="cpu")
    lens, size = glradial.Lens(K1, K2), (640, 360)
    clip = tmp_path / "pan.ts"
    with VideoWriter(clip, VideoInfo.of(size, RATE, codec="libx264"), options=EncodeOptions(crf=18, preset="ultrafast")) as writer:
        for i in range(RATE * SECONDS):
            x0 = 40 + 4 * i
            view = cv2.resize(flat[40:40 + 608, x0:x0 + 1080], size, interpolation=cv2.INTER_AREA)
            writer.write(glradial.distort(view, lens, fit=lens.fit_scale(size, "crop", "distort"), backend="cpu"))
    samples_path = tmp_path / "s.jsonl"
    with open(clip, "rb") as pipe:
        process = _live("-", str(tmp_path / "out.ts"), "--auto", "--realtime", "-q", "--opentrackio", str(samples_path),
                        "--sensor", "2/3-inch", "--focal-mm", "10", stdin=pipe)
        stderr = process.communicate(timeout=120)[1]
    assert process.returncode == 0, stderr
    counts = _report(stderr)
    samples = [json.loads(line) for line in samples_path.read_text().splitlines()]
    assert len(samples) == counts["written"] >= 0.8 * RATE * SECONDS
    fitted = [s["custom"]["glradial"] for s in samples if "uncertainty_px" in s["custom"]["glradial"]]
    assert fitted, "no shot fit landed within the clip"
    errors = max_displacement_px(np.array([[g["k1"], g["k2"]] for g in fitted]), np.array([K1, K2]))
    assert np.max(errors) <= 8.0
    assert all(g["shot"] == 0 for g in fitted)


@pytest.mark.parametrize("argv, status, message", [
    (["udp://127.0.0.1:9", "{exists}", "--k1", "-0.1"], 1, "already exists"),
    (["ftp://host/x", "{out}", "--k1", "-0.1"], 1, "unknown URL scheme 'ftp'"),
    (["-", "rtmp://host/x", "--k1", "-0.1"], 1, "must be udp://"),
    (["{missing}", "{out}", "--k1", "-0.1"], 1, "does not exist"),
    (["{exists}", "{exists}", "--k1", "-0.1", "-y"], 2, "is INPUT"),
    (["-", "{out}", "--k1", "-0.1", "--auto"], 2, "give the lens one way"),
    (["-", "{out}"], 2, "give the lens"),
    (["-", "{out}", "--k1", "-0.1", "--every", "5"], 2, "--every needs --auto"),
    (["-", "{out}", "--k1", "-0.1", "--send", "127.0.0.1:9"], 2, "--focal-mm"),
    (["-", "{out}", "--k1", "-0.1", "--rate", "25"], 2, "--rate is for files"),
])
def test_bad_options_are_refused_before_waiting_for_the_input(tmp_path, capsys, argv, status, message):
    from glradial.cli import main

    exists = tmp_path / "exists.ts"
    exists.write_bytes(b"x")
    names = {"exists": str(exists), "out": str(tmp_path / "out.ts"), "missing": str(tmp_path / "missing.ts")}
    assert main(["live", *[a.format(**names) for a in argv]]) == status  # refused before the input is opened
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out.ts").exists()


def test_nut_on_stdin_to_mpeg_ts_over_udp(clip, tmp_path):
    """A NUT stream on stdin (FFmpeg probes it), the corrected stream out as MPEG-TS over UDP,
    received by ffmpeg on loopback: every frame arrives, at the input's size."""
    port = _free_port()
    received = tmp_path / "received.ts"
    receiver = subprocess.Popen(["ffmpeg", "-v", "error", "-y", "-i", f"udp://127.0.0.1:{port}?timeout=10000000", "-c", "copy",
                                 str(received)])
    nut = subprocess.Popen(["ffmpeg", "-v", "error", "-i", str(clip), "-c", "copy", "-f", "nut", "-"], stdout=subprocess.PIPE)
    time.sleep(0.5)  # the receiver's socket
    process = _live("-", f"udp://127.0.0.1:{port}", "--k1", str(K1), "--realtime", "-q", stdin=nut.stdout)
    nut.stdout.close()
    stderr = process.communicate(timeout=60)[1]
    nut.wait(timeout=10)
    receiver.wait(timeout=30)
    assert process.returncode == 0, stderr
    counts = _report(stderr)
    assert counts["read"] == RATE * SECONDS and counts["written"] + counts["dropped"] == counts["read"]
    probed = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v", "-show_entries",
                             "stream=nb_read_frames,width,height", "-of", "csv=p=0", str(received)],
                            capture_output=True, text=True, check=True)
    width, height, frames = (int(v) for v in probed.stdout.strip().splitlines()[0].split(","))
    assert (width, height) == SIZE and frames == counts["written"]
