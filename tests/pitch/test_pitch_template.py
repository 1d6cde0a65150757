"""The pitch template: IFAB dimensions, keypoints in the order of the shared Bundesliga labels, every
keypoint on the markings it names, configurable dimensions and clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from glradial.pitch import KEYPOINT_NAMES, PitchTemplate

LABELS = Path(__file__).resolve().parents[3] / "shared/data/broadcast_bundesliga/keypoints/keypoints.json"


def _distance_to_markings(template: PitchTemplate, points: np.ndarray) -> np.ndarray:
    """Distance (m) from each point to the nearest sampled marking (1 cm samples)."""
    samples = np.concatenate([p for _, p in template.polylines(0.01)])
    return np.array([np.min(np.hypot(*(samples - q).T)) for q in points])


def test_keypoints_match_the_labels_order_and_positions():
    if not LABELS.is_file():
        pytest.skip("shared Bundesliga labels not present")
    data = json.loads(LABELS.read_text())
    names = [k["name"] for k in data["keypoints"]]
    assert list(KEYPOINT_NAMES) == names
    # the labels round the penalty-arc crossing (sqrt(9.15² - 5.5²) = 7.3125 m) to 7.31 m
    np.testing.assert_allclose(PitchTemplate().keypoints(), [k["pitch_m"] for k in data["keypoints"]], atol=3e-3)


@pytest.mark.parametrize("template", [PitchTemplate(), PitchTemplate(length=100.0, width=64.0)])
def test_every_keypoint_lies_on_the_markings_except_the_spots(template):
    kp = template.keypoints()
    spots = [8, 21]
    on = np.setdiff1d(np.arange(32), spots)
    assert np.all(_distance_to_markings(template, kp[on, :2]) < 0.01)
    np.testing.assert_allclose(kp[spots, :2], template.spots()[[0, 2]])
    assert np.all(np.abs(kp[:, 0]) <= template.length / 2) and np.all(np.abs(kp[:, 1]) <= template.width / 2)


def test_half_turn_symmetry_and_sampling():
    t = PitchTemplate()
    samples = np.concatenate([p for _, p in t.polylines(0.05)])
    turned = -samples
    # the markings map onto themselves under the half turn (x, y) -> (-x, -y)
    assert _distance_to_markings(t, turned[::97]).max() < 0.03
    for label, pts in t.polylines(0.5):
        steps = np.hypot(*np.diff(pts, axis=0).T)
        assert steps.max() <= 0.5 + 1e-9, label
    arc = dict(t.polylines(0.1))["left_arc"]
    # the penalty arc stays outside the area: x >= the box front (-36 m), reaching it at both ends
    assert arc[:, 0].min() >= -36.0 - 1e-9 and np.isclose(arc[[0, -1], 0], -36.0).all()
    assert np.isclose(np.hypot(arc[:, 0] + 41.5, arc[:, 1]), 9.15).all()


@pytest.mark.parametrize("kwargs, word", [({"length": -1.0}, "length"), ({"width": "68"}, "width"),
                                          ({"box_width": 10.0}, "box_width"), ({"circle_radius": 40.0}, "circle_radius")])
def test_bad_dimensions_name_the_argument(kwargs, word):
    with pytest.raises((ValueError, TypeError), match=word):
        PitchTemplate(**kwargs)
