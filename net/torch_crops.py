"""Torch twin of ``shaders/crop.frag``: distorted perspective crops of equirectangular panoramas,
sampled with ``grid_sample`` on any torch device (CUDA for training, the CPU for tests).

Geometry, per output pixel of a crop (the same steps, in float32, as the fragment shader; names as
there): ``p_d = lens_from_uv(uv)`` on the frame geometry ``size`` (lens units, image width = 1);
``p_u = p_d · s(2 |p_d|² / r_c² − 1)`` with ``s`` the lens's Chebyshev series of the exact inverse
(:func:`glradial.lens.inverse_series.fit_inverse_series`, fitted on the host for every crop as the
GL renderer does) where the series was accepted, else the bounded Newton inverse
(:func:`newton_radius`, the twin of common.glsl's ``undistort_radius_exact``; pixels it does not
solve are 0); camera ray ``(p_u, f)``; world ray ``R · ray``; ``(lon, lat)`` and panorama texture
coordinates ``u = 0.5 + lon / 2π``, ``v = 0.5 − lat / π``.

Filtering (the twin of ``textureGrad`` on a mipmapped texture with trilinear filtering): the change
of the world ray across one output pixel is taken inside 2 × 2 pixel quads, as GL's ``dFdx`` /
``dFdy`` are, and turned into the footprint ``(tx, ty)`` in texture units analytically; the level of
detail is ``log2`` of the longer footprint in level-0 texels, clamped to the pyramid; the two
nearest levels are read bilinearly and blended. Levels are 2 × 2 box averages rounded to uint8 (what
``build_mipmaps`` makes of an 8-bit texture), wrapped in ``u`` (the texture repeats across the
±180° seam) and clamped in ``v``. ``supersample`` ``(SX, SY)`` averages sub-pixel reads placed with
the local linear map, as ``CROP_SUPERSAMPLE_X/Y`` do. Output values are rounded to 8 bits, as the
GL atlas stores them.

How close this is to the GL renderer (tests/net/test_gpu_source.py): bilinear reads and level selection
differ between drivers in their last bits (llvmpipe takes one level of detail per quad, in fixed
point), so the twin is held to the GL crops within a fraction of a grey level on a smooth panorama
and to a few hundredths of a pixel in the position of sharp edges.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from glradial.lens import lensfuncs
from glradial.lens.inverse_series import SERIES_DEGREE, fit_inverse_series
from glradial.lens.lens import corner_radius, frame_size
from glradial.lens.metrics import PAPER_SIZE
from glradial.synthesis.crops import CropParams, supersample_grid

#: Columns of every mip level repeated on each side of the ±180° seam (``u`` wraps there).
SEAM_PAD = 2
#: Smallest level height kept in a pyramid (coarser levels are never read by crops of a sane size).
MIN_LEVEL = 4
#: Columns of the per-crop table sent from the host: rotation (9), focal, k1, k2, fold radius,
#: Drap-Lefevre b1..b4, series flag, series coefficients.
_TABLE = 18 + SERIES_DEGREE + 1


def mip_pyramid(panorama: np.ndarray | torch.Tensor, device: torch.device | str) -> list[torch.Tensor]:
    """uint8 ``1 × 3 × H_l × (W_l + 2 SEAM_PAD)`` levels of an ``H × 2H × 3`` uint8 RGB panorama on
    ``device``: level 0 is the panorama, each next one the 2 × 2 box average of the one before,
    rounded to 8 bits; each has :data:`SEAM_PAD` columns wrapped around from the other side."""
    pano = torch.as_tensor(np.asarray(panorama)) if not isinstance(panorama, torch.Tensor) else panorama
    if pano.dtype != torch.uint8 or pano.ndim != 3 or pano.shape[2] != 3 or pano.shape[1] != 2 * pano.shape[0]:
        raise ValueError(f"panorama must be a uint8 H x 2H x 3 RGB array, got {pano.dtype} {tuple(pano.shape)}")
    level = pano.to(device).permute(2, 0, 1).unsqueeze(0).contiguous()
    levels = []
    while True:
        levels.append(torch.cat([level[..., -SEAM_PAD:], level, level[..., :SEAM_PAD]], dim=-1))
        if level.shape[2] // 2 < MIN_LEVEL:
            return levels
        level = F.avg_pool2d(level.float(), 2).add_(0.5).floor_().to(torch.uint8)


def newton_radius(r_d: torch.Tensor, table: torch.Tensor, steps: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The exact inverse ``r_u`` of radii ``r_d`` (``M``) for ``L`` lenses (``table``: rows of the
    crop table) -> ``(r_u, valid)`` of shape ``L × M``: the Drap-Lefevre seed, then ``steps`` Newton
    steps clamped to ``[0, fold radius]``, as common.glsl's ``undistort_radius_exact`` (float32)."""
    k1, k2, fold = table[:, 10:11], table[:, 11:12], table[:, 12:13]
    b1, b2, b3, b4 = (table[:, i : i + 1] for i in range(13, 17))
    rd2 = r_d * r_d
    r = torch.minimum((r_d * (1.0 + rd2 * (b1 + rd2 * (b2 + rd2 * (b3 + rd2 * b4))))).clamp(min=0.0), fold)
    for _ in range(steps):
        r2 = r * r
        f = r * (1.0 + k1 * r2 + k2 * r2 * r2) - r_d
        slope = (1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2).clamp(min=1e-6)
        r = torch.minimum((r - f / slope).clamp(min=0.0), fold)
    r2 = r * r
    residual = (r * (1.0 + k1 * r2 + k2 * r2 * r2) - r_d).abs()
    return r, residual <= lensfuncs.LENS_INVERSE_TOLERANCE * r_d.clamp(min=1.0)


def crop_table(params: Sequence[CropParams], size: tuple[int, int] = PAPER_SIZE) -> np.ndarray:
    """float32 ``N × 29`` per-crop table (host side, float64 until the end): rotation, focal length,
    lens, fold radius (:func:`glradial.lens.lensfuncs.fold_radii`), Drap-Lefevre coefficients, whether
    the series inverse was accepted, and its coefficients (:func:`fit_inverse_series`)."""
    n = len(params)
    table = np.zeros((n, _TABLE), np.float64)
    if n == 0:
        return table.astype(np.float32)
    table[:, :9] = np.stack([p.rotation().reshape(9) for p in params])
    table[:, 9:12] = [(p.focal, p.k1, p.k2) for p in params]
    k1, k2 = table[:, 10], table[:, 11]
    table[:, 12] = lensfuncs.fold_radii(k1, k2)
    table[:, 13:17] = np.stack(lensfuncs.drap_coefficients(k1, k2), axis=1)
    coefficients, accepted = fit_inverse_series(k1, k2, corner_radius(size))
    table[:, 17] = accepted
    table[:, 18:] = coefficients
    return table.astype(np.float32)


class TorchCropRenderer:
    """Renders crops of several panoramas on ``device`` (see the module docstring).

    ``panoramas``: uint8 ``H × 2H × 3`` arrays, uploaded once as mip pyramids (:func:`mip_pyramid`).
    ``size`` is the frame geometry the lens refers to, ``out_size`` ``(w, h)`` the crop size (each
    output pixel covers ``W/w × H/h`` frame pixels), ``newton_steps`` the steps of the Newton inverse
    used for lenses whose series is rejected (as :class:`glradial.synthesis.crops.CropRenderer`).
    Only the exact inverse is rendered (the training crops'; the paper's Drap-Lefevre one is not).
    """

    def __init__(self, panoramas: Sequence[np.ndarray], *, size: tuple[int, int] = PAPER_SIZE,
                 out_size: tuple[int, int] | None = None, supersample: int | tuple[int, int] | str = 1,
                 newton_steps: int = lensfuncs.LENS_NEWTON_STEPS, device: torch.device | str = "cpu"):
        if not len(panoramas):
            raise ValueError("panoramas must not be empty")
        if isinstance(newton_steps, bool) or not isinstance(newton_steps, int) or not 1 <= newton_steps <= 16:
            raise ValueError(f"newton_steps must be an integer in 1..16, got {newton_steps!r}")
        self.device = torch.device(device)
        self.size = frame_size(size)
        self.out_size = frame_size(out_size) if out_size is not None else self.size
        self.supersample = supersample_grid(supersample, self.size, self.out_size)
        self.newton_steps = newton_steps
        self.pyramids = [mip_pyramid(p, self.device) for p in panoramas]
        w, h = self.out_size
        u = (torch.arange(w, dtype=torch.float64) + 0.5) / w
        v = (torch.arange(h, dtype=torch.float64) + 0.5) / h
        aspect = self.size[1] / self.size[0]
        p_d = torch.stack(torch.meshgrid(u - 0.5, (v - 0.5) * aspect, indexing="xy"), dim=-1).reshape(-1, 2)
        r2 = (p_d * p_d).sum(dim=1)
        x = r2 * (2.0 / corner_radius(self.size) ** 2) - 1.0
        basis = [torch.ones_like(x), x]
        for _ in range(SERIES_DEGREE - 1):
            basis.append(2.0 * x * basis[-1] - basis[-2])
        self._p_d = p_d.float().to(self.device)
        self._r_d = r2.sqrt().float().to(self.device)
        self._basis = torch.stack(basis).float().to(self.device)  # (degree + 1) x (h w): T_i at each pixel

    def render(self, params: Sequence[CropParams], which: Sequence[int] | np.ndarray) -> torch.Tensor:
        """Crop ``i`` of ``params`` from panorama ``which[i]`` -> uint8 ``N × h × w × 3`` on the device
        (the layout :class:`glradial.synthesis.crops.CropRenderer` returns)."""
        return self.render_float(params, which).round_().to(torch.uint8).permute(0, 2, 3, 1)

    def render_float(self, params: Sequence[CropParams], which: Sequence[int] | np.ndarray) -> torch.Tensor:
        """As :meth:`render`, as float32 ``N × 3 × h × w`` (channels-last in memory) of whole levels 0..255."""
        return self.render_table(crop_table(params, self.size), which)

    def render_table(self, table: np.ndarray, which: Sequence[int] | np.ndarray) -> torch.Tensor:
        """As :meth:`render_float`, from the crops' :func:`crop_table` (made on the host beforehand,
        e.g. on another thread while the device works)."""
        which = np.asarray(which, np.int64).reshape(-1)
        if len(which) != len(table):
            raise ValueError(f"which must give one panorama per crop: {len(which)} for {len(table)} crops")
        if len(which) and (which.min() < 0 or which.max() >= len(self.pyramids)):
            raise ValueError(f"which must index the {len(self.pyramids)} panoramas, got {which.min()}..{which.max()}")
        indexed = np.concatenate([table, np.arange(len(table), dtype=np.float32)[:, None]], axis=1)
        w, h = self.out_size
        out = torch.empty((len(which), 3, h, w), device=self.device, memory_format=torch.channels_last)
        groups = []  # per panorama: its index, the crops' rows on the device, their footprints and levels of detail
        for pano in np.unique(which):
            rows = np.flatnonzero(which == pano)
            part = self.upload(indexed[rows])
            newton = not table[rows, 17].all()  # decided on the host: no wait for the device
            tex, tx, ty, valid = self.footprints(part[:, :-1], newton)
            groups.append((int(pano), part[:, -1].long(), tex, tx, ty, valid, self._lods(self.pyramids[int(pano)], tx, ty)))
        # the range of mip levels each panorama's crops read, for all of them in one wait for the device
        ranges = torch.stack([torch.stack([lod.amin(), lod.amax()]) for *_, lod in groups]).cpu().numpy()
        for (pano, rows, tex, tx, ty, valid, lod), (low, high) in zip(groups, ranges):
            levels = range(int(np.floor(low)), int(np.ceil(high)) + 1)
            out[rows] = self._sample(self.pyramids[pano], tex, tx, ty, lod, levels) * valid.unsqueeze(1)
        return out

    def upload(self, array: np.ndarray) -> torch.Tensor:
        """A small host array on the device without waiting for the device's queue (pinned, asynchronous)."""
        host = torch.from_numpy(np.ascontiguousarray(array))
        if self.device.type != "cuda":
            return host
        return host.pin_memory().to(self.device, non_blocking=True)

    def footprints(self, table: torch.Tensor, newton: bool = True) -> tuple[torch.Tensor, ...]:
        """Texture coordinates ``(u, v)`` of each output pixel centre and the footprint vectors
        ``tx``, ``ty`` (texture units per output pixel), each ``n × h × w × 2``, and the validity
        ``n × h × w`` (float 0 / 1) of ``n`` crops' table rows (``newton``: some of them need the
        Newton inverse)."""
        w, h = self.out_size
        n = len(table)
        series = table[:, 17:18] > 0.5
        scale = table[:, 18:] @ self._basis  # n x (h w): s(x), the inverse series
        valid = torch.ones_like(scale)
        if newton:
            r_u, ok = newton_radius(self._r_d, table, self.newton_steps)
            newton_scale = torch.where(self._r_d > 0, r_u / self._r_d.clamp(min=1e-30), torch.ones_like(r_u))
            scale = torch.where(series, scale, newton_scale)
            valid = torch.where(series, valid, ok.float())
        p_u = self._p_d * scale.unsqueeze(-1)  # n x (h w) x 2
        ray = torch.cat([p_u, table[:, 9:10, None].expand(n, h * w, 1)], dim=-1)
        world = (ray @ table[:, :9].reshape(n, 3, 3).transpose(1, 2)).reshape(n, h, w, 3)
        dwx = _quad_difference(world, 2)
        dwy = _quad_difference(world, 1)
        x, y, z = world.unbind(-1)
        rho2 = (x * x + z * z).clamp(min=1e-20)
        rho = rho2.sqrt()
        n2 = rho2 + y * y
        tex = torch.stack([0.5 + torch.atan2(x, z) / (2 * math.pi), 0.5 - torch.atan2(-y, rho) / math.pi], dim=-1)

        def change(d: torch.Tensor) -> torch.Tensor:
            dx, dy, dz = d.unbind(-1)
            lon = (z * dx - x * dz) / rho2
            lat = (-rho * dy + y * (x * dx + z * dz) / rho) / n2
            return torch.stack([lon / (2 * math.pi), -lat / math.pi], dim=-1)

        return tex, change(dwx), change(dwy), valid.reshape(n, h, w)

    def _lods(self, levels: list[torch.Tensor], tx: torch.Tensor, ty: torch.Tensor) -> torch.Tensor:
        """Level of detail of each sub-pixel read (``n × h × w``): ``log2`` of its longer footprint in
        level-0 texels, clamped to the pyramid (GL's minification rule, trilinear)."""
        sx, sy = self.supersample
        height = levels[0].shape[2]
        texels = torch.tensor([2.0 * height, float(height)], device=tx.device)
        rho = torch.maximum((tx / sx * texels).norm(dim=-1), (ty / sy * texels).norm(dim=-1))
        return torch.log2(rho.clamp(min=1e-30)).clamp(0.0, len(levels) - 1)

    def _sample(self, levels: list[torch.Tensor], tex: torch.Tensor, tx: torch.Tensor, ty: torch.Tensor,
                lod: torch.Tensor, used: range) -> torch.Tensor:
        """The box average of the ``SX × SY`` trilinear sub-pixel reads -> float ``n × 3 × h × w``
        (``used``: the mip levels ``lod`` reaches)."""
        sx, sy = self.supersample
        n, h, w, _ = tex.shape
        acc = torch.zeros((n, 3, h, w), device=tex.device)
        for j in range(sy):
            for i in range(sx):
                pos = tex + ((i + 0.5) / sx - 0.5) * tx + ((j + 0.5) / sy - 0.5) * ty
                acc += _trilinear(levels, pos, lod, used)
        return acc / (sx * sy)


def _quad_difference(world: torch.Tensor, dim: int) -> torch.Tensor:
    """``dFdx`` (``dim`` 2) or ``dFdy`` (``dim`` 1) of ``n × h × w × 3`` world rays: inside each 2 × 2
    pixel quad the difference of its two columns (rows), as a fragment shader's fine derivatives."""
    count = world.shape[dim]
    first = (torch.arange(count, device=world.device) // 2 * 2).clamp(max=max(count - 2, 0))
    second = (first + 1).clamp(max=count - 1)
    return world.index_select(dim, second) - world.index_select(dim, first)


def _trilinear(levels: list[torch.Tensor], pos: torch.Tensor, lod: torch.Tensor, used: range) -> torch.Tensor:
    """Reads at texture coordinates ``pos`` (``n × h × w × 2``) blended between the two mip levels
    around ``lod`` (``n × h × w``; all within the levels ``used``) -> float ``n × 3 × h × w`` (levels 0..255)."""
    n, h, w, _ = pos.shape
    u = pos[..., 0] - pos[..., 0].floor()  # the texture repeats in u
    acc = None
    for index in used:
        weight = (1.0 - (lod - index).abs()).clamp(min=0.0)
        level = levels[index].float()
        width = level.shape[3] - 2 * SEAM_PAD
        grid = torch.stack([(u * width + SEAM_PAD) / (width + 2 * SEAM_PAD) * 2 - 1, pos[..., 1] * 2 - 1], dim=-1)
        read = F.grid_sample(level, grid.reshape(1, n * h, w, 2), mode="bilinear", padding_mode="border", align_corners=False)
        read = read.reshape(3, n, h, w).transpose(0, 1) * weight.unsqueeze(1)
        acc = read if acc is None else acc + read
    return acc
