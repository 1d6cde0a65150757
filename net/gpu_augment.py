"""Photometric augmentation of a batch on its torch device: :func:`net.augment.augment_batch`'s
operations, in the same order, drawn from the same :class:`~net.augment.AugmentConfig`, for float
``N × 3 × H × W`` batches of levels 0..255 (every draw from one seeded ``torch.Generator`` on the
batch's device; deterministic per seed on one device).

Each operation keeps the semantics of its OpenCV version and rounds to whole levels where that
one writes 8 bits: a per-image lookup of ``gain · channel gain · level^gamma``; saturation against
the ITU-R BT.601 grey (``cv2.COLOR_RGB2GRAY``); Gaussian blur with OpenCV's 8-bit kernel size
(``round(6 σ + 1)``, odd) and reflect-101 borders; motion blur with the kernels of
:func:`net.augment.motion_kernel` (angles in whole degrees, from a bank made once); Gaussian sensor
noise; JPEG compression as its lossy part (:func:`jpeg_artefacts`); horizontal and vertical flips
(which keep the lens). ``paired``: images ``2i`` and ``2i + 1`` get the same draws, noise included,
as :func:`net.augment.augment_pairs` gives them.
"""

from __future__ import annotations

from functools import lru_cache

import torch
import torch.nn.functional as F

from .augment import AugmentConfig, motion_kernel
from .model import LUMA_WEIGHTS

#: The JPEG standard's example quantisation tables (ITU-T T.81 Annex K), row-major 8 × 8.
JPEG_LUMA = (16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
             14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
             49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99)
JPEG_CHROMA = (17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99,
               47, 66, 99, 99, 99, 99, 99, 99, *([99] * 32))


def _round(x: torch.Tensor) -> torch.Tensor:
    """To whole levels 0..255 (round half up), as a saturating 8-bit write."""
    return x.add(0.5).floor_().clamp_(0.0, 255.0)


class DeviceAugment:
    """``augment(images, paired)`` for float ``N × 3 × H × W`` batches on ``device`` (see the module
    docstring); draws come from ``torch.Generator(device).manual_seed(seed)``."""

    def __init__(self, config: AugmentConfig, seed: int, device: torch.device | str):
        self.config = config
        self.device = torch.device(device)
        self.generator = torch.Generator(self.device).manual_seed(int(seed))
        self.motion_bank = motion_bank(*config.motion_length).to(self.device)
        self.blur_half = _half_width(config.blur_sigma[1])
        self.size = self.motion_bank.shape[-1]
        self.dct = _dct_matrix().to(self.device)
        self.grey = torch.tensor(LUMA_WEIGHTS, device=self.device).view(1, 3, 1, 1)  # OpenCV's RGB -> grey

    def _uniform(self, count: int, low: float, high: float) -> torch.Tensor:
        return torch.rand(count, generator=self.generator, device=self.device) * (high - low) + low

    def augment(self, images: torch.Tensor, paired: bool = False) -> torch.Tensor:
        """A new augmented batch (input untouched); ``paired``: even ``N``, pairs share their draws."""
        if images.ndim != 4 or images.shape[1] != 3 or not images.is_floating_point():
            raise ValueError(f"images must be float N x 3 x H x W, got {images.dtype} {tuple(images.shape)}")
        if paired and images.shape[0] % 2:
            raise ValueError(f"pairs need an even batch, got {images.shape[0]} images")
        if not self.config.enabled:
            return images.clone()
        n = images.shape[0] // 2 if paired else images.shape[0]
        draw = self.draws(n, images.shape[2:])
        if paired:
            draw = {name: value.repeat_interleave(2, dim=0) for name, value in draw.items()}
        return self.apply(images, draw)

    def draws(self, n: int, shape: tuple[int, int]) -> dict[str, torch.Tensor]:
        """Every random number of ``n`` images' augmentation (per-image tensors, leading dim ``n``;
        ``noise_field``: a ``3 × H × W`` standard normal field per image)."""
        c = self.config
        draw = {"gamma": self._uniform(n, *c.gamma), "gain": self._uniform(n, *c.gain),
                "cgain": self._uniform(3 * n, *c.channel_gain).reshape(n, 3), "sat": self._uniform(n, *c.saturation)}
        for name, p in (("blur", c.p_blur), ("motion", c.p_motion), ("noise", c.p_noise), ("jpeg", c.p_jpeg),
                        ("flip_h", c.p_flip_h), ("flip_v", c.p_flip_v)):
            draw[name] = torch.rand(n, generator=self.generator, device=self.device) < p
        draw["sigma"] = self._uniform(n, *c.blur_sigma)
        low, high = c.motion_length
        draw["length"] = torch.randint(low, high + 1, (n,), generator=self.generator, device=self.device)
        draw["angle"] = torch.randint(0, 180, (n,), generator=self.generator, device=self.device)
        draw["noise_sigma"] = self._uniform(n, *c.noise_sigma)
        draw["quality"] = torch.randint(c.jpeg_quality[0], c.jpeg_quality[1] + 1, (n,), generator=self.generator, device=self.device)
        draw["noise_field"] = torch.randn((n, 3, *shape), generator=self.generator, device=self.device)
        return draw

    def apply(self, x: torch.Tensor, d: dict[str, torch.Tensor]) -> torch.Tensor:
        """The operations of :meth:`draws`' draws ``d`` on ``x``, in :func:`net.augment.augment_batch`'s order."""
        gains = (d["gain"].unsqueeze(1) * d["cgain"]).view(-1, 3, 1, 1)
        x = _round((x / 255.0).pow(d["gamma"].view(-1, 1, 1, 1)) * gains * 255.0)
        grey = _round((x * self.grey).sum(dim=1, keepdim=True))
        sat = d["sat"].view(-1, 1, 1, 1)
        x = _round(x * sat + grey * (1.0 - sat))
        # every operation runs on the whole batch and is kept where drawn: no wait for the device
        # to learn which images it applies to (the operations are cheap beside a training step)
        x = _pick(d["blur"], _round(gaussian_blur(x, d["sigma"], self.blur_half)), x)
        x = _pick(d["motion"], _round(self.motion_blur(x, d["length"], d["angle"])), x)
        x = _pick(d["noise"], _round(x + d["noise_field"] * d["noise_sigma"].view(-1, 1, 1, 1)), x)
        x = _pick(d["jpeg"], jpeg_artefacts(x, d["quality"], self.dct), x)
        x = _pick(d["flip_h"], x.flip(3), x)
        return _pick(d["flip_v"], x.flip(2), x)

    def motion_blur(self, x: torch.Tensor, length: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
        """Per-image linear motion blur of float ``n × 3 × H × W``: the kernel of
        :func:`net.augment.motion_kernel` of each image's ``length`` (pixels) and ``angle`` (whole
        degrees, 0..179), as ``cv2.filter2D`` applies it (correlation, reflect-101 borders), unrounded."""
        kernel = self.motion_bank[length - self.config.motion_length[0], angle]
        n, c, h, w = x.shape
        half = self.size // 2
        padded = F.pad(x.reshape(1, n * c, h, w), (half, half, half, half), mode="reflect")
        weight = kernel.repeat_interleave(c, dim=0).unsqueeze(1)
        return F.conv2d(padded, weight, groups=n * c).reshape(n, c, h, w)


@lru_cache(maxsize=4)
def motion_bank(low: int, high: int) -> torch.Tensor:
    """``(high - low + 1) × 180 × K × K`` kernels of :func:`net.augment.motion_kernel` for every length
    ``low..high`` and whole angle 0..179 degrees, each placed so that OpenCV's anchor (``length // 2``)
    sits on the centre of the odd ``K × K`` (``K`` = ``high``, or ``high + 1`` when even)."""
    size = high if high % 2 else high + 1
    bank = torch.zeros((high - low + 1, 180, size, size))
    for i, length in enumerate(range(low, high + 1)):
        at = size // 2 - length // 2
        for angle in range(180):
            bank[i, angle, at : at + length, at : at + length] = torch.from_numpy(motion_kernel(length, angle))
    return bank


def _half_width(sigma: float) -> int:
    """Half the size of OpenCV's 8-bit Gaussian kernel of ``sigma``: ``round(6 σ + 1)`` made odd."""
    return (int(round(6 * sigma + 1)) | 1) // 2


def gaussian_blur(x: torch.Tensor, sigma: torch.Tensor, half: int | None = None) -> torch.Tensor:
    """Per-image Gaussian blur of float ``n × C × H × W`` with standard deviations ``sigma`` (``n``,
    pixels), as ``cv2.GaussianBlur(img, (0, 0), sigma)`` blurs an 8-bit image (kernel size
    ``round(6 σ + 1)`` made odd, reflect-101 borders), unrounded. ``half``: the largest half-width
    any ``sigma`` needs, when known (else read back from the device)."""
    sizes = ((sigma * 6 + 1).round().long() | 1) // 2  # each image's own half-width
    half = int(sizes.max()) if half is None else half
    t = torch.arange(-half, half + 1, device=x.device, dtype=x.dtype)
    kernel = torch.exp(-(t * t) / (2 * sigma.view(-1, 1) ** 2)) * (t.abs() <= sizes.view(-1, 1))
    return _separable(x, kernel / kernel.sum(dim=1, keepdim=True))


def _pick(chosen: torch.Tensor, changed: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """``changed`` for the images where ``chosen`` (``n`` bools) is true, ``x`` for the others."""
    return torch.where(chosen.view(-1, 1, 1, 1), changed, x)


def _separable(x: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """Per-image separable correlation with ``kernel`` (``n × k``, k odd), reflect-101 borders."""
    n, c, h, w = x.shape
    half = kernel.shape[1] // 2
    weight = kernel.repeat_interleave(c, dim=0)
    flat = F.pad(x.reshape(1, n * c, h, w), (half, half, 0, 0), mode="reflect")
    flat = F.conv2d(flat, weight.view(n * c, 1, 1, -1), groups=n * c)
    flat = F.pad(flat, (0, 0, half, half), mode="reflect")
    return F.conv2d(flat, weight.view(n * c, 1, -1, 1), groups=n * c).reshape(n, c, h, w)


def _dct_matrix() -> torch.Tensor:
    """The orthonormal 8-point DCT-II matrix (rows: frequencies)."""
    k = torch.arange(8, dtype=torch.float64)
    m = torch.cos(torch.pi * (2 * k.view(1, 8) + 1) * k.view(8, 1) / 16) * (2 / 8) ** 0.5
    m[0] /= 2**0.5
    return m.float()


@lru_cache(maxsize=None)
def _standard_tables(device: torch.device) -> torch.Tensor:
    """The standard's luma and chroma tables as a ``1 × 2 × 64`` float tensor on ``device``, copied
    there once (a copy per batch would make the host wait for the device)."""
    return torch.tensor([JPEG_LUMA, JPEG_CHROMA], dtype=torch.float32, device=device).view(1, 2, 64)


def quality_tables(quality: torch.Tensor) -> torch.Tensor:
    """``n × 2 × 8 × 8`` luma and chroma quantisation tables of JPEG qualities 1..100, scaled as the
    IJG library (libjpeg, OpenCV's encoder) scales the standard's tables."""
    q = quality.clamp(1, 100).float().view(-1, 1)
    scale = torch.where(q < 50, 5000.0 / q, 200.0 - 2.0 * q)
    base = _standard_tables(quality.device)
    return ((base * scale.unsqueeze(-1) + 50.0) / 100.0).floor().clamp(1.0, 255.0).view(-1, 2, 8, 8)


def jpeg_artefacts(x: torch.Tensor, quality: torch.Tensor, dct: torch.Tensor) -> torch.Tensor:
    """The lossy part of baseline JPEG at per-image ``quality`` on float ``n × 3 × H × W`` (levels
    0..255): JFIF YCbCr, 4:2:0 chroma (2 × 2 means, upsampled back bilinearly), 8 × 8 DCT of each
    plane (edges padded by repetition, as the encoder pads), quantised with :func:`quality_tables`,
    inverse DCT, RGB rounded to whole levels. (The entropy coding it leaves out is lossless.)"""
    n, _, h, w = x.shape
    r, g, b = x.unbind(1)
    y = 0.299 * r + 0.587 * g + 0.114 * b
    cb = (b - y) * 0.564 + 128.0
    cr = (r - y) * 0.713 + 128.0
    tables = quality_tables(quality)
    y = _block_roundtrip(y, tables[:, 0], dct)
    chroma = F.avg_pool2d(F.pad(torch.stack([cb, cr], 1), (0, w % 2, 0, h % 2), mode="replicate"), 2)
    chroma = torch.stack([_block_roundtrip(chroma[:, i], tables[:, 1], dct) for i in range(2)], 1)
    chroma = F.interpolate(chroma, scale_factor=2, mode="bilinear", align_corners=False)[..., :h, :w]
    cb, cr = chroma[:, 0] - 128.0, chroma[:, 1] - 128.0
    rgb = torch.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr, y + 1.772 * cb], 1)
    return _round(rgb)


def _block_roundtrip(plane: torch.Tensor, table: torch.Tensor, dct: torch.Tensor) -> torch.Tensor:
    """One plane (``n × H × W``) through level shift, 8 × 8 DCT, quantisation by ``table`` (``n × 8 × 8``)
    and back."""
    n, h, w = plane.shape
    ph, pw = -h % 8, -w % 8
    padded = F.pad(plane.unsqueeze(1), (0, pw, 0, ph), mode="replicate").squeeze(1) - 128.0
    blocks = padded.reshape(n, (h + ph) // 8, 8, (w + pw) // 8, 8).transpose(2, 3)
    coeff = dct @ blocks @ dct.T
    t = table.view(n, 1, 1, 8, 8)
    coeff = torch.round(coeff / t) * t
    back = (dct.T @ coeff @ dct).transpose(2, 3).reshape(n, h + ph, w + pw)
    return back[:, :h, :w] + 128.0
