"""bench/bench_video.py runs from a checkout alone: its default picture is the frame shipped in the package."""

from __future__ import annotations

from pathlib import Path

import pytest
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


def test_a_subset_of_paths_reports_only_the_ratios_it_has(capsys) -> None:
    bench = _bench_video()
    args = bench.parse_args(["--paths", "ffmpeg,fixed lens", "--frames", "100"])
    inf = float("inf")
    # three rounds: the best times (2.0 and 2.5 s) come from different rounds, the rounds' own
    # ratios are 2.0/2.5, 3.0/3.0 and 2.4/3.2
    turns = {"ffmpeg": [2.0, 3.0, 2.4], "fixed lens": [2.5, 3.0, 3.2]}
    results = bench.report(args, {"ffmpeg": 2.0, "fixed lens": 2.5}, {"pass 1": inf, "pass 2": inf},
                           {"RGB": 1.0, "YUV": 0.5, "YUV 1/32": 0.7}, {"ffmpeg": 3.0, "fixed lens": 4.0}, turns)
    # frames per second: 40 against 50; CPU: 4 s against 3 s for the same frames; rounds: median of 0.8, 1.0, 0.75
    assert results["ratios"] == {"fixed / ffmpeg": 0.8, "fixed / ffmpeg (CPU)": 0.75, "fixed / ffmpeg (median of rounds)": 0.8}
    assert results["per_round_ratios"].keys() == {"fixed / ffmpeg"}
    assert results["per_round_ratios"]["fixed / ffmpeg"] == pytest.approx([0.8, 1.0, 0.75], rel=1e-12)
    assert results["cpu_ms_per_frame"] == {"ffmpeg": 30.0, "fixed lens": 40.0}
    assert results["fps"] == {"ffmpeg": 50.0, "fixed lens": 40.0} and results["paths"] == ["ffmpeg", "fixed lens"]
    out = capsys.readouterr().out
    assert "fixed / ffmpeg                    : 0.80  (target >= 0.8)" in out
    assert "fixed / ffmpeg (median of rounds) : 0.80  (target >= 0.8, rounds 0.75-1.00)" in out
