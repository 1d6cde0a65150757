"""The doubt policy is one function (glradial.lens.doubt.applies), and every input kind follows it:
an array through glradial.correct, a video's lens track, the live corrector's lens."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import glradial
from glradial.lens.doubt import FOLD_OVER, applies


@pytest.mark.parametrize("doubtful, reason, apply_doubtful",
                         list(itertools.product([False, True], ["ok", "uncertain", FOLD_OVER], [False, True])))
def test_the_policy_table(doubtful, reason, apply_doubtful):
    expected = (not doubtful) or (apply_doubtful and reason != FOLD_OVER)
    assert applies(doubtful, reason, apply_doubtful) is expected


def test_a_bad_choice_is_named():
    with pytest.raises(TypeError, match="apply_doubtful"):
        applies(True, "uncertain", "yes")


def test_correct_follows_the_policy(monkeypatch):
    calls = []
    real = glradial.lens.doubt.applies
    monkeypatch.setattr(glradial.lens.doubt, "applies", lambda *a: calls.append(a) or real(*a))
    frame = np.random.default_rng(0).integers(0, 255, (36, 64, 3), np.uint8)
    doubtful = glradial.LensEstimate(-0.3, 0.0, doubtful=True, reason="weak_geometry")
    assert np.array_equal(glradial.correct(frame, doubtful, backend="cpu"), frame)
    applied = glradial.correct(frame, doubtful, backend="cpu", apply_doubtful=True)
    assert np.array_equal(applied, glradial.correct(frame, -0.3, backend="cpu"))
    assert calls[:2] == [(True, "weak_geometry", False), (True, "weak_geometry", True)]


def test_a_video_track_follows_the_policy(monkeypatch):
    from glradial.video import shot_track

    calls = []
    real = glradial.lens.doubt.applies
    monkeypatch.setattr(glradial.lens.doubt, "applies", lambda *a: calls.append(a) or real(*a))

    class Fit:
        doubtful, reason, uncertainty_px = True, "uncertain", 25.0

        @staticmethod
        def lens_at(zoom):
            return np.tile([-0.2, 0.03], (len(zoom), 1))

    class Shots:
        starts, fits, sampled, estimates = [0], [Fit()], [(np.array([0]), np.array([0.0]))], []

    class Info:
        rate, size = 25, (64, 36)

    track = shot_track._track(Info(), np.arange(3) / 25, Shots(), False, 10.0)
    assert not track.applied.any() and calls == [(True, "uncertain", False)] * 3
    calls.clear()
    assert shot_track._track(Info(), np.arange(3) / 25, Shots(), True, 10.0).applied.all()
    assert calls == [(True, "uncertain", True)] * 3


def test_the_live_lens_follows_the_policy(monkeypatch):
    from glradial.video import live_lens

    calls = []
    real = glradial.lens.doubt.applies
    monkeypatch.setattr(glradial.lens.doubt, "applies", lambda *a: calls.append(a) or real(*a))
    online = object.__new__(live_lens.OnlineShotLens)  # the lens state alone: no worker started
    online._fits, online._last_sure, online.until_sure = {}, None, "none"
    online._fits[0] = live_lens._Fit(glradial.Lens(-0.2, 0.03), 25.0, True, "uncertain")
    for apply_doubtful in (False, True):
        online.apply_doubtful = apply_doubtful
        state = online._state(0)
        assert state.doubtful and (state.applied == glradial.Lens(-0.2, 0.03) if apply_doubtful else state.applied is None)
    assert calls == [(True, "uncertain", False), (True, "uncertain", True)]
