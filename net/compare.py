"""``python -m net.compare``: several models on the same evaluation crops, with paired differences.

Usage::

    python -m net.compare runs/abl_base/last.pt runs/abl_comparator/last.pt \
        --split val --test-panoramas 4 --n 800 --panorama-size 2048x1024

The crops are those of ``glradial evaluate`` / ``python -m net.evaluate`` with the same options
(rendered once, at twice the first model's input size; every model must take the same input size).
For each model: the median maximum displacement (px at 1920 wide) overall and for near-zero lenses
(``|k1| < 0.1``), the p90, the mean distortion loss and A beats B; against the first model, the
paired bootstrap 95 % interval of the change of the median and of the mean loss (the same crops
resampled for both, :data:`DRAWS` draws). A ``.pt`` model with a comparator head also gets its
ordering accuracy: how often it says which of two crops (random pairs of the evaluation crops) has
the larger k1 and k2, beside the same accuracy of its regression outputs.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from glradial.commands.evaluate import add_arguments, settings
from glradial.evaluation.evaluation import OnnxPredictor, a_beats_b, render_test_crops
from glradial.lens.metrics import distortion_loss, max_displacement_px

#: Bootstrap draws of the paired intervals.
DRAWS = 2000
#: ``|k1|`` below this is a near-zero lens (the evaluation's middle k1 bin).
NEAR_ZERO = 0.1


def paired_interval(a: np.ndarray, b: np.ndarray, stat, draws: int = DRAWS, seed: int = 0) -> list[float]:
    """95 % percentile-bootstrap interval of ``stat(b) - stat(a)`` over the same resampled indices."""
    idx = np.random.default_rng(seed).integers(0, len(a), size=(draws, len(a)))
    diffs = [stat(b[i]) - stat(a[i]) for i in idx]
    lo, hi = np.percentile(diffs, [2.5, 97.5])
    return [float(lo), float(hi)]


def ordering_accuracy(path: str, frames: np.ndarray, labels: np.ndarray, seed: int = 0) -> dict | None:
    """For a ``.pt`` model with a comparator head: the fraction of random pairs of ``frames``
    (uint8 N x H x W x 3, area-resized to its input) whose order of k1 and of k2 its comparator gets
    right, and the same for its regression outputs; ``None`` for other models."""
    if not path.endswith(".pt"):
        return None
    import cv2
    import torch

    from .export import load_checkpoint
    from .loss import comparison_partners
    from .model import normalise_batch

    model = load_checkpoint(path)
    if model.head_compare is None:
        return None
    small = np.stack([cv2.resize(f, model.config.input_size, interpolation=cv2.INTER_AREA) for f in frames])
    partner = torch.from_numpy(comparison_partners(len(small), False, np.random.default_rng(seed)))
    with torch.no_grad():
        out = model(normalise_batch(torch.from_numpy(small), model.config), partner).double().numpy()
    p = partner.numpy()
    truth = (labels - labels[p]) > 0
    regression = ((out[:, :2] - out[p, :2]) > 0) == truth
    comparator = (out[:, -2:] > 0) == truth
    return {"comparator": comparator.mean(axis=0).tolist(), "regression": regression.mean(axis=0).tolist()}


def compare(paths: list[str], chosen, threads: int | None) -> list[dict]:
    """The rows described in the module docstring, one per model of ``paths`` (the first is the reference)."""
    from glradial.synthesis.crops import crop_labels

    from .evaluate import TorchPredictor

    predictors = [(TorchPredictor if p.endswith(".pt") else OnnxPredictor)(p, threads) for p in paths]
    sizes = {tuple(pr.input_size) for pr in predictors}
    if len(sizes) != 1:
        raise ValueError(f"MODEL: every model must take the same input size, got {sorted(sizes)}")
    frames, params, _ = render_test_crops(chosen, predictors[0].input_size)
    labels = crop_labels(params)
    near = np.abs(labels[:, 0]) < NEAR_ZERO
    rows, ref = [], None
    for path, predictor in zip(paths, predictors):
        pred = np.asarray(predictor(frames), np.float64)[:, :2]
        px, dl = max_displacement_px(labels, pred), distortion_loss(labels, pred)
        row = {"model": path, "median_px": float(np.median(px)), "near_zero_median_px": float(np.median(px[near])),
               "p90_px": float(np.percentile(px, 90)), "mean_dl": float(dl.mean()), "a_beats_b": a_beats_b(pred, labels),
               "ordering": ordering_accuracy(path, frames, labels)}
        if ref is None:
            ref = (px, dl)
        else:
            row["d_median_px_ci95"] = paired_interval(ref[0], px, np.median)
            row["d_near_zero_median_px_ci95"] = paired_interval(ref[0][near], px[near], np.median)
            row["d_mean_dl_ci95"] = paired_interval(ref[1], dl, np.mean)
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = add_arguments(argparse.ArgumentParser(prog="python -m net.compare", description=__doc__.split("\n")[0]))
    parser.set_defaults(ood_n=0)
    parser.add_argument("models", nargs="+", metavar="MODEL",
                        help="a .pt checkpoint or .onnx model (the first is the reference; --model is not used)")
    args = parser.parse_args(argv)
    rows = compare(args.models, settings(args, "python -m net.compare"), args.threads)
    for row in rows:
        line = (f"{row['model']}: median {row['median_px']:.2f} px, |k1| < {NEAR_ZERO}: {row['near_zero_median_px']:.2f} px, "
                f"p90 {row['p90_px']:.2f} px, mean DL {row['mean_dl']:.3e}, A beats B {100 * row['a_beats_b']:.1f} %")
        if "d_median_px_ci95" in row:
            lo, hi = row["d_median_px_ci95"]
            nlo, nhi = row["d_near_zero_median_px_ci95"]
            dlo, dhi = row["d_mean_dl_ci95"]
            line += (f"; vs the first, paired 95 %: median {lo:+.2f} to {hi:+.2f} px, near-zero {nlo:+.2f} to {nhi:+.2f} px, "
                     f"mean DL {dlo:+.2e} to {dhi:+.2e}")
        if row["ordering"]:
            c, r = row["ordering"]["comparator"], row["ordering"]["regression"]
            line += f"; order right, comparator k1 {100 * c[0]:.1f} % k2 {100 * c[1]:.1f} %, regression {100 * r[0]:.1f} / {100 * r[1]:.1f} %"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
