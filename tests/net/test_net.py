"""net/: the distortion loss (known answers), the model (shapes, size), augmentation, ONNX export."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from glradial.lens.lens import corner_radius  # noqa: E402
from net.augment import AugmentConfig, augment_batch, augment_pairs, jpeg_roundtrip, motion_kernel  # noqa: E402
from net.loss import distortion_loss, loss_radii, training_loss  # noqa: E402
from net.model import DistortionNet, ModelConfig, count_parameters, load_grown  # noqa: E402

SHIPPED_CONFIG = "net/configs/stage01_128.json"


def _integral(d1: float, d2: float, r: float) -> float:
    """Closed form of int_0^r (t^3 d1 + t^5 d2)^2 dt."""
    return d1 * d1 * r**7 / 7 + 2 * d1 * d2 * r**9 / 9 + d2 * d2 * r**11 / 11


@pytest.mark.parametrize("d1,d2", [(0.1, 0.0), (0.0, 0.05), (-0.2, 0.13), (0.3, -0.4)])
def test_distortion_loss_matches_the_integral(d1, d2):
    # With n radii on [0, R] (step h) the trapezoid rule h * (sum - (f_0 + f_n) / 2) approximates the
    # integral with error <= R h^2 max|f''| / 12; for n = 4001, R = 0.7 that is < 1e-9 here.
    n, r_max = 4001, 0.7
    radii = loss_radii(n, r_max, dtype=torch.float64)
    y = torch.tensor([[-0.3, 0.1]], dtype=torch.float64)
    y_hat = y + torch.tensor([[d1, d2]], dtype=torch.float64)
    total = float(distortion_loss(y, y_hat, radii)[0])
    end = (r_max**3 * d1 + r_max**5 * d2) ** 2
    h = r_max / (n - 1)
    assert h * (total - end / 2) == pytest.approx(_integral(d1, d2, r_max), rel=1e-6, abs=1e-12)


def test_training_loss_judges_each_coefficient_with_the_other_true():
    # L = DL(y, (k1^, k2)) + DL(y, (k1, k2^)) = d1^2 sum r^6 + d2^2 sum r^10 (no cross term).
    radii = loss_radii(dtype=torch.float64)
    y = torch.tensor([[-0.5, 0.2], [0.1, 0.0]], dtype=torch.float64)
    d = torch.tensor([[0.05, -0.03], [-0.1, 0.07]], dtype=torch.float64)
    expected = (d[:, 0] ** 2 * (radii**6).sum() + d[:, 1] ** 2 * (radii**10).sum()).mean()
    assert float(training_loss(y, y + d, radii)) == pytest.approx(float(expected), rel=1e-12)
    assert float(training_loss(y, y.clone())) == 0.0


def test_joint_term_judges_both_coefficients_inside_the_frame():
    # joint_weight w adds w * mean DL(y, y_hat) on radii over [0, 0.5737] (the 16:9 corner radius).
    y = torch.tensor([[-0.5, 0.2], [0.1, 0.0]], dtype=torch.float64)
    d = torch.tensor([[0.05, -0.03], [-0.1, 0.07]], dtype=torch.float64)
    frame = loss_radii(64, corner_radius((16, 9)), dtype=torch.float64)
    a, c, b = (frame**6).sum(), (frame**8).sum(), (frame**10).sum()
    joint = (a * d[:, 0] ** 2 + 2 * c * d[:, 0] * d[:, 1] + b * d[:, 1] ** 2).mean()
    paper = float(training_loss(y, y + d))
    assert float(training_loss(y, y + d, joint_weight=3.0)) == pytest.approx(paper + 3.0 * float(joint), rel=1e-12)
    # With k2 exact and a k1 error, the paper's loss leaves k2 alone; the joint term moves k2 to
    # offset the k1 error (gradient sign equal to the k1 error's: descent goes the other way).
    y_hat = (y + torch.tensor([[0.05, 0.0], [0.05, 0.0]], dtype=torch.float64)).requires_grad_(True)
    training_loss(y, y_hat).backward()
    assert torch.all(y_hat.grad[:, 1] == 0)
    y_hat.grad = None
    training_loss(y, y_hat, joint_weight=1.0).backward()
    assert torch.all(y_hat.grad[:, 1] > 0)


def test_loss_rejects_bad_shapes():
    with pytest.raises(ValueError, match="N x 2"):
        distortion_loss(torch.zeros(3, 2), torch.zeros(3, 3))


def test_model_shapes_and_parameter_budget():
    cfg = ModelConfig(input_size=(96, 54))
    model = DistortionNet(cfg).eval()
    x = torch.randn(3, 3, 54, 96)
    feats = model.forward_features(x)
    assert feats.shape == (3, cfg.feature_channels)
    assert model.forward_head(feats).shape == (3, 2)
    assert model(x).shape == (3, 2)
    assert count_parameters(model) <= 6_600_000
    shipped = ModelConfig.from_dict(json.load(open(SHIPPED_CONFIG))["model"])
    assert count_parameters(DistortionNet(shipped)) <= 6_600_000


def _trained_like(model: DistortionNet, seed: int) -> DistortionNet:
    """Random non-trivial batch-norm statistics and scales, as a trained model has."""
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in model.modules():
            if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
                m.weight.copy_(1 + 0.3 * torch.randn(m.weight.shape, generator=gen))
                m.bias.copy_(0.2 * torch.randn(m.bias.shape, generator=gen))
                m.running_mean.copy_(0.2 * torch.randn(m.running_mean.shape, generator=gen))
                m.running_var.copy_(0.5 + torch.rand(m.running_var.shape, generator=gen))
        for head in (model.head_k1, model.head_k2):
            torch.nn.init.normal_(head.net[-1].weight, std=0.5, generator=gen)
    return model.eval()


def test_grown_model_computes_the_same_function():
    # Wider expansions and channels, a wider feature conv and heads, two new blocks at the end of
    # the last stage: the grown model's output equals the small one's to float32 rounding.
    torch.manual_seed(0)  # the constructors' initial weights and the input: the same case in any test order
    small_cfg = ModelConfig(input_size=(96, 54), stages=[(1, 16, 1, 2), (3, 24, 2, 2), (3, 32, 2, 1)],
                            feature_channels=64, head_hidden=16)
    big_cfg = ModelConfig(input_size=(96, 54), stages=[(1, 16, 1, 2), (6, 32, 2, 2), (6, 40, 4, 1)],
                          feature_channels=96, head_hidden=24)
    small = _trained_like(DistortionNet(small_cfg), 0)
    big = DistortionNet(big_cfg).eval()
    report = load_grown(big, small.state_dict())
    assert report["grown"] and report["copied"]
    assert {n.split(".")[1] for n in report["new"]} == {"5", "6"}  # the two appended blocks
    x = torch.randn(4, 3, 54, 96)
    with torch.no_grad():
        expected, got = small(x), big(x)
    assert float(expected.std()) > 0.05  # the heads' outputs vary, so the comparison means something
    assert torch.allclose(got, expected, atol=1e-5), float((got - expected).abs().max())
    # The new units are not dead: one training step moves the zero weights that read them.
    big.train()
    loss = training_loss(torch.zeros(4, 2), big(x))
    loss.backward()
    assert float(big.blocks[5].block[2][1].weight.grad.abs().sum()) > 0


def test_grown_model_rejects_shrinking_and_new_strided_blocks():
    small = DistortionNet(ModelConfig(input_size=(64, 36), stages=[(3, 24, 2, 2)], feature_channels=64))
    with pytest.raises(ValueError, match="cannot grow"):
        load_grown(DistortionNet(ModelConfig(input_size=(64, 36), stages=[(3, 16, 2, 2)], feature_channels=64)),
                   small.state_dict())
    with pytest.raises(ValueError, match="expansion of 1"):
        load_grown(DistortionNet(ModelConfig(input_size=(64, 36), stages=[(2, 24, 2, 2)], feature_channels=64)),
                   DistortionNet(ModelConfig(input_size=(64, 36), stages=[(1, 24, 2, 2)], feature_channels=64)).state_dict())
    with pytest.raises(ValueError, match="identity shortcut"):
        load_grown(DistortionNet(ModelConfig(input_size=(64, 36), stages=[(3, 24, 2, 2), (3, 32, 1, 2)],
                                             feature_channels=64)), small.state_dict())


def test_grayscale_variant_and_config_roundtrip(tmp_path):
    cfg = ModelConfig(input_size=(64, 36), channels=1, mean=(0.5,), std=(0.25,), coord_channels=False)
    model = DistortionNet(cfg).eval()
    assert model(torch.randn(2, 1, 36, 64)).shape == (2, 2)
    cfg.save(tmp_path / "c.json")
    again = ModelConfig.load(tmp_path / "c.json")
    assert again == cfg and again.channel_order == "L"
    with pytest.raises(ValueError, match="channels"):
        ModelConfig(channels=2)


def test_augment_keeps_shape_is_seeded_and_flips_only():
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (4, 36, 64, 3), dtype=np.uint8)
    a = augment_batch(images, np.random.default_rng(5))
    b = augment_batch(images, np.random.default_rng(5))
    assert a.shape == images.shape and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    # photometric ops off: only flips remain, so each output is a mirror of its input
    cfg = AugmentConfig(gain=(1, 1), gamma=(1, 1), channel_gain=(1, 1), saturation=(1, 1), p_blur=0, p_motion=0,
                        p_noise=0, p_jpeg=0, p_flip_h=1.0, p_flip_v=1.0)
    np.testing.assert_array_equal(augment_batch(images, rng, cfg), images[:, ::-1, ::-1])
    with pytest.raises(ValueError, match="uint8"):
        augment_batch(images.astype(np.float32), rng)


def test_augment_pairs_applies_one_draw_per_pair_on_any_number_of_threads():
    rng = np.random.default_rng(1)
    scene = rng.integers(0, 256, (1, 36, 64, 3), dtype=np.uint8)
    images = np.repeat(scene, 12, axis=0)  # six pairs, all of the same image
    cfg = AugmentConfig(p_noise=1.0, p_jpeg=0.5, p_blur=0.5)
    inline = augment_pairs(images, np.random.default_rng(9), cfg)
    # the same operations (noise included) on both members: identical inputs stay identical
    np.testing.assert_array_equal(inline[0::2], inline[1::2])
    # different pairs get different draws (noise on every image makes equal outputs all but impossible)
    assert all(not np.array_equal(inline[0], inline[2 * k]) for k in range(1, 6))
    threaded = augment_pairs(images, np.random.default_rng(9), cfg, workers=3)
    np.testing.assert_array_equal(threaded, inline)
    with pytest.raises(ValueError, match="even"):
        augment_pairs(images[:3], rng)


def test_motion_kernel_and_jpeg():
    k = motion_kernel(5, 0.0)
    assert k.sum() == pytest.approx(1.0) and np.count_nonzero(k[2]) == 5  # a horizontal line
    flat = np.full((32, 32, 3), 128, np.uint8)
    assert np.abs(jpeg_roundtrip(flat, 50).astype(int) - 128).max() <= 1  # a flat image survives JPEG


def test_export_agrees_with_onnxruntime(tmp_path):
    onnx = pytest.importorskip("onnx")
    from net.export import ATOL, check_agreement, export_onnx

    torch.manual_seed(0)
    model = DistortionNet(ModelConfig(input_size=(64, 36), stem_channels=8,
                                      stages=[(1, 8, 1, 2), (2, 12, 1, 2)], feature_channels=32))
    for head in (model.head_k1, model.head_k2):  # heads start at zero weight: make the output depend on the input
        torch.nn.init.normal_(head.net[-1].weight, std=0.5)
    model.eval()
    path = export_onnx(model, tmp_path / "m.onnx", {"metrics": {"x": 1}})
    proto = onnx.load(str(path))
    onnx.checker.check_model(proto)
    meta = {p.key: p.value for p in proto.metadata_props}
    assert meta["input_size"] == "64,36" and meta["input_layout"] == "NHWC uint8 RGB"
    assert json.loads(meta["model_config"])["input_size"] == [64, 36]
    err = check_agreement(model, path, n=4)
    assert err <= ATOL
    # the outputs must actually vary with the input (else agreement would prove nothing)
    import onnxruntime as ort

    images = np.random.default_rng(1).integers(0, 256, (4, 36, 64, 3), dtype=np.uint8)
    out = ort.InferenceSession(str(path)).run(None, {"image": images})[0]
    assert np.ptp(out[:, 0]) > 1e-3
    # the export records the SHA-256 beside the model: the estimator validates and accepts it, and
    # refuses the same file with one flipped byte
    from glradial.estimation.net_lines import ModelLoadError, NetLinesEstimator

    assert path.with_suffix(".sha256").read_text().split() == [hashlib.sha256(path.read_bytes()).hexdigest(), "m.onnx"]
    assert NetLinesEstimator(path, threads=1).input_size == (64, 36)
    data = bytearray(path.read_bytes())
    data[-100] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(ModelLoadError, match="SHA-256"):
        NetLinesEstimator(path, threads=1)


def test_pool_keeps_pairs_adjacent():
    from net.data import CropPool

    pool = CropPool(8, (4, 2))
    images = np.arange(10, dtype=np.uint8)[:, None, None, None] * np.ones((10, 2, 4, 3), np.uint8)
    pool.add(images, np.stack([np.arange(10), np.arange(10)], 1).astype(np.float32))
    assert pool.count == 8  # ring buffer: items 8, 9 overwrote 0, 1
    _, labels = pool.sample(6, np.random.default_rng(0), paired=True)
    first = labels[0::2, 0].astype(int)
    assert np.all(first % 2 == 0) and np.all(labels[1::2, 0] == first + 1)


def test_k2_residual_head_starts_on_the_manifold():
    # With k2_residual the k2 head adds to 0.019 k1 + 0.805 k1^2 of the predicted k1; a zeroed head
    # therefore reproduces the paper's method B exactly.
    model = DistortionNet(ModelConfig(input_size=(64, 36), stem_channels=8, stages=[(1, 8, 1, 2)],
                                      feature_channels=16, k2_residual=True)).eval()
    torch.nn.init.normal_(model.head_k1.net[-1].weight, std=0.5)
    with torch.no_grad():
        model.head_k2.net[-1].weight.zero_()
        model.head_k2.net[-1].bias.zero_()
        out = model(torch.randn(4, 3, 36, 64)).double()
    k1 = out[:, 0]
    assert torch.allclose(out[:, 1], 0.019 * k1 + 0.805 * k1 * k1, atol=1e-6)
    assert k1.std() > 0


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[2] / "net" / "configs").glob("*.json")),
                         ids=lambda p: p.name)
def test_every_shipped_training_config_loads_and_fits_the_parameter_budget(path):
    # make train and the README's recipe run these files: a stale key or a model over the paper's
    # 6.6 M parameters must fail here, not hours into a run
    from net.train import TrainConfig

    cfg = TrainConfig.from_json(path)
    model = DistortionNet(ModelConfig.from_dict(cfg.model))
    assert 0 < count_parameters(model) <= 6_600_000
    assert cfg.batch_size > 0 and (cfg.steps > 0 or cfg.time_budget_s)


def test_shards_partition_the_panoramas():
    from net.data import PanoramaSource, shard_source

    source = PanoramaSource(kind="stadium", seeds=list(range(10, 17)), size=(512, 256))
    shards = [shard_source(source, i, 3) for i in range(3)]
    assert [s.seeds for s in shards] == [[10, 13, 16], [11, 14], [12, 15]]
    assert all(s.kind == "stadium" and s.size == (512, 256) for s in shards)
    assert [len(s) for s in shards] == [3, 2, 2]
    files = shard_source(PanoramaSource(kind="files", files=["a.png", "b.png"]), 1, 2)
    assert list(files.files) == ["b.png"]
    with pytest.raises(ValueError, match="cannot split 7 panoramas into 8 shards"):
        shard_source(source, 0, 8)
    with pytest.raises(ValueError, match="shard index 3"):
        shard_source(source, 3, 3)


class _CountingProducer:
    """Stand-in for a CropProducer: chunk ``c`` of producer ``name`` holds labels ``(name, c)``."""

    def __init__(self, name: int, chunk: int):
        self.name, self.chunk, self.taken, self.wait_s = name, chunk, 0, 0.5

    def take(self, n: int, timeout: float = 600.0):
        assert n == self.chunk, "CropProducers must take whole chunks"
        labels = np.array([(self.name, self.taken)] * n, np.float32)
        self.taken += 1
        return np.full((n, 2, 2, 3), self.name, np.uint8), labels


def test_several_producers_give_each_panorama_the_same_share_of_crops():
    # shards of 3, 2 and 2 panoramas: per 7 chunks, 3 from the first and 2 from each other one, so
    # every panorama gets 1/7 of the crops as it would from one producer holding all seven
    from net.data import CropProducers

    fakes = [_CountingProducer(i, chunk=4) for i in range(3)]
    group = CropProducers(fakes, [3, 2, 2], chunk=4)
    images, labels = group.take(5)
    rest_images, rest_labels = group.take(4 * 70 - 5)
    labels = np.concatenate([labels, rest_labels])
    assert images.shape == (5, 2, 2, 3) and len(labels) == 280
    chunks = labels[::4]  # (producer, its chunk index) per chunk, in order
    assert np.all(labels.reshape(70, 4, 2) == chunks[:, None, :]), "a chunk was split or reordered"
    for cycle in chunks.reshape(10, 7, 2):
        assert np.bincount(cycle[:, 0].astype(int), minlength=3).tolist() == [3, 2, 2]
    for i, fake in enumerate(fakes):  # each producer's chunks arrive in its own order
        assert chunks[chunks[:, 0] == i, 1].tolist() == list(range(fake.taken))
    assert len(set(map(int, chunks[:7, 0]))) == 3, "producers are interleaved within a cycle"
    assert group.wait_s == 1.5
    with pytest.raises(ValueError):
        CropProducers(fakes, [3, 0, 2], chunk=4)


def test_training_producer_streams_the_glradial_crop_producer():
    # The trainer's producer is glradial's crop producer in one worker process over the source's
    # panoramas: its crops equal the in-process stream of the same seed (<= 1 level: llvmpipe's
    # thread count may differ between the processes)
    from glradial.synthesis.crop_producer import crop_batches
    from net.data import CropProducer, PanoramaSource

    source = PanoramaSource(kind="synthetic", seeds=[1, 2], size=(512, 256))
    with CropProducer(source, seed=4, out_size=(48, 27), chunk=6) as producer:
        images, labels = producer.take(10)
    with crop_batches(source.load(), 6, seed=4, out_size=(48, 27), cache=2) as stream:
        batches = [next(stream) for _ in range(2)]
    want_images = np.concatenate([b.images for b in batches])[:10]
    want_labels = np.concatenate([b.labels for b in batches])[:10]
    assert np.array_equal(labels, want_labels)
    assert np.abs(images.astype(int) - want_images).max() <= 1


def test_configs_name_a_base_and_hold_their_differences(tmp_path):
    from net.train import TrainConfig, load_config_dict, merge_config

    # nested objects merge key by key; lists and null replace
    assert merge_config({"a": {"x": 1, "y": [1, 2]}, "b": 2}, {"a": {"y": [3]}, "b": None}) == {"a": {"x": 1, "y": [3]}, "b": None}
    (tmp_path / "one.json").write_text(json.dumps({"seed": 1, "lr": 0.5, "model": {"input_size": [64, 36], "head_hidden": 8}}))
    (tmp_path / "two.json").write_text(json.dumps({"base": "one.json", "lr": 0.25, "model": {"head_hidden": 16}}))
    cfg = TrainConfig.from_json(tmp_path / "two.json")
    assert (cfg.seed, cfg.lr, cfg.model) == (1, 0.25, {"input_size": [64, 36], "head_hidden": 16})
    (tmp_path / "loop.json").write_text(json.dumps({"base": "loop2.json"}))
    (tmp_path / "loop2.json").write_text(json.dumps({"base": "loop.json"}))
    with pytest.raises(ValueError, match="cycle"):
        load_config_dict(tmp_path / "loop.json")
    (tmp_path / "orphan.json").write_text(json.dumps({"base": "nope.json"}))
    with pytest.raises(ValueError, match="nope.json"):
        load_config_dict(tmp_path / "orphan.json")


def test_the_shipped_stage_config_describes_the_shipped_model():
    # stage11_error_head.json is the run that produced glradial/models/glradial_k1k2.onnx (stage 10's
    # network with an error head): the same network as the model's embedded config
    import onnx

    from net.train import TrainConfig

    root = Path(__file__).resolve().parents[2]
    cfg = TrainConfig.from_json(root / "net" / "configs" / "stage11_error_head.json")
    props = {p.key: p.value for p in onnx.load(str(root / "glradial" / "models" / "glradial_k1k2.onnx")).metadata_props}
    assert ModelConfig.from_dict(cfg.model) == ModelConfig.from_dict(json.loads(props["model_config"]))


def test_torch_distortion_loss_is_the_twin_of_glradial_metrics():
    # training's loss (torch) and the evaluation's (NumPy) compare the same radii: same numbers
    from glradial.lens.metrics import distortion_loss as numpy_loss

    rng = np.random.default_rng(5)
    y, y_hat = rng.normal(0.0, 0.3, (16, 2)), rng.normal(0.0, 0.3, (16, 2))
    got = distortion_loss(torch.from_numpy(y), torch.from_numpy(y_hat)).numpy()
    assert np.allclose(got, numpy_loss(y, y_hat), rtol=1e-12, atol=0)


def test_net_evaluate_takes_a_checkpoint_and_matches_its_onnx_export(tmp_path):
    # python -m net.evaluate is glradial evaluate plus .pt checkpoints: a checkpoint and its ONNX
    # export, both run without mirror averaging, give the same figures on the same crops (float32
    # kernels of two libraries: 1e-4 lens units is 0.19 px at 1920 wide)
    from glradial.evaluation.evaluation import EvaluationSettings, OnnxPredictor, evaluate
    from net.evaluate import TorchPredictor, main
    from net.export import export_onnx

    torch.manual_seed(0)
    cfg = ModelConfig(input_size=(64, 36), stem_channels=8, stages=[(1, 8, 1, 2), (2, 12, 1, 2)], feature_channels=16)
    model = DistortionNet(cfg).eval()
    checkpoint = tmp_path / "m.pt"
    torch.save({"model": model.state_dict(), "model_config": cfg.to_dict()}, checkpoint)
    common = ["--n", "6", "--test-panoramas", "1", "--panorama-size", "256x128", "--cache-dir", str(tmp_path / "cache")]
    assert main(["--model", str(checkpoint), "--out", str(tmp_path / "pt"), *common]) == 0
    from_pt = json.loads((tmp_path / "pt" / "metrics.json").read_text())
    assert from_pt["overall"]["n"] == 6 and "python -m net.evaluate" in (tmp_path / "pt" / "results.md").read_text()
    onnx_path = export_onnx(model, tmp_path / "m.onnx")
    predictor = OnnxPredictor(onnx_path, threads=1, mirror_average=False)
    settings = EvaluationSettings(n=6, panoramas=1, panorama_size=(256, 128), cache_dir=str(tmp_path / "cache"))
    from_onnx = evaluate(predictor, predictor.input_size, tmp_path / "onnx", settings, str(onnx_path))
    torch_pred = TorchPredictor(str(checkpoint), threads=1)
    assert torch_pred.input_size == predictor.input_size
    for key in ("k1_mae", "k2_mae"):
        assert from_pt["overall"][key] == pytest.approx(from_onnx["overall"][key], abs=1e-4)
