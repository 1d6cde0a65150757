"""Shared fixtures: one headless EGL context for the session, the GL error flag checked around
each test that uses it, and the real photographs of tests/data (copies of ../shared/data)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
# the shared helpers beside this file (repo_scripts, pitch_template) for the tests in the sub-folders
sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def gl_ctx():
    """The test thread's glradial context (the one the module-level functions use)."""
    from glradial.gl.egl import thread_context

    return thread_context()


@pytest.fixture()
def ctx(gl_ctx):
    """The session context, with the GL error flag required clean before and after the test."""
    assert gl_ctx.error == "GL_NO_ERROR", "GL error flag was set before the test"
    yield gl_ctx
    assert gl_ctx.error == "GL_NO_ERROR", "test left the GL error flag set"


def read_rgb(name: str) -> np.ndarray:
    """A test photo as H×W×3 uint8 RGB."""
    image = cv2.imread(str(DATA / name), cv2.IMREAD_COLOR)
    assert image is not None, f"cannot read {DATA / name}"
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="session")
def chessboard() -> np.ndarray:
    return read_rgb("chessboard_calibration2.jpg")


@pytest.fixture(scope="session")
def road() -> np.ndarray:
    return read_rgb("road_straight_lines1.jpg")


@pytest.fixture(scope="session")
def field_panorama() -> np.ndarray:
    return read_rgb("panorama_field_2048x1024.jpg")


#: the live streaming tests' clip: (width, height) px, frames per second, seconds
LIVE_SIZE, LIVE_RATE, LIVE_SECONDS = (320, 180), 25, 2


@pytest.fixture(scope="session")
def live_clip(tmp_path_factory) -> Path:
    """2 s of testsrc2 at 320x180 25p, H.264 (a key frame every 10 frames) in MPEG-TS: the clip the
    live tests stream (tests/video/test_live.py, tests/media/test_live_transports.py)."""
    path = tmp_path_factory.mktemp("live") / "clip.ts"
    subprocess.run(["ffmpeg", "-v", "error", "-f", "lavfi", "-i",
                    f"testsrc2=size={LIVE_SIZE[0]}x{LIVE_SIZE[1]}:rate={LIVE_RATE}:duration={LIVE_SECONDS}",
                    "-c:v", "libx264", "-preset", "ultrafast", "-crf", "12", "-g", "10", "-pix_fmt", "yuv420p",
                    "-f", "mpegts", str(path)], check=True)
    return path


def check_existing_out_needs_y(argv: list[str], out: Path, expensive: str, monkeypatch, capsys) -> None:
    """The CLI's overwrite rule for a command writing the single file ``out``: without -y an existing
    ``out`` is refused (one error line, file untouched, no temporary file) before ``expensive`` (the
    dotted name of the function doing the work) is called; with -y the command succeeds."""
    from glradial.cli import main

    out.write_bytes(b"keep me")
    with monkeypatch.context() as patch:
        patch.setattr(expensive, lambda *a, **k: pytest.fail(f"{expensive} ran before the overwrite check"))
        assert main(argv) == 1
    assert f"output {str(out)!r} already exists (overwrite it with -y/--overwrite)" in capsys.readouterr().err
    assert out.read_bytes() == b"keep me" and list(out.parent.iterdir()) == [out]
    assert main([*argv, "-y"]) == 0
