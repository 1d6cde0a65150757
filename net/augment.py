"""Photometric augmentation of training crops: what broadcast frames do to an image.

Convention: input and output are uint8 RGB batches ``N x H x W x 3`` (the crops, already at the
network input size). Nothing here moves a pixel except flips, which keep the lens: a radial
distortion centred on the frame is symmetric under horizontal and vertical mirroring, so the labels
``(k1, k2)`` stay valid. Every operation is drawn per image from a ``numpy.random.Generator``
(deterministic per seed).

Operations (probabilities and ranges in :class:`AugmentConfig`): exposure (gain) and gamma, per-
channel colour gains and saturation, Gaussian blur, linear motion blur, Gaussian sensor noise, JPEG
compression at a random quality (``cv2.imencode``), horizontal / vertical flips.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class AugmentConfig:
    """Probabilities (``p_*``) and ranges of each operation; ``enabled=False`` turns all off."""

    enabled: bool = True
    p_flip_h: float = 0.5
    p_flip_v: float = 0.5
    gain: tuple[float, float] = (0.6, 1.4)
    gamma: tuple[float, float] = (0.7, 1.4)
    channel_gain: tuple[float, float] = (0.85, 1.15)
    saturation: tuple[float, float] = (0.6, 1.3)
    p_blur: float = 0.3
    blur_sigma: tuple[float, float] = (0.3, 1.0)
    p_motion: float = 0.15
    motion_length: tuple[int, int] = (3, 7)
    p_noise: float = 0.5
    noise_sigma: tuple[float, float] = (1.0, 6.0)
    p_jpeg: float = 0.5
    jpeg_quality: tuple[int, int] = (30, 95)


def motion_kernel(length: int, angle_deg: float) -> np.ndarray:
    """Normalised ``length x length`` kernel of a line through the centre at ``angle_deg``."""
    if length < 1:
        raise ValueError(f"length must be >= 1, got {length}")
    kernel = np.zeros((length, length), np.float32)
    c = (length - 1) / 2.0
    t = np.linspace(-c, c, 4 * length)
    a = np.radians(angle_deg)
    xs = np.clip(np.rint(c + t * np.cos(a)).astype(int), 0, length - 1)
    ys = np.clip(np.rint(c - t * np.sin(a)).astype(int), 0, length - 1)
    kernel[ys, xs] = 1.0
    return kernel / kernel.sum()


def jpeg_roundtrip(image: np.ndarray, quality: int) -> np.ndarray:
    """Encode an RGB uint8 image as JPEG at ``quality`` (1..100) and decode it again."""
    ok, buf = cv2.imencode(".jpg", image[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("cv2.imencode failed")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[:, :, ::-1]


def augment_batch(images: np.ndarray, rng: np.random.Generator, config: AugmentConfig | None = None) -> np.ndarray:
    """Augment a uint8 ``N x H x W x 3`` RGB batch; returns a new array (input untouched)."""
    config = config or AugmentConfig()
    images = np.asarray(images)
    if images.dtype != np.uint8 or images.ndim != 4 or images.shape[3] != 3:
        raise ValueError(f"images must be uint8 N x H x W x 3, got {images.dtype} {images.shape}")
    if not config.enabled:
        return images.copy()
    n = images.shape[0]
    out = np.empty_like(images)
    levels = np.arange(256, dtype=np.float32) / 255.0
    for i in range(n):
        # exposure (gain), gamma and per-channel colour gains as one lookup table per image
        gamma = rng.uniform(*config.gamma)
        gain = rng.uniform(*config.gain)
        cgain = rng.uniform(*config.channel_gain, 3)
        lut = np.power(levels, gamma)[:, None] * (gain * cgain)[None, :] * 255.0
        lut = np.clip(lut + 0.5, 0, 255).astype(np.uint8).reshape(256, 1, 3)
        img = cv2.LUT(np.ascontiguousarray(images[i]), lut)
        sat = rng.uniform(*config.saturation)
        grey = cv2.cvtColor(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
        img = cv2.addWeighted(img, sat, grey, 1.0 - sat, 0.0)
        if rng.random() < config.p_blur:
            img = cv2.GaussianBlur(img, (0, 0), float(rng.uniform(*config.blur_sigma)))
        if rng.random() < config.p_motion:
            length = int(rng.integers(config.motion_length[0], config.motion_length[1] + 1))
            img = cv2.filter2D(img, -1, motion_kernel(length, float(rng.uniform(0, 180))))
        if rng.random() < config.p_noise:
            sigma = float(rng.uniform(*config.noise_sigma))
            noise = rng.standard_normal(img.shape, dtype=np.float32) * sigma
            img = np.clip(img + noise + 0.5, 0, 255).astype(np.uint8)
        if rng.random() < config.p_jpeg:
            img = jpeg_roundtrip(np.ascontiguousarray(img), int(rng.integers(config.jpeg_quality[0], config.jpeg_quality[1] + 1)))
        if rng.random() < config.p_flip_h:
            img = img[:, ::-1]
        if rng.random() < config.p_flip_v:
            img = img[::-1]
        out[i] = img
    return out


def augment_pairs(images: np.ndarray, rng: np.random.Generator, config: AugmentConfig | None = None,
                  workers: int = 0) -> np.ndarray:
    """Like :func:`augment_batch`, but images ``2i`` and ``2i + 1`` get exactly the same operations
    (same draws, same noise), so that within a pair only the lens differs.

    ``workers`` > 0 augments the pairs on that many threads (OpenCV and numpy release the GIL; a
    GPU trainer is otherwise bound by this loop). The result does not depend on ``workers``: each
    pair's seed is drawn from ``rng`` in order before any work starts.
    """
    images = np.asarray(images)
    if images.ndim != 4 or images.shape[0] % 2:
        raise ValueError(f"pairs need an even N x H x W x 3 batch, got shape {images.shape}")
    out = np.empty_like(images)
    seeds = [int(rng.integers(2**63)) for _ in range(0, images.shape[0], 2)]

    def one_pair(k: int) -> None:
        i = 2 * k
        out[i] = augment_batch(images[i : i + 1], np.random.default_rng(seeds[k]), config)[0]
        out[i + 1] = augment_batch(images[i + 1 : i + 2], np.random.default_rng(seeds[k]), config)[0]

    if workers > 0:
        list(_thread_pool(workers).map(one_pair, range(len(seeds))))
    else:
        for k in range(len(seeds)):
            one_pair(k)
    return out


_pools: dict[int, ThreadPoolExecutor] = {}


def _thread_pool(workers: int) -> ThreadPoolExecutor:
    """One shared pool per thread count (created on first use, lives as long as the process)."""
    if workers not in _pools:
        _pools[workers] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="augment")
    return _pools[workers]
