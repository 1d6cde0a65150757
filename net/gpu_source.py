"""A GPU-resident batch source: every crop rendered and augmented on the training device.

:class:`GpuCropSource` keeps the training panoramas on the device as mip pyramids and, per batch,
renders fresh crops with :class:`net.torch_crops.TorchCropRenderer` (the torch twin of the GL crop
shader) and augments them with :class:`net.gpu_augment.DeviceAugment`. No pool, no producer process,
no CPU augmentation: the host only plans each batch (a few numbers per crop).

Batch ``i`` of a source with seed ``S`` has exactly the crop parameters and panoramas of batch ``i``
of ``glradial.synthesis.crop_producer.crop_batches(panoramas, batch_size, seed=S, ...)`` with the
same options (its :func:`~glradial.synthesis.crop_producer.plan_batch`, drawn from
``numpy.random.default_rng([S, i])`` on the host: the one definition of the paper's distribution),
so the GL producer and this source render the same crops. A paired plan holds one panorama; a
paired batch ``i`` is therefore the ``panoramas_per_batch`` plans ``i k .. i k + k - 1`` of batch size
``batch_size / k`` (``k`` panoramas per batch, as unpaired batches have); the augmentation's draws come from a
``torch.Generator`` on the device seeded with ``augment_seed``. Batches start at index ``start``
(a resumed run passes its step count). Deterministic per seed on one device.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from typing import Sequence

import numpy as np
import torch

from glradial.lens.metrics import PAPER_SIZE
from glradial.synthesis.crop_producer import crop_batches, plan_batch
from glradial.synthesis.crops import crop_labels

from .augment import AugmentConfig
from .gpu_augment import DeviceAugment
from .torch_crops import TorchCropRenderer, crop_table


class GpuCropSource:
    """:class:`net.sources.BatchSource` rendering on ``device`` (see the module docstring).

    ``panoramas``: uint8 RGB equirectangular arrays; ``out_size`` ``(w, h)`` the network input;
    ``panoramas_per_batch`` panoramas feed each batch (as the crop producer picks them);
    ``augment`` the photometric augmentation (``None``: none). A planner thread draws the next
    batch's crops on the host while the device works; ``wait_s`` counts the seconds waited for it.
    """

    def __init__(self, panoramas: Sequence[np.ndarray], *, batch_size: int, seed: int, out_size: tuple[int, int],
                 device: torch.device | str, augment: AugmentConfig | None = None, augment_seed: int = 0,
                 paired: bool = False, panoramas_per_batch: int = 4, start: int = 0, size: tuple[int, int] = PAPER_SIZE):
        self.device = torch.device(device)
        # paired plans hold one panorama each: a batch is then panoramas_per_batch consecutive plans
        self.parts = panoramas_per_batch if paired else 1
        if batch_size % (2 * self.parts if paired else 1):
            raise ValueError(f"batch_size {batch_size} must split into {self.parts} groups of pairs (panoramas_per_batch)")
        # crop_batches with no worker makes no GL context until a batch is asked of it: only its plan is used
        self.plan = crop_batches(list(panoramas), batch_size // self.parts, seed=seed, size=size, out_size=out_size,
                                 workers=0, panoramas_per_batch=panoramas_per_batch, paired=paired)
        steps = self.plan.config.newton_steps
        self.renderer = TorchCropRenderer(panoramas, size=size, out_size=out_size, newton_steps=steps, device=self.device)
        self.augment = DeviceAugment(augment, augment_seed, self.device) if augment is not None else None
        self.paired = paired
        self.index = int(start)
        self.wait_s = 0.0
        self._planner = ThreadPoolExecutor(max_workers=1, thread_name_prefix="gpu-source-plan")
        self._next = self._planner.submit(self._planned, self.index)

    def _planned(self, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batch ``index``'s per-crop table, panorama indices and labels (host work, on the planner thread)."""
        plans = [plan_batch(self.plan.config, index * self.parts + j) for j in range(self.parts)]
        params = [p for part, _ in plans for p in part]
        which = np.concatenate([w for _, w in plans])
        return crop_table(params, self.renderer.size), which, crop_labels(params, np.float32)

    def next_batch(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The next batch (module docstring of :mod:`net.sources`)."""
        t0 = time.monotonic()
        table, which, labels = self._next.result()
        self.wait_s += time.monotonic() - t0
        self.index += 1
        self._next = self._planner.submit(self._planned, self.index)  # planned while the device renders this one
        images = self.renderer.render_table(table, which)
        if self.augment is not None:
            images = self.augment.augment(images, paired=self.paired)
        return images.round_().to(torch.uint8).permute(0, 2, 3, 1), self.renderer.upload(labels)

    def close(self) -> None:
        """Stop the planner thread (the panoramas are freed with the source)."""
        self._planner.shutdown(wait=True, cancel_futures=True)
        self.plan.close()
