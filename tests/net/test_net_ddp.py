"""net.train under torchrun: 2 processes x a few steps of a tiny model (gloo on this CPU machine)."""

from __future__ import annotations

import csv
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_ddp_two_processes_train_and_checkpoint(tmp_path):
    config = json.loads((ROOT / "net/configs/tiny.json").read_text())
    # the config asks for an hour; the command line's --steps 4 --time-budget-s 0 must win (make train
    # reproduces the GPU stages' schedules that way)
    config.update(steps=1000, time_budget_s=3600.0, val_size=16, log_every=1, augment_workers=2)
    # with the multi-task recipe on: the comparator head's parameters are used in the one forward
    # call DDP sees (net.model.DistortionNet.forward with partner), so its gradients are reduced too
    config.update(model=dict(config["model"], comparator_head=True), comparator_loss_weight=0.01, small_k1_weight=1.0)
    (tmp_path / "tiny.json").write_text(json.dumps(config))
    out = tmp_path / "run"
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2", f"--master_port={_free_port()}",
           "-m", "net.train", "--config", str(tmp_path / "tiny.json"), "--out", str(out), "--steps", "4",
           "--time-budget-s", "0"]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert "world 2" in proc.stdout
    assert "1 crop producer(s) on this rank, holding 1 panoramas" in proc.stdout  # 2 panoramas, 2 ranks
    state = torch.load(out / "last.pt", map_location="cpu", weights_only=False)
    assert state["step"] == 4
    rows = list(csv.DictReader(open(out / "train.csv")))
    assert [int(r["step"]) for r in rows] == [1, 2, 3, 4]
    assert all(float(r["loss"]) > 0 for r in rows)
    # the ranks saw different crops (their own seed ranges) but DDP keeps one set of weights:
    # the checkpointed weights moved away from the seeded initialisation
    from net.model import DistortionNet, ModelConfig

    torch.manual_seed(config["seed"])
    init = DistortionNet(ModelConfig.from_dict(config["model"])).state_dict()
    moved = [k for k, v in state["model"].items() if v.dtype.is_floating_point and not torch.equal(v, init[k])]
    assert moved, "training did not change the weights"


def test_grown_fine_tune_with_joint_loss_stops_early(tmp_path):
    # One process: --init from a smaller checkpoint (net.model.load_grown), the joint loss term,
    # stop_at_s (a run ended early with its schedule unchanged: here after the first step) and two
    # crop producers, one per panorama.
    from net.model import DistortionNet, ModelConfig

    config = json.loads((ROOT / "net/configs/tiny.json").read_text())
    small = DistortionNet(ModelConfig.from_dict(config["model"]))
    torch.save({"model": small.state_dict()}, tmp_path / "small.pt")
    grown = dict(config["model"], stages=[[e * 2 if e > 1 else e, c, n, s, *rest] for e, c, n, s, *rest in config["model"]["stages"]])
    config.update(model=grown, steps=1000, time_budget_s=1000.0, stop_at_s=1e-6, joint_loss_weight=5.0,
                  val_size=16, log_every=1, producers=2)
    (tmp_path / "grown.json").write_text(json.dumps(config))
    out = tmp_path / "run"
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "net.train", "--config", str(tmp_path / "grown.json"), "--out", str(out),
           "--init", str(tmp_path / "small.pt")]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert " grown, " in proc.stdout and "0 grown" not in proc.stdout
    assert "2 crop producer(s) on this rank, holding 1 + 1 panoramas" in proc.stdout
    state = torch.load(out / "last.pt", map_location="cpu", weights_only=False)
    assert state["step"] == 1


def test_more_producers_than_panoramas_is_an_error_before_the_run_folder_exists(tmp_path):
    from net.train import main

    config = json.loads((ROOT / "net/configs/tiny.json").read_text())
    config.update(producers=3)  # 2 panoramas
    (tmp_path / "tiny.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="cannot split 2 panoramas into 3 shards"):
        main(["--config", str(tmp_path / "tiny.json"), "--out", str(tmp_path / "run")])
    assert not (tmp_path / "run").exists()
