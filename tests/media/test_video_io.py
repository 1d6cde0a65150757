"""Broadcast-grade video through 'glradial correct' (glradial.media.video_io on PyAV): real codecs made by
the ffmpeg command and checked with ffprobe (the independent oracle): audio copied bit for bit,
depth, exact frame rate, timecode and frame count kept, frames equal to glradial.correct() in
memory; lens tracks in and out; nothing left behind on a full disk, SIGTERM/SIGHUP or a truncated
input. Clips are tiny (64x36 to 160x90, 10-40 frames) so the file runs in seconds."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import glradial
from glradial.cli import main
from glradial.media.video_io import VideoInfo, VideoReader, VideoWriter, is_sequence, sequence_files

FFMPEG = shutil.which("ffmpeg")
FFPROBE = shutil.which("ffprobe")
pytestmark = pytest.mark.skipif(FFMPEG is None or FFPROBE is None, reason="needs the ffmpeg and ffprobe commands (make setup installs them)")

K1, K2 = -0.25, 0.05
ROOT = Path(__file__).resolve().parents[2]


def _ffmpeg(*args: str) -> None:
    subprocess.run([FFMPEG, "-v", "error", "-y", *args], check=True)


def _clip(path: Path, video: list[str], *, size: str = "64x36", rate: str = "30000/1001", frames: int = 10,
          audio: list[str] | None = None, timecode: str | None = "01:02:03:04") -> Path:
    """A test-pattern clip with a sine tone: ``frames`` frames at ``rate``."""
    args = ["-f", "lavfi", "-i", f"testsrc2=size={size}:rate={rate}"]
    if audio is not None:
        args += ["-f", "lavfi", "-i", "sine=frequency=440:sample_rate=48000"]
    args += ["-frames:v", str(frames), *video]
    if audio is not None:
        args += [*audio, "-shortest"]
    if timecode:
        args += ["-timecode", timecode]
    _ffmpeg(*args, str(path))
    return path


def _probe(path: Path) -> dict:
    out = subprocess.run([FFPROBE, "-v", "error", "-count_frames", "-show_streams", "-show_format", "-of", "json", str(path)],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def _stream(probe: dict, kind: str) -> dict:
    return next(s for s in probe["streams"] if s["codec_type"] == kind)


def _audio_md5(path: Path) -> str:
    """MD5 of the audio packets as stored (no decoding): equal only for an untouched copy."""
    out = subprocess.run([FFMPEG, "-v", "error", "-i", str(path), "-map", "0:a", "-c", "copy", "-f", "md5", "-"],
                         check=True, capture_output=True, text=True).stdout
    return out.strip()


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def _frames(path: Path) -> list[np.ndarray]:
    with VideoReader(path) as reader:
        return list(reader)


@pytest.mark.parametrize("kind", ["prores10_pcm", "h264_aac"])
def test_round_trip_keeps_audio_depth_rate_timecode_and_count(tmp_path, kind):
    if kind == "prores10_pcm":
        # 4:4:4 (ProRes 4444, H.264 High 4:4:4) so that the pixel comparison below measures the
        # pipeline, not the chroma subsampling of a 64-px test pattern (4:2:2 and 4:2:0 round trips
        # of a corrected frame lose ~2.5x the identity's loss there)
        source = _clip(tmp_path / "in.mov", ["-c:v", "prores_ks", "-profile:v", "4", "-pix_fmt", "yuv444p10le"],
                       audio=["-c:a", "pcm_s16le"])
        out = tmp_path / "out.mov"
    else:
        source = _clip(tmp_path / "in.mp4", ["-c:v", "libx264", "-pix_fmt", "yuv444p", "-color_primaries", "bt709",
                                             "-color_trc", "bt709", "-colorspace", "bt709"], audio=["-c:a", "aac"])
        out = tmp_path / "out.mp4"
    assert main(["correct", str(source), str(out), "--k1", str(K1), "--k2", str(K2), "--backend", "cpu", "-q"]) == 0
    before, after = _probe(source), _probe(out)
    video_in, video_out = _stream(before, "video"), _stream(after, "video")
    for key in ("codec_name", "pix_fmt", "width", "height", "r_frame_rate", "avg_frame_rate", "nb_read_frames",
                "color_space", "color_transfer", "color_primaries", "color_range"):
        assert video_out.get(key) == video_in.get(key), key
    assert video_out["r_frame_rate"] == "30000/1001" and video_out["nb_read_frames"] == "10"
    assert video_out["tags"]["timecode"] == "01:02:03:04"
    assert _audio_md5(out) == _audio_md5(source)  # audio packets copied untouched
    assert _stream(after, "audio")["codec_name"] == _stream(before, "audio")["codec_name"]
    # frames: the decoded input corrected in memory; the output went through the lossy codec (and
    # its chroma subsampling) once more. The codec's own loss on that content is measured by writing
    # the in-memory correction itself with the same encoder (VideoWriter, the source's settings) and
    # reading it back: the output may lose that much, plus 25 % and 0.2 % of full scale for pass 2
    # resampling the source's own YUV samples instead of RGB (glradial.remapping.planes; measured:
    # the YUV output is closer, 0.0152 against 0.0161 of full scale for the 4:4:4 H.264 clip).
    frames_in, frames_out = _frames(source), _frames(out)
    expected = [glradial.correct(a, K1, K2, backend="cpu") for a in frames_in]
    reference = tmp_path / f"reference{out.suffix}"
    with VideoReader(source) as reader:
        info = reader.info
    with VideoWriter(reference, info) as writer:
        for frame in expected:
            writer.write(frame)
    assert len(frames_out) == 10
    deep = kind == "prores10_pcm"
    assert frames_out[0].dtype == (np.uint16 if deep else np.uint8)
    scale = 65535.0 if deep else 255.0
    codec_loss = max(np.abs(a.astype(float) - b).mean() / scale for a, b in zip(expected, _frames(reference)))
    errors = [np.abs(a.astype(float) - b).mean() / scale for a, b in zip(expected, frames_out)]
    assert max(errors) < 1.25 * codec_loss + 0.002, (errors, codec_loss)
    wrong = np.abs(frames_in[5].astype(float) - frames_out[5]).mean() / scale  # no correction at all
    assert wrong > 3 * max(errors)
    assert _names(tmp_path) == sorted([source.name, out.name, reference.name])


def test_colour_tags_are_read_once_per_version_of_a_file(tmp_path):
    """A command opens its input several times (correct --auto: the check, pass 1, pass 2): the
    first frame's colour tags are decoded once and kept, and a file written again in its place
    (other tags: the ffprobe oracle says which) is read anew, never answered from the old one."""
    from glradial.media import video_io

    path = tmp_path / "in.mp4"
    tagged = {"bt709": ["-color_primaries", "bt709", "-color_trc", "bt709", "-colorspace", "bt709"],
              "smpte170m": ["-color_primaries", "smpte170m", "-color_trc", "smpte170m", "-colorspace", "smpte170m"]}
    video_io._read_first_frame_tags.cache_clear()
    seen = []
    for name in ("bt709", "smpte170m"):
        _clip(path, ["-c:v", "libx264", "-pix_fmt", "yuv420p", *tagged[name]], timecode=None)
        assert _stream(_probe(path), "video")["color_space"] == name
        infos = []
        for _ in range(3):
            with VideoReader(path) as reader:
                infos.append(reader.info)
        assert infos[0] == infos[1] == infos[2]
        seen.append(infos[0].colorspace)
    assert seen == [1, 6]  # FFmpeg's AVCOL_SPC_BT709, AVCOL_SPC_SMPTE170M
    assert video_io._read_first_frame_tags.cache_info().misses == 2  # one decode per version


def test_ten_bit_stays_ten_bit_and_lossless_is_exact(tmp_path):
    """FFV1 (lossless) in planar RGB: 8-bit frames come out exactly as glradial.correct() makes them
    in memory; 10-bit frames within one 10-bit level (the 16-bit result is rounded to 10 bits:
    <= 32 of 65535 plus the 10 -> 16 bit expansion; an 8-bit path would be off by up to 128)."""
    for pix_fmt, tolerance in (("gbrp", 0), ("gbrp10le", 64)):
        source = _clip(tmp_path / f"{pix_fmt}.mkv", ["-c:v", "ffv1", "-pix_fmt", pix_fmt], size="96x54", timecode=None)
        out = tmp_path / f"{pix_fmt}_out.mkv"
        assert main(["correct", str(source), str(out), "--k1", str(K1), "--k2", str(K2), "--backend", "cpu", "-q"]) == 0
        # (FFV1 stores 8-bit planar RGB as bgr0: compare with what the input holds)
        assert _stream(_probe(out), "video")["pix_fmt"] == _stream(_probe(source), "video")["pix_fmt"]
        for a, b in zip(_frames(source), _frames(out)):
            expected = glradial.correct(a, K1, K2, backend="cpu")
            assert b.dtype == a.dtype
            assert np.abs(expected.astype(int) - b.astype(int)).max() <= tolerance, pix_fmt


def test_codec_options_and_image_sequences(tmp_path, capsys):
    source = _clip(tmp_path / "in.mp4", ["-c:v", "libx264", "-pix_fmt", "yuv420p"], timecode=None)
    out = tmp_path / "out.mkv"
    assert main(["correct", str(source), str(out), "--k1", "-0.1", "--codec", "hevc", "--crf", "30", "--preset", "ultrafast",
                 "--pix-fmt", "yuv420p10le", "-q"]) == 0
    video = _stream(_probe(out), "video")
    assert (video["codec_name"], video["pix_fmt"], video["nb_read_frames"]) == ("hevc", "yuv420p10le", "10")
    # image sequence out, then back in
    frames = tmp_path / "seq"
    frames.mkdir()
    pattern = frames / "f_%03d.png"
    assert is_sequence(pattern) and not is_sequence(out)
    assert main(["correct", str(source), str(pattern), "--k1", "-0.1", "-q"]) == 0
    assert [p.name for p in sequence_files(pattern)] == [f"f_{i:03d}.png" for i in range(1, 11)]
    assert _names(frames) == [f"f_{i:03d}.png" for i in range(1, 11)]  # no temporary folder left
    assert main(["correct", str(source), str(pattern), "--k1", "-0.1", "-q"]) == 1  # exists: needs -y
    assert main(["correct", str(pattern), str(tmp_path / "back.mkv"), "--k1", "0.1", "--codec", "ffv1", "--rate", "30000/1001", "-q"]) == 0
    back = _stream(_probe(tmp_path / "back.mkv"), "video")
    assert (back["nb_read_frames"], back["r_frame_rate"]) == ("10", "30000/1001")
    assert main(["correct", str(source), str(tmp_path / "r.mkv"), "--k1", "0.1", "--rate", "25", "-q"]) == 2  # videos keep theirs
    # a codec FFmpeg lacks, or options the encoder refuses: one line, nothing written
    for extra, message in ((["--codec", "nosuchcodec"], "no FFmpeg encoder 'nosuchcodec'"),
                           (["--codec", "prores", "--crf", "20"], "--crf is for"),
                           (["--codec", "ffv1"], "does not support 'ffv1'"),
                           (["--codec", "prores", "--pix-fmt", "yuv420p"], "cannot write pix_fmt 'yuv420p'")):
        names = _names(tmp_path)
        capsys.readouterr()
        assert main(["correct", str(source), str(tmp_path / "x.mov"), "--k1", "-0.1", "-q", *extra]) == 1, extra
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and message in err[0] and "x.mov" in err[0], err
        assert _names(tmp_path) == names


def test_overwrite_only_with_y_and_never_the_input(tmp_path, capsys):
    source = _clip(tmp_path / "in.mp4", ["-c:v", "libx264"], timecode=None)
    out = tmp_path / "out.mp4"
    out.write_bytes(b"precious")
    assert main(["correct", str(source), str(out), "--k1", "-0.1", "-q"]) == 1
    assert "already exists (overwrite it with -y" in capsys.readouterr().err
    assert out.read_bytes() == b"precious"
    assert main(["correct", str(source), str(out), "--k1", "-0.1", "-y"]) == 0
    assert _stream(_probe(out), "video")["nb_read_frames"] == "10"
    assert main(["correct", str(source), str(tmp_path / "." / "in.mp4"), "--k1", "-0.1", "-y"]) == 2
    assert "must differ from INPUT" in capsys.readouterr().err


class _Estimate(glradial.Lens):
    """A stand-in for the estimator's LensEstimate: a Lens that states its uncertainty and method."""

    def __init__(self, k1: float, k2: float, uncertainty_px: float, method: str) -> None:
        super().__init__(k1, k2)
        object.__setattr__(self, "uncertainty_px", uncertainty_px)
        object.__setattr__(self, "method", method)


def test_lens_track_out_and_back_in(tmp_path, monkeypatch, capsys):
    """--auto writes a sidecar with uncertainty and method per frame and warns about the doubtful
    shot; fed back with --lens-track it gives the same frames (lossless FFV1); an edited track is
    used as edited; bad rows get one error naming the line and leave no output."""
    source = tmp_path / "in.mkv"
    size = (96, 54)
    with VideoWriter(source, VideoInfo.of(size, 25, codec="ffv1", pix_fmt="gbrp")) as writer:
        for i in range(24):
            frame = np.full((54, 96, 3), 40, np.uint8)
            frame[:, : 48 if i < 12 else 10] = (200, 60, 30) if i < 12 else (30, 90, 220)  # a cut at frame 12
            frame[0, 0] = (i, 0, 0)
            writer.write(frame)
    # flat frames: no lines, no motion, so each shot rests on its per-frame estimates; shot 0's are
    # sure (2 px), shot 1's doubtful (40 px; many equal samples of one picture gain nothing)
    monkeypatch.setattr("glradial.video.video_pipeline.default_estimator",
                        lambda model=None, method=None: lambda f: _Estimate(-0.2, 0.03, 2.0, "lines") if f[0, 0, 0] < 12 else _Estimate(-0.1, 0.01, 40.0, "net"))
    auto = tmp_path / "auto.mkv"
    assert main(["correct", str(source), str(auto), "--auto", "--every", "3", "--backend", "cpu", "-q"]) == 0
    captured = capsys.readouterr()
    warnings = [line for line in captured.err.splitlines() if "doubtful" in line]
    assert len(warnings) == 1 and "shot 1 (frames 12-23)" in warnings[0] and "uncertainty 40.0 px" in warnings[0]
    assert "no_geometry" in warnings[0] and "passed through uncorrected" in warnings[0]
    assert "DOUBTFUL" in captured.out
    sidecar = tmp_path / "auto.mkv.lens.csv"
    lines = sidecar.read_text().splitlines()
    assert lines[0] == ("frame,time_s,shot,k1,k2,cx,cy,pixel_aspect,uncertainty_px,doubtful,reason,applied,method,"
                        "k1_raw,k2_raw,raw_uncertainty_px,weight")
    rows = [dict(zip(lines[0].split(","), line.split(","))) for line in lines[1:]]
    assert len(rows) == 24 and rows[12]["shot"] == "1" and rows[12]["doubtful"] == "1" and rows[0]["doubtful"] == "0"
    assert (rows[0]["applied"], rows[12]["applied"], rows[12]["reason"], rows[0]["reason"]) == ("1", "0", "no_geometry", "")
    assert rows[0]["method"] == "lines" and rows[12]["method"] == "net" and rows[1]["method"] == ""
    assert float(rows[3]["time_s"]) == pytest.approx(3 / 25)
    assert float(rows[0]["uncertainty_px"]) <= 2.0 and float(rows[20]["uncertainty_px"]) >= 20.0
    originals = _frames(source)
    np.testing.assert_array_equal(_frames(auto)[15], originals[15])  # the doubtful shot passed through
    # back in: the same frames (the applied column honoured)
    again = tmp_path / "again.mkv"
    assert main(["correct", str(source), str(again), "--lens-track", str(sidecar), "--backend", "cpu", "-q"]) == 0
    for a, b in zip(_frames(auto), _frames(again)):
        np.testing.assert_array_equal(a, b)
    # edited: frame 5 gets another lens, only the required columns are kept
    edited = tmp_path / "edited.csv"
    body = ["frame,k1,k2"] + [f"{i},{-0.3 if i == 5 else float(r['k1'])},{float(r['k2'])}" for i, r in enumerate(rows)]
    edited.write_text("\n".join(body) + "\n")
    out = tmp_path / "edited.mkv"
    assert main(["correct", str(source), str(out), "--lens-track", str(edited), "--backend", "cpu", "-q"]) == 0
    np.testing.assert_array_equal(_frames(out)[5], glradial.correct(originals[5], -0.3, float(rows[5]["k2"]), backend="cpu"))
    # bad rows: one line naming the file and the line, nothing written
    bad = [
        ("frame,k1\n0,0.1\n", "line 1: the header lacks the column(s) k2"),
        ("frame,k1,k2\n0,-0.1,0\n1,abc,0\n", "line 3: k1 'abc' is not a number"),
        ("frame,k1,k2\n0,-0.1,0\n2,-0.1,0\n", "line 3: frame '2', expected 1"),
        ("frame,k1,k2\n0,-3,0\n", "line 2: lens k1=-3"),
        ("frame,k1,k2,uncertainty_px\n0,-0.1,0,-1\n", "line 2: uncertainty_px: -1.0 is less than the minimum of 0"),
        ("frame,k1,k2,applied\n0,-0.1,0,2\n", "line 2: applied: 2.0 is not one of [0, 1]"),
        ("frame,k1,k2\n" + "".join(f"{i},-0.1,0\n" for i in range(30)), "the lens track has 30 frames but"),
        ("frame,k1,k2\n" + "".join(f"{i},-0.1,0\n" for i in range(20)), "the lens track has 20 frames; the video has more"),
    ]
    for text, message in bad:
        edited.write_text(text)
        names = _names(tmp_path)
        capsys.readouterr()
        assert main(["correct", str(source), str(tmp_path / "bad.mkv"), "--lens-track", str(edited), "--backend", "cpu"]) == 1, text
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and message in err[0], (message, err)
        assert _names(tmp_path) == names


def test_truncated_input_is_reported_with_the_frames_decoded(tmp_path, capsys):
    source = _clip(tmp_path / "long.mkv", ["-c:v", "ffv1", "-pix_fmt", "gbrp"], size="160x90", rate="25", frames=40, timecode=None)
    data = source.read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[: len(data) // 3])
    assert main(["correct", str(cut), str(tmp_path / "out.mkv"), "--k1", "-0.1", "-q"]) == 1
    err = capsys.readouterr().err
    assert "is truncated: its header says 1.60 s" in err and "frames" in err
    assert _names(tmp_path) == ["cut.mkv", "long.mkv"]


def _can_mount_tmpfs(folder: Path) -> bool:
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)], capture_output=True)
    return done.returncode == 0


def test_full_disk_fails_cleanly(tmp_path, capsys):
    """An output that does not fit on a 64 KiB tmpfs: exit 1, one line naming the path and the
    cause, and nothing left on the full file system."""
    source = _clip(tmp_path / "in.mkv", ["-c:v", "ffv1", "-pix_fmt", "gbrp"], size="160x90", rate="25", frames=40, timecode=None)
    assert source.stat().st_size > 150_000  # the corrected copy (FFV1, as large) cannot fit
    disk = tmp_path / "disk"
    disk.mkdir()
    if not _can_mount_tmpfs(disk):
        pytest.skip("mounting a small tmpfs needs root and a mount command (not allowed here)")
    try:
        target = disk / "out.mkv"
        assert main(["correct", str(source), str(target), "--k1", "-0.1", "-q"]) == 1
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and "out.mkv" in err[0] and "No space left on device" in err[0], err
        assert _names(disk) == []
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT], ids=["SIGTERM", "SIGHUP", "SIGINT-ignored-at-start"])
def test_a_signal_mid_video_leaves_nothing(tmp_path, signum):
    """SIGINT is sent to a run started with it ignored (a script's background job: Python keeps an
    inherited SIG_IGN), which must stop all the same, as ffmpeg does."""
    source = _clip(tmp_path / "in.mkv", ["-c:v", "ffv1", "-pix_fmt", "gbrp"], size="640x360", rate="25", frames=150, timecode=None)
    out = tmp_path / "out.mkv"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "glradial", "correct", str(source), str(out), "--k1", "-0.2",
                                "--backend", "cpu", "--interpolation", "cubic", "-q"], env=env, stderr=subprocess.PIPE, text=True,
                               preexec_fn=_ignore_sigint)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and process.poll() is None:  # wait until the output is being written
        temporary = [p for p in tmp_path.iterdir() if p.name.startswith(".out.")]
        if temporary and temporary[0].stat().st_size > 0:
            break
        time.sleep(0.01)
    assert process.poll() is None, "the video was done before the signal: make it longer"
    process.send_signal(signum)
    sent = time.monotonic()
    _, err = process.communicate(timeout=60)
    assert time.monotonic() - sent < 15, "the run went on after the signal"
    assert process.returncode == 128 + signum, err
    assert ("interrupted" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}") in err
    assert _names(tmp_path) == ["in.mkv"]


def test_gl_corrector_lives_and_dies_on_its_worker_thread(tmp_path, ctx, monkeypatch):
    """backend 'gl': the pipeline's worker thread makes its own Remapper (own context), corrects
    every frame with it like the GL path in memory, and releases it on that thread when it ends."""
    import threading

    from glradial.remapping.remap import Remapper
    from glradial.video.video_pipeline import correct_video

    made, released = [], []
    real_init, real_release = Remapper.__init__, Remapper.release

    def init(self, *args, **kwargs):
        made.append(threading.current_thread().name)
        real_init(self, *args, **kwargs)

    def release(self):
        released.append(threading.current_thread().name)
        real_release(self)

    monkeypatch.setattr(Remapper, "__init__", init)
    monkeypatch.setattr(Remapper, "release", release)
    source = _clip(tmp_path / "in.mkv", ["-c:v", "ffv1", "-pix_fmt", "gbrp"], size="96x54", timecode=None)
    assert correct_video(source, tmp_path / "gl.mkv", lambda _i: (K1, K2), backend="gl", progress=False) == 10
    assert made == ["glradial-correct"] and released == ["glradial-correct"]
    for a, b in zip(_frames(source), _frames(tmp_path / "gl.mkv")):
        # the GL path in memory on this thread's context: same shaders, same result (lossless FFV1)
        np.testing.assert_array_equal(b, glradial.correct(a, K1, K2, backend="gl"))


def test_files_encode_with_frame_threads_and_live_outputs_without(tmp_path):
    """A file is encoded as the ffmpeg command does (frame and slice threads: throughput); a live
    output with slice threads only, so that no frame waits in the encoder for the frames after it."""
    from glradial.media.stream_io import open_live_output

    info = VideoInfo.of((64, 36), 25, codec="libx264")
    frame, slice_ = 1, 2  # FFmpeg's FF_THREAD_FRAME, FF_THREAD_SLICE
    for writer, expected in ((VideoWriter(tmp_path / "file.mp4", info), frame | slice_),
                             (open_live_output(str(tmp_path / "live.ts"), info), slice_)):
        kinds = writer._stream.codec_context.thread_type.value
        writer.abort()
        assert kinds == expected, (writer.path, kinds)
