"""Where a training step's batch comes from: the :class:`BatchSource` interface and its CPU
implementation, :class:`PoolSource` (the GPU one is :class:`net.gpu_source.GpuCropSource`).

Convention: ``next_batch()`` returns ``(images, labels)`` on the training device: images uint8
``N × H × W × 3`` RGB at the network input size (augmented; the trainer normalises them with
:func:`net.model.normalise_batch`), labels float32 ``N × 2`` = ``(k1, k2)`` in width-normalised lens
units of the 16:9 frame; with ``paired`` crops ``2i`` and ``2i + 1`` share view and augmentation and
differ in the lens. ``wait_s`` counts the seconds spent waiting for crops to arrive; ``close()``
stops whatever the source started.
"""

from __future__ import annotations

import time
from typing import Protocol

import numpy as np
import torch

from .augment import AugmentConfig, augment_batch, augment_pairs
from .data import CropPool, CropProducers


class BatchSource(Protocol):
    """A stream of training batches (see the module docstring)."""

    @property
    def wait_s(self) -> float:
        """Seconds spent waiting for crops so far."""
        ...

    def next_batch(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The next ``(images, labels)``."""
        ...

    def close(self) -> None:
        """Stop the source's workers (idempotent)."""
        ...


class PoolSource:
    """Batches from GL crop producer processes through a reuse pool, augmented on the CPU (the
    trainer's data path before the GPU source; net/train.py's module docstring).

    Each ``next_batch`` takes exactly ``fresh_per_step`` new crops from ``producers`` into ``pool``,
    samples ``batch_size`` crops from the pool with ``rng`` and augments them with ``rng``
    (:func:`~net.augment.augment_pairs` on ``augment_workers`` threads when ``paired``, else
    :func:`~net.augment.augment_batch`). ``rng`` is the trainer's generator, shared with the loss
    (its draws interleave exactly as before the interface existed). :meth:`fill` fills the pool
    to ``need`` crops first.
    """

    def __init__(self, producers: CropProducers, pool: CropPool, *, batch_size: int, fresh_per_step: int, chunk: int,
                 rng: np.random.Generator, augment: AugmentConfig, paired: bool, augment_workers: int,
                 device: torch.device):
        self.producers = producers
        self.pool = pool
        self.batch_size = batch_size
        self.fresh_per_step = fresh_per_step
        self.chunk = chunk
        self.rng = rng
        self.augment = augment
        self.paired = paired
        self.augment_workers = augment_workers
        self.device = device

    @property
    def wait_s(self) -> float:
        return self.producers.wait_s

    def fill(self, need: int) -> float:
        """Take chunks until the pool holds ``need`` crops; returns the seconds it took."""
        t0 = time.monotonic()
        while self.pool.count < need:
            self.pool.add(*self.producers.take(self.chunk))
        return time.monotonic() - t0

    def next_batch(self) -> tuple[torch.Tensor, torch.Tensor]:
        self.pool.add(*self.producers.take(self.fresh_per_step))
        images, labels = self.pool.sample(self.batch_size, self.rng, paired=self.paired)
        if self.paired:
            images = augment_pairs(images, self.rng, self.augment, workers=self.augment_workers)
        else:
            images = augment_batch(images, self.rng, self.augment)
        return torch.from_numpy(images).to(self.device), torch.from_numpy(labels).to(self.device)

    def close(self) -> None:
        self.producers.close()
