"""The network's error head and the ONNX -> torch rebuild (net.from_onnx, net.loss.error_scale_loss).

Oracles: the folded ONNX graph itself (onnxruntime) for the rebuilt torch network; the NumPy metric
(glradial.lens.metrics.max_displacement_px) for the torch error; the Laplace likelihood's known
minimiser (the mean) for the error loss."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from glradial.estimation.net_lines import NetLinesEstimator  # noqa: E402
from glradial.lens.metrics import max_displacement_px as numpy_max_displacement_px  # noqa: E402
from net.export import export_onnx  # noqa: E402
from net.from_onnx import calibrate_batchnorm, check_against_onnx, rebuild  # noqa: E402
from net.loss import error_scale_loss, max_displacement_px  # noqa: E402
from net.model import DistortionNet, ModelConfig  # noqa: E402
from net.train import freeze_all_but_error_head  # noqa: E402

TINY = dict(input_size=(64, 36), stem_channels=8, stages=[(1, 8, 1, 2), (2, 12, 2, 2)], feature_channels=16,
            head_hidden=8)


def _trained_like(config: ModelConfig, seed: int = 0) -> DistortionNet:
    """A tiny network with non-trivial batch-norm statistics and weights (as after training)."""
    torch.manual_seed(seed)
    model = DistortionNet(config)
    with torch.no_grad():
        for m in model.modules():
            if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.5, 2.0)
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.2, 0.2)
            if isinstance(m, torch.nn.Linear):
                m.weight.normal_(0.0, 0.3)
    return model.eval()


def _frames(n: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (n, 36, 64, 3), dtype=np.uint8)


@pytest.mark.parametrize("error_head", [False, True])
def test_rebuild_from_onnx_is_the_exported_function(tmp_path, error_head):
    # the exported graph folds every conv + batch norm; the rebuilt torch network must compute the
    # same (k1, k2) as onnxruntime on that graph, before and after its batch-norm statistics are set
    model = _trained_like(ModelConfig(**TINY, error_head=error_head))
    path = export_onnx(model, tmp_path / "m.onnx")
    rebuilt = rebuild(path)
    frames = _frames(8)
    assert check_against_onnx(rebuilt, path, frames) < 1e-5
    calibrate_batchnorm(rebuilt, _frames(32, seed=2))
    assert check_against_onnx(rebuilt, path, frames) < 1e-5
    # calibrated: on the calibration frames, the backbone's train-mode batch norms (batch statistics)
    # compute what its eval-mode function does, so fine-tuning starts from the exported function
    from net.model import normalise_batch

    x = normalise_batch(torch.from_numpy(_frames(32, seed=2)), rebuilt.config)
    with torch.no_grad():
        eval_features = rebuilt.eval().forward_features(x)
        train_features = rebuilt.train().forward_features(x)
    assert float((eval_features - train_features).abs().max()) < 1e-3 * float(eval_features.abs().max())


def test_rebuild_rejects_a_file_that_is_not_a_glradial_model(tmp_path):
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])
    onnx.save(helper.make_model(graph), str(tmp_path / "other.onnx"))
    with pytest.raises(ValueError, match="model_config"):
        rebuild(tmp_path / "other.onnx")


def test_torch_max_displacement_is_the_numpy_metric():
    rng = np.random.default_rng(3)
    y, y_hat = rng.normal(0, 0.2, (50, 2)), rng.normal(0, 0.2, (50, 2))
    ours = max_displacement_px(torch.from_numpy(y), torch.from_numpy(y_hat)).numpy()
    np.testing.assert_allclose(ours, numpy_max_displacement_px(y, y_hat), rtol=1e-9)


def test_error_loss_is_minimised_at_the_mean_error_and_teaches_only_the_scale():
    # Laplace NLL log b + e / b over a batch: minimum at b = mean(e); no gradient reaches y_hat
    rng = np.random.default_rng(4)
    y = torch.from_numpy(rng.normal(-0.2, 0.1, (64, 2)))
    y_hat = (y + torch.from_numpy(rng.normal(0, 0.02, (64, 2)))).requires_grad_(True)
    mean_error = float(max_displacement_px(y, y_hat.detach()).mean())
    grid = np.linspace(np.log(mean_error) - 1, np.log(mean_error) + 1, 201)
    losses = [float(error_scale_loss(y, y_hat, torch.full((64,), g, dtype=y.dtype))) for g in grid]
    assert abs(np.exp(grid[int(np.argmin(losses))]) / mean_error - 1) < 0.02
    error_scale_loss(y, y_hat, torch.zeros(64, dtype=y.dtype, requires_grad=True)).backward()
    assert y_hat.grad is None


def test_error_head_only_keeps_the_lens_function(tmp_path):
    # a step of training with error_head_only changes the error head and nothing else
    model = _trained_like(ModelConfig(**TINY, error_head=True))
    before = {k: v.clone() for k, v in model.state_dict().items()}
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-2)
    from net.model import normalise_batch

    x = normalise_batch(torch.from_numpy(_frames(16)), model.config)
    y = torch.zeros(16, 2)
    model.train()
    freeze_all_but_error_head(model)
    out = model(x)
    error_scale_loss(y, out[:, :2], out[:, 2]).backward()
    optimizer.step()
    changed = {k for k, v in model.state_dict().items() if not torch.equal(v, before[k])}
    assert changed and all(k.startswith("head_error.") for k in changed)


def test_estimator_reads_the_error_output(tmp_path):
    model = _trained_like(ModelConfig(**TINY, error_head=True))
    path = export_onnx(model, tmp_path / "m.onnx")
    estimator = NetLinesEstimator(path, threads=1)
    assert estimator.has_error_head
    frames = _frames(3)
    k, error = estimator.run_with_error(frames)
    assert k.shape == (3, 2) and error.shape == (3,) and np.all(error > 0)
    np.testing.assert_allclose(estimator.run(frames), k)
    # the scale is exp(third column), mirror-averaged like k
    from net.model import normalise_batch

    x = normalise_batch(torch.from_numpy(np.concatenate([frames, frames[:, :, ::-1]])), model.config)
    with torch.no_grad():
        log_scale = model(x)[:, 2].double().numpy()
    np.testing.assert_allclose(error, 0.5 * (np.exp(log_scale[:3]) + np.exp(log_scale[3:])), rtol=1e-4)


def test_the_shipped_model_has_an_error_head():
    estimator = NetLinesEstimator()
    assert estimator.has_error_head
    meta = json.loads(estimator.metadata["model_config"])
    assert meta["error_head"] is True
