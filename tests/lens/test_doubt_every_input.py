"""The one doubt policy (glradial.lens.doubt.applies) decides for every input kind of
``correct --auto``: an image through the CLI, a folder (the job's per-file work in this process,
and a real ``--out-dir`` run in worker processes), a video through the CLI, and a live stream. Each
test forces the policy's verdict against what the estimate says (a sure estimate refused, a doubtful
one applied) and checks the output follows the verdict, not the estimate: the decision is made in
that one function and nowhere else. Oracles: the input's own pixels (lossless PNG / FFV1) for a
refused lens, ``glradial.correct`` with the estimate's lens for an applied one."""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from job_inputs import image, pan_video, panorama, read_frames

import glradial
import glradial.lens.doubt
from glradial.cli import build_parser, main
from glradial.jobs.command_line import command_options
from glradial.jobs.tasks import CommandWork
from glradial.media.image_io import read_image, write_image

K1, K2 = -0.2, 0.03
ROAD = Path(__file__).resolve().parents[1] / "data" / "road_straight_lines1.jpg"


def force(monkeypatch, verdict: bool) -> list[tuple]:
    """Make the doubt policy answer ``verdict`` whatever it is asked; the questions are recorded."""
    asked: list[tuple] = []
    monkeypatch.setattr(glradial.lens.doubt, "applies", lambda *question: asked.append(question) or verdict)
    return asked


def estimate_as(monkeypatch, doubtful: bool) -> None:
    """The image estimator (patched in this process) reads K1, K2, sure or doubtful."""
    found = glradial.LensEstimate(K1, K2, uncertainty_px=30.0 if doubtful else 3.0, method="lines",
                                  doubtful=doubtful, reason="weak_geometry" if doubtful else "ok")
    monkeypatch.setattr("glradial.camera.estimator.Estimator.estimate", lambda self, frame, **kw: found)


@pytest.fixture(scope="module")
def pano() -> np.ndarray:
    return panorama()


@pytest.mark.parametrize("verdict", [False, True])
def test_an_image_follows_the_verdict(tmp_path, monkeypatch, pano, verdict):
    source, out = image(tmp_path / "in.png", pano), tmp_path / "out.png"
    estimate_as(monkeypatch, doubtful=verdict)  # the verdict contradicts the estimate
    asked = force(monkeypatch, verdict)
    assert main(["correct", str(source), str(out), "--auto", "--backend", "cpu"]) == 0
    assert asked[0] == (verdict, "weak_geometry" if verdict else "ok", False)
    frame = read_image(source)
    expected = glradial.correct(frame, K1, K2, backend="cpu") if verdict else frame
    np.testing.assert_array_equal(read_image(out), expected)


@pytest.mark.parametrize("verdict", [False, True])
def test_a_folder_job_follows_the_verdict(tmp_path, monkeypatch, pano, verdict):
    """The job's per-file work (what each worker runs for each image of a folder) in this process."""
    folder, staging = tmp_path / "shots", tmp_path / "staging"
    folder.mkdir()
    staging.mkdir()
    sources = [image(folder / f"{i}.png", pano, 40 * i) for i in range(2)]
    estimate_as(monkeypatch, doubtful=verdict)
    asked = force(monkeypatch, verdict)
    args = build_parser().parse_args(["correct", str(folder), "--auto", "--backend", "cpu", "--out-dir", str(tmp_path / "o")])
    work = CommandWork("correct", command_options(args))
    for source in sources:
        facts = work(str(source), staging)
        assert facts["doubtful"] is verdict
        frame = read_image(source)
        expected = glradial.correct(frame, K1, K2, backend="cpu") if verdict else frame
        np.testing.assert_array_equal(read_image(staging / source.name), expected)
    assert [q[0] for q in asked[:1]] == [verdict]


def test_a_folder_through_worker_processes_leaves_a_doubtful_image(tmp_path):
    """The real CLI job (one spawned worker, the bundled estimator): a road photo is not a pitch, so
    its estimate is doubtful and the image comes back untouched; --apply-doubtful corrects it."""
    folder = tmp_path / "shots"
    folder.mkdir()
    write_image(folder / "road.png", cv2.resize(read_image(ROAD), (128, 72), interpolation=cv2.INTER_AREA))
    original = read_image(folder / "road.png")
    for extra, out in (([], tmp_path / "left"), (["--apply-doubtful"], tmp_path / "applied")):
        assert main(["correct", str(folder), "--auto", "--backend", "cpu", "--out-dir", str(out), "--workers", "1",
                     "-q", *extra]) == 0
        result = read_image(out / "road.png")
        assert np.array_equal(result, original) is not bool(extra)


@pytest.mark.parametrize("verdict", [False, True])
def test_a_video_follows_the_verdict(tmp_path, monkeypatch, pano, verdict):
    source, out = pan_video(tmp_path / "in.mkv", pano, n=12), tmp_path / "out.mkv"
    monkeypatch.setattr("glradial.video.video_pipeline.default_estimator", lambda *_: lambda frame: (K1, K2))
    asked = force(monkeypatch, verdict)
    assert main(["correct", str(source), str(out), "--auto", "--every", "2", "--backend", "cpu", "-q"]) == 0
    assert asked and all(len(question) == 3 for question in asked)
    rows = np.genfromtxt(f"{out}.lens.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert np.all(rows["applied"] == int(verdict))  # whatever each shot's own doubt
    for frame, result, row in zip(read_frames(source), read_frames(out), rows):
        expected = glradial.correct(frame, float(row["k1"]), float(row["k2"]), backend="cpu") if verdict else frame
        if verdict:  # RGB through the encoder's planar RGB and back: a level at most
            assert np.abs(result.astype(int) - expected.astype(int)).max() <= 1
            assert not np.array_equal(result, frame)
        else:
            np.testing.assert_array_equal(result, frame)


def test_a_live_stream_follows_the_verdict(monkeypatch, pano):
    """The live corrector's lens (its worker on a thread): an estimator that states no bound leaves
    the shot doubtful and apply_doubtful is off, yet a verdict to apply gets its lens applied."""
    from conftest import LIVE_RATE, LIVE_SIZE

    asked = force(monkeypatch, True)
    frame = cv2.resize(pano[400:670, 300:780], LIVE_SIZE, interpolation=cv2.INTER_AREA)
    with glradial.LiveCorrector("auto", LIVE_SIZE, LIVE_RATE, max_delay=20, estimator=lambda f: (K1, K2),
                                backend="cpu", auto={"every": 4, "worker": "thread"}) as live:
        out = []
        for i in range(12):
            live.push(frame, i / LIVE_RATE)
            out.append(live.pull(None))
            time.sleep(0.03)
    later = out[-1]
    assert later.state.doubtful and later.state.applied is not None  # doubtful, applied: the verdict decided
    assert (later.state.applied.k1, later.state.applied.k2) == pytest.approx((K1, K2))
    assert any(question[0] is True and question[2] is False for question in asked)
    assert np.abs(later.image.astype(int) - glradial.correct(frame, K1, K2, backend="cpu").astype(int)).max() <= 2
