"""Export a trained estimator to ONNX with its metadata; check it against torch.

Usage::

    python -m net.export --checkpoint runs/gpu384b/best.pt --out glradial/models/glradial_k1k2.onnx \
        [--metrics runs/gpu384b/eval.json] [--run-config runs/gpu384b/config.json]

Graph (opset 17). Input ``image``: uint8 ``N x H x W x 3`` RGB (NHWC), the 16:9 frame already
resized (area interpolation) to the network input ``input_size = (W, H)``. The graph does the rest
of the preprocessing itself: cast to float, ``/ 255``, (grayscale models: BT.601 luma), minus
``mean``, divided by ``std``, NHWC -> NCHW. Output ``k``: float32 ``N x 2`` = ``(k1, k2)`` in
width-normalised lens units. ``N`` is dynamic.

Metadata (``metadata_props``, all strings; JSON where structured): ``glradial_format`` ("1"),
``model_config`` (the :class:`~.model.ModelConfig` dict), ``input_size`` ("W,H"), ``input_layout``
("NHWC uint8 RGB"), ``preprocessing`` (prose), ``output`` (prose), ``training`` (JSON: data, steps,
wall time), ``metrics`` (JSON), ``version`` (glradial version), ``onnx_check`` (the agreement
measured here).

Check: the ONNX checker, then onnxruntime against torch on the same random uint8 batch; they must
agree within ``ATOL`` (1e-4 lens units = 0.19 px at 1920 wide; float32 round-off between two
kernel libraries is ~1e-6).
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from glradial.estimation.model_check import write_checksum
from glradial.media.atomic import atomic_path

from .model import DistortionNet, ModelConfig, inference_model, normalise_batch

#: Largest |torch - onnxruntime| (lens units) accepted by :func:`check_agreement`.
ATOL = 1e-4
OPSET = 17
PREPROCESSING = (
    "Resize the whole 16:9 RGB frame to input_size (W, H) with area interpolation "
    "(cv2.INTER_AREA; the aspect ratio is squashed if input_size is not 16:9), keep uint8 RGB, "
    "stack N x H x W x 3. The graph casts to float, divides by 255, applies (x - mean) / std per "
    "channel and transposes to NCHW."
)
OUTPUT = "k: float32 N x 2 = (k1, k2), width-normalised lens units (image width = 1, origin at the centre)"
ERROR_OUTPUT = ("error_px: float32 N x 1, the network's expected error for the frame: the scale of a Laplace "
                "model of its maximum displacement error over the 16:9 frame, px at 1920 wide (uncalibrated)")


class ExportWrapper(nn.Module):
    """uint8 NHWC RGB -> :func:`~.model.normalise_batch` -> the model -> (k1, k2); the graph that ships."""

    def __init__(self, model: DistortionNet):
        super().__init__()
        self.model = model

    def forward(self, image: torch.Tensor):
        out = self.model(normalise_batch(image, self.model.config))
        if not self.model.config.error_head:
            return out
        return out[:, :2], torch.exp(out[:, 2:3])


def load_checkpoint(path: str | Path, which: str = "auto") -> DistortionNet:
    """Rebuild the model of a ``.pt`` checkpoint (``best.pt``: EMA weights; ``last.pt``: EMA if
    ``which`` is "auto" or "ema", raw if "raw")."""
    state = torch.load(path, map_location="cpu", weights_only=False)
    model = DistortionNet(ModelConfig.from_dict(state["model_config"]))
    if "ema" in state and which in ("auto", "ema"):
        weights = state["ema"]
    else:
        weights = state["model"]
    model.load_state_dict(weights)
    return model.eval()


def export_onnx(model: DistortionNet, path: str | Path, metadata: dict | None = None) -> Path:
    """Write ``model`` (eval mode) as ONNX with the preprocessing graph and metadata (atomically);
    returns the path. Training-only parts (the comparator head) are dropped first
    (:func:`~.model.inference_model`): the graph's outputs and its ``model_config`` are those of the
    network without them."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    model = inference_model(model.eval())
    wrapper = ExportWrapper(model).eval()
    width, height = model.config.input_size
    dummy = torch.zeros(1, height, width, 3, dtype=torch.uint8)
    with atomic_path(path) as tmp:
        with warnings.catch_warnings():  # the TorchScript exporter is deprecated; onnxscript (dynamo) is not a dependency
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", torch.jit.TracerWarning)  # the preprocessing constants
            outputs = ["k", "error_px"] if model.config.error_head else ["k"]
            torch.onnx.export(
                wrapper, (dummy,), str(tmp), dynamo=False, input_names=["image"], output_names=outputs,
                dynamic_axes={"image": {0: "N"}, **{name: {0: "N"} for name in outputs}}, opset_version=OPSET,
                do_constant_folding=True,
            )
        _add_metadata(tmp, model.config, metadata)
    write_checksum(path)  # the estimator refuses a model whose recorded SHA-256 differs
    return path


def _add_metadata(path: Path, config: ModelConfig, metadata: dict | None) -> None:
    """Write the metadata properties into the ONNX file at ``path`` (in place) and check the model."""
    import onnx

    proto = onnx.load(str(path))
    width, height = config.input_size
    props = {
        "glradial_format": "1",
        "model_config": json.dumps(config.to_dict()),
        "input_size": f"{width},{height}",
        "input_layout": "NHWC uint8 RGB",
        "preprocessing": PREPROCESSING,
        "output": OUTPUT + ("; " + ERROR_OUTPUT if config.error_head else ""),
    }
    try:
        from glradial import __version__

        props["version"] = __version__
    except Exception:  # pragma: no cover
        props["version"] = "unknown"
    for key, value in (metadata or {}).items():
        props[key] = value if isinstance(value, str) else json.dumps(value)
    del proto.metadata_props[:]
    for key, value in props.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    proto.doc_string = "glradial radial distortion estimator: " + OUTPUT
    onnx.checker.check_model(proto)
    onnx.save(proto, str(path))


def max_difference(model: DistortionNet, onnx_path: str | Path, images: np.ndarray) -> float:
    """Largest |torch - onnxruntime| of ``model`` (through :class:`ExportWrapper`) and the graph at
    ``onnx_path`` over ``images`` (uint8 N x H x W x 3), in lens units; an error head's ``error_px``
    is compared divided by 1920, the width its pixels refer to."""
    import onnxruntime as ort

    with torch.no_grad():
        ref = ExportWrapper(model.eval())(torch.from_numpy(np.ascontiguousarray(images)))
    ref = [t.numpy() for t in ref] if isinstance(ref, tuple) else [ref.numpy()]
    session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
    got = session.run(None, {session.get_inputs()[0].name: np.ascontiguousarray(images)})
    return max([float(np.abs(ref[0] - got[0]).max())]
               + [float(np.abs(r - g).max() / 1920.0) for r, g in zip(ref[1:], got[1:])])


def check_agreement(model: DistortionNet, onnx_path: str | Path, n: int = 8, seed: int = 0) -> float:
    """:func:`max_difference` over a random uint8 batch; raises AssertionError beyond :data:`ATOL`."""
    width, height = model.config.input_size
    images = np.random.default_rng(seed).integers(0, 256, (n, height, width, 3), dtype=np.uint8)
    err = max_difference(model, onnx_path, images)
    if not err <= ATOL:
        raise AssertionError(f"onnxruntime and torch disagree by {err:.3g} > {ATOL} lens units")
    return err


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m net.export", description="Export a checkpoint to ONNX.")
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument("--out", required=True, help="the .onnx file to write")
    parser.add_argument("--metrics", help="JSON file of evaluation metrics to embed")
    parser.add_argument("--run-config", help="the run's config.json (training data description) to embed")
    parser.add_argument("--training", help="JSON string or file with training facts (steps, wall time, hardware)")
    parser.add_argument("--weights", choices=["auto", "ema", "raw"], default="auto")
    args = parser.parse_args(argv)
    model = load_checkpoint(args.checkpoint, args.weights)
    state = torch.load(args.checkpoint, map_location="cpu", weights_only=False)
    training: dict = {"steps": state.get("step"), "train_time_s": state.get("train_time")}
    if args.run_config:
        run = json.loads(Path(args.run_config).read_text())
        training["data"] = {k: run.get(k) for k in ("panoramas", "augment", "batch_size", "seed")}
    if args.training:
        text = Path(args.training).read_text() if Path(args.training).exists() else args.training
        training.update(json.loads(text))
    metadata: dict = {"training": training}
    if args.metrics:
        metadata["metrics"] = json.loads(Path(args.metrics).read_text())
    elif "val" in state:
        metadata["metrics"] = {"validation": state["val"]}
    path = export_onnx(model, args.out, metadata)
    err = check_agreement(model, path)
    import onnx

    proto = onnx.load(str(path))
    entry = proto.metadata_props.add()
    entry.key, entry.value = "onnx_check", json.dumps({"max_abs_diff_vs_torch": err, "atol": ATOL})
    with atomic_path(path) as tmp:
        onnx.save(proto, str(tmp))
    write_checksum(path)
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB); torch vs onnxruntime max |diff| {err:.2e} (atol {ATOL})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
