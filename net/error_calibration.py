"""Per-crop errors and the network's own error scale on held-out procedural crops.

For a model exported with an error head (ONNX outputs ``k`` and ``error_px``), render ``n`` crops of
the ``split`` stadiums (as ``glradial evaluate`` does: 768x432, area-resized to the input size by the
estimator's preprocessing, mirror-averaged), and save per crop the true lens, the prediction, the
maximum displacement error (px at 1920) and the predicted error scale (px at 1920) to an ``.npz``.
The 90 % quantile of ``error / scale`` on the validation split is the factor that turns the scale
into a 90 % bound; the test split checks its coverage.

    python -m net.error_calibration --model runs/stage11/model.onnx --split val --out runs/stage11/val_errors.npz
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from glradial.estimation.estimator import Estimator
from glradial.evaluation.evaluation import EvaluationSettings, render_test_crops
from glradial.lens.metrics import max_displacement_px
from glradial.media.atomic import atomic_path
from glradial.synthesis.crops import crop_labels


def crop_errors(model: str, split: str, n: int, seed: int, panoramas: int, cache_dir: str) -> dict[str, np.ndarray]:
    """True and predicted lenses, error and predicted scale (both px at 1920) of ``n`` crops: the
    crops ``glradial evaluate`` renders for these settings."""
    estimator = Estimator(model)
    settings = EvaluationSettings(n=n, panoramas=panoramas, split=split, seed=seed, cache_dir=cache_dir)
    frames, params, _ = render_test_crops(settings, estimator.input_size)
    truth = crop_labels(params)
    if not estimator.has_error_head:
        raise ValueError(f"model {model} has no error head (no 'error_px' output)")
    k, scale = estimator.run_with_error(np.stack([estimator.preprocess(f) for f in frames]))
    error = max_displacement_px(truth, k)
    return {"truth": truth, "pred": k, "error_px": error, "scale_px": scale}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m net.error_calibration", description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True)
    parser.add_argument("--split", choices=("val", "test"), default="val")
    parser.add_argument("--n", type=int, default=800)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--panoramas", type=int, default=4)
    parser.add_argument("--cache-dir", default="data_cache")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    result = crop_errors(args.model, args.split, args.n, args.seed, args.panoramas, args.cache_dir)
    ratio = result["error_px"] / result["scale_px"]
    with atomic_path(args.out) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, **result)
    q90 = float(np.quantile(ratio, 0.9))
    print(f"{args.split}: median error {np.median(result['error_px']):.2f} px, median scale "
          f"{np.median(result['scale_px']):.2f} px, 90 % quantile of error/scale {q90:.3f}, "
          f"corr(log error, log scale) {np.corrcoef(np.log(result['error_px'] + 1e-3), np.log(result['scale_px']))[0, 1]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
