"""Pass 1 on a subsample: the decoder skips the frames no other frame refers to, the frames it
decodes are numbered by the packets' timestamps, and a candidate cut seen between two decoded
frames is confirmed and placed by the full decode's test on just that stretch, decoded again.

Oracle: clips whose cuts are known by construction (three different scenes, each drifting a
little so that consecutive frames differ), encoded by libx264 with B-frames (x264's defaults:
about half the frames are not referenced); ffprobe says which frames are B-frames and how many
there are. Every frame must land in its true shot, also for a shot that starts and ends between
two samples, and the answer must equal the full decode's (``sparse=False``).
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

import glradial.video.shot_track as shot_track
from glradial.lens.lens import Lens
from glradial.media.video_io import VideoInfo, VideoWriter, frame_timestamps
from glradial.video.cuts import ShotDetector

pytestmark = pytest.mark.skipif(shutil.which("ffprobe") is None, reason="needs ffprobe (make setup installs it)")
SIZE = (160, 90)


def _scene(kind: int, step: int) -> np.ndarray:
    """A textured picture of one of three colour schemes, moved ``step`` px across."""
    rng = np.random.default_rng(kind)
    texture = rng.integers(0, 60, (SIZE[1], SIZE[0] + 64, 3))
    base = np.array([(40, 150, 50), (160, 60, 60), (50, 70, 180)][kind])
    return np.clip(base + texture[:, step : step + SIZE[0]], 0, 255).astype(np.uint8)


def _clip(path, shots: list[tuple[int, int]], scenecut: bool = True) -> np.ndarray:
    """H.264 clip of ``shots`` ((scene, frames) each) by the ffmpeg command (libx264, 3 B-frames;
    ``scenecut=False``: no key frame forced at a cut, as in a fixed-GOP broadcast encode); returns
    the true shot of every frame."""
    frames = [_scene(kind, step) for kind, count in shots for step in range(count)]
    truth = np.concatenate([np.full(count, number) for number, (_kind, count) in enumerate(shots)])
    params = "keyint=60:bframes=3" + ("" if scenecut else ":scenecut=0")
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{SIZE[0]}x{SIZE[1]}",
                    "-r", "25", "-i", "-", "-c:v", "libx264", "-crf", "20", "-x264-params", params, "-pix_fmt", "yuv420p",
                    str(path)], input=np.stack(frames).tobytes(), check=True)
    return truth


class Counting(ShotDetector):
    """A cut detector that counts the frames it is shown."""

    seen = 0

    def update(self, frame: np.ndarray, advance: int = 1) -> bool:
        Counting.seen += 1
        return super().update(frame, advance)


def _track(path, sparse: bool, monkeypatch) -> tuple[np.ndarray, list, int]:
    """The shot of every frame, the candidate cuts checked ``(a, b, first frame or None)``, and
    how many frames the cut detector saw."""
    windows: list = []
    confirm = shot_track.CutCheck.confirm

    def spy(self, a, b, start):
        windows.append((a, b, confirm(self, a, b, start)))
        return windows[-1][2]

    monkeypatch.setattr(shot_track.CutCheck, "confirm", spy)
    Counting.seen = 0
    track = shot_track.track_shots(path, lambda _frame: Lens(-0.2, 0.0), every=10, progress=False, sparse=sparse,
                                   detector=Counting())
    monkeypatch.undo()
    return track.shot, windows, Counting.seen


def _b_frames(path) -> list[int]:
    out = subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries", "frame=pict_type",
                          "-of", "json", str(path)], check=True, capture_output=True, text=True).stdout
    return [i for i, frame in enumerate(json.loads(out)["frames"]) if frame["pict_type"] == "B"]


@pytest.mark.parametrize("cut", [17, 18, 19, 20])
def test_cuts_are_placed_exactly_from_a_sparse_decode(tmp_path, monkeypatch, cut):
    path = tmp_path / "clip.mp4"
    truth = _clip(path, [(0, cut), (1, 40 - cut)])
    assert len(frame_timestamps(path)) == 40
    shots, windows, decoded = _track(path, True, monkeypatch)
    assert list(shots) == list(truth)
    assert decoded < 0.8 * len(truth) and len(_b_frames(path)) > 0.3 * len(truth)  # a real subsample
    exact, _, everything = _track(path, False, monkeypatch)
    assert list(exact) == list(truth) and everything == len(truth)
    assert [first for _a, _b, first in windows if first is not None] == [cut]  # confirmed, placed exactly
    assert all(a < cut <= b for a, b, first in windows if first is not None)


def test_a_window_is_placed_when_the_cut_falls_on_a_skipped_frame(tmp_path, monkeypatch):
    """Over a few cut positions, at least one shot starts on a frame the sparse decode skipped."""
    placed = 0
    for cut in (13, 14, 15):
        path = tmp_path / f"clip{cut}.mp4"
        truth = _clip(path, [(0, cut), (2, 30 - cut)], scenecut=False)
        shots, windows, _ = _track(path, True, monkeypatch)
        assert list(shots) == list(truth)
        placed += any(first == cut < b for _a, b, first in windows)
    assert placed >= 1


def test_a_shot_between_two_samples(tmp_path, monkeypatch):
    """Shot 1 lasts 6 frames, shorter than the sampling stride (10): it starts and ends between
    the samples of its neighbours and still gets its frames, exactly."""
    path = tmp_path / "short.mp4"
    truth = _clip(path, [(0, 23), (1, 6), (2, 21)], scenecut=False)
    shots, _, _ = _track(path, True, monkeypatch)
    assert list(shots) == list(truth)


def test_streams_that_cannot_be_numbered_are_decoded_whole(tmp_path, monkeypatch):
    path = tmp_path / "lossless.mkv"
    with VideoWriter(path, VideoInfo.of(SIZE, 25, codec="ffv1")) as writer:
        for step in range(12):
            writer.write(_scene(0, step))
    assert frame_timestamps(path) is None  # FFV1: every frame is a key frame, nothing to skip
    shots, windows, decoded = _track(path, True, monkeypatch)
    assert decoded == 12 and windows == [] and list(shots) == [0] * 12  # and no cut was checked
    with pytest.raises(TypeError, match="sparse must be a bool"):
        shot_track.track_shots(path, lambda _frame: Lens(0, 0), sparse="yes")
