"""Self-consistent error of net / lines / auto on the five shared matches' broadcast frames (validation only).

Usage: ``python bench/bundesliga_consistency.py [--frames DIR ...] [--matches 2e57b9,...] [--limit N]
[--cache /tmp/matches_consistency.pkl] [--checkout PATH] [--no-pitch] [--dump FILE]``

Each frame of the ``DIR`` folders (default ../shared/data/broadcast_bundesliga and broadcast_more: 640 x
640 files of 16:9 frames; grouped by match, ``bench/calibrate_matches.py``'s ``match_of``; ``--limit N``:
N frames per match, evenly spread) is
resized to 1280 x 720 (bicubic) and distorted with 2 paper and 2 extended lenses
(:func:`glradial.evaluation.real_eval.paper_lenses` / ``extended_lenses``, seeds 7000 + i and
8000 + i, i the frame's index in its folder) by ``glradial.distort`` at ``fit="crop"``. The frames' own lens is unknown, so a reading of
a distorted frame is scored against the applied lens composed with the same method's reading of the
unmodified frame: the exact composite radial map (own lens, then the crop scale, then the applied
lens; ``glradial.evaluation.real_eval.self_consistent_map``), with no refit to ``(k1, k2)`` (a
least-squares refit, used before, flattered the median by 0.24 px: docs/LINES.md). Also printed: the
same error over the ideal radii whose image lies inside the frame ("in-frame"; the headline metric
runs to the corner radius in ideal radii, beyond the picture under a pincushion lens), and the error
against the applied lens alone ("raw"). Frames, lenses and CNN readings are cached in
``--cache``; ``--checkout`` runs another checkout (one that has ``self_consistent_map``) on the same
cache.

Methods: ``net``, ``lines`` and ``auto`` of the estimation layer (``glradial.estimation.net_lines``: the
CNN and the line fit; ``auto`` there is what ``glradial.estimate`` answered before the pitch camera fit
was fed back), and ``auto+pitch``, the public ``glradial.estimate(method="auto")``
(:mod:`glradial.camera.estimator`: the camera fit's lens where the pitch template fits, the estimation
layer's ``auto`` elsewhere), with the share of samples it answered from the pitch and how often its
stated bound covered its self-consistent error there; ``pitch alone``: the camera fit's lens alone where
it fits (``auto`` elsewhere), with the bound of ``lens_bound_px``. ``--no-pitch`` (or a checkout without
``glradial.camera.estimator``) leaves it out; both rows come from ``estimator.with_pitch``, the function
``glradial.estimate`` itself calls (a checkout with ``pitch_lens`` but without it: use ``--no-pitch``). ``--dump FILE`` writes one JSON line per scored sample
and method (clip, frame, applied lens, reading, error, stated bound, source, the camera fit's marking RMS, its
reason, markings, support, field of view and lens; the
unmodified frame's readings too, with ``truth`` null). Figures: ``docs/figures/lens_consistency_matches.json``.
"""

from __future__ import annotations

import argparse
import functools
import json
import pickle
import sys
from pathlib import Path

import numpy as np
from figures import printed_report, write_figure

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
DATA = ROOT.parent / "shared" / "data"


def _build(folders: list[Path], cache: Path, matches: list[str], limit: int) -> list[dict]:
    from calibrate_matches import match_of

    from glradial.evaluation.real_eval import Evaluator, extended_lenses, paper_lenses, read_broadcast
    from glradial.remapping.remap import distort

    evaluator = Evaluator(threads=1)
    out = []
    for path, i in _frames(folders, matches, limit):
        image = read_broadcast(path)
        lenses = paper_lenses(2, 7000 + i) + extended_lenses(2, 8000 + i)
        items = [(None, image)] + [((k1, k2), distort(image, k1, k2, fit="crop", backend="cpu")) for k1, k2 in lenses]
        for truth, frame in items:
            k = evaluator.estimator.run(evaluator.estimator.preprocess(frame)[None])[0]
            out.append({"clip": match_of(path.stem), "frame": path.name, "truth": truth, "image": frame,
                        "net": (float(k[0]), float(k[1]))})
    cache.write_bytes(pickle.dumps(out))
    return out


def _frames(folders: list[Path], matches: list[str], limit: int) -> list[tuple[Path, int]]:
    """``(file, its index in its folder: the lenses' seed)`` of each frame of ``matches``; with ``limit``,
    that many per match, evenly spread over the match's sorted frames."""
    from calibrate_matches import match_of

    by_match: dict[str, list[tuple[Path, int]]] = {}
    for folder in folders:
        for i, path in enumerate(sorted(folder.glob("*.jpg"))):
            if match_of(path.stem) in matches:
                by_match.setdefault(match_of(path.stem), []).append((path, i))
    out = []
    for items in by_match.values():
        keep = np.unique(np.linspace(0, len(items) - 1, limit).round().astype(int)) if limit else range(len(items))
        out += [items[k] for k in keep]
    return out


@functools.lru_cache(maxsize=4096)
def _crop_scale(applied: tuple[float, float], size: tuple[int, int]) -> float:
    """The zoom of ``distort(..., fit="crop")`` with the applied lens (one per sample: cached)."""
    from glradial.lens.lens import Lens

    return Lens(*applied).fit_scale(size, "crop", "distort")


@functools.lru_cache(maxsize=1 << 20)  # bench/pitch_lens_choice.py scores the same readings under many settings
def exact_error_px(k: tuple[float, float], applied: tuple[float, float], own: tuple[float, float],
                   size=(1280, 720)) -> tuple[float, float]:
    """Error (px at 1920) of the reading ``k`` of a distorted frame against the frame's true radial map,
    the frame's own lens ``own`` followed by ``applied`` at ``fit="crop"``
    (:func:`glradial.evaluation.real_eval.self_consistent_map`), with no refit of the composite to two
    coefficients: ``(the headline metric, largest displacement over the ideal radii up to the 16:9
    corner radius; the same over the ideal radii whose image lies inside the frame)``. The two differ
    where the lens moves the corner: under a pincushion lens the first also scores radii beyond the
    picture, under a barrel lens it stops short of the corners."""
    from glradial.lens.metrics import CORNER_RADIUS_16_9, REPORT_WIDTH, radial_map

    r, q, inside = _true_map(tuple(applied), tuple(own), tuple(size))
    d = REPORT_WIDTH * np.abs(radial_map(r, np.array(k)) - q)
    return float(d[r <= CORNER_RADIUS_16_9].max()), float(d[inside].max())


@functools.lru_cache(maxsize=1 << 16)
def _true_map(applied: tuple[float, float], own: tuple[float, float], size: tuple[int, int]):
    """``(ideal radii, the frame's true distorted radii, the radii whose image lies in the frame)`` of
    :func:`exact_error_px` (one per sample and reading of its unmodified frame: cached)."""
    from glradial.evaluation.real_eval import self_consistent_map
    from glradial.lens.metrics import CORNER_RADIUS_16_9

    r = np.linspace(0.0, 2.0 * CORNER_RADIUS_16_9, 2049)  # a barrel lens at k1 = -1 shows ideal radii to 1.6 R
    q = self_consistent_map(r, applied, own, _crop_scale(applied, size))
    return r, q, np.cumprod(q <= CORNER_RADIUS_16_9).astype(bool)  # up to the radius that reaches the corner


def _readings(estimator, frame: np.ndarray, pitch: bool) -> dict:
    """``{method: LensEstimate}`` of one frame (and the camera fit's marking RMS under ``"rms"``)."""
    from glradial.estimation.lens_estimate import judge

    evidence = estimator.evidence_batch([frame])[0]  # what estimate() judges, gathered once for the three methods
    out = {method: judge(evidence, method) for method in ("net", "lines", "auto")}
    if pitch:
        from glradial.camera import estimator as pl
        from glradial.estimation.lens_estimate import LensEstimate

        # what glradial.estimate(method="auto") answers: the estimation layer's auto with the camera fit fed back
        out["auto+pitch"], camera = pl.with_pitch(frame, out["auto"])
        if camera is None:  # no pitch evidence: the camera fit was not run
            out["pitch alone"], out["rms"], out["camera"] = out["auto"], None, None
            return out
        # the camera fit's lens alone where it fits (auto elsewhere): what the bound of pitch_lens_bound.py calibrates
        lens = pl.camera_lens(camera) if not camera.doubtful else None
        out["pitch alone"] = out["auto"] if lens is None else LensEstimate(
            lens.k1, lens.k2, uncertainty_px=pl.lens_bound_px(camera), method="pitch")
        out["rms"] = camera.rms_px
        out["camera"] = camera_record(frame, camera)
    return out


def camera_record(frame: np.ndarray, camera) -> dict:
    """What ``bench/pitch_lens_choice.py`` replays of a camera fit of ``frame`` (a ``CameraEstimate``):
    its verdict, markings, support, :func:`glradial.camera.estimator.centre_shift_px` (px at 1920), field
    of view (degrees) and raw lens ``k`` (width-normalised ``(k1, k2)``; None without a lens)."""
    from glradial.camera import estimator as pl

    return {"reason": camera.reason, "markings": len(camera.markings), "support": camera.support,
            "centre_shift_px": pl.centre_shift_px(frame, camera),
            "hfov_deg": camera.hfov_deg, "k": None if camera.lens is None else [camera.lens.k1, camera.lens.k2]}


def _print(errors: dict) -> None:
    print(f"{'group':12s} {'method':11s} {'n':>4s} {'self-cons. median':>18s} {'p90':>6s} {'in-frame median':>16s} "
          f"{'raw median':>11s} {'from pitch':>10s} {'bound covers':>12s}")
    for (group, method), values in sorted(errors.items()):
        v = np.array([row[:3] for row in values])
        pitched = [row for row in values if row[3] == "pitch"]
        share = f"{len(pitched) / len(values):10.1%}" if method in ("auto+pitch", "pitch alone") else " " * 10
        covers = f"{np.mean([r[0] <= r[4] for r in pitched]):12.1%}" if pitched else " " * 12
        print(f"{group:12s} {method:11s} {len(v):4d} {np.median(v[:, 0]):18.2f} {np.percentile(v[:, 0], 90):6.1f} "
              f"{np.median(v[:, 2]):16.2f} {np.median(v[:, 1]):11.2f} {share} {covers}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", nargs="+", default=[str(DATA / "broadcast_bundesliga"), str(DATA / "broadcast_more")])
    parser.add_argument("--matches", default="2e57b9,42ba34,08fd33,121364,video_1", help="comma-separated match prefixes")
    parser.add_argument("--limit", type=int, default=0, help="N frames per match, evenly spread (0: all)")
    parser.add_argument("--cache", default="/tmp/matches_consistency.pkl")
    parser.add_argument("--checkout", default=str(ROOT))
    parser.add_argument("--no-pitch", action="store_true", help="leave out auto+pitch (the camera fit's lens)")
    parser.add_argument("--dump", help="write per-sample results (JSON lines) here")
    args = parser.parse_args()
    sys.path.insert(0, args.checkout)
    from glradial.estimation.net_lines import NetLinesEstimator
    from glradial.lens.metrics import max_displacement_px

    try:
        import glradial.camera.estimator  # noqa: F401
        pitch = not args.no_pitch
    except ImportError:  # a checkout from before the lens was fed back
        pitch = False
    estimator = NetLinesEstimator(threads=1)

    cache = Path(args.cache)
    matches = [m.strip() for m in args.matches.split(",") if m.strip()]
    samples = (pickle.loads(cache.read_bytes()) if cache.is_file()
               else _build([Path(f) for f in args.frames], cache, matches, args.limit))
    own: dict = {}
    errors: dict = {}
    dump = open(args.dump, "w") if args.dump else None
    for sample in samples:  # each frame's unmodified reading comes first
        found = _readings(estimator, sample["image"], pitch)
        for method, e in found.items():
            if method in ("rms", "camera"):
                continue
            if sample["truth"] is None:
                own[sample["frame"], method] = (e.k1, e.k2)
                if dump:  # the reading of the unmodified frame, which the scoring composes with the applied lens
                    dump.write(json.dumps({"clip": sample["clip"], "frame": sample["frame"], "truth": None, "method": method,
                                           "source": e.method, "k": [e.k1, e.k2], "bound_px": e.uncertainty_px,
                                           "camera_rms_px": found.get("rms"), "camera": found.get("camera")}) + "\n")
                continue
            err, in_frame = exact_error_px((e.k1, e.k2), sample["truth"], own[sample["frame"], method])
            raw = float(max_displacement_px(np.array([e.k1, e.k2]), np.array(sample["truth"])))
            k1 = sample["truth"][0]
            groups = (sample["clip"], "all") + (("k1 <= -0.6",) if k1 <= -0.6 else ()) + (("k1 > 0.1",) if k1 > 0.1 else ())
            for group in groups:
                errors.setdefault((group, method), []).append((err, raw, in_frame, e.method, e.uncertainty_px))
            if dump:
                dump.write(json.dumps({"clip": sample["clip"], "frame": sample["frame"], "truth": sample["truth"],
                                       "method": method, "source": e.method, "k": [e.k1, e.k2], "error_px": err,
                                       "bound_px": e.uncertainty_px, "camera_rms_px": found.get("rms"),
                                       "camera": found.get("camera")}) + "\n")
    if dump:
        dump.close()
    with printed_report() as lines:
        _print(errors)
    write_figure("lens_consistency_matches", {"frames_per_match": args.limit or "all", "self_consistent_px": {
        f"{group} / {method}": {"n": len(v), "median": float(np.median([r[0] for r in v])),
                                "p90": float(np.percentile([r[0] for r in v], 90))} for (group, method), v in sorted(errors.items())},
        "report": lines})


if __name__ == "__main__":
    main()
