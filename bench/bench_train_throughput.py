"""Training throughput: samples/s of each batch source and of whole training steps, and the GPU's busy share.

Usage: python bench/bench_train_throughput.py [--config net/configs/stage12_multitask.json] [--seconds 6]
       [--sources gpu,pool] [--amp off|bf16] [--no-channels-last] [--compile] [--panoramas N] [--full]
       [--sources-only]

Phases, each ``--seconds`` of wall time after a warm-up, in one process, on the device training uses
(CUDA when there is one):
  * ``source <name>``: ``next_batch()`` alone (crops rendered, augmented, on the device);
  * ``step (fixed batch)``: one batch reused, so the network's step alone (the model bound);
  * ``train <name>``: ``net.train.train_step`` fed by the source: what training gets.
The sources are those of net.train (``net.train.batch_source``): ``gpu`` (net.gpu_source: torch
crops and augmentation on the device) and ``pool`` (GL crop producer processes, a reuse pool, CPU
augmentation). Ratios are against the fixed-batch step, in the same process.

GPU busy share (CUDA only): the NVML utilisation (the fraction of time a kernel ran), sampled every
50 ms while a phase runs (``torch.cuda.utilization``, else ``nvidia-smi``), and the share of wall time
covered by the steps' CUDA-event intervals. Without CUDA the run uses net/configs/tiny.json's network
and synthetic panoramas unless ``--full`` is given, and says so: a CPU figure is no GPU figure.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import torch  # noqa: E402
from figures import write_figure  # noqa: E402

from net.train import AMP, Run, TrainConfig, batch_source, build_run, panorama_source, rank_shards, train_step  # noqa: E402


class BusyMeter:
    """Mean GPU utilisation (NVML, percent) sampled on a thread between ``start`` and ``stop``."""

    def __init__(self, device: torch.device):
        self.device = device
        self.samples: list[float] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def read(self) -> float | None:
        try:
            return float(torch.cuda.utilization(self.device))
        except Exception:  # noqa: BLE001 - no pynvml: ask nvidia-smi
            if shutil.which("nvidia-smi") is None:
                return None
            out = subprocess.run(["nvidia-smi", "--query-gpu=utilization.gpu", "--format=csv,noheader,nounits",
                                  f"--id={self.device.index or 0}"], capture_output=True, text=True, timeout=5)
            return float(out.stdout.strip()) if out.returncode == 0 and out.stdout.strip() else None

    def start(self) -> None:
        if self.device.type != "cuda":
            return
        self.samples, self._stop = [], threading.Event()

        def poll() -> None:
            while not self._stop.wait(0.05):
                value = self.read()
                if value is not None:
                    self.samples.append(value)

        self._thread = threading.Thread(target=poll, daemon=True)
        self._thread.start()

    def stop(self) -> float | None:
        if self._thread is None:
            return None
        self._stop.set()
        self._thread.join()
        self._thread = None
        return float(np.mean(self.samples)) if self.samples else None


def timed(run: Run, seconds: float, batch: int, one, meter: BusyMeter) -> dict:
    """Calls ``one()`` for ``seconds`` after two warm-up calls -> samples/s, busy share, event share."""
    cuda = run.device.type == "cuda"
    for _ in range(2):
        one()
    if cuda:
        torch.cuda.synchronize(run.device)
    meter.start()
    events, count, t0 = [], 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        if cuda:
            begin, end = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
            begin.record()
        one()
        if cuda:
            end.record()
            events.append((begin, end))
        count += 1
    if cuda:
        torch.cuda.synchronize(run.device)
    wall = time.perf_counter() - t0
    busy = meter.stop()
    covered = sum(b.elapsed_time(e) for b, e in events) / 1000.0 if cuda else None
    return {"samples_s": count * batch / wall, "steps": count, "busy": busy, "event_share": covered / wall if cuda else None}


def bench_config(args: argparse.Namespace, cuda: bool) -> TrainConfig:
    """The run config to measure: ``--config`` (on CPU, unless ``--full``, shrunk to tiny.json's
    network and synthetic panoramas) with the command line's options."""
    cfg = TrainConfig.from_json(args.config)
    if not cuda and not args.full:
        tiny = TrainConfig.from_json(ROOT / "net/configs/tiny.json")
        heads = {k: v for k, v in cfg.model.items() if k.endswith("_head") or k == "k2_residual"}  # the loss needs them
        cfg.model, cfg.panoramas, cfg.batch_size = {**tiny.model, **heads}, tiny.panoramas, tiny.batch_size
        cfg.pool_min, cfg.pool_capacity, cfg.producer_chunk, cfg.fresh_per_step = 32, 256, 16, 8
    elif args.panoramas and isinstance(cfg.panoramas.get("seeds"), dict):
        cfg.panoramas = {**cfg.panoramas, "seeds": {**cfg.panoramas["seeds"], "n": args.panoramas}}
    cfg.pool_min = min(cfg.pool_min, 4 * cfg.batch_size)  # the pool's steady state, without a long fill
    cfg.amp, cfg.channels_last, cfg.compile = args.amp, args.channels_last, args.compile
    cfg.producers = min(cfg.producers, len(panorama_source(cfg.panoramas, cfg.cache_dir)))
    return cfg


def measure_source(run: Run, name: str, shards, meter: BusyMeter, fixed: dict | None, seconds: float, rng) -> dict | None:
    """The source's own rate and (unless ``fixed`` is ``None``: sources only) the training step's
    rate when fed by it."""
    run.cfg.source = name
    t0 = time.perf_counter()
    data = batch_source(run, panorama_source(run.cfg.panoramas, run.cfg.cache_dir), shards, rng)
    print(f"  {name} source ready in {time.perf_counter() - t0:.1f} s", flush=True)
    try:
        alone = timed(run, seconds, run.cfg.batch_size, data.next_batch, meter)
        fed = timed(run, seconds, run.cfg.batch_size, lambda: train_step(run, data, rng, 0.5), meter) if fixed else None
    finally:
        data.close()
    report(f"source {name}", alone, fixed)
    if fed is not None:
        report(f"train {name}", fed, fixed)
    return fed


#: every phase's figures, by label, for :func:`write_figure` at the end of the run
FIGURES: dict[str, dict] = {}


def report(label: str, result: dict, fixed: dict | None) -> None:
    """Print one phase's samples/s (and its ratio to the fixed-batch step) and keep it in :data:`FIGURES`."""
    FIGURES[label] = {**result, "ratio_to_fixed_batch": None if fixed is None else result["samples_s"] / fixed["samples_s"]}
    busy = "n/a" if result["busy"] is None else f"{result['busy']:.0f} %"
    share = "n/a" if result["event_share"] is None else f"{100 * result['event_share']:.0f} %"
    ratio = "" if fixed is None else f"  ({result['samples_s'] / fixed['samples_s']:.2f}x the fixed-batch step)"
    print(f"{label:22s} {result['samples_s']:9.1f} samples/s  GPU busy {busy:>6s}  event share {share:>6s}{ratio}", flush=True)


class FixedBatch:
    """A source that returns one batch again and again (the network's step alone)."""

    wait_s = 0.0

    def __init__(self, run: Run):
        w, h = run.model_cfg.input_size
        gen = torch.Generator().manual_seed(0)
        self.images = torch.randint(0, 256, (run.cfg.batch_size, h, w, 3), generator=gen, dtype=torch.uint8).to(run.device)
        self.labels = (torch.rand((run.cfg.batch_size, 2), generator=gen) * 0.2 - 0.1).to(run.device)

    def next_batch(self):
        return self.images, self.labels

    def close(self) -> None:
        pass


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=str(ROOT / "net/configs/stage12_multitask.json"))
    parser.add_argument("--seconds", type=float, default=6.0, help="wall seconds per phase (after a warm-up)")
    parser.add_argument("--sources", default="gpu,pool", help="comma-separated batch sources to measure")
    parser.add_argument("--amp", choices=AMP, default="off")
    parser.add_argument("--channels-last", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--compile", action="store_true")
    parser.add_argument("--panoramas", type=int, help="use only this many of the config's training stadiums (shorter start)")
    parser.add_argument("--sources-only", action="store_true", help="only the sources' own rates (no training steps)")
    parser.add_argument("--full", action="store_true", help="on the CPU too: the config's network and panoramas")
    args = parser.parse_args()
    cuda = torch.cuda.is_available()
    cfg = bench_config(args, cuda)
    with tempfile.TemporaryDirectory() as tmp:
        run = build_run(cfg, Path(tmp), False, 0, 1)
        run.train_model = torch.compile(run.model) if cfg.compile else run.model
        name = torch.cuda.get_device_name(run.device) if cuda else "CPU (no CUDA: tiny network, synthetic panoramas)" if not args.full else "CPU"
        print(f"device {name}; input {run.model_cfg.input_size}, batch {cfg.batch_size}, amp {cfg.amp}, "
              f"channels_last {cfg.channels_last}, compile {cfg.compile}, torch {torch.__version__}", flush=True)
        if not cuda:
            print("NOTE: no CUDA device: these are CPU figures of a tiny network; the GPU figures (samples/s at the "
                  "shipped input size, GPU busy share) need a lent GPU (scripts/device_session.sh)", flush=True)
        source = panorama_source(cfg.panoramas, cfg.cache_dir)
        source.inputs()
        shards = rank_shards(source, cfg, 0, 1)
        meter = BusyMeter(run.device)
        fixed = None
        if not args.sources_only:
            same = FixedBatch(run)
            fixed = timed(run, args.seconds, cfg.batch_size, lambda: train_step(run, same, np.random.default_rng(0), 0.5), meter)
            report("step (fixed batch)", fixed, None)
        rng = np.random.default_rng(0)
        for source_name in [s for s in args.sources.split(",") if s]:
            measure_source(run, source_name, shards, meter, fixed, args.seconds, rng)
    write_figure("bench_train_throughput_" + ("gpu" if cuda else "cpu"), {"device": name, **FIGURES})
    return 0


if __name__ == "__main__":
    sys.exit(main())
