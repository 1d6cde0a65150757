"""Float images on the CPU path are interpolated bilinearly at the exact float32 source positions
(float maps), not at positions rounded to 1/32 px (OpenCV's fixed-point maps): a float32 picture
with sharp edges, through :func:`glradial.correct` and through ``glradial correct`` on an OpenEXR
FLOAT file, against an independent bilinear oracle (``scipy.ndimage.map_coordinates(order=1)``) at
the source positions of glradial's own lens map (float64)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage

import glradial
from glradial.cli import main
from glradial.media.exr_io import ExrImage, read_exr, write_exr

SIZE = (240, 136)
K1, K2 = -0.24, 0.04
#: within this fraction of the picture's peak value: float32 arithmetic (~1e-7) plus the float32
#: positions (~1e-5 px, times an edge of the peak per pixel); the 1/32-px fixed-point maps miss by
#: up to half a step (1/64 of the peak at a one-pixel edge, ~1.6 %)
TOLERANCE = 1e-3


def _blocks(seed: int, channels: int) -> np.ndarray:
    """H x W x C float32: 8 x 8-pixel blocks of random values 0 .. 50 (sharp one-pixel edges)."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(0.0, 50.0, (SIZE[1] // 8 + 1, SIZE[0] // 8 + 1, channels)).astype(np.float32)
    return np.ascontiguousarray(np.repeat(np.repeat(coarse, 8, 0), 8, 1)[: SIZE[1], : SIZE[0]])


def _oracle(image: np.ndarray, lens: glradial.Lens) -> np.ndarray:
    """Exact bilinear interpolation at glradial's float64 source positions (edge pixels repeated)."""
    map_x, map_y = lens.maps(SIZE, "undistort", dtype=np.float64)
    return np.stack([ndimage.map_coordinates(image[..., c].astype(np.float64), [map_y, map_x], order=1, mode="nearest")
                     for c in range(image.shape[2])], axis=-1)


def _relative(result: np.ndarray, oracle: np.ndarray, image: np.ndarray) -> float:
    return float(np.max(np.abs(result.astype(np.float64) - oracle)) / np.max(np.abs(image)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_float_frames_are_exact_bilinear(dtype, channels):
    image = _blocks(channels, channels).astype(dtype)
    lens = glradial.Lens(K1, K2)
    result = glradial.correct(image, lens, interpolation="linear", backend="cpu", alpha="premultiplied")
    assert result.dtype == dtype
    oracle = _oracle(image, lens)
    assert _relative(result, oracle, image) <= TOLERANCE
    # the oracle tells the two apart: the fixed-point maps miss it by far more on the same picture
    map1, map2 = cv2.convertMaps(*lens.maps(SIZE, "undistort"), cv2.CV_16SC2)
    fixed = cv2.remap(image.astype(np.float32), map1, map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    assert _relative(fixed.reshape(image.shape), oracle, image) > 5 * TOLERANCE


def test_integer_frames_keep_the_fixed_point_maps():
    """uint16 frames still go through the 1/32-px maps (faster for several channels): within a
    level plus the rounding of the positions, as before."""
    image = (_blocks(7, 3) * 1000).astype(np.uint16)
    lens = glradial.Lens(K1, K2)
    map1, map2 = cv2.convertMaps(*lens.maps(SIZE, "undistort"), cv2.CV_16SC2)
    fixed = cv2.remap(image, map1, map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    np.testing.assert_array_equal(glradial.correct(image, lens, backend="cpu"), fixed)


def test_cli_corrects_a_float_exr_to_exact_bilinear(tmp_path):
    image = _blocks(11, 3)
    source, target = tmp_path / "in.exr", tmp_path / "out.exr"
    write_exr(source, ExrImage({name: image[..., i] for i, name in enumerate("RGB")}))
    assert main(["correct", str(source), str(target), "--k1", str(K1), "--k2", str(K2), "--interpolation", "linear",
                 "--backend", "cpu", "-q"]) == 0
    written = read_exr(target)
    assert all(written.channels[name].dtype == np.float32 for name in "RGB")
    result = np.dstack([written.channels[name] for name in "RGB"])
    assert _relative(result, _oracle(image, glradial.Lens(K1, K2)), image) <= TOLERANCE
