"""``python -m net.evaluate``: ``glradial evaluate`` (:mod:`glradial.evaluation.evaluation`) that also takes
``.pt`` checkpoints (through torch, in a checkout).

Usage::

    python -m net.evaluate --model runs/gpu384b/best.pt --out runs/gpu384b/eval [--split val] [--n 800]

The options, the test set, the metrics and the report are those of ``glradial evaluate`` (see
``glradial evaluate --help``); an ``.onnx`` model goes through :class:`glradial.estimation.net_lines.NetLinesEstimator`
exactly as there.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from glradial.cli import messages_to_stderr
from glradial.commands.evaluate import add_arguments, settings
from glradial.estimation.net_lines import default_model_path
from glradial.evaluation.evaluation import PREDICT_BATCH, OnnxPredictor, evaluate, summary


class TorchPredictor:
    """Predicts with a ``.pt`` checkpoint: area resize to the input, then the exported graph's
    preprocessing and the model (:class:`net.export.ExportWrapper`)."""

    def __init__(self, path: str, threads: int | None):
        import torch

        from .export import ExportWrapper, load_checkpoint

        if threads:
            torch.set_num_threads(threads)
        self.model = ExportWrapper(load_checkpoint(path)).eval()
        self.input_size = self.model.model.config.input_size

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        import cv2
        import torch

        out = []
        with torch.no_grad():
            for i in range(0, len(frames), PREDICT_BATCH):
                batch = np.stack([cv2.resize(f, self.input_size, interpolation=cv2.INTER_AREA) for f in frames[i : i + PREDICT_BATCH]])
                k = self.model(torch.from_numpy(batch))
                out.append((k[0] if isinstance(k, tuple) else k).double().numpy())  # (k, error_px) with an error head
        return np.concatenate(out)


def main(argv: list[str] | None = None) -> int:
    parser = add_arguments(argparse.ArgumentParser(prog="python -m net.evaluate", description=__doc__.split("\n")[0]))
    args = parser.parse_args(argv)
    model = str(args.model or default_model_path())
    chosen = settings(args, "python -m net.evaluate")
    predictor = (TorchPredictor if model.endswith(".pt") else OnnxPredictor)(model, args.threads)
    with messages_to_stderr():  # the evaluation's progress, as `glradial evaluate` shows it
        result = evaluate(predictor, predictor.input_size, args.out, chosen, model)
    print(summary(args.out, result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
