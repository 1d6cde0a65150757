"""The CPU path's fixed-point maps and its samples with no source (``cpu_maps``), against the
float64 NumPy reference maps of :meth:`Lens.maps` and the per-sample test of every source.

The per-sample test is skipped for correction maps whose border samples' sources lie inside the
frame (a proof from the radial map's monotonicity, :func:`glradial.remapping.remap._no_source`);
these tests check that the skip never changes the answer, on lenses where it applies (barrel,
``fit="same"``) and where it must not (pincushion, ``fit="full"``, off-centre principal points).
"""

from __future__ import annotations

import numpy as np
import pytest

from glradial.lens.lens import Lens, Plane
from glradial.remapping.planes import yuv_planes
from glradial.remapping.remap import cpu_maps

SIZE = (320, 180)
LENSES = [
    Lens(-0.3, 0.02),                                  # barrel, sources all inside with fit "same"
    Lens(-0.18, 0.0, cx=0.04, cy=-0.02),                # off-centre principal point
    Lens(-0.25, 0.01, pixel_aspect=1.1),                # non-square pixels
    Lens(0.2, 0.05),                                    # pincushion: corners' sources outside
]
LATTICES = [None, *yuv_planes(SIZE, (1, 1), "left")[1:2], *yuv_planes((321, 181), (1, 0), "center")[1:2]]


def _decoded(map1: np.ndarray, map2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of ``CV_16SC2`` + ``CV_16UC1`` maps (1/32-pixel fractions), in plane pixels."""
    return map1[..., 0] + (map2 & 31) / 32.0, map1[..., 1] + (map2 >> 5) / 32.0


def _source_outside(lens, size, direction, scale, plane):
    """Margin (luma pixels, > 0 outside) of each sample's source beyond the frame's area, from the
    float64 reference maps."""
    plane = plane or Plane.full(size)
    map_x, map_y = lens.maps(size, direction, scale=scale, dtype=np.float64, plane=plane)
    x, y = plane.x0 + plane.step_x * map_x, plane.y0 + plane.step_y * map_y
    return np.maximum.reduce([-0.5 - x, x - (size[0] - 0.5), -0.5 - y, y - (size[1] - 0.5)]), (map_x, map_y)


@pytest.mark.parametrize("lens", LENSES, ids=["barrel", "off-centre", "aspect", "pincushion"])
@pytest.mark.parametrize("fit", ["same", "full", "crop"])
@pytest.mark.parametrize("lattice", LATTICES, ids=["luma", "chroma-420-left", "chroma-422-center"])
def test_maps_and_sourceless_samples_match_the_reference(lens, fit, lattice):
    size = SIZE if lattice is None or lattice.width == SIZE[0] // 2 else (321, 181)
    if fit != "same" and not lens.is_centred:
        fit = "same"
    scale = lens.fit_scale(size, fit, "undistort")
    map1, map2, outside = cpu_maps(lens, size, "undistort", scale, "exact", False, lattice)
    margin, (ref_x, ref_y) = _source_outside(lens, size, "undistort", scale, lattice)
    x, y = _decoded(map1, map2)
    inside = margin.reshape(-1) <= -1e-3
    # fixed-point maps: the reference rounded to 1/32 px (half a step), plus float32 rounding
    assert np.abs(x - ref_x).reshape(-1)[inside].max() <= 1 / 64 + 1e-3
    assert np.abs(y - ref_y).reshape(-1)[inside].max() <= 1 / 64 + 1e-3
    flagged = np.zeros(margin.size, bool)
    flagged[outside] = True
    # every source beyond the area by more than float32 rounding is flagged, none well inside is
    assert not np.any(flagged & inside)
    assert np.all(flagged[margin.reshape(-1) >= 1e-3])
    # and the answer is the per-sample test's on the float32 maps, sample for sample
    plane = lattice or Plane.full(size)
    map_x, map_y = lens.maps(size, "undistort", scale=scale, plane=lattice)
    fx, fy = plane.x0 + plane.step_x * map_x, plane.y0 + plane.step_y * map_y
    expected = np.flatnonzero((fx < -0.5) | (fx > size[0] - 0.5) | (fy < -0.5) | (fy > size[1] - 0.5))
    np.testing.assert_array_equal(outside, expected)


def test_the_cases_cover_both_answers():
    """The skip is taken (no sample without source) and refused (corners without source)."""
    barrel, pincushion = LENSES[0], LENSES[3]
    assert cpu_maps(barrel, SIZE, "undistort", 1.0, "exact", False)[2].size == 0
    full = barrel.fit_scale(SIZE, "full", "undistort")
    assert cpu_maps(barrel, SIZE, "undistort", full, "exact", False)[2].size > 0
    assert cpu_maps(pincushion, SIZE, "undistort", 1.0, "exact", False)[2].size > 0


def test_distort_maps_flag_samples_without_inverse():
    lens = Lens(-0.3, 0.02)
    scale = lens.fit_scale(SIZE, "same", "distort")
    _, _, outside = cpu_maps(lens, SIZE, "distort", scale, "exact", False)
    map_x, map_y = lens.maps(SIZE, "distort", scale=scale)
    expected = np.flatnonzero((map_x < -0.5) | (map_x > SIZE[0] - 0.5) | (map_y < -0.5) | (map_y > SIZE[1] - 0.5))
    np.testing.assert_array_equal(outside, expected)
    assert outside.size > 0
