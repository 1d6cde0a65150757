"""Tiny inputs shared by the job tests: pan videos over the real field panorama (lossless FFV1),
crops of it as images, rendered pitch views with a known camera, and a corrupt file; what the tests
read back (the report, the manifest while a job runs)."""

from __future__ import annotations

import csv
import json
import signal
import time
from pathlib import Path

import cv2
import numpy as np

from glradial import Lens
from glradial.camera.model import Camera
from glradial.camera.views import render_view
from glradial.media.video_io import VideoInfo, VideoWriter

ROOT = Path(__file__).resolve().parents[1]


def panorama() -> np.ndarray:
    return cv2.imread(str(ROOT / "tests" / "data" / "panorama_field_2048x1024.jpg"))[:, :, ::-1].copy()


def pan_video(path: Path, pano: np.ndarray, n: int = 10, x0: int = 200) -> Path:
    """160x90 frames panning over ``pano`` (FFV1, planar RGB: lossless, so outputs compare exactly)."""
    with VideoWriter(path, VideoInfo.of((160, 90), 25, codec="ffv1", pix_fmt="gbrp")) as writer:
        for i in range(n):
            crop = pano[420:690, x0 + 4 * i : x0 + 4 * i + 480]
            writer.write(cv2.resize(crop, (160, 90), interpolation=cv2.INTER_AREA))
    return path


def image(path: Path, pano: np.ndarray, dy: int = 0) -> Path:
    cv2.imwrite(str(path), cv2.resize(pano[400 + dy : 670 + dy, 300:780], (320, 180), interpolation=cv2.INTER_AREA)[:, :, ::-1])
    return path


def pitch_view(path: Path, pan: float) -> Camera:
    """A 640x360 rendered view of the main camera (barrel lens) aimed ``pan`` m along the pitch."""
    cam = Camera.look_at((3.0, -64.0, 18.0), (-25.0 + pan, 2.0), 48.0, (640, 360), Lens(-0.18, 0.0187))
    cv2.imwrite(str(path), render_view(cam, seed=5).frame[:, :, ::-1])
    return cam


def corrupt(path: Path) -> Path:
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(200)))
    return path


def read_frames(path: Path) -> list[np.ndarray]:
    from glradial.media.video_io import VideoReader

    with VideoReader(path) as reader:
        return [np.array(frame) for frame in reader]


def rows_of(out: Path) -> dict[str, dict]:
    """DIR/report.csv by input file name."""
    with open(out / "report.csv", newline="") as handle:
        return {Path(row["input"]).name: row for row in csv.DictReader(handle)}


def wait_for_a_done_input(out: Path, job, seconds: float) -> None:
    """Until the running ``job`` (a ``Popen``) has recorded an input as done in DIR/manifest.json."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and job.poll() is None:
        try:
            if any(e["status"] == "done" for e in json.loads((out / "manifest.json").read_text())["entries"].values()):
                return
        except (OSError, ValueError, KeyError):
            pass
        time.sleep(0.05)


def ignore_sigint() -> None:
    """``preexec_fn`` of a job started to be interrupted: with SIGINT ignored, as a script's background
    job (``cmd &``) starts; glradial must stop on it all the same (``cli._signals_unwind``)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
