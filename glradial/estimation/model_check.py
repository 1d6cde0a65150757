"""Validation of an ONNX lens-estimation model at load, before it is trusted with a frame.

A usable model (the contract of ``net/export.py``) has one input, uint8 ``N x H x W x 3`` RGB with
``H`` and ``W`` concrete in the graph or given by the ``input_size`` metadata (``"W,H"``; both must
agree where both exist), and one output, float ``N x 2`` = ``(k1, k2)``. A model whose metadata says
``glradial_format`` names its input ``image`` and its output ``k``. A checksum file beside the model
(``<model>.sha256``, ``sha256sum`` format: hex digest, two spaces, file name), which the bundled
model has, must match the file's SHA-256, so corrupted weights are refused; a model without one is
checked structurally and by the probe only. The probe runs a batch of two mid-grey frames and
requires an ``2 x 2`` finite output. Every failure is a :class:`ModelLoadError` naming the file and
what is wrong.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ModelLoadError

#: input and output names of a model exported by net/export.py (``glradial_format`` metadata)
INPUT_NAME = "image"
OUTPUT_NAME = "k"
#: the optional second output: the network's own expected error, px at 1920 (net.export)
ERROR_OUTPUT_NAME = "error_px"
#: value of a probe frame's pixels (mid-grey)
PROBE_LEVEL = 128


@dataclass(frozen=True)
class ModelInfo:
    """What the estimator needs from a validated model."""

    input_name: str
    input_size: tuple[int, int]  # (W, H)


def checksum_path(model_path: Path) -> Path:
    """The checksum file of ``model_path``: the same name with ``.sha256`` instead of ``.onnx``."""
    return model_path.with_suffix(".sha256")


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def write_checksum(path: Path) -> Path:
    """Record ``path``'s SHA-256 in its checksum file (atomically); returns the checksum file."""
    from ..media.atomic import atomic_write_text

    path = Path(path)
    return atomic_write_text(checksum_path(path), f"{file_sha256(path)}  {path.name}\n")


def check_checksum(path: Path) -> bool:
    """Compare ``path`` with its checksum file; True if one exists and matches, False if there is
    none; :class:`ModelLoadError` if it does not match or cannot be read."""
    recorded = checksum_path(path)
    if not recorded.is_file():
        return False
    try:
        fields = recorded.read_text().split()
    except (OSError, UnicodeDecodeError) as err:
        raise ModelLoadError(f"cannot read the checksum file {recorded} of {path}: {err}") from None
    expected = fields[0].lower() if fields else ""
    if len(expected) != 64 or any(c not in "0123456789abcdef" for c in expected):
        raise ModelLoadError(f"the checksum file {recorded} of {path} holds no SHA-256 hex digest")
    actual = file_sha256(path)
    if actual != expected:
        raise ModelLoadError(
            f"{path} is corrupt: its SHA-256 is {actual}, {recorded.name} records {expected} "
            f"(reinstall glradial, or re-export the model and its checksum)"
        )
    return True


def _input_size(path: Path, shape: list[Any], meta: dict[str, str]) -> tuple[int, int]:
    graph_hw = shape[1:3]
    concrete = all(isinstance(v, int) and v > 0 for v in graph_hw)
    text = meta.get("input_size")
    if text is not None:
        try:
            width, height = (int(v) for v in text.split(","))
        except ValueError:
            raise ModelLoadError(f"{path}: metadata input_size must be 'W,H' integers, got {text!r}") from None
        if width < 1 or height < 1:
            raise ModelLoadError(f"{path}: metadata input_size must be positive, got {text!r}")
        if concrete and (height, width) != tuple(graph_hw):
            raise ModelLoadError(
                f"{path}: metadata input_size {width}×{height} disagrees with the graph's input {graph_hw[1]}×{graph_hw[0]}"
            )
        return width, height
    if not concrete:
        raise ModelLoadError(
            f"{path}: the input's height and width are symbolic ({graph_hw}) and the metadata has no "
            f"input_size 'W,H': the frame size the network expects is unknown"
        )
    return int(graph_hw[1]), int(graph_hw[0])


def check_model(session: Any, path: Path) -> ModelInfo:
    """Validate an onnxruntime ``InferenceSession`` of ``path`` (structure, then the probe) and
    return its :class:`ModelInfo`; :class:`ModelLoadError` otherwise."""
    meta = dict(session.get_modelmeta().custom_metadata_map)
    inputs, outputs = session.get_inputs(), session.get_outputs()
    if len(inputs) != 1 or len(outputs) not in (1, 2) or (len(outputs) == 2 and outputs[1].name != ERROR_OUTPUT_NAME):
        raise ModelLoadError(
            f"{path} is not a glradial model: expected 1 input and 1 output (or 2, the second named "
            f"{ERROR_OUTPUT_NAME!r}), got {len(inputs)} and {[o.name for o in outputs]}"
        )
    inp, out = inputs[0], outputs[0]
    if "glradial_format" in meta and (inp.name, out.name) != (INPUT_NAME, OUTPUT_NAME):
        raise ModelLoadError(
            f"{path}: a glradial_format model names its input {INPUT_NAME!r} and output {OUTPUT_NAME!r}, "
            f"got {inp.name!r} and {out.name!r}"
        )
    shape = list(inp.shape)
    if inp.type != "tensor(uint8)" or len(shape) != 4 or shape[3] != 3:
        raise ModelLoadError(f"{path} is not a glradial model: input must be uint8 N×H×W×3, got {inp.type} {shape}")
    out_shape = list(out.shape) if out.shape is not None else []
    if out.type not in ("tensor(float)", "tensor(double)", "tensor(float16)") or len(out_shape) != 2 or (
        isinstance(out_shape[1], int) and out_shape[1] != 2
    ):
        raise ModelLoadError(f"{path} is not a glradial model: output must be float N×2 (k1, k2), got {out.type} {out_shape}")
    width, height = _input_size(path, shape, meta)
    probe = np.full((2, height, width, 3), PROBE_LEVEL, np.uint8)
    try:
        result = np.asarray(session.run([out.name], {inp.name: probe})[0])
    except Exception as err:  # onnxruntime raises its own exception types
        raise ModelLoadError(f"{path}: the probe batch of 2 frames {width}×{height} fails: {' '.join(str(err).split())[:300]}") from None
    if result.shape != (2, 2):
        raise ModelLoadError(f"{path}: the probe batch of 2 frames gave an output of shape {result.shape}, not 2×2")
    if not np.all(np.isfinite(result)):
        raise ModelLoadError(f"{path}: the probe frame gives non-finite (k1, k2) {result[0].tolist()}")
    return ModelInfo(inp.name, (width, height))
