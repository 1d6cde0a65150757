"""Evaluate a distortion estimator (ONNX or checkpoint) on held-out crops: metrics, tables, plots.

Usage::

    python -m net.evaluate --model glradial/models/glradial_k1k2.onnx --out docs/eval [--n 800]

Test set: ``--n`` crops drawn from the paper's distribution over the held-out **test** split of the
procedural stadiums (:func:`glradial.stadium_style.split_seeds` "test": never used in training),
rendered like the training crops (no augmentation); plus, as an out-of-domain figure, crops of the
real panorama ``tests/data/panorama_field_2048x1024.jpg``.

Metrics (DESIGN.md), for predictions ``y_hat = (k1_hat, k2_hat)`` against labels ``y``:

* ``mean_dl``: mean distortion loss ``DL(y, y_hat)`` (sum over 64 radii on [0, 0.7]);
* ``k1_mae``, ``k2_mae``: mean absolute coefficient errors;
* ``median_max_px`` / ``p90_max_px``: median / 90th percentile of the maximum displacement error
  ``1920 * max_{r <= 0.5737} |P(r, y) - P(r, y_hat)|`` (pixels of a 1920-wide frame);
  ``median_max_px_ci95``: the median's 95 % bootstrap interval (percentiles of the median over
  :data:`BOOTSTRAP_DRAWS` resamples of the images, fixed seed): how far two models' medians on the
  same set must differ to mean anything;
* ``k2_deviation_corr``: Pearson correlation between the predicted and the true deviation of k2 from
  the manifold, ``k2_hat - m(k1_hat)`` against ``k2 - m(k1)``: whether the k2 output carries any
  information beyond the manifold (``None`` when either deviation is constant);
* ``a_beats_b``: share of images where method A (both coefficients from the net) has a smaller DL
  than method B (the net's k1 and ``k2 = 0.019 k1 + 0.805 k1^2``); the paper reports 0.612;
* the same for method B and for the trivial baseline that always predicts the training mean.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from glradial.metrics import (
    BOOTSTRAP_DRAWS,
    CORNER_RADIUS_16_9,
    REPORT_WIDTH,
    distortion_loss,
    manifold_k2,
    max_displacement_px,
    median_interval,
    radial_map,
)

#: Mean (k1, k2) of the paper's training distribution: k1 ~ U[-0.7, 0.3] -> -0.2;
#: E[k2] = 0.019 E[k1] + 0.805 E[k1^2] = 0.019 (-0.2) + 0.805 (0.04 + 1/12) = 0.0955.
TRAINING_MEAN = (-0.2, 0.019 * -0.2 + 0.805 * (0.04 + 1.0 / 12.0))


def method_b(pred: np.ndarray) -> np.ndarray:
    """The net's k1 with ``k2`` from the manifold."""
    pred = np.asarray(pred, np.float64)
    return np.stack([pred[:, 0], manifold_k2(pred[:, 0])], axis=1)


def deviation_correlation(pred: np.ndarray, labels: np.ndarray) -> float | None:
    """Correlation of ``k2_hat - m(k1_hat)`` with ``k2 - m(k1)`` (``None`` if either is constant)."""
    dev_pred = pred[:, 1] - manifold_k2(pred[:, 0])
    dev_true = labels[:, 1] - manifold_k2(labels[:, 0])
    if len(pred) < 2 or dev_pred.std() == 0 or dev_true.std() == 0:
        return None
    return float(np.corrcoef(dev_pred, dev_true)[0, 1])


def metrics(pred: np.ndarray, labels: np.ndarray) -> dict:
    """All metrics of predictions ``N x 2`` against labels ``N x 2`` (see the module docstring)."""
    pred = np.asarray(pred, np.float64)
    labels = np.asarray(labels, np.float64)
    if pred.shape != labels.shape or pred.ndim != 2 or pred.shape[1] != 2:
        raise ValueError(f"pred and labels must both be N x 2, got {pred.shape} and {labels.shape}")
    b = method_b(pred)
    dl_a, dl_b = distortion_loss(labels, pred), distortion_loss(labels, b)
    px_a, px_b = max_displacement_px(labels, pred), max_displacement_px(labels, b)
    mean = np.broadcast_to(np.array(TRAINING_MEAN), labels.shape)
    px_mean = max_displacement_px(labels, mean)
    return {
        "n": int(len(labels)),
        "mean_dl": float(dl_a.mean()),
        "k1_mae": float(np.abs(pred[:, 0] - labels[:, 0]).mean()),
        "k2_mae": float(np.abs(pred[:, 1] - labels[:, 1]).mean()),
        "median_max_px": float(np.median(px_a)),
        "median_max_px_ci95": median_interval(px_a),
        "p90_max_px": float(np.percentile(px_a, 90)),
        "a_beats_b": float((dl_a < dl_b).mean()),
        "k2_deviation_corr": deviation_correlation(pred, labels),
        "b_mean_dl": float(dl_b.mean()),
        "b_median_max_px": float(np.median(px_b)),
        "b_p90_max_px": float(np.percentile(px_b, 90)),
        "baseline_mean_dl": float(distortion_loss(labels, mean).mean()),
        "baseline_median_max_px": float(np.median(px_mean)),
    }


# --- test sets ---------------------------------------------------------------------------------------

#: Bins of the breakdown tables.
K1_BINS = [(-0.7, -0.5), (-0.5, -0.3), (-0.3, -0.1), (-0.1, 0.1), (0.1, 0.3)]
HFOV_BINS = [(15.0, 25.0), (25.0, 35.0), (35.0, 45.0), (45.0, 60.0)]
FIELD_PANORAMA = Path(__file__).resolve().parents[1] / "tests" / "data" / "panorama_field_2048x1024.jpg"


def render_frames(panoramas: list[np.ndarray], n: int, seed: int, frame_size: tuple[int, int]) -> tuple[np.ndarray, list]:
    """``n`` crops spread evenly over ``panoramas``, rendered at ``frame_size`` (area-filtered 16:9
    frames of the 1280 x 720 geometry), with their :class:`CropParams`."""
    from glradial.crops import CropRenderer, sample_crop_params

    counts = [n // len(panoramas) + (1 if i < n % len(panoramas) else 0) for i in range(len(panoramas))]
    frames, params_all = [], []
    for j, (pano, count) in enumerate(zip(panoramas, counts)):
        if count:
            params = sample_crop_params(count, seed * 1000 + j, size=(1280, 720))
            with CropRenderer(pano, size=(1280, 720), out_size=frame_size) as renderer:
                frames.append(np.ascontiguousarray(renderer.render(params)[..., :3]))
            params_all += params
    return np.concatenate(frames), params_all


class OnnxPredictor:
    """Predicts through :class:`glradial.estimator.Estimator` (the shipped path, area resize included)."""

    def __init__(self, path: str, threads: int | None):
        from glradial.estimator import Estimator

        self.estimator = Estimator(path, threads=threads)
        self.input_size = self.estimator.input_size

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        out = []
        for i in range(0, len(frames), 64):
            batch = np.stack([self.estimator.preprocess(f) for f in frames[i : i + 64]])
            out.append(self.estimator.run(batch))
        return np.concatenate(out)


class TorchPredictor:
    """Predicts with a ``.pt`` checkpoint (same preprocessing: area resize, then the model)."""

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
            for i in range(0, len(frames), 64):
                batch = np.stack([cv2.resize(f, self.input_size, interpolation=cv2.INTER_AREA) for f in frames[i : i + 64]])
                out.append(self.model(torch.from_numpy(batch)).double().numpy())
        return np.concatenate(out)


def breakdown(pred: np.ndarray, labels: np.ndarray, values: np.ndarray, bins: list[tuple[float, float]]) -> list[dict]:
    rows = []
    for lo, hi in bins:
        sel = (values >= lo) & (values < hi) if hi != bins[-1][1] else (values >= lo) & (values <= hi)
        if sel.any():
            m = metrics(pred[sel], labels[sel])
            rows.append({"range": f"[{lo:g}, {hi:g}]", **m})
    return rows


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def _table(rows: list[dict], first: str) -> str:
    head = f"| {first} | n | median px | p90 px | mean DL | k1 MAE | k2 MAE | A beats B | B median px |\n|---|---|---|---|---|---|---|---|---|\n"
    body = "".join(
        f"| {r['range']} | {r['n']} | {r['median_max_px']:.2f} | {r['p90_max_px']:.2f} | {r['mean_dl']:.2e} | "
        f"{r['k1_mae']:.4f} | {r['k2_mae']:.4f} | {100 * r['a_beats_b']:.1f} % | {r['b_median_max_px']:.2f} |\n"
        for r in rows
    )
    return head + body


def plots(out: Path, pred: np.ndarray, labels: np.ndarray, ood: tuple[np.ndarray, np.ndarray] | None) -> list[str]:
    """Error distribution (A, B, baseline), predicted vs true k1/k2; returns the PNG names written."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plots (pip install matplotlib)")
        return []
    names = []
    px_a = max_displacement_px(labels, pred)
    px_b = max_displacement_px(labels, method_b(pred))
    px_0 = max_displacement_px(labels, np.broadcast_to(np.array(TRAINING_MEAN), labels.shape))
    fig, ax = plt.subplots(figsize=(6.4, 4.0), dpi=110)
    top = float(np.percentile(np.concatenate([px_a, px_b]), 98)) * 1.2
    bins = np.linspace(0, max(top, 1.0), 50)
    ax.hist(px_a, bins, alpha=0.6, label=f"A: net k1, k2 (median {np.median(px_a):.2f} px)")
    ax.hist(px_b, bins, alpha=0.6, label=f"B: net k1, manifold k2 (median {np.median(px_b):.2f} px)")
    if ood is not None:
        px_o = max_displacement_px(ood[1], ood[0])
        ax.hist(px_o, bins, histtype="step", color="k", label=f"A on the real panorama (median {np.median(px_o):.2f} px)")
    ax.axvline(4.0, color="r", ls="--", lw=1, label="target median 4 px")
    ax.set_xlabel("max displacement error over the frame (px of a 1920-wide frame)")
    ax.set_ylabel("test crops")
    ax.set_title(f"Error distribution, held-out stadiums (n = {len(labels)}; mean predictor median {np.median(px_0):.1f} px)", fontsize=8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "error_distribution.png")
    plt.close(fig)
    names.append("error_distribution.png")
    fig, axes = plt.subplots(1, 2, figsize=(8.0, 4.0), dpi=110)
    for i, (ax, name) in enumerate(zip(axes, ("k1", "k2"))):
        ax.scatter(labels[:, i], pred[:, i], s=4, alpha=0.5, label="held-out stadiums")
        if ood is not None:
            ax.scatter(ood[1][:, i], ood[0][:, i], s=4, alpha=0.5, c="k", label="real panorama")
        lo, hi = float(labels[:, i].min()), float(labels[:, i].max())
        ax.plot([lo, hi], [lo, hi], "r-", lw=1)
        ax.set_xlabel(f"true {name}")
        ax.set_ylabel(f"predicted {name}")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "predicted_vs_true.png")
    plt.close(fig)
    names.append("predicted_vs_true.png")
    return names


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m net.evaluate", description="Evaluate an estimator on held-out crops.")
    parser.add_argument("--model", required=True, help=".onnx (through glradial.estimate) or .pt checkpoint")
    parser.add_argument("--out", default="docs/eval", help="folder for metrics.json, results.md and plots")
    parser.add_argument("--n", type=int, default=800, help="test crops from held-out stadiums")
    parser.add_argument("--test-panoramas", type=int, default=8, help="held-out stadiums of --split")
    parser.add_argument("--split", choices=("test", "val"), default="test",
                        help="stadium split to evaluate on: test (the reported figures) or val (checkpoint selection)")
    parser.add_argument("--panorama-size", type=int, nargs=2, default=(4096, 2048))
    parser.add_argument("--ood-n", type=int, default=200, help="crops of the real panorama (out of domain)")
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--cache-dir", default="data_cache")
    args = parser.parse_args(argv)

    from .data import split_seeds, stadium_panorama_cached

    t0 = time.monotonic()
    predictor = (TorchPredictor if args.model.endswith(".pt") else OnnxPredictor)(args.model, args.threads)
    width, height = predictor.input_size
    frame_size = (2 * width, 2 * height)  # rendered at twice the input, area-resized by the predictor
    seeds = split_seeds(args.split, args.test_panoramas)
    panoramas = [stadium_panorama_cached(s, tuple(args.panorama_size), args.cache_dir) for s in seeds]
    frames, params = render_frames(panoramas, args.n, args.seed, frame_size)
    labels = np.array([(p.k1, p.k2) for p in params])
    t_render = time.monotonic() - t0
    t1 = time.monotonic()
    pred = predictor(frames)
    t_pred = time.monotonic() - t1
    result = {
        "model": str(args.model),
        "test_set": {"split": args.split, "stadium_seeds": seeds, "panorama_size": list(args.panorama_size), "crops": len(labels),
                     "crop_seed": args.seed, "frame_size_rendered": list(frame_size), "distribution": "paper (crops.PAPER_RANGES)"},
        "overall": metrics(pred, labels),
        "by_k1": breakdown(pred, labels, labels[:, 0], K1_BINS),
        "by_hfov": breakdown(pred, labels, np.array([p.hfov for p in params]), HFOV_BINS),
    }
    ood = None
    if args.ood_n > 0 and FIELD_PANORAMA.exists():
        import cv2

        field = cv2.cvtColor(cv2.imread(str(FIELD_PANORAMA), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        ood_frames, ood_params = render_frames([field], args.ood_n, args.seed + 1, frame_size)
        ood_labels = np.array([(p.k1, p.k2) for p in ood_params])
        ood_pred = predictor(ood_frames)
        ood = (ood_pred, ood_labels)
        result["out_of_domain"] = {"panorama": FIELD_PANORAMA.name, "crops": len(ood_labels), **metrics(ood_pred, ood_labels)}
    result["seconds"] = {"render": round(t_render, 1), "predict": round(t_pred, 1), "total": round(time.monotonic() - t0, 1)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(result, indent=2) + "\n")
    names = plots(out, pred, labels, ood)
    o = result["overall"]
    lines = [
        f"# Evaluation of `{Path(args.model).name}`\n",
        f"Held-out procedural stadiums ({args.split} split seeds {seeds}, {args.panorama_size[0]}×{args.panorama_size[1]}), "
        f"{len(labels)} crops from the paper's distribution, rendered at {frame_size[0]}×{frame_size[1]} and area-resized "
        f"to the {width}×{height} input. Command: `python -m net.evaluate --model {args.model} --out {args.out} --n {args.n}"
        f"{'' if args.split == 'test' else ' --split ' + args.split}`.\n",
        "| metric | method A (net k1, k2) | method B (net k1, manifold k2) | mean predictor |",
        "|---|---|---|---|",
        f"| median max displacement (px @1920) | {o['median_max_px']:.2f} (95 % bootstrap interval "
        f"{o['median_max_px_ci95'][0]:.2f}–{o['median_max_px_ci95'][1]:.2f}) | {o['b_median_max_px']:.2f} | {o['baseline_median_max_px']:.2f} |",
        f"| 90th percentile (px @1920) | {o['p90_max_px']:.2f} | {o['b_p90_max_px']:.2f} | |",
        f"| mean distortion loss | {o['mean_dl']:.3e} | {o['b_mean_dl']:.3e} | {o['baseline_mean_dl']:.3e} |",
        f"| k1 / k2 mean abs error | {o['k1_mae']:.4f} / {o['k2_mae']:.4f} | | |",
        f"| A beats B (by DL) | {100 * o['a_beats_b']:.1f} % (paper: 61.2 %) | | |",
        f"| correlation of predicted and true k2 deviation from the manifold | {_number(o['k2_deviation_corr'])} | | |\n",
        "## By k1 range\n", _table(result["by_k1"], "k1"),
        "## By horizontal field of view (degrees)\n", _table(result["by_hfov"], "hfov"),
    ]
    if ood is not None:
        d = result["out_of_domain"]
        lines += [
            "## Out of domain: crops of a real panorama\n",
            f"`tests/data/{d['panorama']}`: a real 2048×1024 photo of a grass field at dusk (no stadium, no pitch "
            f"lines: the horizon and a few trees are the only lines, and its 2048 px hold less detail than the 4096 px "
            f"stadiums), {d['crops']} crops from the same distribution: median {d['median_max_px']:.2f} px, p90 {d['p90_max_px']:.2f} px, "
            f"k1 MAE {d['k1_mae']:.4f}, A beats B {100 * d['a_beats_b']:.1f} % (mean predictor median "
            f"{d['baseline_median_max_px']:.2f} px).\n",
        ]
    lines += [f"![{n}]({n})\n" for n in names]
    (out / "results.md").write_text("\n".join(lines))
    print("\n".join(lines[:10]))
    print(f"wrote {out / 'metrics.json'}, {out / 'results.md'} ({result['seconds']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
