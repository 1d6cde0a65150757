"""Train the distortion estimator (single process or ``torchrun`` / DistributedDataParallel).

Usage::

    python -m net.train --config net/configs/stage01_128.json --out runs/stage01 [--resume]
    python -m net.train --config net/configs/stage12_multitask.json --out runs/stage12 \
        --init runs/shipped_from_onnx.pt --resume --stop-after-s 420   # one call of a longer run
    python -m net.train --config net/configs/stage13_gpu_source.json --out runs/stage13 \
        --init net/checkpoints/continue.pt                             # GPU batch source, bf16
    torchrun --nproc_per_node=2 -m net.train --config net/configs/tiny.json --out runs/ddp

Data path per rank: a :class:`~.sources.BatchSource` (``source`` in the config, ``--source``).
``"pool"`` (:class:`~.sources.PoolSource`, the default): ``producers`` :class:`~.data.CropProducer`
processes render crops ahead of time, each with its own EGL context, its own seed
(``seed * 1000 + shard``) and its own shard of the training panoramas (shard
``rank * producers + j`` of ``world * producers``, so memory per process falls as processes are
added); :class:`~.data.CropProducers` interleaves their chunks in proportion to shard size. Every
step takes exactly ``fresh_per_step`` new crops into a :class:`~.data.CropPool` and samples the
batch from the pool, then applies :func:`~.augment.augment_batch` (photometric + flips).
``"gpu"`` (:class:`~.gpu_source.GpuCropSource`): this rank's shard of the panoramas on the device,
fresh crops every step rendered by the torch twin of the crop shader and augmented on the device.
``amp`` "bf16" runs the forward pass under bfloat16 autocast, ``channels_last`` keeps the network
and its input channels-last, ``compile`` wraps the network in ``torch.compile``.
Loss (:func:`step_loss`): :func:`~.loss.training_loss` (the paper's; ``joint_loss_weight`` > 0 adds the
joint in-frame term; ``small_k1_weight`` > 0 weights near-zero lenses more), plus, with
``comparator_loss_weight`` > 0, the comparator head's BCE on pairs of crops (training-only: export
drops the head). AdamW, linear warm-up then cosine decay; the
schedule's progress is ``step / steps`` or, with ``time_budget_s``, the training wall time spent
over the budget (so a run ends on time on a shared machine; then the run is not bit-reproducible).
``stop_at_s`` ends a run early without changing its schedule.
An exponential moving average (EMA) of the weights is kept and is what validation, the "best"
checkpoint and export use.

Outputs in ``--out`` (written through :mod:`glradial.media.atomic`, except the log ``train.csv``, one
row per log interval appended and flushed as it comes), ``last.pt`` (every
``checkpoint_s`` seconds and at the end; ``--resume`` continues from it), ``best.pt`` (best
validation median max-displacement), ``config.json`` (the full run config, model config included).
Uses CUDA when ``torch.cuda.is_available()`` (NCCL for DDP) and the CPU otherwise (gloo).
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import csv
import json
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist

from glradial.evaluation.evaluation import metrics
from glradial.media.atomic import atomic_path, atomic_write_text
from glradial.schemas import validate_config

from .augment import AugmentConfig
from .data import CropPool, CropProducer, CropProducers, PanoramaSource, render_test_set, shard_source
from .gpu_source import GpuCropSource
from .loss import comparator_loss, comparison_partners, error_scale_loss, small_k1_weights, training_loss
from .model import DistortionNet, ModelConfig, count_parameters, load_grown, normalise_batch
from .sources import BatchSource, PoolSource

#: Batch sources (:mod:`net.sources`): GL producers + pool + CPU augmentation, or all on the device.
SOURCES = ("pool", "gpu")
#: Autocast choices of the forward pass.
AMP = ("off", "bf16")


@dataclass
class TrainConfig:
    """Full description of a run (a JSON file; unknown keys are an error)."""

    model: dict = field(default_factory=dict)
    augment: dict = field(default_factory=dict)
    seed: int = 0
    batch_size: int = 64
    steps: int = 1000
    time_budget_s: float | None = None
    lr: float = 2e-3
    min_lr_ratio: float = 0.02
    warmup_steps: int = 200
    weight_decay: float = 1e-4
    ema_decay: float = 0.998
    fresh_per_step: int = 16
    pool_capacity: int = 8192
    pool_min: int = 1024
    producer_chunk: int = 64
    producer_threads: int = 1
    producers: int = 1  # crop producer processes per rank, each rendering its own shard of the panoramas
    augment_workers: int = 0  # threads augmenting a paired batch (0: inline); results do not depend on it
    paired: bool = False
    stop_at_s: float | None = None  # stop after this much step time, leaving the schedule as it is
    joint_loss_weight: float = 0.0  # > 0 adds the joint in-frame term to the paper's loss (net.loss)
    error_loss_weight: float = 0.1  # weight of the error head's Laplace likelihood (models with error_head)
    error_head_lr_scale: float = 1.0  # the error head's learning rate over lr
    error_head_only: bool = False  # train only the error head: the rest (batch-norm statistics too) stays as loaded
    comparator_loss_weight: float = 0.0  # > 0: the comparator's BCE beside the regression (needs model.comparator_head)
    small_k1_weight: float = 0.0  # > 0: extra loss weight at k1 = 0, 1 + w exp(-k1^2 / 2 s^2) (net.loss.small_k1_weights)
    small_k1_scale: float = 0.1  # s of that weight, lens units
    panoramas: dict = field(default_factory=lambda: {"kind": "stadium", "seeds": {"split": "train", "n": 16}, "size": [2048, 1024]})
    val_panoramas: dict | None = field(default_factory=lambda: {"kind": "stadium", "seeds": {"split": "val", "n": 4}, "size": [2048, 1024]})
    val_size: int = 256
    val_every_s: float = 300.0
    checkpoint_s: float = 300.0
    log_every: int = 20
    threads: int = 1  # torch threads per process: >1 collapses (OpenMP spin-waits) on a shared machine
    cache_dir: str = "data_cache"
    source: str = "pool"  # batch source: "pool" (GL crop producers, a reuse pool, CPU augmentation) or "gpu" (net.gpu_source)
    panoramas_per_batch: int = 4  # panoramas feeding one batch of the "gpu" source (as the crop producer picks them)
    amp: str = "off"  # "bf16": the forward pass under bfloat16 autocast (the loss in float32)
    channels_last: bool = True  # the network and its input in channels-last memory layout
    compile: bool = False  # torch.compile the network for training

    @classmethod
    def from_json(cls, path: str | Path) -> "TrainConfig":
        """Load a run config; ``"base"`` names a config (relative to this file's folder) that it
        extends (:func:`load_config_dict`)."""
        data = load_config_dict(path)
        validate_config(data, f"training config {str(path)!r}")  # types, ranges, unknown keys
        cfg = cls(**data)
        if cfg.producers < 1:
            raise ValueError(f"producers must be at least 1, got {cfg.producers}")
        comparator = bool(cfg.model.get("comparator_head", False))
        if not cfg.comparator_loss_weight >= 0 or (cfg.comparator_loss_weight > 0) != comparator:
            raise ValueError(f"comparator_loss_weight {cfg.comparator_loss_weight} in {path} needs model.comparator_head "
                             f"true exactly when it is > 0 (comparator_head is {comparator})")
        if not cfg.small_k1_weight >= 0 or not cfg.small_k1_scale > 0:
            raise ValueError(f"small_k1_weight must be >= 0 and small_k1_scale > 0 in {path}, got "
                             f"{cfg.small_k1_weight} and {cfg.small_k1_scale}")
        if cfg.paired and (cfg.batch_size % 2 or cfg.fresh_per_step % 2 or cfg.producer_chunk % 2 or cfg.pool_capacity % 2):
            raise ValueError("paired training needs even batch_size, fresh_per_step, producer_chunk and pool_capacity")
        cfg.check_speed_options(str(path))
        return cfg

    def check_speed_options(self, where: str) -> None:
        """``ValueError`` naming ``where`` and the value for a batch source, autocast or layout
        option that does not exist."""
        if self.source not in SOURCES:
            raise ValueError(f"source must be one of {SOURCES} in {where}, got {self.source!r}")
        if self.amp not in AMP:
            raise ValueError(f"amp must be one of {AMP} in {where}, got {self.amp!r}")
        for name in ("channels_last", "compile"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false in {where}, got {getattr(self, name)!r}")
        if isinstance(self.panoramas_per_batch, bool) or not isinstance(self.panoramas_per_batch, int) or self.panoramas_per_batch < 1:
            raise ValueError(f"panoramas_per_batch must be an integer >= 1 in {where}, got {self.panoramas_per_batch!r}")


def merge_config(base: dict, changes: dict) -> dict:
    """``base`` updated by ``changes``: nested dicts merge key by key, anything else (lists, numbers,
    ``null``) replaces the base's value."""
    out = dict(base)
    for key, value in changes.items():
        out[key] = merge_config(out[key], value) if isinstance(value, dict) and isinstance(out.get(key), dict) else value
    return out


def load_config_dict(path: str | Path, _seen: tuple[Path, ...] = ()) -> dict:
    """A config file as a dict, its ``"base"`` chain resolved: the file holds only its differences
    from the config it names (a path relative to the file's folder), merged by :func:`merge_config`.
    A missing base or a cycle is a ``ValueError`` naming the files."""
    path = Path(path).resolve()
    if path in _seen:
        raise ValueError(f"config base cycle: {' -> '.join(str(p.name) for p in (*_seen, path))}")
    data = json.loads(path.read_text())
    if not isinstance(data, dict):
        raise ValueError(f"{path} must hold a JSON object, got {type(data).__name__}")
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str):
        raise ValueError(f"'base' in {path} must be a file name, got {base!r}")
    base_path = path.parent / base
    if not base_path.is_file():
        raise ValueError(f"{path}: its base {str(base_path)!r} does not exist")
    return merge_config(load_config_dict(base_path, (*_seen, path)), data)


def panorama_source(spec: dict, cache_dir: str) -> PanoramaSource:
    """Build a :class:`PanoramaSource` from a config entry (``seeds`` a list or ``{split, n, start}``)."""
    seeds = spec.get("seeds", [])
    if isinstance(seeds, dict):
        from glradial.synthesis.stadium_style import split_seeds

        seeds = split_seeds(seeds["split"], int(seeds["n"]), int(seeds.get("start", 0)))
    return PanoramaSource(kind=spec["kind"], seeds=list(seeds), size=tuple(spec.get("size", (2048, 1024))),
                          cache_dir=cache_dir, files=spec.get("files", ()))


def lr_factor(progress: float, step: int, cfg: TrainConfig) -> float:
    warm = min(1.0, (step + 1) / max(1, cfg.warmup_steps))
    progress = min(max(progress, 0.0), 1.0)
    cosine = cfg.min_lr_ratio + (1 - cfg.min_lr_ratio) * 0.5 * (1 + math.cos(math.pi * progress))
    return warm * cosine


def freeze_all_but_error_head(model: torch.nn.Module) -> None:
    """Only ``head_error`` learns: every other parameter stops needing gradients and every other
    batch norm uses (and keeps) its running statistics, so the (k1, k2) function stays as loaded."""
    for name, p in model.named_parameters():
        p.requires_grad_(name.startswith("head_error."))
    for name, m in model.named_modules():
        if isinstance(m, torch.nn.modules.batchnorm._BatchNorm) and not name.startswith("head_error."):
            m.eval()


def predict(model: torch.nn.Module, images: np.ndarray, config: ModelConfig, device, batch: int = 128) -> np.ndarray:
    model.eval()
    out = []
    with torch.no_grad():
        for i in range(0, len(images), batch):
            x = normalise_batch(torch.from_numpy(images[i : i + batch]).to(device), config)
            out.append(model(x.contiguous(memory_format=torch.channels_last))[:, :2].float().cpu().numpy())
    return np.concatenate(out)


class EMA:
    """Exponential moving average of a model's parameters and buffers."""

    def __init__(self, model: torch.nn.Module, decay: float):
        self.decay = decay
        self.model = copy.deepcopy(model).eval()
        for p in self.model.parameters():
            p.requires_grad_(False)

    @torch.no_grad()
    def update(self, model: torch.nn.Module, step: int) -> None:
        d = min(self.decay, (1 + step) / (10 + step))
        for e, m in zip(self.model.state_dict().values(), model.state_dict().values()):
            if e.dtype.is_floating_point:
                e.mul_(d).add_(m.detach(), alpha=1 - d)
            else:
                e.copy_(m)


def save_checkpoint(path: Path, **state) -> None:
    """``torch.save`` of ``state`` to ``path``, atomically (a killed run leaves the previous file)."""
    with atomic_path(path) as tmp:
        torch.save(state, tmp)


def rank_shards(source: PanoramaSource, cfg: TrainConfig, rank: int, world: int) -> list[tuple[int, PanoramaSource]]:
    """This rank's ``(shard index, panoramas)``: producer ``j`` gets shard ``rank * producers + j`` of
    the ``world * producers`` shards of ``source`` (``ValueError`` when there are more shards than
    panoramas)."""
    count = world * cfg.producers
    first = rank * cfg.producers
    return [(shard, shard_source(source, shard, count)) for shard in range(first, first + cfg.producers)]


def start_producers(shards: list[tuple[int, PanoramaSource]], cfg: TrainConfig, step: int,
                    out_size: tuple[int, int]) -> CropProducers:
    """One crop producer per shard of :func:`rank_shards`, with seed ``cfg.seed * 1000 + shard +
    7919 * step`` (a resumed run never repeats the crops it has seen). With one producer and one
    rank this is the single full-set producer of the runs made before producers were sharded:
    same stream."""
    producers: list[CropProducer] = []
    try:
        for shard, part in shards:
            producers.append(CropProducer(part, seed=cfg.seed * 1000 + shard + 7919 * step, out_size=out_size,
                                          chunk=cfg.producer_chunk, threads=cfg.producer_threads, paired=cfg.paired))
    except BaseException:
        for started in producers:
            started.close()
        raise
    return CropProducers(producers, [len(part) for _, part in shards], cfg.producer_chunk)


def step_loss(train_model: torch.nn.Module, x: torch.Tensor, y: torch.Tensor, cfg: TrainConfig,
              model_cfg: ModelConfig, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """One batch's loss (scalar) and the predicted ``(k1, k2)`` (``N x 2``): the regression loss
    (:func:`~.loss.training_loss`, with ``joint_loss_weight`` and, when ``small_k1_weight`` > 0,
    :func:`~.loss.small_k1_weights`), the error head's likelihood when the model has one, and the
    comparator's BCE when ``comparator_loss_weight`` > 0 (pairs: :func:`~.loss.comparison_partners`;
    ``rng`` is drawn from only for unpaired batches). With both weights 0 it is the loss of the
    runs before them, to the bit. With ``cfg.amp`` "bf16" the network runs under bfloat16
    autocast and its outputs are taken back to float32 before the loss."""
    partner = None
    if cfg.comparator_loss_weight > 0:
        partner = torch.from_numpy(comparison_partners(len(y), cfg.paired, rng)).to(y.device)
    with torch.autocast(x.device.type, dtype=torch.bfloat16) if cfg.amp == "bf16" else contextlib.nullcontext():
        out_all = train_model(x) if partner is None else train_model(x, partner)
    out_all = out_all.float()
    pred = out_all[:, :2]
    weights = small_k1_weights(y[:, 0], cfg.small_k1_weight, cfg.small_k1_scale) if cfg.small_k1_weight > 0 else None
    loss = training_loss(y, pred, joint_weight=cfg.joint_loss_weight, sample_weight=weights)
    if model_cfg.error_head:
        loss = loss + cfg.error_loss_weight * error_scale_loss(y, pred, out_all[:, 2])
    if partner is not None:
        loss = loss + cfg.comparator_loss_weight * comparator_loss(out_all[:, -2:], y, partner)
    return loss, pred


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line of ``python -m net.train`` (module docstring)."""
    parser = argparse.ArgumentParser(prog="python -m net.train", description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="run config JSON (see TrainConfig; \"base\" names the config it extends)")
    parser.add_argument("--out", required=True, help="run folder (checkpoints, CSV, config)")
    parser.add_argument("--resume", action="store_true", help="continue from OUT/last.pt if present")
    parser.add_argument("--steps", type=int, help="override the config's step count")
    parser.add_argument("--time-budget-s", type=float,
                        help="override the config's time budget (0: none; the schedule then follows the step count)")
    parser.add_argument("--threads", type=int, help="torch threads per process")
    parser.add_argument("--stop-after-s", type=float,
                        help="end this call after this many more seconds of step time (the schedule unchanged; "
                        "--resume continues): a long run in calls of limited length")
    parser.add_argument("--init", help="start from this checkpoint's (EMA) weights; new optimizer and schedule "
                        "(fine-tuning). The config's model may be wider or deeper: net.model.load_grown grows "
                        "the weights so that training starts from the same function")
    parser.add_argument("--zero-k2-head", action="store_true",
                        help="with --init: zero the k2 head's last layer (a k2_residual model then starts on the manifold)")
    parser.add_argument("--source", choices=SOURCES, help="override the config's batch source (pool: GL producers + CPU "
                        "augmentation; gpu: crops rendered and augmented on the training device, net.gpu_source)")
    parser.add_argument("--amp", choices=AMP, help="override the config's autocast of the forward pass")
    parser.add_argument("--channels-last", action=argparse.BooleanOptionalAction, default=None,
                        help="override the config's memory layout of the network and its input")
    parser.add_argument("--compile", action=argparse.BooleanOptionalAction, default=None,
                        help="override the config's torch.compile of the network")
    args = parser.parse_args(argv)
    if args.stop_after_s is not None and not args.stop_after_s > 0:
        raise ValueError(f"--stop-after-s must be positive, got {args.stop_after_s}")
    return args


def run_config(args: argparse.Namespace) -> TrainConfig:
    """The config file with the command line's overrides."""
    cfg = TrainConfig.from_json(args.config)
    for name in ("steps", "time_budget_s", "threads", "source", "amp", "channels_last", "compile"):
        if getattr(args, name) is not None:
            setattr(cfg, name, getattr(args, name))
    return cfg


@dataclass
class Run:
    """The state of one training process: config, placement, network, optimiser and progress."""

    cfg: TrainConfig
    model_cfg: ModelConfig
    device: torch.device
    rank: int
    world: int
    distributed: bool
    out: Path
    model: torch.nn.Module
    ema: EMA
    optimizer: torch.optim.Optimizer
    train_model: torch.nn.Module | None = None
    step: int = 0
    train_time: float = 0.0
    best: float = math.inf

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    def log(self, msg: str) -> None:
        if self.is_main:
            print(time.strftime("%H:%M:%S"), msg, flush=True)

    def memory_format(self) -> torch.memory_format:
        return torch.channels_last if self.cfg.channels_last else torch.contiguous_format

    def progress(self) -> float:
        """Fraction of the schedule done: training time over the budget, or steps over ``steps``."""
        return self.train_time / self.cfg.time_budget_s if self.cfg.time_budget_s else self.step / max(1, self.cfg.steps)

    def save_last(self) -> None:
        save_checkpoint(self.out / "last.pt", model=self.model.state_dict(), ema=self.ema.model.state_dict(),
                        optimizer=self.optimizer.state_dict(), step=self.step, train_time=self.train_time, best=self.best,
                        model_config=self.model_cfg.to_dict())

    def save_best(self, vm: dict) -> None:
        save_checkpoint(self.out / "best.pt", model=self.ema.model.state_dict(), model_config=self.model_cfg.to_dict(),
                        step=self.step, train_time=self.train_time, val=vm)


def placement() -> tuple[bool, int, int]:
    """``(distributed, rank, world)``: a process group under ``torchrun`` (NCCL on CUDA, else gloo)."""
    distributed = "WORLD_SIZE" in os.environ and int(os.environ["WORLD_SIZE"]) > 1
    if not distributed:
        return False, 0, 1
    dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return True, dist.get_rank(), dist.get_world_size()


def training_device() -> torch.device:
    """This process's CUDA device (``LOCAL_RANK``) when there is one, else the CPU."""
    if not torch.cuda.is_available():
        return torch.device("cpu")
    local = int(os.environ.get("LOCAL_RANK", 0))
    torch.cuda.set_device(local)
    return torch.device("cuda", local)


def build_run(cfg: TrainConfig, out: Path, distributed: bool, rank: int, world: int) -> Run:
    """The network (in ``cfg.channels_last`` layout), its EMA and AdamW (decayed weights, undecayed
    biases and norms, the error head at its own learning-rate scale) on this process's device."""
    device = training_device()
    torch.set_num_threads(max(1, cfg.threads))
    torch.manual_seed(cfg.seed)
    model_cfg = ModelConfig.from_dict(cfg.model)
    model = DistortionNet(model_cfg).to(device)
    if cfg.channels_last:
        model = model.to(memory_format=torch.channels_last)
    ema = EMA(model, cfg.ema_decay)
    decay, no_decay, error_head = [], [], []
    for name, p in model.named_parameters():
        (error_head if name.startswith("head_error.") else no_decay if p.ndim <= 1 else decay).append(p)
    groups = [{"params": decay, "weight_decay": cfg.weight_decay, "lr_scale": 1.0},
              {"params": no_decay, "weight_decay": 0.0, "lr_scale": 1.0}]
    if error_head:  # a new head next to trained weights: its own (larger) learning rate
        groups.append({"params": error_head, "weight_decay": 0.0, "lr_scale": cfg.error_head_lr_scale})
    optimizer = torch.optim.AdamW(groups, lr=cfg.lr)
    return Run(cfg, model_cfg, device, rank, world, distributed, out, model, ema, optimizer)


def load_weights(run: Run, args: argparse.Namespace) -> None:
    """``--init`` (weights, grown to the config's network; optionally a zeroed k2 head) and
    ``--resume`` (everything, from ``OUT/last.pt``)."""
    if args.init:
        state = torch.load(args.init, map_location=run.device, weights_only=False)
        weights = state.get("ema", state["model"])
        grown = load_grown(run.model, weights)
        unexpected = sorted(set(weights) - set(run.model.state_dict()))
        if args.zero_k2_head:
            with torch.no_grad():
                run.model.head_k2.net[-1].weight.zero_()
                run.model.head_k2.net[-1].bias.zero_()
        run.ema.model.load_state_dict(run.model.state_dict())
        run.log(f"initialised from {args.init} ({len(grown['copied'])} tensors copied, {len(grown['grown'])} grown, "
                f"{len(grown['new'])} new, unexpected {unexpected})")
    if args.resume and (run.out / "last.pt").exists():
        state = torch.load(run.out / "last.pt", map_location=run.device, weights_only=False)
        run.model.load_state_dict(state["model"])
        run.ema.model.load_state_dict(state["ema"])
        run.optimizer.load_state_dict(state["optimizer"])
        run.step, run.train_time, run.best = state["step"], state["train_time"], state.get("best", math.inf)
        run.log(f"resumed from {run.out / 'last.pt'} at step {run.step} ({run.train_time:.0f} s trained)")


def prepare(run: Run, args: argparse.Namespace) -> None:
    """Stop time, the run folder's config files, the (DDP-wrapped, optionally compiled) training network."""
    if args.stop_after_s is not None:
        run.cfg.stop_at_s = run.train_time + args.stop_after_s
    if run.is_main:
        run.out.mkdir(parents=True, exist_ok=True)
        full = asdict(run.cfg)
        full["model"] = run.model_cfg.to_dict()
        atomic_write_text(run.out / "config.json", json.dumps(full, indent=2) + "\n")
        run.model_cfg.save(run.out / "model_config.json")
    run.train_model = torch.nn.parallel.DistributedDataParallel(run.model) if run.distributed else run.model
    if run.cfg.compile:
        run.train_model = torch.compile(run.train_model)
    run.log(f"model {count_parameters(run.model)} parameters, input {run.model_cfg.input_size}, device {run.device}, "
            f"world {run.world}, source {run.cfg.source}, amp {run.cfg.amp}, channels_last {run.cfg.channels_last}, "
            f"compile {run.cfg.compile}")


def validation_set(run: Run) -> tuple | None:
    """The validation crops (GL-rendered, the reference renderer), on the main process only."""
    cfg = run.cfg
    if not (run.is_main and cfg.val_panoramas and cfg.val_size > 0):
        return None
    vsrc = panorama_source(cfg.val_panoramas, cfg.cache_dir)
    t0 = time.monotonic()
    val = render_test_set(vsrc, cfg.val_size, seed=10_000 + cfg.seed, out_size=run.model_cfg.input_size)
    run.log(f"validation set: {len(val[0])} crops from {len(vsrc)} panoramas ({time.monotonic() - t0:.1f} s)")
    return val


def batch_source(run: Run, source: PanoramaSource, shards: list[tuple[int, PanoramaSource]],
                 rng: np.random.Generator) -> BatchSource:
    """This rank's :class:`~.sources.BatchSource`: GL crop producers on its shards with a reuse pool
    (``source`` "pool", the pool filled before it returns), or the GPU source on its shard
    (seed ``cfg.seed * 1000 + rank``, batches from index ``step``, augmentation seeded by seed, rank
    and step, so a resumed run never repeats what it has seen)."""
    cfg, model_cfg = run.cfg, run.model_cfg
    aug_cfg = AugmentConfig(**cfg.augment)
    if cfg.source == "gpu":
        part = shard_source(source, run.rank, run.world)
        augment_seed = int(np.random.SeedSequence([cfg.seed, run.rank, run.step]).generate_state(1)[0])
        gpu = GpuCropSource(part.load(), batch_size=cfg.batch_size, seed=cfg.seed * 1000 + run.rank,
                            out_size=model_cfg.input_size, device=run.device, augment=aug_cfg, augment_seed=augment_seed,
                            paired=cfg.paired, panoramas_per_batch=cfg.panoramas_per_batch, start=run.step)
        run.log(f"GPU batch source: {len(part)} panoramas on {run.device}")
        return gpu
    producers = start_producers(shards, cfg, run.step, model_cfg.input_size)
    run.log(f"{len(producers.producers)} crop producer(s) on this rank, holding "
            f"{' + '.join(str(w) for w in producers.weights)} panoramas")
    pool = PoolSource(producers, CropPool(cfg.pool_capacity, model_cfg.input_size), batch_size=cfg.batch_size,
                      fresh_per_step=cfg.fresh_per_step, chunk=cfg.producer_chunk, rng=rng, augment=aug_cfg,
                      paired=cfg.paired, augment_workers=cfg.augment_workers, device=run.device)
    try:
        took = pool.fill(max(cfg.pool_min, cfg.batch_size))
    except BaseException:
        pool.close()
        raise
    run.log(f"pool filled with {pool.pool.count} crops ({took:.1f} s)")
    return pool


def open_log(run: Run, resume: bool):
    """The run's ``train.csv`` (appended to on resume), its header written when new; ``None`` off rank 0."""
    if not run.is_main:
        return None
    new = not (run.out / "train.csv").exists() or not resume
    csv_file = open(run.out / "train.csv", "w" if new else "a", newline="")
    if new:
        csv.writer(csv_file).writerow(["step", "train_s", "lr", "loss", "k1_mae", "k2_mae", "img_per_s", "producer_wait_s",
                                       "val_dl", "val_median_px", "val_p90_px", "val_a_beats_b"])
    return csv_file


def train_step(run: Run, data: BatchSource, rng: np.random.Generator, progress: float) -> tuple[torch.Tensor, torch.Tensor, float]:
    """One optimiser step on the next batch; returns the loss and ``|pred - y|`` per output, detached
    on the device (read back only when logged: no host sync per step), and the learning-rate factor."""
    cfg = run.cfg
    images, y = data.next_batch()
    x = normalise_batch(images, run.model_cfg).contiguous(memory_format=run.memory_format())
    factor = lr_factor(progress, run.step, cfg)
    for group in run.optimizer.param_groups:
        group["lr"] = cfg.lr * factor * group.get("lr_scale", 1.0)
    run.train_model.train()
    if cfg.error_head_only:
        freeze_all_but_error_head(run.model)
    loss, pred = step_loss(run.train_model, x, y, cfg, run.model_cfg, rng)
    run.optimizer.zero_grad(set_to_none=True)
    loss.backward()
    run.optimizer.step()
    run.ema.update(run.model, run.step)
    run.step += 1
    return loss.detach(), (pred.detach() - y).abs().mean(dim=0), factor


class Window:
    """Sums over one log interval, kept on the device (float64) until a row is written."""

    def __init__(self, device: torch.device):
        self.device = device
        self.reset()

    def reset(self) -> None:
        self.loss = torch.zeros((), dtype=torch.float64, device=self.device)
        self.k = torch.zeros(2, dtype=torch.float64, device=self.device)
        self.n, self.t = 0, 0.0

    def add(self, loss: torch.Tensor, k_err: torch.Tensor, dt: float) -> None:
        self.loss += loss.double()
        self.k += k_err.double()
        self.n += 1
        self.t += dt


def report(run: Run, window: Window, val: tuple | None, with_val: bool, factor: float, wait: float, writer) -> None:
    """One CSV row and log line (validating the EMA first when ``with_val``; a new best is saved)."""
    vm = {}
    if with_val:
        vm = metrics(predict(run.ema.model, val[0], run.model_cfg, run.device), val[1])
        if vm["median_max_px"] < run.best:
            run.best = vm["median_max_px"]
            run.save_best(vm)
    k = window.k.cpu().numpy()
    n = window.n
    row = [run.step, round(run.train_time, 1), f"{run.cfg.lr * factor:.3g}", f"{float(window.loss) / n:.4g}",
           f"{k[0] / n:.4f}", f"{k[1] / n:.4f}", f"{n * run.cfg.batch_size * run.world / max(window.t, 1e-9):.1f}",
           f"{wait:.1f}", f"{vm.get('mean_dl', float('nan')):.4g}", f"{vm.get('median_max_px', float('nan')):.2f}",
           f"{vm.get('p90_max_px', float('nan')):.2f}", f"{vm.get('a_beats_b', float('nan')):.3f}"]
    writer.writerow(row)
    run.log("step {} t {}s lr {} loss {} |dk1| {} |dk2| {} img/s {} wait {}s val DL {} med {}px p90 {}px A>B {}".format(*row))


def should_stop(run: Run) -> bool:
    """The schedule is done, or this call's stop time reached (every DDP rank follows the slowest
    clock under a time budget, so all take the same number of steps)."""
    if run.distributed and run.cfg.time_budget_s:
        clock = torch.tensor([run.train_time], dtype=torch.float64)
        dist.all_reduce(clock, op=dist.ReduceOp.MAX)
        run.train_time = float(clock)
    return run.progress() >= 1.0 or (run.cfg.stop_at_s is not None and run.train_time >= run.cfg.stop_at_s)


def train_loop(run: Run, data: BatchSource, rng: np.random.Generator, val: tuple | None, csv_file) -> None:
    """Steps until :func:`should_stop`, a log row every ``log_every`` steps (and at validations),
    ``last.pt`` every ``checkpoint_s`` seconds and at the end, ``best.pt`` at each better validation."""
    cfg = run.cfg
    writer = csv.writer(csv_file) if csv_file is not None else None
    last_ckpt = last_val = time.monotonic()
    window = Window(run.device)
    wait_before = data.wait_s
    while not should_stop(run):
        ts = time.monotonic()
        loss, k_err, factor = train_step(run, data, rng, run.progress())
        dt = time.monotonic() - ts
        run.train_time += dt
        window.add(loss, k_err, dt)
        now = time.monotonic()
        do_val = val is not None and (now - last_val >= cfg.val_every_s)
        done = (not run.distributed or not cfg.time_budget_s) and run.progress() >= 1.0
        if run.is_main and (run.step % cfg.log_every == 0 or do_val or done):
            report(run, window, val, do_val or (done and val is not None), factor, data.wait_s - wait_before, writer)
            csv_file.flush()
            if do_val or (done and val is not None):
                last_val = time.monotonic()
            wait_before = data.wait_s
            window.reset()
        if run.is_main and (now - last_ckpt >= cfg.checkpoint_s or done):
            run.save_last()
            last_ckpt = time.monotonic()
        if done:
            break


def finish(run: Run, val: tuple | None) -> None:
    """The final ``last.pt`` and, when no validation made one, ``best.pt`` (main process)."""
    if not run.is_main:
        return
    run.save_last()
    if val is not None and not (run.out / "best.pt").exists():
        run.save_best(metrics(predict(run.ema.model, val[0], run.model_cfg, run.device), val[1]))


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    cfg = run_config(args)
    distributed, rank, world = placement()
    source = panorama_source(cfg.panoramas, cfg.cache_dir)
    shards = rank_shards(source, cfg, rank, world)  # too many producers: an error before anything is written
    run = build_run(cfg, Path(args.out), distributed, rank, world)
    load_weights(run, args)
    prepare(run, args)
    t0 = time.monotonic()
    if run.is_main:
        source.inputs()  # stadiums rendered into the cache once, before the producers start (they read the cache)
    if distributed:
        dist.barrier()
    run.log(f"{len(source)} training panoramas ready ({time.monotonic() - t0:.1f} s)")
    val = validation_set(run)
    rng = np.random.default_rng([cfg.seed, rank, run.step])
    data = batch_source(run, source, shards, rng)
    csv_file = None
    try:
        csv_file = open_log(run, args.resume)
        train_loop(run, data, rng, val, csv_file)
        finish(run, val)
    finally:
        data.close()
        if csv_file is not None:
            csv_file.close()
        if distributed:
            dist.destroy_process_group()
    run.log(f"done: {run.step} steps, {run.train_time:.0f} s of training")
    return 0


if __name__ == "__main__":
    sys.exit(main())
