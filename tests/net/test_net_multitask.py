"""The multi-task recipe of net/ (issue 28, item 1): the comparator head and its loss, the small-|k1|
weight, the export without the training-only head, and the GPU-ready stage-12 config run for a few steps.

Oracles: the binary cross-entropy and the weighted mean written out by hand (known answers); the
closed form of the paper's loss for a known error (sum r^6, sum r^10); onnxruntime on the exported
graph; the graph exported from a network built without the head (byte-identical)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from net.loss import (  # noqa: E402
    comparator_loss,
    comparator_targets,
    comparison_partners,
    loss_radii,
    small_k1_weights,
    training_loss,
)
from net.model import DistortionNet, ModelConfig, inference_model  # noqa: E402
from net.train import TrainConfig, step_loss  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TINY = dict(input_size=(64, 36), stem_channels=8, stages=[(1, 8, 1, 2), (2, 12, 1, 2)], feature_channels=16,
            head_hidden=8)


def _sigmoid(z: float) -> float:
    return 1.0 / (1.0 + math.exp(-z))


def test_comparator_loss_is_the_binary_cross_entropy_by_hand():
    # three crops, partners 0 -> 1, 1 -> 2, 2 -> 0; lens (k1, k2) and logits chosen by hand
    y = torch.tensor([[-0.5, 0.20], [0.1, 0.0], [-0.2, 0.0]], dtype=torch.float64)
    partner = torch.tensor([1, 2, 0])
    logits = torch.tensor([[-1.5, 2.0], [0.3, 0.0], [0.0, -0.7]], dtype=torch.float64)
    # k1: -0.5 < 0.1 (0), 0.1 > -0.2 (1), -0.2 > -0.5 (1); k2: 0.2 > 0 (1), 0 = 0 (tie: 0.5), 0 < 0.2 (0)
    targets = [[0.0, 1.0], [1.0, 0.5], [1.0, 0.0]]
    assert comparator_targets(y, partner).tolist() == targets
    expected = 0.0
    for row_t, row_z in zip(targets, logits.tolist()):
        for t, z in zip(row_t, row_z):
            p = _sigmoid(z)
            expected -= t * math.log(p) + (1 - t) * math.log(1 - p)
    assert float(comparator_loss(logits, y, partner)) == pytest.approx(expected / 6, rel=1e-12)
    with pytest.raises(ValueError, match="logits must have the shape"):
        comparator_loss(logits[:, :1], y, partner)


def test_partners_pair_the_crops_of_a_pair_or_form_one_cycle():
    paired = comparison_partners(6, True, None)  # adjacent pairs (net.data.CropPool.sample paired=True)
    assert paired.tolist() == [1, 0, 3, 2, 5, 4]
    rng = np.random.default_rng(3)
    for n in (2, 5, 32):
        partner = comparison_partners(n, False, rng)
        assert sorted(partner.tolist()) == list(range(n))  # a permutation ...
        assert np.all(partner != np.arange(n))  # ... that compares no crop with itself
        seen, i = set(), 0  # ... and one cycle through the whole batch
        while i not in seen:
            seen.add(i)
            i = int(partner[i])
        assert len(seen) == n
    # the labels follow the order of the pair: swapping the two crops of a pair swaps 1 and 0
    y = torch.tensor([[-0.3, 0.05], [0.2, 0.04]])
    p = torch.from_numpy(paired[:2])
    assert comparator_targets(y, p).tolist() == [[0.0, 1.0], [1.0, 0.0]]
    for bad in ((1, False), (5, True)):
        with pytest.raises(ValueError, match="cannot be"):
            comparison_partners(*bad, rng)


def test_comparator_head_is_antisymmetric_and_needs_the_config():
    torch.manual_seed(0)
    model = DistortionNet(ModelConfig(**TINY, comparator_head=True)).eval()
    x = torch.randn(4, 3, 36, 64)
    with torch.no_grad():
        out = model(x, torch.tensor([1, 0, 3, 2]))
        same = model(x, torch.arange(4))
    assert out.shape == (4, 4)
    assert torch.allclose(out[0, 2:], -out[1, 2:], atol=1e-6) and out[0, 2:].abs().min() > 0
    assert torch.equal(same[:, 2:], torch.zeros(4, 2))  # a crop against itself: exactly p = 0.5
    with torch.no_grad():
        assert torch.equal(out[:, :2], model(x))  # the lens columns do not depend on the comparison
    plain = DistortionNet(ModelConfig(**TINY)).eval()
    with pytest.raises(ValueError, match="without comparator_head"):
        plain(x, torch.arange(4))


def test_small_k1_weight_on_a_known_batch():
    radii = loss_radii(dtype=torch.float64)
    a, b = float((radii**6).sum()), float((radii**10).sum())
    y = torch.tensor([[0.0, 0.0], [0.1, 0.008], [-0.5, 0.19]], dtype=torch.float64)
    d = torch.tensor([[0.04, 0.0], [0.0, 0.02], [0.01, -0.005]], dtype=torch.float64)
    w = small_k1_weights(y[:, 0], 2.0, 0.1)
    # 1 + 2 exp(-k1^2 / (2 * 0.1^2)): 3 at k1 = 0, 1 + 2 e^-0.5 one scale away, ~1 at -0.5 (1 + 2 e^-12.5)
    assert w.tolist() == pytest.approx([3.0, 1 + 2 * math.exp(-0.5), 1 + 2 * math.exp(-12.5)], rel=1e-12)
    per = [d[i, 0].item() ** 2 * a + d[i, 1].item() ** 2 * b for i in range(3)]  # the paper's loss, no cross term
    expected = sum(wi * li for wi, li in zip(w.tolist(), per)) / sum(w.tolist())
    got = float(training_loss(y, y + d, radii, sample_weight=w))
    assert got == pytest.approx(expected, rel=1e-12)
    assert got > float(training_loss(y, y + d, radii))  # the near-zero crops' errors (the larger here) count more
    assert float(training_loss(y, y + d, radii, sample_weight=torch.ones(3, dtype=torch.float64))) == pytest.approx(
        sum(per) / 3, rel=1e-12)
    with pytest.raises(ValueError, match="scale must be positive"):
        small_k1_weights(y[:, 0], 1.0, 0.0)
    with pytest.raises(ValueError, match="sample_weight must have shape"):
        training_loss(y, y + d, radii, sample_weight=w[:2])


def test_weights_zero_are_the_old_loss_to_the_bit():
    # the recipe before this change: training_loss (joint term 10) + 0.1 x the error head's likelihood,
    # drawing nothing from the step's random generator
    from net.loss import error_scale_loss

    cfg = TrainConfig(model=dict(TINY, error_head=True), joint_loss_weight=10.0, paired=True)
    torch.manual_seed(1)
    model = DistortionNet(ModelConfig.from_dict(cfg.model))
    x, y = torch.randn(8, 3, 36, 64), torch.rand(8, 2) * 0.4 - 0.3
    rng = np.random.default_rng(5)
    loss, pred = step_loss(model, x, y, cfg, model.config, rng)
    assert rng.random() == np.random.default_rng(5).random()
    torch.manual_seed(1)
    out = model(x)  # train mode: same batch statistics
    old = training_loss(y, out[:, :2], joint_weight=10.0) + 0.1 * error_scale_loss(y, out[:, :2], out[:, 2])
    assert torch.equal(loss, old) and torch.equal(pred, out[:, :2])
    # and the recipe's parts change it when switched on
    cfg_on = TrainConfig(model=dict(TINY, error_head=True), joint_loss_weight=10.0, paired=True, small_k1_weight=2.0)
    assert not torch.equal(step_loss(model, x, y, cfg_on, model.config, rng)[0], old)


def test_config_refuses_a_comparator_weight_without_the_head(tmp_path):
    base = json.loads((ROOT / "net/configs/tiny.json").read_text())
    for changes, match in (({"comparator_loss_weight": 0.5}, "comparator_head"),
                           ({"model": dict(base["model"], comparator_head=True)}, "comparator_head"),
                           ({"small_k1_scale": 0.0}, "small_k1_scale")):
        (tmp_path / "c.json").write_text(json.dumps(dict(base, **changes)))
        with pytest.raises(ValueError, match=match):
            TrainConfig.from_json(tmp_path / "c.json")


@pytest.mark.parametrize("error_head", [False, True])
def test_export_drops_the_comparator_head(tmp_path, error_head):
    onnx = pytest.importorskip("onnx")
    import onnxruntime as ort

    from net.export import check_agreement, export_onnx
    from net.from_onnx import check_against_onnx, rebuild

    torch.manual_seed(0)
    model = DistortionNet(ModelConfig(**TINY, error_head=error_head, comparator_head=True))
    with torch.no_grad():  # as after training: non-trivial weights and batch-norm statistics
        for m in model.modules():
            if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.5, 2.0)
                m.bias.uniform_(-0.2, 0.2)
            if isinstance(m, torch.nn.Linear):
                m.weight.normal_(0.0, 0.3)
    model.eval()
    slim = inference_model(model)
    assert slim.head_compare is None and not slim.config.comparator_head
    assert not any(k.startswith("head_compare.") for k in slim.state_dict())
    plain = DistortionNet(ModelConfig(**TINY, error_head=error_head)).eval()
    plain.load_state_dict(slim.state_dict())  # the same network built without the head ever existing
    with_head = export_onnx(model, tmp_path / "with_head.onnx")
    without = export_onnx(plain, tmp_path / "plain.onnx")
    a, b = onnx.load(str(with_head)), onnx.load(str(without))
    assert a.graph.SerializeToString() == b.graph.SerializeToString()  # the same graph, byte for byte
    meta = {p.key: p.value for p in a.metadata_props}
    assert json.loads(meta["model_config"])["comparator_head"] is False
    session = ort.InferenceSession(str(with_head))
    assert [o.name for o in session.get_outputs()] == (["k", "error_px"] if error_head else ["k"])
    assert check_agreement(model, with_head, n=4) < 1e-5
    frames = np.random.default_rng(2).integers(0, 256, (4, 36, 64, 3), dtype=np.uint8)
    rebuilt = rebuild(with_head)  # net.from_onnx still rebuilds the shipped function
    assert rebuilt.head_compare is None and check_against_onnx(rebuilt, with_head, frames) < 1e-5


def test_stage12_config_trains_a_few_steps_on_cpu(tmp_path):
    # the GPU-ready config, shrunk to a tiny network and synthetic panoramas, everything else as it
    # is: from an init without the comparator (as runs/shipped_from_onnx.pt), 3 steps, then export
    from dataclasses import asdict

    from net.export import export_onnx, load_checkpoint
    from net.train import main

    config = asdict(TrainConfig.from_json(ROOT / "net/configs/stage12_multitask.json"))
    tiny = json.loads((ROOT / "net/configs/tiny.json").read_text())
    assert config["model"]["comparator_head"] and config["model"]["error_head"] and not config["error_head_only"]
    keep = {k: config[k] for k in ("comparator_loss_weight", "small_k1_weight", "small_k1_scale", "joint_loss_weight",
                                   "error_loss_weight", "error_head_lr_scale", "paired", "augment", "lr")}
    run = dict(tiny, **keep, model=dict(tiny["model"], comparator_head=config["model"]["comparator_head"],
                                        error_head=True), steps=3, time_budget_s=None, val_size=16)
    (tmp_path / "c.json").write_text(json.dumps(run))
    init = DistortionNet(ModelConfig.from_dict(dict(tiny["model"], error_head=True)))
    torch.save({"model": init.state_dict()}, tmp_path / "init.pt")
    # in two calls, as scripts/device_session.sh train runs it: the first stops after one step
    # (--stop-after-s), the second resumes and finishes the schedule (--init is then ignored)
    call = ["--config", str(tmp_path / "c.json"), "--out", str(tmp_path / "run"), "--init", str(tmp_path / "init.pt"),
            "--resume"]
    assert main(call + ["--stop-after-s", "1e-6"]) == 0
    assert torch.load(tmp_path / "run/last.pt", map_location="cpu", weights_only=False)["step"] == 1
    assert main(call) == 0
    state = torch.load(tmp_path / "run/last.pt", map_location="cpu", weights_only=False)
    assert state["step"] == 3
    with pytest.raises(ValueError, match="--stop-after-s must be positive"):
        main(call + ["--stop-after-s", "0"])
    assert any(k.startswith("head_compare.") for k in state["model"])
    moved = [k for k, v in state["model"].items() if k in init.state_dict() and v.dtype.is_floating_point
             and not torch.equal(v, init.state_dict()[k])]
    assert moved, "training did not change the weights"
    model = load_checkpoint(tmp_path / "run/last.pt")
    path = export_onnx(model, tmp_path / "m.onnx")
    import onnxruntime as ort

    assert [o.name for o in ort.InferenceSession(str(path)).get_outputs()] == ["k", "error_px"]


def test_paired_interval_known_answers():
    from net.compare import paired_interval

    a = np.random.default_rng(0).exponential(5.0, 200)
    assert paired_interval(a, a.copy(), np.median) == [0.0, 0.0]
    assert paired_interval(a, a + 1.5, np.median) == pytest.approx([1.5, 1.5])  # a shift moves every resample alike
    lo, hi = paired_interval(a, a * 0.8, np.mean)
    assert lo < 0 and hi < 0 and lo <= -0.2 * a.mean() * 0.8 and hi >= -0.2 * a.mean() * 1.2


def test_compare_two_checkpoints_on_the_same_crops(tmp_path):
    # the same network twice: every paired difference is exactly zero; a comparator model also gets
    # its ordering accuracy, and the regression's accuracy is a fraction of the 8 pairs
    from glradial.evaluation.evaluation import EvaluationSettings
    from net.compare import compare

    torch.manual_seed(0)
    plain = DistortionNet(ModelConfig(**TINY))
    torch.nn.init.normal_(plain.head_k1.net[-1].weight, std=0.5)
    with_head = DistortionNet(ModelConfig(**TINY, comparator_head=True))
    with_head.load_state_dict(plain.state_dict(), strict=False)  # the same network plus a comparator
    for name, model in (("a", plain), ("b", with_head)):
        torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, tmp_path / f"{name}.pt")
    chosen = EvaluationSettings(n=8, panoramas=1, split="val", panorama_size=(512, 256), ood_n=0,
                                cache_dir=str(tmp_path / "cache"))
    rows = compare([str(tmp_path / "a.pt"), str(tmp_path / "b.pt")], chosen, 1)
    assert rows[0]["ordering"] is None and "d_median_px_ci95" not in rows[0]
    assert rows[1]["d_median_px_ci95"] == [0.0, 0.0] and rows[1]["d_mean_dl_ci95"] == [0.0, 0.0]
    assert rows[1]["median_px"] == rows[0]["median_px"] > 0
    accuracy = rows[1]["ordering"]
    assert all(v * 8 == round(v * 8) and 0 <= v <= 1 for v in accuracy["comparator"] + accuracy["regression"])
    other = DistortionNet(ModelConfig(**dict(TINY, input_size=(96, 54))))
    torch.save({"model": other.state_dict(), "model_config": other.config.to_dict()}, tmp_path / "c.pt")
    with pytest.raises(ValueError, match="same input size"):  # refused before anything is rendered
        compare([str(tmp_path / "a.pt"), str(tmp_path / "c.pt")], chosen, 1)
