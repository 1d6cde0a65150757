"""Self-consistent error of net / lines / auto on the Bundesliga broadcast frames (validation only).

Usage: ``python bench/bundesliga_consistency.py [--frames DIR] [--cache /tmp/bundesliga.pkl] [--checkout PATH]``

Each frame of ``DIR`` (../shared/data/broadcast_bundesliga: 640 x 640 files of 16:9 frames) is
resized to 1280 x 720 (bicubic) and distorted with 2 paper and 2 extended lenses
(:func:`glradial.evaluation.real_eval.paper_lenses` / ``extended_lenses``, seeds 7000 + i and
8000 + i) by ``glradial.distort`` at ``fit="crop"``. The frames' own lens is unknown, so a reading of
a distorted frame is scored against the applied lens composed with the same method's reading of the
unmodified frame: the composite radial map (own lens, then the crop scale, then the applied lens)
refitted to ``(k1, k2)`` by least squares over the 16:9 frame's radius range. Also printed: the error
against the applied lens alone ("raw"). Frames, lenses and CNN readings are cached in ``--cache``;
``--checkout`` runs the line detection and fit of another checkout (e.g. main) on the same cache.
"""

from __future__ import annotations

import argparse
import pickle
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _build(folder: Path, cache: Path) -> list[dict]:
    import cv2

    from glradial.evaluation.real_eval import Evaluator, extended_lenses, paper_lenses
    from glradial.remapping.remap import distort

    evaluator = Evaluator(threads=1)
    out = []
    for i, path in enumerate(sorted(folder.glob("*.jpg"))):
        image = cv2.resize(cv2.imread(str(path)), (1280, 720), interpolation=cv2.INTER_CUBIC)[:, :, ::-1].copy()
        lenses = paper_lenses(2, 7000 + i) + extended_lenses(2, 8000 + i)
        items = [(None, image)] + [((k1, k2), distort(image, k1, k2, fit="crop", backend="cpu")) for k1, k2 in lenses]
        for truth, frame in items:
            k = evaluator.estimator.run(evaluator.estimator.preprocess(frame)[None])[0]
            out.append({"clip": path.name.split("_")[0], "frame": path.name, "truth": truth, "image": frame,
                        "net": (float(k[0]), float(k[1]))})
    cache.write_bytes(pickle.dumps(out))
    return out


def composed(own: tuple[float, float], applied: tuple[float, float], size=(1280, 720)) -> np.ndarray:
    """``(k1, k2)`` of the frame's own lens followed by ``applied`` at ``fit="crop"``: a point at
    undistorted radius ``r`` (units of the distorted output) lands at ``s ro (1 + k1a (s ro)² + ...)``
    with ``ro = (r/s)(1 + k1o (r/s)² + k2o (r/s)⁴)``; refitted over the output's 16:9 radius range."""
    from glradial.lens.lens import Lens
    from glradial.lens.metrics import CORNER_RADIUS_16_9

    s = Lens(*applied).fit_scale(size, "crop", "distort")
    r = np.linspace(1e-3, 0.8, 800)
    ro = (r / s) * (1 + own[0] * (r / s) ** 2 + own[1] * (r / s) ** 4)
    q = s * ro * (1 + applied[0] * (s * ro) ** 2 + applied[1] * (s * ro) ** 4)
    keep = q <= CORNER_RADIUS_16_9
    design = np.stack([r[keep] ** 3, r[keep] ** 5], axis=1)
    return np.linalg.lstsq(design, q[keep] - r[keep], rcond=None)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", default=str(ROOT.parent / "shared/data/broadcast_bundesliga"))
    parser.add_argument("--cache", default="/tmp/bundesliga.pkl")
    parser.add_argument("--checkout", default=str(ROOT))
    args = parser.parse_args()
    sys.path.insert(0, args.checkout)
    from glradial.estimation.estimator import Estimator
    from glradial.lens.metrics import max_displacement_px

    estimator = Estimator(threads=1)

    cache = Path(args.cache)
    samples = pickle.loads(cache.read_bytes()) if cache.is_file() else _build(Path(args.frames), cache)
    own: dict = {}
    errors: dict = {}
    for sample in samples:  # each frame's unmodified reading comes first
        for method in ("net", "lines", "auto"):
            e = estimator.estimate(sample["image"], method=method)
            if sample["truth"] is None:
                own[sample["frame"], method] = (e.k1, e.k2)
                continue
            reference = composed(own[sample["frame"], method], sample["truth"])
            err = float(max_displacement_px(np.array([e.k1, e.k2]), reference))
            raw = float(max_displacement_px(np.array([e.k1, e.k2]), np.array(sample["truth"])))
            for group in (sample["clip"], "all") + (("k1 <= -0.6",) if sample["truth"][0] <= -0.6 else ()):
                errors.setdefault((group, method), []).append((err, raw))
    print(f"{'group':12s} {'method':6s} {'n':>4s} {'self-cons. median':>18s} {'p90':>6s} {'raw median':>11s}")
    for (group, method), values in sorted(errors.items()):
        v = np.array(values)
        print(f"{group:12s} {method:6s} {len(v):4d} {np.median(v[:, 0]):18.2f} {np.percentile(v[:, 0], 90):6.1f} "
              f"{np.median(v[:, 1]):11.2f}")


if __name__ == "__main__":
    main()
