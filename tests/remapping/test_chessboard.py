"""The real chessboard photo: correction with the converted OpenCV calibration straightens the
board's corner rows and columns.

Photo and calibration: tests/data/README.md (1280×720; fx = 1156.4996, fy = 1151.3055,
cx = 671.3496, cy = 389.1760, k = (-0.2475567, -0.0195370), p = (-0.0006705, 0.0001363)). The
principal point is ~31 px right of and ~30 px below the centre and fx != fy, both exact in
``Lens.from_opencv``; ``approximate=True`` drops only p1/p2.

Measure: the 9×6 inner corners (cv2.findChessboardCorners + cornerSubPix) form 6 rows and 9
columns; for each, a total-least-squares line fit; the RMS perpendicular residual over all 15 lines,
in input-frame pixels (residuals of the fit='full' output are multiplied by its scale s).
Measured (python3 -m pytest tests/remapping/test_chessboard.py): before 1.91 px; after 0.81 px with both
backends (0.75 px with the centred approximation f = sqrt(fx fy) used before the principal point
was modelled); OpenCV's own full model (off-centre, tangential) on the points: 0.80 px; the
opposite lens (sign flipped): 3.27 px. The ~0.75-0.8 px floor is detection noise and the
calibration's fit.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from glradial import Lens, correct, fit_scale

SIZE = (1280, 720)
K = np.array([[1156.4996, 0.0, 671.3496], [0.0, 1151.3055, 389.1760], [0.0, 0.0, 1.0]])
DIST = np.array([-0.2475567, -0.0195370, -0.0006705, 0.0001363, 0.0])
PATTERN = (9, 6)


def corners(gray: np.ndarray) -> np.ndarray:
    found, points = cv2.findChessboardCorners(gray, PATTERN)
    assert found, "chessboard not found"
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, points, (7, 7), (-1, -1), criteria).reshape(-1, 2).astype(np.float64)


def line_residual(points: np.ndarray) -> float:
    """RMS distance of the corners to their row / column lines (total least squares)."""
    grid = points.reshape(PATTERN[1], PATTERN[0], 2)
    squares = []
    for line in list(grid) + list(grid.transpose(1, 0, 2)):
        centred = line - line.mean(axis=0)
        smallest = np.linalg.svd(centred, compute_uv=False)[-1]
        squares.append(smallest**2 / len(line))
    return float(np.sqrt(np.mean(squares)))


@pytest.fixture(scope="module")
def gray(chessboard):
    return cv2.cvtColor(chessboard, cv2.COLOR_RGB2GRAY)


@pytest.fixture(scope="module")
def lens():
    return Lens.from_opencv(K, DIST, SIZE, approximate=True)


@pytest.mark.parametrize("backend", ["gl", "cpu"])
def test_correction_straightens_the_chessboard(ctx, gray, lens, backend):
    before = line_residual(corners(gray))
    assert 1.5 < before < 2.5  # the photo is visibly distorted
    # fit='full' keeps the whole board in view (at fit='same' its corners leave the frame)
    s = fit_scale(lens, SIZE, "full")
    corrected = correct(gray, lens, fit="full", fill=255, backend=backend)
    after = line_residual(corners(corrected)) * s
    assert after < 0.5 * before, (before, after)
    assert after < 1.0
    # as straight as OpenCV's full calibration model makes the same corners (within 0.15 px)
    reference = line_residual(cv2.undistortPoints(corners(gray)[:, None], K, DIST, P=K)[:, 0])
    assert after < reference + 0.15, (after, reference)


def test_point_correction_agrees_with_image_correction(gray, lens):
    """Undistorting the detected corners (Lens.undistort_points) straightens them as much as
    correcting the image and detecting again."""
    after_points = line_residual(lens.undistort_points(corners(gray), SIZE))
    assert after_points < 1.0
    # the wrong direction makes them worse: the check can fail
    flipped = Lens(-lens.k1, -lens.k2, lens.cx, lens.cy, lens.pixel_aspect)
    assert line_residual(flipped.undistort_points(corners(gray), SIZE)) > line_residual(corners(gray))
