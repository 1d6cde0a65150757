"""Rebuild a trainable torch checkpoint from a shipped ONNX model.

Training checkpoints (``runs/*.pt``) are not kept in the repository; the shipped model is. The
exported graph has every ``Conv -> BatchNorm`` of the backbone folded into one convolution with a
bias (``W' = W * g / s``, ``b' = beta - mu * g / s`` with ``s = sqrt(var + eps)``), so the original
batch-norm parameters cannot be recovered. What can be rebuilt exactly is the *function*: each
convolution gets ``W'``, and its batch norm is set so that in eval mode it adds ``b'``:

    running_mean = m, running_var = v, weight = sqrt(v + eps), bias = b' + m

for any per-channel ``(m, v)``. Choosing ``(m, v)`` as the mean and variance of the convolution's
output on representative frames (procedural stadium crops) makes train-mode batch norm, which
normalises by the batch's own statistics, agree with the eval-mode function on such data, so
fine-tuning starts where the shipped model is instead of from a shaken copy.

Check: the rebuilt network in eval mode and onnxruntime on the original file agree within
``net.export.ATOL`` on the same frames (:func:`check_against_onnx`).

    python -m net.from_onnx --onnx glradial/models/glradial_k1k2.onnx --out runs/shipped_from_onnx.pt
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .model import DistortionNet, ModelConfig, normalise_batch

#: Frames used for the batch-norm statistics (procedural stadium crops of the model's input size).
STAT_FRAMES = 128


def _conv_tensors(proto) -> list[tuple[np.ndarray, np.ndarray]]:
    """(weight, bias) of every Conv node of the graph, in graph (= forward) order."""
    from onnx import numpy_helper

    inits = {t.name: numpy_helper.to_array(t) for t in proto.graph.initializer}
    out = []
    for node in proto.graph.node:
        if node.op_type == "Conv":
            weight = inits[node.input[1]]
            bias = inits[node.input[2]] if len(node.input) > 2 else np.zeros(weight.shape[0], np.float32)
            out.append((weight, bias))
    return out


def _conv_bn_pairs(model: DistortionNet) -> list[tuple[nn.Conv2d, nn.BatchNorm2d]]:
    """Every (Conv2d, BatchNorm2d) of the backbone, in definition (= forward) order."""
    modules = list(model.modules())
    pairs = []
    for i, m in enumerate(modules):
        if isinstance(m, nn.Conv2d):
            bn = modules[i + 1]
            if not isinstance(bn, nn.BatchNorm2d):
                raise ValueError(f"conv {i} is not followed by a batch norm: {type(bn).__name__}")
            pairs.append((m, bn))
    return pairs


def rebuild(onnx_path: str | Path) -> DistortionNet:
    """The network of ``onnx_path`` with the folded weights loaded and every batch norm an identity
    plus the folded bias (exact in eval mode); :func:`calibrate_batchnorm` then sets its statistics."""
    import onnx

    proto = onnx.load(str(onnx_path))
    meta = {p.key: p.value for p in proto.metadata_props}
    if "model_config" not in meta:
        raise ValueError(f"onnx_path {onnx_path} has no 'model_config' metadata: not a glradial model")
    model = DistortionNet(ModelConfig.from_dict(json.loads(meta["model_config"])))
    convs, pairs = _conv_tensors(proto), _conv_bn_pairs(model)
    if len(convs) != len(pairs):
        raise ValueError(f"onnx_path {onnx_path}: {len(convs)} convolutions, the config builds {len(pairs)}")
    with torch.no_grad():
        for (weight, bias), (conv, bn) in zip(convs, pairs):
            if tuple(weight.shape) != tuple(conv.weight.shape):
                raise ValueError(f"conv shape {weight.shape} in the graph, {tuple(conv.weight.shape)} in the config")
            conv.weight.copy_(torch.from_numpy(weight.copy()))
            bn.running_mean.zero_()
            bn.running_var.fill_(1.0 - bn.eps)
            bn.weight.fill_(1.0)
            bn.bias.copy_(torch.from_numpy(bias.copy()))
        from onnx import numpy_helper

        state = model.state_dict()
        for t in proto.graph.initializer:
            name = t.name.removeprefix("model.")
            if name in state and name.startswith("head_"):
                state[name].copy_(torch.from_numpy(numpy_helper.to_array(t).copy()))
    return model.eval()


def calibrate_batchnorm(model: DistortionNet, images: torch.Tensor) -> None:
    """Set each backbone batch norm's statistics to its convolution's output mean/variance on
    ``images`` (uint8 N x H x W x 3 at the input size) without changing the eval-mode function."""
    pairs = _conv_bn_pairs(model)
    stats: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}

    def hook(index):
        def record(_module, _inputs, output):
            out = output.double()
            stats[index] = (out.mean(dim=(0, 2, 3)), out.var(dim=(0, 2, 3), unbiased=False))
        return record

    handles = [conv.register_forward_hook(hook(i)) for i, (conv, _) in enumerate(pairs)]
    try:
        with torch.no_grad():
            model.eval()(normalise_batch(torch.from_numpy(np.ascontiguousarray(images)), model.config))
    finally:
        for h in handles:
            h.remove()
    with torch.no_grad():
        for i, (_, bn) in enumerate(pairs):
            mean, var = stats[i]
            folded_bias = bn.bias.double() - bn.running_mean.double()  # b' (running_mean is 0 or a previous m)
            bn.running_mean.copy_(mean.float())
            bn.running_var.copy_(var.float())
            bn.weight.copy_(torch.sqrt(var + bn.eps).float())
            bn.bias.copy_((folded_bias + mean).float())


def check_against_onnx(model: DistortionNet, onnx_path: str | Path, images: np.ndarray) -> float:
    """Largest |torch - onnxruntime| over ``images`` (uint8 N x H x W x 3), lens units
    (:func:`net.export.max_difference`)."""
    from .export import max_difference

    return max_difference(model, onnx_path, images)


def stadium_frames(config: ModelConfig, count: int = STAT_FRAMES, seed: int = 0) -> np.ndarray:
    """``count`` procedural stadium crops at the model's input size (uint8 N x H x W x 3)."""
    from glradial.synthesis.crops import render_crops, sample_crop_params
    from glradial.synthesis.stadium import stadium_panorama
    from glradial.synthesis.stadium_style import split_seeds

    width, height = config.input_size
    rng = np.random.default_rng(seed)
    frames = []
    seeds = split_seeds("val", 4)
    for i, s in enumerate(seeds):
        panorama = stadium_panorama(int(s), (2048, 1024))
        n = count // len(seeds) + (1 if i < count % len(seeds) else 0)
        params = sample_crop_params(n, int(rng.integers(2**31)))
        frames.append(render_crops(panorama, params, out_size=(width, height), supersample="auto"))
    return np.concatenate(frames)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m net.from_onnx", description=__doc__.splitlines()[0])
    parser.add_argument("--onnx", required=True, help="a glradial ONNX model (e.g. glradial/models/glradial_k1k2.onnx)")
    parser.add_argument("--out", required=True, help="checkpoint to write (.pt, usable with net.train --init)")
    parser.add_argument("--frames", type=int, default=STAT_FRAMES, help="stadium crops for the batch-norm statistics")
    args = parser.parse_args(argv)
    from .train import save_checkpoint

    model = rebuild(args.onnx)
    images = stadium_frames(model.config, args.frames)
    exact = check_against_onnx(model, args.onnx, images[:16])
    calibrate_batchnorm(model, images)
    after = check_against_onnx(model, args.onnx, images[:16])
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    save_checkpoint(out, model=model.state_dict(), model_config=model.config.to_dict(), source=str(args.onnx))
    print(f"wrote {out}: max |torch - onnx| {exact:.2e} before, {after:.2e} after batch-norm calibration")
    return 0


if __name__ == "__main__":
    sys.exit(main())
