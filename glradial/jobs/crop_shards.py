"""``glradial crops PANORAMA ... --out DIR --workers N | --ray``: the crops dataset in shards, one per
panorama, each a complete crops dataset of its own (:mod:`glradial.synthesis.dataset`) in
``DIR/<panorama file name>.crops/``, run as a job (manifest, retries, report; :mod:`glradial.jobs.runner`).

A shard is fixed by the settings alone, whatever the number of workers: panorama ``j`` (in the order
given) gets ``count // P`` crops, one more for ``j < count % P``; its split is the one
:func:`~glradial.synthesis.dataset.assign_splits` gives it among all ``P`` panoramas with ``--seed``
(so no panorama is in two splits, as in one dataset); its crops are drawn with the seed
``SeedSequence([seed, j])`` gives. A shard is written in the worker's staging folder and moved into
place complete.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..synthesis.dataset import SPLITS, assign_splits, write_crops_dataset

__all__ = ["CropShardWork", "shard_plan", "crop_job"]


def shard_plan(names: list[str], count: int, seed: int, splits) -> dict[str, tuple[int, int, str]]:
    """``{panorama file name: (crops, shard seed, split)}`` of the module docstring."""
    split_of = assign_splits(len(names), splits, seed)
    plan = {}
    for j, name in enumerate(names):
        crops = count // len(names) + (1 if j < count % len(names) else 0)
        shard_seed = int(np.random.SeedSequence([seed, j]).generate_state(1)[0])
        plan[name] = (crops, shard_seed, split_of[j])
    return plan


@dataclass(frozen=True)
class CropShardWork:
    """``work(source, staging) -> facts`` writing one panorama's shard (picklable)."""

    plan: dict
    options: dict

    def __call__(self, source: str, staging: Path) -> dict:
        name = Path(source).name
        crops, seed, split = self.plan[name]
        if crops == 0:
            raise ValueError(f"--count {self.options['count']} leaves no crop for panorama {source!r} (give at least one per panorama)")
        fractions = tuple(1.0 if s == split else 0.0 for s in SPLITS)
        o = self.options
        summary = write_crops_dataset([source], staging / f"{name}.crops", count=crops, seed=seed, size=o["size"],
                                      out_size=o["out_size"], inverse=o["inverse"], supersample=o["supersample"],
                                      splits=fractions, image_format=o["format"])
        return {"frames": summary.written + summary.skipped, "split": split}


def crop_job(args: argparse.Namespace):
    """``(inputs, work, options, planned)`` of the sharded ``crops`` job (run by :mod:`glradial.jobs.command_line`)."""
    from .inputs import expand_inputs

    inputs = expand_inputs(args.panoramas)
    options = {key: getattr(args, key) for key in ("count", "seed", "size", "out_size", "inverse", "supersample", "splits", "format")}
    plan = shard_plan([p.name for p in inputs], args.count, args.seed, args.splits)
    return inputs, CropShardWork(plan, options), options, lambda source: [f"{source.name}.crops"]
