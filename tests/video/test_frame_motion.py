"""Frame-to-frame matches (glradial.video.frame_motion): two views of one textured plane related by a
known homography (``cv2.warpPerspective``, independent of the matcher) must be matched where the
homography puts each point, with corners found ahead giving the same matches."""

from __future__ import annotations

import cv2
import numpy as np

from glradial.lens.lens import lens_to_pixels
from glradial.video.frame_motion import FB_MAX_PX, match_frames, track_corners

W, H = 640, 360


def _texture(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = cv2.GaussianBlur(rng.uniform(0, 255, (H, W)).astype(np.float32), (0, 0), 2.0)
    return cv2.normalize(noise, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)


def test_matches_follow_a_known_pan_and_zoom_and_take_corners_found_ahead():
    a = _texture(7)
    # a pan of 18 px right, 7 px down and a 4 % zoom about the centre, as pixels of the 640 x 360 copy
    centre = np.array([[1, 0, -W / 2], [0, 1, -H / 2], [0, 0, 1]], np.float64)
    h = np.linalg.inv(centre) @ np.diag([1.04, 1.04, 1.0]) @ centre @ np.array([[1, 0, 18], [0, 1, 7], [0, 0, 1.0]])
    b = cv2.warpPerspective(a, h, (W, H), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    m = match_frames(a, b, corners=track_corners(a))
    assert m is not None and len(m) >= 100 and m.width == W
    pa, pb = lens_to_pixels(m.a, (W, H)), lens_to_pixels(m.b, (W, H))
    moved = np.c_[pa, np.ones(len(pa))] @ h.T
    error = np.hypot(*(moved[:, :2] / moved[:, 2:] - pb).T)
    # corners are located to ~0.1 px of the copy (frame_motion's docstring; 0.07 median, 0.17-0.20 max
    # measured here); none beyond the forward-backward bound FB_MAX_PX
    assert np.median(error) < 0.1 and error.max() < FB_MAX_PX, (np.median(error), error.max())
    plain = match_frames(a, b)  # corners found ahead or here: the same matches
    assert np.array_equal(plain.a, m.a) and np.array_equal(plain.b, m.b)


def test_frames_that_share_nothing_give_no_matches():
    """Two unrelated textures (a cut): fewer than MIN_MATCHES points survive the backward check and RANSAC."""
    assert match_frames(_texture(1), _texture(2)) is None
