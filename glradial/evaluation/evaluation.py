"""Evaluation of a distortion estimator on held-out crops: metrics, breakdowns, report (no torch).

Used by ``glradial evaluate`` (an ONNX model through :class:`glradial.estimation.net_lines.NetLinesEstimator`) and by
``python -m net.evaluate`` in a checkout (which adds ``.pt`` checkpoints through torch). Needs
NumPy, OpenCV, onnxruntime and a GL context; plots need matplotlib and are skipped, with a message,
without it.

Test set: ``n`` crops drawn from the paper's distribution over the held-out **test** split of the
procedural stadiums (:func:`glradial.synthesis.stadium_style.split_seeds`: never used in training; ``val``
for choosing between checkpoints), rendered like the training crops (no augmentation) at twice
the network input and area-resized by the predictor (:func:`glradial.synthesis.crops.render_crop_set`).
Optionally, as an out-of-domain figure, crops of a real panorama given by the caller (the
repository's ``tests/data/panorama_field_2048x1024.jpg`` in ``make evaluate``).

Metrics (docs/DESIGN.md; definitions in :mod:`glradial.lens.metrics`), for predictions ``y_hat = (k1_hat,
k2_hat)`` against labels ``y``:

* ``mean_dl``: mean distortion loss ``DL(y, y_hat)`` (sum over 64 radii on [0, 0.7]);
* ``k1_mae``, ``k2_mae``: mean absolute coefficient errors;
* ``median_max_px`` / ``p90_max_px``: median / 90th percentile of the maximum displacement error
  (:func:`glradial.lens.metrics.max_displacement_px`: pixels of a 1920-wide frame, up to the 16:9
  corner); ``median_max_px_ci95``: the median's 95 % bootstrap interval
  (:func:`glradial.lens.metrics.median_interval`): how far two models' medians on the same set must
  differ to mean anything;
* ``k2_deviation_corr``: Pearson correlation between the predicted and the true deviation of k2 from
  the manifold, ``k2_hat - m(k1_hat)`` against ``k2 - m(k1)``: whether the k2 output carries any
  information beyond the manifold (``None`` when either deviation is constant);
* ``a_beats_b``: share of images where method A (both coefficients from the net) has a smaller DL
  than method B (the net's k1 and the manifold's k2); the paper reports 0.612;
* the same for method B and for the trivial baseline that always predicts the training mean.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import check_count
from ..lens.metrics import PAPER_SIZE, distortion_loss, manifold_k2, max_displacement_px, median_interval
from ..synthesis.crops import PAPER_RANGES

#: progress of an evaluation (INFO) and what it leaves out (WARNING); ``glradial evaluate`` shows both on stderr
logger = logging.getLogger(__name__)

__all__ = [
    "TRAINING_MEAN",
    "lens_mean",
    "K1_BINS",
    "HFOV_BINS",
    "method_b",
    "a_beats_b",
    "deviation_correlation",
    "metrics",
    "breakdown",
    "OnnxPredictor",
    "EvaluationSettings",
    "evaluate",
    "summary",
    "report_markdown",
    "plots",
]

def lens_mean(k1_range: tuple[float, float] = PAPER_RANGES["k1"]) -> tuple[float, float]:
    """Mean ``(k1, k2)`` of the crops' lens distribution: ``k1 ~ U[k1_range]`` and ``k2 =``
    :func:`~glradial.lens.metrics.manifold_k2` ``(k1)`` + zero-mean noise (the rare lenses that
    :func:`~glradial.synthesis.crops.sample_crop_params` redraws because they fold over are ignored). The
    manifold is a quadratic, so Simpson's rule over ``k1_range`` is its exact mean."""
    low, high = (float(v) for v in k1_range)
    mid = (low + high) / 2
    return mid, float((manifold_k2(low) + 4 * manifold_k2(mid) + manifold_k2(high)) / 6)


#: Mean (k1, k2) of the paper's training distribution (:data:`glradial.synthesis.crops.PAPER_RANGES`).
TRAINING_MEAN = lens_mean()
#: Bins of the breakdown tables.
K1_BINS = [(-0.7, -0.5), (-0.5, -0.3), (-0.3, -0.1), (-0.1, 0.1), (0.1, 0.3)]
HFOV_BINS = [(15.0, 25.0), (25.0, 35.0), (35.0, 45.0), (45.0, 60.0)]
#: Frames sent to the predictor per call.
PREDICT_BATCH = 64

#: A predictor: uint8 RGB frames ``N x H x W x 3`` -> float64 ``N x 2`` (k1, k2).
Predictor = Callable[[np.ndarray], np.ndarray]


def method_b(pred: np.ndarray) -> np.ndarray:
    """The net's k1 with ``k2`` from the manifold."""
    pred = np.asarray(pred, np.float64)
    return np.stack([pred[:, 0], manifold_k2(pred[:, 0])], axis=1)


def a_beats_b(pred: np.ndarray, labels: np.ndarray) -> float:
    """Share of rows where method A (``pred``, both coefficients) has a smaller distortion loss
    against ``labels`` than method B (:func:`method_b` of ``pred``); ties count as not beating."""
    pred = np.asarray(pred, np.float64)
    return float(np.mean(distortion_loss(labels, pred) < distortion_loss(labels, method_b(pred))))


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
        "a_beats_b": a_beats_b(pred, labels),
        "k2_deviation_corr": deviation_correlation(pred, labels),
        "b_mean_dl": float(dl_b.mean()),
        "b_median_max_px": float(np.median(px_b)),
        "b_p90_max_px": float(np.percentile(px_b, 90)),
        "baseline_mean_dl": float(distortion_loss(labels, mean).mean()),
        "baseline_median_max_px": float(np.median(px_mean)),
    }


def breakdown(pred: np.ndarray, labels: np.ndarray, values: np.ndarray, bins: list[tuple[float, float]]) -> list[dict]:
    """:func:`metrics` per bin ``[lo, hi)`` of ``values`` (the last bin closed); empty bins left out."""
    rows = []
    for lo, hi in bins:
        sel = (values >= lo) & (values < hi) if hi != bins[-1][1] else (values >= lo) & (values <= hi)
        if sel.any():
            rows.append({"range": f"[{lo:g}, {hi:g}]", **metrics(pred[sel], labels[sel])})
    return rows


class OnnxPredictor:
    """Predicts through :class:`glradial.estimation.net_lines.NetLinesEstimator` (the shipped path, area resize and
    mirror averaging included; ``mirror_average=False`` runs the network once per crop)."""

    def __init__(self, path: str | os.PathLike, threads: int | None = None, mirror_average: bool = True):
        from ..estimation.net_lines import NetLinesEstimator

        self.estimator = NetLinesEstimator(path, threads=threads, mirror_average=mirror_average)
        self.input_size = self.estimator.input_size

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        out = []
        for i in range(0, len(frames), PREDICT_BATCH):
            batch = np.stack([self.estimator.preprocess(f) for f in frames[i : i + PREDICT_BATCH]])
            out.append(self.estimator.run(batch))
        return np.concatenate(out)


@dataclass(frozen=True)
class EvaluationSettings:
    """What :func:`evaluate` renders: ``n`` crops over ``panoramas`` stadiums of ``split`` at
    ``panorama_size`` (W, H), crop seed ``seed``; ``field_panorama`` (an image file, or ``None``)
    adds ``ood_n`` out-of-domain crops of it (seed ``seed + 1``); stadiums are cached in
    ``cache_dir``. ``command`` is the command line quoted in the report."""

    n: int = 800
    panoramas: int = 8
    split: str = "test"
    panorama_size: tuple[int, int] = (4096, 2048)
    field_panorama: str | None = None
    ood_n: int = 200
    seed: int = 2024
    cache_dir: str | None = "data_cache"
    command: str = "glradial evaluate"

    def __post_init__(self) -> None:
        if self.split not in ("test", "val"):
            raise ValueError(f"split must be 'test' or 'val', got {self.split!r}")
        for name in ("n", "panoramas"):
            check_count(name, getattr(self, name))
        check_count("ood_n", self.ood_n, minimum=0)
        if self.field_panorama is not None and not Path(self.field_panorama).is_file():
            raise FileNotFoundError(f"field panorama {str(self.field_panorama)!r} does not exist")


def render_test_crops(settings: EvaluationSettings, input_size: tuple[int, int]) -> tuple[np.ndarray, list, list[int]]:
    """The held-out crops :func:`evaluate` scores: ``settings.n`` crops of the ``settings.split``
    stadiums, rendered at twice ``input_size`` (W, H; area-resized by the predictor). Returns uint8
    frames, their :class:`~glradial.synthesis.crops.CropParams` and the stadium seeds. Progress goes
    to stderr."""
    from ..synthesis.crops import render_crop_set
    from ..synthesis.stadium import stadium_panorama_cached
    from ..synthesis.stadium_style import split_seeds

    width, height = input_size
    frame_size = (2 * width, 2 * height)
    seeds = split_seeds(settings.split, settings.panoramas)
    panoramas = []
    for i, seed in enumerate(seeds):
        logger.info(f"stadium {i + 1}/{len(seeds)} (seed {seed}, {settings.split} split)")
        panoramas.append(stadium_panorama_cached(seed, settings.panorama_size, settings.cache_dir))
    logger.info(f"rendering {settings.n} crops at {frame_size[0]}x{frame_size[1]}")
    frames, params = render_crop_set(panoramas, settings.n, settings.seed, size=PAPER_SIZE, out_size=frame_size)
    return frames, params, seeds


def evaluate(predictor: Predictor, input_size: tuple[int, int], out: str | os.PathLike,
             settings: EvaluationSettings, model_name: str) -> dict:
    """Render the test set, predict, write ``metrics.json``, ``results.md`` and the plots to ``out``
    (all atomically); returns the metrics dict. ``input_size`` (W, H) is the network input:
    crops are rendered at twice it. Progress is logged (``logging``, INFO); :func:`summary` is
    what to print after it."""
    from ..synthesis.crops import crop_labels, load_panorama, render_crop_set

    field = None
    if settings.field_panorama is not None and settings.ood_n > 0:  # checked before the long work
        field = load_panorama(settings.field_panorama)
        if field.shape[1] != 2 * field.shape[0]:
            raise ValueError(f"field panorama {settings.field_panorama!r} must be equirectangular 2:1, "
                             f"got {field.shape[1]}×{field.shape[0]}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    frames, params, seeds = render_test_crops(settings, input_size)
    labels = crop_labels(params)
    frame_size = (frames.shape[2], frames.shape[1])
    t_render = time.monotonic() - t0
    logger.info(f"predicting {len(frames)} crops")
    t1 = time.monotonic()
    pred = predictor(frames)
    t_pred = time.monotonic() - t1
    result: dict = {
        "model": model_name,
        "test_set": {"split": settings.split, "stadium_seeds": seeds, "panorama_size": list(settings.panorama_size),
                     "crops": len(labels), "crop_seed": settings.seed, "frame_size_rendered": list(frame_size),
                     "distribution": "paper (crops.PAPER_RANGES)"},
        "overall": metrics(pred, labels),
        "by_k1": breakdown(pred, labels, labels[:, 0], K1_BINS),
        "by_hfov": breakdown(pred, labels, np.array([p.hfov for p in params]), HFOV_BINS),
    }
    ood = None
    if field is None:
        logger.warning("no out-of-domain figure: " + ("no field panorama given (--field-panorama)"
                                            if settings.field_panorama is None else "--ood-n is 0"))
    else:
        logger.info(f"out of domain: {settings.ood_n} crops of {settings.field_panorama}")
        ood_frames, ood_params = render_crop_set([field], settings.ood_n, settings.seed + 1, size=PAPER_SIZE,
                                                 out_size=frame_size)
        ood_labels = crop_labels(ood_params)
        ood = (predictor(ood_frames), ood_labels)
        result["out_of_domain"] = {"panorama": Path(settings.field_panorama).name, "size": [field.shape[1], field.shape[0]],
                                   "crops": len(ood_labels), **metrics(*ood)}
    result["seconds"] = {"render": round(t_render, 1), "predict": round(t_pred, 1), "total": round(time.monotonic() - t0, 1)}
    from ..media.atomic import atomic_write_text

    atomic_write_text(out / "metrics.json", json.dumps(result, indent=2) + "\n")
    names = plots(out, pred, labels, ood)
    text = report_markdown(result, settings, input_size, names)
    atomic_write_text(out / "results.md", text)
    return result


def summary(out: str | os.PathLike, result: dict) -> str:
    """What a command prints after :func:`evaluate` wrote to ``out``: the head of ``results.md``
    (the overall figures) and the files written, with the seconds each part took."""
    out = Path(out)
    head = "\n".join((out / "results.md").read_text(encoding="utf-8").split("\n")[:12])
    return f"{head}\nwrote {out / 'metrics.json'}, {out / 'results.md'} ({result['seconds']})"


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def _table(rows: list[dict], first: str) -> str:
    head = (f"| {first} | n | median px | p90 px | mean DL | k1 MAE | k2 MAE | A beats B | B median px |\n"
            "|---|---|---|---|---|---|---|---|---|\n")
    body = "".join(
        f"| {r['range']} | {r['n']} | {r['median_max_px']:.2f} | {r['p90_max_px']:.2f} | {r['mean_dl']:.2e} | "
        f"{r['k1_mae']:.4f} | {r['k2_mae']:.4f} | {100 * r['a_beats_b']:.1f} % | {r['b_median_max_px']:.2f} |\n"
        for r in rows
    )
    return head + body


def report_markdown(result: dict, settings: EvaluationSettings, input_size: tuple[int, int], plot_names: Sequence[str]) -> str:
    """``results.md``: the summary table, the breakdowns, the out-of-domain line and the plots."""
    o, t = result["overall"], result["test_set"]
    width, height = input_size
    frame_w, frame_h = t["frame_size_rendered"]
    options = f"--n {settings.n}" + ("" if settings.split == "test" else f" --split {settings.split}")
    if settings.field_panorama is not None:
        options += f" --field-panorama {settings.field_panorama}"
    lines = [
        f"# Evaluation of `{Path(result['model']).name}`\n",
        f"Held-out procedural stadiums ({settings.split} split seeds {t['stadium_seeds']}, "
        f"{settings.panorama_size[0]}×{settings.panorama_size[1]}), {t['crops']} crops from the paper's distribution, "
        f"rendered at {frame_w}×{frame_h} and area-resized to the {width}×{height} input. "
        f"Command: `{settings.command} --model {result['model']} {options}`.\n",
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
    d = result.get("out_of_domain")
    if d is not None:
        lines += [
            "## Out of domain: crops of a real panorama\n",
            f"`{d['panorama']}` ({d['size'][0]}×{d['size'][1]}), {d['crops']} crops from the same distribution: "
            f"median {d['median_max_px']:.2f} px, p90 {d['p90_max_px']:.2f} px, k1 MAE {d['k1_mae']:.4f}, "
            f"A beats B {100 * d['a_beats_b']:.1f} % (mean predictor median {d['baseline_median_max_px']:.2f} px).\n",
        ]
    else:
        lines += ["No out-of-domain figure (no real panorama was given: `--field-panorama`).\n"]
    lines += [f"![{n}]({n})\n" for n in plot_names]
    return "\n".join(lines)


def plots(out: Path, pred: np.ndarray, labels: np.ndarray, ood: tuple[np.ndarray, np.ndarray] | None) -> list[str]:
    """Error distribution (A, B, baseline), predicted vs true k1/k2; returns the PNG names written
    (none, with a warning logged, when matplotlib is not installed)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        logger.warning("matplotlib is not installed: no plots (pip install matplotlib)")
        return []
    from ..media.atomic import atomic_path

    def save(name: str) -> str:
        fig.tight_layout()
        with atomic_path(out / name) as tmp:
            fig.savefig(tmp)
        plt.close(fig)
        return name

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
    names.append(save("error_distribution.png"))
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
    names.append(save("predicted_vs_true.png"))
    return names
