"""The camera's first guess (glradial.camera.first_guess) against pinhole views with known cameras:
frames drawn from the pitch template through a known homography (tests/pitch_template.py, cv2
drawing, independent of the search) must give that homography back at the keypoints; frames with no
pitch must give nothing; bad arguments are refused by name."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pitch_template
import pytest

import glradial
from glradial.camera.first_guess import Candidate, first_guess
from glradial.camera.line_hypotheses import camera_of, template_lines
from glradial.pitch import PitchTemplate

SIZE = (1280, 720)
#: pitch_template's homographies take corner-origin pitch coordinates; first_guess centre-spot ones.
TO_CORNER = np.array([[1.0, 0.0, pitch_template.LENGTH / 2], [0.0, 1.0, pitch_template.WIDTH / 2], [0.0, 0.0, 1.0]])
ROAD = Path(__file__).resolve().parents[2].parent / "shared/data/road_straight_lines1.jpg"


@pytest.fixture(scope="module")
def template():
    return PitchTemplate().sampled_points(0.25)


def _view(camera, target, hfov_deg, lens=None, size=SIZE):
    """``(frame RGB, true homography centre-spot metres -> px)`` of a pinhole view (corner-origin
    camera and target, as pitch_template takes them), through ``lens`` when given."""
    h = pitch_template.homography(camera, target, hfov_deg, size)
    image = pitch_template.render(h, size, thickness=max(2, round(3 * size[0] / SIZE[0])))
    if lens is not None:  # at scale 1 (fit "same"): the undistorted frame is the rendered one
        map_x, map_y = glradial.Lens(*lens).maps(size, direction="distort", fit="same")
        image = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(image[:, :, ::-1]), h @ TO_CORNER


def _project(h, points):
    p = np.column_stack([points, np.ones(len(points))]) @ h.T
    return p[:, :2] / p[:, 2:3]


def _keypoint_errors(found: Candidate, truth: np.ndarray, size=SIZE) -> np.ndarray:
    """Distances (px) between the keypoints in the frame by the true and the found homography."""
    keypoints = PitchTemplate().keypoints()[:, :2]
    true_xy = _project(truth, keypoints)
    inside = (true_xy[:, 0] >= 0) & (true_xy[:, 0] < size[0]) & (true_xy[:, 1] >= 0) & (true_xy[:, 1] < size[1])
    assert inside.sum() >= 4
    return np.linalg.norm(_project(found.homography, keypoints[inside]) - true_xy[inside], axis=1)


# Views of the main camera (corner-origin metres): the centre (circle, halfway line, both touchlines,
# the boxes at the sides), a wide view of one half, and a tele view of one box and nothing else.
VIEWS = {
    "centre": pitch_template.CENTRE_VIEW,
    "half": dict(camera=(60.0, -45.0, 25.0), target=(60.0, 34.0), hfov_deg=70.0),
    "box": pitch_template.BOX_VIEW,
}


@pytest.mark.parametrize("name", sorted(VIEWS))
def test_known_view_comes_back_at_the_keypoints(template, name):
    frame, truth = _view(**VIEWS[name])
    found = first_guess(frame, *template)
    assert found, "a clear view of the pitch must be answered"
    errors = _keypoint_errors(found[0], truth)
    # lines drawn 3 px wide and found on a 640-px copy: the keypoints within about 1-2 px
    assert np.sqrt(np.mean(errors**2)) <= 1.5, errors
    assert errors.max() <= 4.0, errors
    assert found[0].homography.shape == (3, 3) and found[0].homography.dtype == np.float64
    assert [c.score for c in found] == sorted((c.score for c in found), reverse=True)


@pytest.mark.parametrize("size", [(1920, 1080), (480, 270)])
def test_other_frame_sizes(template, size):
    # the search runs on a 640-px copy; the homography is the frame's own, at any size
    frame, truth = _view(**VIEWS["centre"], size=size)
    found = first_guess(frame, *template)
    assert found
    assert np.sqrt(np.mean(_keypoint_errors(found[0], truth, size) ** 2)) <= 1.5 * size[0] / SIZE[0]


def test_partial_view_of_one_box_is_answered(template):
    # tele view of the left penalty area only: no touchline, no halfway line, no circle
    frame, truth = _view(camera=(25.0, -25.0, 15.0), target=(8.0, 34.0), hfov_deg=28.0)
    seen = _project(truth, PitchTemplate().keypoints()[:, :2])
    assert not np.any((np.abs(seen[13:17, 0] - 640) < 640) & (np.abs(seen[13:17, 1] - 360) < 360))  # no halfway point
    found = first_guess(frame, *template)
    assert found
    assert np.sqrt(np.mean(_keypoint_errors(found[0], truth) ** 2)) <= 1.5


@pytest.mark.parametrize("view", [
    dict(camera=(52.5, -30.0, 20.0), target=(52.5, 40.0), hfov_deg=34.0),  # circle, halfway, far touchline
    dict(camera=(60.0, -40.0, 18.0), target=(55.0, 20.0), hfov_deg=28.0),  # ... and the near touchline
])
def test_centre_circle_and_halfway_line_are_enough(template, view):
    frame, truth = _view(**view)
    seen = _project(truth, PitchTemplate().keypoints()[:, :2])
    inside = (np.abs(seen[:, 0] - 640) < 640) & (np.abs(seen[:, 1] - 360) < 360)
    assert set(np.flatnonzero(inside)) <= {13, 14, 15, 16, 30, 31}  # only the halfway line's points
    found = first_guess(frame, *template)
    assert found
    assert np.sqrt(np.mean(_keypoint_errors(found[0], truth) ** 2)) <= 1.5


def test_lens_given_maps_to_the_undistorted_frame(template):
    lens = (-0.12, 0.02)
    frame, truth = _view(**VIEWS["centre"], lens=lens)
    plain = first_guess(frame, *template)
    found = first_guess(frame, *template, lens=lens)
    assert found
    errors = _keypoint_errors(found[0], truth)
    assert np.sqrt(np.mean(errors**2)) <= 2.0, errors
    # without the lens the same frame is fitted worse by a plain homography
    assert not plain or np.sqrt(np.mean(_keypoint_errors(plain[0], truth) ** 2)) > np.sqrt(np.mean(errors**2))


def test_camera_read_from_the_homography(template):
    view = VIEWS["half"]
    _, truth = _view(**view)
    focal, centre, metric = camera_of(truth[None], SIZE)
    assert metric[0]
    assert focal[0] == pytest.approx(0.5 / np.tan(np.radians(view["hfov_deg"] / 2)), rel=1e-6)
    expected = np.array(view["camera"]) - [pitch_template.LENGTH / 2, pitch_template.WIDTH / 2, 0.0]
    assert centre[0] == pytest.approx(expected, abs=1e-6)


def test_template_lines_are_read_from_the_points(template):
    xs, ys = template_lines(template[0], 0.25)
    assert xs == pytest.approx([-52.5, -47.0, -36.0, 0.0, 36.0, 47.0, 52.5])
    assert ys == pytest.approx([-34.0, -20.16, -9.16, 9.16, 20.16, 34.0])


def _green_noise() -> np.ndarray:
    rng = np.random.default_rng(1)
    grass = np.full((*SIZE[::-1], 3), (40, 110, 40), np.float64)
    return np.clip(grass + rng.normal(0, 12, grass.shape), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("kind", ["blank", "noise", "green_noise", "road"])
def test_frames_without_a_pitch_give_nothing(template, kind):
    if kind == "road":
        if not ROAD.exists():
            pytest.skip("../shared/data is not here")
        frame = np.ascontiguousarray(cv2.imread(str(ROAD))[:, :, ::-1])
    elif kind == "blank":
        frame = np.full((*SIZE[::-1], 3), (40, 110, 40), np.uint8)
    elif kind == "noise":
        frame = np.random.default_rng(0).integers(0, 256, (*SIZE[::-1], 3), dtype=np.uint8)
    else:
        frame = _green_noise()
    assert first_guess(frame, *template) == []


def test_bad_arguments_are_refused_by_name(template):
    points, labels = template
    frame = np.zeros((72, 128, 3), np.uint8)
    with pytest.raises(TypeError, match="frame_rgb"):
        first_guess([[0]], points, labels)
    with pytest.raises(ValueError, match="frame_rgb"):
        first_guess(frame.astype(np.float32), points, labels)
    with pytest.raises(ValueError, match="frame_rgb"):
        first_guess(frame[..., 0], points, labels)
    with pytest.raises(ValueError, match="template_points"):
        first_guess(frame, points[:, :1], labels)
    with pytest.raises(ValueError, match="template_points"):
        first_guess(frame, np.where(np.arange(len(points))[:, None] == 3, np.nan, points), labels)
    with pytest.raises(ValueError, match="template_labels"):
        first_guess(frame, points, labels[:-1])
    with pytest.raises(ValueError, match="template_labels"):
        first_guess(frame, points, labels.astype(float))
    with pytest.raises(TypeError, match="max_candidates"):
        first_guess(frame, points, labels, max_candidates=2.0)
    with pytest.raises(ValueError, match="max_candidates"):
        first_guess(frame, points, labels, max_candidates=0)
    with pytest.raises(ValueError, match="lens"):
        first_guess(frame, points, labels, lens=(0.1,))
    with pytest.raises(ValueError, match="lens"):  # folds over inside the frame: no undistorted frame
        first_guess(frame, points, labels, lens=(-3.0, 0.0))


def test_coverage_lookup_path_equals_the_direct_one():
    """Scoring many hypotheses looks each pixel's gain up from an image computed once; the scores and
    shares must equal those of the hypotheses scored one at a time (the direct path)."""
    from glradial.camera.first_guess import coverage

    rng = np.random.default_rng(5)
    dist = rng.uniform(0, 6, (90, 160)).astype(np.float32)
    field = (rng.uniform(size=(90, 160)) > 0.2).astype(np.uint8)
    points = np.stack(np.meshgrid(np.linspace(-50, 50, 30), np.linspace(-30, 30, 20)), -1).reshape(-1, 2)
    h = np.array([[[1.5 + 0.1 * a, 0.2, 80], [0.05, -1.0 - 0.1 * a, 45], [0.0, 0.001 * a, 1]] for a in range(40)])
    many = coverage(h, points, 0.5, dist, field, share=True)
    one = np.column_stack([coverage(h[k:k + 1], points, 0.5, dist, field, share=True) for k in range(len(h))])
    assert len(h) * len(points) > dist.size > len(points)  # the two paths are the ones compared
    np.testing.assert_array_equal(many, one)
    assert np.all(many[1] >= 0) and np.all(many[1] <= 1) and np.ptp(many[0]) > 0
