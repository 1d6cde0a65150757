"""Per-crop errors and the network's own error scale on held-out procedural crops.

For a model exported with an error head (ONNX outputs ``k`` and ``error_px``), render ``n`` crops of
the ``split`` stadiums (as ``glradial evaluate`` does: 768x432, area-resized to the input size by the
estimator's preprocessing, mirror-averaged), and save per crop the true lens, the prediction, the
maximum displacement error (px at 1920) and the predicted error scale (px at 1920) to an ``.npz``.
The 90 % quantile of ``error / scale`` on the validation split is the factor that turns the scale
into a 90 % bound; the test split checks its coverage.

    python -m net.error_calibration --model runs/stage11/model.onnx --split val --out runs/stage11/val_errors.npz

With ``--real DATA`` (a folder holding ``real_football/`` and ``broadcast_bundesliga/``, validation
only: never trained on) the same per-frame error and scale are measured on real frames instead, and
the coverage of ``q x error_px`` is reported (docs/MODEL.md, "The error head"):

* ``real_frames``: the pinhole frames of ``real_football`` (football360 and USL; the 2:1 panorama is
  left out) with the known lenses ``glradial evaluate --frames`` applies (``--lenses`` paper and as
  many extended lenses per frame, same seeds), scored against the applied lens;
* ``broadcast``: the Bundesliga frames with the lenses ``glradial evaluate --broadcast`` applies
  (``--broadcast-lenses`` per frame), scored self-consistently (the applied lens composed with the
  network's own reading of the unmodified frame, :func:`glradial.evaluation.real_eval.self_consistent_truth`).

``q`` is the procedural validation split's 90 % quantile (``--q``, 1.82 for the shipped model) and,
split conformal, the 90 % quantile of one real source checked on the other (frames of one clip are
not independent, so the split is by source, and by clip within the broadcast frames).

    python -m net.error_calibration --model glradial/models/glradial_k1k2.onnx --real ../shared/data --out /tmp/real_errors.npz
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from glradial.estimation.net_lines import NetLinesEstimator
from glradial.evaluation.evaluation import EvaluationSettings, render_test_crops
from glradial.evaluation.real_eval import applied_lenses, broadcast_frames, folder_sources, self_consistent_items, self_consistent_truth
from glradial.evaluation.trust_calibration import COVERAGE, conformal_quantile
from glradial.lens.metrics import max_displacement_px
from glradial.lens.options import check_positive
from glradial.media.atomic import atomic_path
from glradial.media.progress import Progress
from glradial.synthesis.crops import crop_labels

#: The procedural validation split's 90 % quantile of error / error_px for the shipped model (docs/MODEL.md).
SHIPPED_VAL_Q = 1.82


def crop_errors(model: str, split: str, n: int, seed: int, panoramas: int, cache_dir: str) -> dict[str, np.ndarray]:
    """True and predicted lenses, error and predicted scale (both px at 1920) of ``n`` crops: the
    crops ``glradial evaluate`` renders for these settings."""
    estimator = NetLinesEstimator(model)
    settings = EvaluationSettings(n=n, panoramas=panoramas, split=split, seed=seed, cache_dir=cache_dir)
    frames, params, _ = render_test_crops(settings, estimator.input_size)
    truth = crop_labels(params)
    if not estimator.has_error_head:
        raise ValueError(f"model {model} has no error head (no 'error_px' output)")
    k, scale = estimator.run_with_error(np.stack([estimator.preprocess(f) for f in frames]))
    error = max_displacement_px(truth, k)
    return {"truth": truth, "pred": k, "error_px": error, "scale_px": scale}


def _estimator_with_head(model: str) -> NetLinesEstimator:
    estimator = NetLinesEstimator(model)
    if not estimator.has_error_head:
        raise ValueError(f"model {model} has no error head (no 'error_px' output)")
    return estimator


def _read(estimator: NetLinesEstimator, frames: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The network's mirror-averaged ``(k1, k2)`` (N x 2) and ``error_px`` (N) of ``frames``."""
    k, scale = estimator.run_with_error(np.stack([estimator.preprocess(f) for f in frames]))
    return np.asarray(k, np.float64), np.asarray(scale, np.float64).reshape(-1)


def real_errors(model: str, data: str | Path, lenses: int = 12, broadcast_lenses: int = 3, seed: int = 0,
                remove_own_lens: bool = False, progress=print) -> dict[str, np.ndarray]:
    """Per sample of the real validation frames under ``data`` (module docstring): ``source``
    (``real_frames`` / ``broadcast``), ``group`` (frame name / clip), the lens it is scored against
    (``truth``), the prediction, the error and the predicted scale (both px at 1920).
    ``remove_own_lens``: as ``glradial evaluate --remove-own-lens`` (docs/eval/real.md)."""
    for name, value in (("lenses", lenses), ("broadcast_lenses", broadcast_lenses)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
    _estimator_with_head(model)
    data = Path(data)
    sources, own = {}, {}
    evaluator = folder_sources(data / "real_football", model, None, lenses, seed, remove_own_lens, sources, own, {})
    rows: list[tuple[str, str, np.ndarray, np.ndarray, np.ndarray]] = []
    for key, items in sources.items():  # the frames' sources of glradial evaluate --frames (panorama crops left out)
        if key.rsplit("/", 1)[0] in own:
            truth, frames = zip(*items)
            k, scale = _read(evaluator.estimator, list(frames))
            rows.append(("real_frames", key.rsplit("/", 1)[0], np.array(truth, np.float64), k, scale))
    progress(f"real_frames: {len(own)} frames x {2 * lenses} lenses")
    clips = broadcast_frames(data / "broadcast_bundesliga")
    with Progress(sum(len(items) for items in clips.values()), "broadcast frames") as bar:
        for clip, items in clips.items():
            for i, (_name, frame) in enumerate(items):  # the lenses and seeds of real_eval.broadcast_samples
                reading = _read(evaluator.estimator, [frame])[0][0]
                found = list(self_consistent_items(frame, applied_lenses(broadcast_lenses, seed * 1000 + i)))
                truth = np.array([self_consistent_truth(a, (reading[0], reading[1]), s) for a, s, _ in found], np.float64)
                k, scale = _read(evaluator.estimator, [d for _, _, d in found])
                rows.append(("broadcast", clip, truth, k, scale))
                bar.update(1)
            progress(f"broadcast/{clip}: {len(items)} frames x {broadcast_lenses} lenses")
    truth, pred, scale = (np.concatenate([r[j] for r in rows]) for j in (2, 3, 4))
    counts = [len(r[2]) for r in rows]
    return {"source": np.repeat([r[0] for r in rows], counts), "group": np.repeat([r[1] for r in rows], counts),
            "truth": truth, "pred": pred, "error_px": max_displacement_px(truth, pred), "scale_px": scale}


def _stats(error: np.ndarray, scale: np.ndarray, q: float) -> str:
    ratio = error / scale
    return (f"{len(error)} | {np.median(error):.2f} | {np.median(scale):.2f} | {np.quantile(ratio, COVERAGE):.2f} | "
            f"{np.mean(error <= q * scale):.1%} | {np.median(q * scale):.1f}")


def coverage_report(result: dict[str, np.ndarray], q_val: float = SHIPPED_VAL_Q) -> str:
    """Markdown tables: per source (and clip) the median error and ``error_px``, the 90 % quantile of
    error / ``error_px``, the coverage and median bound of ``q_val x error_px``; then split conformal:
    ``q`` (:func:`glradial.evaluation.trust_calibration.conformal_quantile`, 90 %) on one part, checked on the other."""
    q_val = check_positive("q_val", q_val)
    error, scale, source = result["error_px"], result["scale_px"], result["source"]
    keys = [f"{s}/{g}" for s, g in zip(source, result["group"])]
    parts = {"all real": np.ones(len(error), bool)}
    parts.update({str(s): source == s for s in dict.fromkeys(source)})
    parts.update({k: np.array([x == k for x in keys]) for k in dict.fromkeys(keys) if k.startswith("broadcast/")})
    text = (f"| samples | n | median error px | median error_px | 90 % quantile of error / error_px | "
            f"covered by {q_val:g} x error_px | median bound px |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: |\n")
    text += "".join(f"| {name} | {_stats(error[m], scale[m], q_val)} |\n" for name, m in parts.items())
    splits = [(a, b) for a, b in (("real_frames", "broadcast"), ("broadcast", "real_frames"),
                                  ("broadcast/42ba34", "broadcast/2e57b9"), ("broadcast/2e57b9", "broadcast/42ba34"))
              if a in parts and b in parts and parts[a].any() and parts[b].any()]
    text += ("\n| calibrated on | q (conformal 90 %) | checked on | n | covered | median bound px |\n"
             "| --- | ---: | --- | ---: | ---: | ---: |\n")
    for cal, check in splits:
        q = conformal_quantile(error[parts[cal]] / scale[parts[cal]], COVERAGE)
        covered = np.mean(error[parts[check]] <= q * scale[parts[check]])
        text += f"| {cal} | {q:.2f} | {check} | {parts[check].sum()} | {covered:.1%} | {np.median(q * scale[parts[check]]):.1f} |\n"
    return text


def _save(result: dict[str, np.ndarray], out: str) -> None:
    with atomic_path(out) as tmp:
        with open(tmp, "wb") as handle:
            np.savez(handle, **result)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m net.error_calibration", description=__doc__.splitlines()[0])
    parser.add_argument("--model", required=True)
    parser.add_argument("--split", choices=("val", "test"), default="val")
    parser.add_argument("--n", type=int, default=800)
    parser.add_argument("--seed", type=int, default=2024)
    parser.add_argument("--panoramas", type=int, default=4)
    parser.add_argument("--cache-dir", default="data_cache")
    parser.add_argument("--real", metavar="DATA", help="real validation frames instead (real_football/, broadcast_bundesliga/)")
    parser.add_argument("--lenses", type=int, default=12, help="--real: paper (and as many extended) lenses per real_football frame")
    parser.add_argument("--broadcast-lenses", type=int, default=3, help="--real: lenses per Bundesliga frame")
    parser.add_argument("--remove-own-lens", action="store_true", help="--real: as glradial evaluate --remove-own-lens")
    parser.add_argument("--q", type=float, default=SHIPPED_VAL_Q, help="--real: the procedural val split's 90 %% quantile")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    if args.real is not None:
        try:
            check_positive("--q", args.q)  # before the long run
            result = real_errors(args.model, args.real, args.lenses, args.broadcast_lenses, remove_own_lens=args.remove_own_lens)
        except (ValueError, OSError) as err:  # bad arguments, a missing model or folder: one line, status 2
            parser.error(str(err))
        _save(result, args.out)
        print(coverage_report(result, args.q))
        return 0
    result = crop_errors(args.model, args.split, args.n, args.seed, args.panoramas, args.cache_dir)
    ratio = result["error_px"] / result["scale_px"]
    _save(result, args.out)
    q90 = float(np.quantile(ratio, 0.9))
    print(f"{args.split}: median error {np.median(result['error_px']):.2f} px, median scale "
          f"{np.median(result['scale_px']):.2f} px, 90 % quantile of error/scale {q90:.3f}, "
          f"corr(log error, log scale) {np.corrcoef(np.log(result['error_px'] + 1e-3), np.log(result['scale_px']))[0, 1]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
