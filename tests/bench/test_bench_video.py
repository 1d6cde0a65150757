"""bench/bench_video.py runs from a checkout alone: its default picture is the frame shipped in the package."""

from __future__ import annotations

from pathlib import Path

from repo_scripts import load_script

import glradial
from glradial.commands.demo import FRAME_NAME
from glradial.media.image_io import read_image


def _bench_video():
    return load_script("bench/bench_video.py")


def test_default_frame_is_the_packaged_one() -> None:
    args = _bench_video().parse_args([])
    frame = Path(args.frame).resolve()
    assert frame.is_relative_to(Path(glradial.__file__).resolve().parent / "data"), frame
    assert frame.name == FRAME_NAME and read_image(frame).shape == (720, 1280, 3)
    assert _bench_video().parse_args(["--frame", "x.png"]).frame == Path("x.png")
