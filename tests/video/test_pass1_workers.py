"""Pass 1 with its work on worker threads (``track_shots(ahead=True)``: the estimator ahead of the
samples, the matches beside the line chains, each shot's fit beside the next shot's scan) gives
the very track of the same work done in turn (``ahead=False``): the oracle is that sequential run.

Two clips: three shots of textured, drifting pictures (matches found, few line chains, so the
per-frame estimator also runs on samples that are not due: the order-sensitive case), and
bench_video's pan across the packaged real match frame (pitch lines: a joint fit of chains and
frame pairs). The estimator's answer and stated bound depend on the frame, so that the hint the
line detector and matcher use changes from sample to sample.
"""

from __future__ import annotations

import shutil
import threading

import numpy as np
import pytest
from repo_scripts import load_script
from test_sparse_pass import _clip

import glradial.video.shot_track as shot_track
from glradial.estimation.lens_estimate import LensEstimate

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs ffmpeg (make setup installs it)")


class Estimator:
    """A frame's lens from its brightness, a bound that varies; records the threads that call it."""

    def __init__(self, fail_at: int | None = None) -> None:
        self.threads: set[int] = set()
        self.calls = 0
        self.fail_at = fail_at

    def __call__(self, frame: np.ndarray) -> LensEstimate:
        self.threads.add(threading.get_ident())
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("estimator failed")
        level = float(frame.mean()) / 255.0
        return LensEstimate(-0.05 - 0.3 * level, 0.02, uncertainty_px=5.0 + float(int(frame.sum()) % 11), method="net")


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    path = tmp_path_factory.mktemp("workers") / "three_shots.mp4"
    _clip(path, [(0, 40), (1, 33), (2, 47)])
    return path


@pytest.fixture(scope="module")
def pan(tmp_path_factory):
    bench = load_script("bench/bench_video.py")
    path = tmp_path_factory.mktemp("workers") / "pan.mp4"
    bench.make_clip(path, (480, 270), 60, "pan", bench.bundled_frame_path())
    return path


def _tracked(path, estimator, ahead: bool):
    """The track, and per shot the evidence its fit got: samples (frame, chains, estimate), zooms,
    travel and pan, and each frame pair's homography."""
    seen = []
    fit = shot_track.fit_shot

    def spy(evidence, **kwargs):
        seen.append(([(s.frame, None if s.evidence is None else len(s.evidence.chains), None if s.estimate is None else
                       (s.estimate.k1, s.estimate.k2)) for s in evidence.samples], list(evidence.zoom), evidence.travel,
                     evidence.pan, [(i, j, m.homography.round(12).tolist()) for i, j, m in evidence.pairs]))
        return fit(evidence, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(shot_track, "fit_shot", spy)
        track = shot_track.track_shots(path, estimator, every=4, progress=False, ahead=ahead)
    return track, seen


@pytest.mark.parametrize("name, frames, shots", [("clip", 120, 3), ("pan", 60, 1)])
def test_workers_give_the_sequential_track(name, frames, shots, request):
    path = request.getfixturevalue(name)
    alone, ahead = Estimator(), Estimator()
    a, evidence_a = _tracked(path, alone, False)
    b, evidence_b = _tracked(path, ahead, True)
    assert evidence_a == evidence_b and any(pairs for *_, pairs in evidence_a)  # what each shot's fit was given
    assert a.n_frames == b.n_frames == frames and len(a.per_shot()) == shots
    if name == "pan":
        assert "lines" in a.per_shot()[0]["methods"] or a.per_shot()[0]["uncertainty_px"] < 30  # a joint fit, not the estimates
    for name, value in vars(a).items():
        other = getattr(b, name)
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, other, equal_nan=True), name
        else:
            assert value == other, name
    assert alone.calls == ahead.calls > len(a.per_shot())  # the same frames estimated
    assert alone.threads == {threading.get_ident()}
    assert len(ahead.threads) == 1 and threading.get_ident() not in ahead.threads  # one worker thread uses it


def test_the_last_shot_is_fitted_while_the_frames_after_its_last_sample_decode(clip, monkeypatch):
    """Once the last shot has its last sample (no frame left a stride on), it is closed and its fit
    starts while the frames after that sample still decode; the track is the one of a fit started
    at the end of the video (the oracle: the same run with the early close switched off)."""
    from test_sparse_pass import Counting

    closed_at: list[int] = []  # frames the cut detector had seen when each shot was closed
    close = shot_track._Shots.close

    def spy(self):
        if self.collector is not None:
            closed_at.append(Counting.seen)
        close(self)

    monkeypatch.setattr(shot_track._Shots, "close", spy)

    def run():
        Counting.seen = 0
        closed_at.clear()
        track = shot_track.track_shots(clip, Estimator(), every=4, progress=False, detector=Counting())
        return track, list(closed_at), Counting.seen

    early, at, seen = run()
    assert len(at) == 3 and at[-1] < seen  # the last shot closed before the decode ended
    monkeypatch.setattr(shot_track, "_last_sample", lambda *args: False)
    late, at_end, _ = run()
    assert at_end[-1] == seen and at_end[:2] == at[:2]  # closed at the end; the others at their cuts
    for name, value in vars(early).items():
        other = getattr(late, name)
        assert np.array_equal(value, other, equal_nan=True) if isinstance(value, np.ndarray) else value == other, name


def test_an_estimator_error_reaches_the_caller_and_ends_the_workers(clip):
    with pytest.raises(RuntimeError, match="estimator failed"):
        shot_track.track_shots(clip, Estimator(fail_at=3), every=4, progress=False, ahead=True)
    assert not [t for t in threading.enumerate() if t.name.startswith(("glradial-estimate", "glradial-fit", "glradial-motion"))]


def test_one_core_runs_in_turn_and_ahead_must_be_a_bool(clip, monkeypatch):
    from glradial import threads

    monkeypatch.setitem(threads._BUDGET, "threads", 1)  # a job's worker with one core
    estimator = Estimator()
    shot_track.track_shots(clip, estimator, every=8, progress=False, ahead=True)
    assert estimator.threads == {threading.get_ident()}
    with pytest.raises(TypeError, match="ahead must be a bool, got 'yes'"):
        shot_track.track_shots(clip, estimator, ahead="yes")
