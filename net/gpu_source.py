"""A GPU-resident batch source: every crop rendered and augmented on the training device.

:class:`GpuCropSource` keeps the training panoramas on the device as mip pyramids and, per batch,
renders fresh crops with :class:`net.torch_crops.TorchCropRenderer` (the torch twin of the GL crop
shader) and augments them with :class:`net.gpu_augment.DeviceAugment`. No pool, no producer process,
no CPU augmentation: the host only plans each batch (a few numbers per crop).

Batch ``i`` of a source with seed ``S`` has exactly the crop parameters and panoramas of batch ``i``
of ``glradial.synthesis.crop_producer.crop_batches(panoramas, batch_size, seed=S, ...)`` with the
same options (its :func:`~glradial.synthesis.crop_producer.plan_batch`, drawn from
``numpy.random.default_rng([S, i])`` on the host: the one definition of the paper's distribution),
so the GL producer and this source render the same crops; the augmentation's draws come from a
``torch.Generator`` on the device seeded with ``augment_seed``. Batches start at index ``start``
(a resumed run passes its step count). Deterministic per seed on one device.
"""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np
import torch

from glradial.lens.metrics import PAPER_SIZE
from glradial.synthesis.crop_producer import crop_batches, plan_batch
from glradial.synthesis.crops import crop_labels

from .augment import AugmentConfig
from .gpu_augment import DeviceAugment
from .torch_crops import TorchCropRenderer


class GpuCropSource:
    """:class:`net.sources.BatchSource` rendering on ``device`` (see the module docstring).

    ``panoramas``: uint8 RGB equirectangular arrays; ``out_size`` ``(w, h)`` the network input;
    ``panoramas_per_batch`` panoramas feed each batch (as the crop producer picks them);
    ``augment`` the photometric augmentation (``None``: none).
    """

    def __init__(self, panoramas: Sequence[np.ndarray], *, batch_size: int, seed: int, out_size: tuple[int, int],
                 device: torch.device | str, augment: AugmentConfig | None = None, augment_seed: int = 0,
                 paired: bool = False, panoramas_per_batch: int = 4, start: int = 0, size: tuple[int, int] = PAPER_SIZE):
        self.device = torch.device(device)
        # crop_batches with no worker makes no GL context until a batch is asked of it: only its plan is used
        self.plan = crop_batches(list(panoramas), batch_size, seed=seed, size=size, out_size=out_size, workers=0,
                                 panoramas_per_batch=panoramas_per_batch, paired=paired)
        steps = self.plan.config.newton_steps
        self.renderer = TorchCropRenderer(panoramas, size=size, out_size=out_size, newton_steps=steps, device=self.device)
        self.augment = DeviceAugment(augment, augment_seed, self.device) if augment is not None else None
        self.paired = paired
        self.index = int(start)
        self.wait_s = 0.0
        self.render_s = 0.0

    def next_batch(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The next batch (module docstring of :mod:`net.sources`)."""
        t0 = time.monotonic()
        params, which = plan_batch(self.plan.config, self.index)
        self.index += 1
        images = self.renderer.render_float(params, which)
        if self.augment is not None:
            images = self.augment.augment(images, paired=self.paired)
        labels = torch.from_numpy(crop_labels(params, np.float32)).to(self.device, non_blocking=True)
        images = images.round_().to(torch.uint8).permute(0, 2, 3, 1)
        self.render_s += time.monotonic() - t0
        return images, labels

    def close(self) -> None:
        """Nothing runs in the background; the panoramas are freed with the source."""
        self.plan.close()
