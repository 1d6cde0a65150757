"""Does the automatic lens help on real-looking pitch views unlike close broadcast frames?

Usage::

    python bench/pitch_views.py [--data ../shared/data] [--frames /tmp/pitch_views_frames.pkl]
        [--evidence /tmp/pitch_views_evidence.pkl] [--trust glradial/data/trust.json] [--json OUT]
        [--sources wide_camera,...] [--list]

Validation sets (validation only: nothing is trained or tuned on them for the figures reported):

* ``wide_camera``: 30 frames spread over ``real_wide_camera/wide_pitch_camera.mp4`` (a real static
  wide camera, checkerboard-calibrated k1 -0.6615, k2 +0.4098), reduced to 1536x864 (the lens is
  width-normalised: the same lens at any size).
* ``real_stadium_views``: 24 wide perspective views (hfov 60-90 deg, tilt -10..+8) of the real
  stadium panorama (``real_football/stadium_01_1k_tonemapped.jpg``: camera at pitch level, large
  stands and sky) through a known lens (k1 -0.70..-0.15, k2 on or above the manifold), 1280x720.
* ``field_views``: 12 such views of the real dry-grass field panorama (``panorama_field_2048x1024``:
  grass and a horizon, no painted lines).
* ``real_frames``: the three football360 frames (real stadium views, 640x360), six strong known
  lenses each (``distort``, ``fit="crop"``), scored against the applied lens composed with the frame's
  own reading (k1 -0.023 / +0.029 / +0.024 on the manifold, docs/eval/shots.md).
* ``procedural_high``: 8 views each of five held-out procedural stadiums seen from high tribune or
  main-stand cameras (15-49 m up), three of them at night (floodlights), hfov 55-90 deg, tilted down.
* ``offcentre`` (a diagnostic, not counted among the pitch views): 8 views each of six
  validation-split procedural stadiums the trust records do not use (high cameras as above) through
  strong lenses whose principal point is 4-8 % of the width off centre (the shared wide camera's is
  about 6.5 %), which the centred two-coefficient model cannot represent; scored against the
  centred lens a checkerboard calibration with the principal point fixed at the centre reports
  (:func:`centred_fit`, as the wide camera's lens was measured).
* negatives: ``test_patterns`` (ffmpeg testsrc2, smptehdbars, mandelbrot; true lens none),
  ``road`` (the road photo and the chessboard photo of the calibrated road camera,
  docs/eval/road_camera.json), ``blank_noise`` (a flat frame and three noise frames; lens none).

Per source: median / p90 error of ``auto`` (max displacement over the 16:9 frame, px at 1920,
:func:`glradial.lens.metrics.max_displacement_px`), share doubtful, share doubtful among the frames
whose estimate is within its bound, coverage of the stated bound, and the benefit of correcting:
each frame's error after correction with the estimate is compared with the error of leaving the
lens in (the identity lens's error, same metric). **Left uncorrected, would have helped**: doubtful
frames whose estimate is closer to the truth than the identity; **corrected, made worse**: frames
not doubtful whose estimate is farther from it than the identity (both as a share of the source's
frames).

Frames are cached in ``--frames`` (pickle; delete to rebuild), the estimator's evidence in
``--evidence`` (delete it whenever the detection, the fit or ``FrameEvidence`` change); ``--trust``
judges the cached evidence with another calibration. ``--list`` adds one row per doubtful or
made-worse frame of the pitch sources: its reason, the answer's source, stated bound, error, the
identity lens's error and the answer's own shift from no lens (:func:`frame_rows`).
"""

from __future__ import annotations

import argparse
import json
import math
import pickle
import sys
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # run from a checkout without installing
from figures import write_figure  # noqa: E402

from glradial.estimation.lens_estimate import judge  # noqa: E402
from glradial.estimation.trust import load_trust, shipped_trust  # noqa: E402
from glradial.lens.metrics import manifold_k2, max_displacement_px  # noqa: E402

WIDE_CAMERA_LENS = (-0.6615, 0.4098)
#: the football360 frames' own reading (k1 on the manifold; docs/eval/shots.md "--own")
OWN_K1 = {"football360_cam_0000000": -0.023, "football360_cam_0012000": 0.029, "football360_cam_0019000": 0.024}
#: held-out procedural stadiums with high cameras: (seed, lighting override or None)
HIGH_STADIUMS = ((179, None), (219, None), (319, None), (39, None), (389, None))
SIZE = (1280, 720)
NEGATIVE_SOURCES = ("test_patterns", "road", "blank_noise")
#: grass without a pitch (no painted lines), and lenses off the model: reported, not counted among the pitch views
NOT_PITCH_SOURCES = ("field_views", "offcentre") + NEGATIVE_SOURCES
#: the off-centre diagnostic: validation-split stadiums from this seed, views each, offset range (width units)
OFFCENTRE_SEED, OFFCENTRE_STADIUMS, OFFCENTRE_OFFSET = 48, 6, (0.04, 0.08)


def _lens_draws(n: int, seed: int, k1_range=(-0.70, -0.15)) -> list[tuple[float, float]]:
    from glradial.synthesis.crops import lens_covers_frame

    rng = np.random.default_rng(seed)
    out: list[tuple[float, float]] = []
    while len(out) < n:
        k1 = float(rng.uniform(*k1_range))
        k2 = float(manifold_k2(k1) + abs(rng.normal(0.0, 0.03)))
        if lens_covers_frame(k1, k2, SIZE):
            out.append((k1, k2))
    return out


def _views(pano: np.ndarray, n: int, seed: int, hfov, tilt, pan=(-180.0, 180.0)) -> list[tuple[np.ndarray, tuple]]:
    from glradial.synthesis.crops import CropParams, CropRenderer

    rng = np.random.default_rng(seed)
    lenses = _lens_draws(n, seed + 1)
    params = [CropParams(float(rng.uniform(*pan)), float(rng.uniform(*tilt)), float(rng.uniform(-1.5, 1.5)),
                         float(rng.uniform(*hfov)), k1, k2) for k1, k2 in lenses]
    with CropRenderer(pano, size=SIZE, supersample=2) as renderer:
        frames = renderer.render(params)[..., :3]
    return [(np.ascontiguousarray(f), (p.k1, p.k2)) for f, p in zip(frames, params)]


def _wide_camera(data: Path, n: int = 30) -> list[tuple[str, np.ndarray, tuple]]:
    import av

    wanted = set(np.linspace(0, 249, n).round().astype(int).tolist())
    out = []
    with av.open(str(data / "real_wide_camera" / "wide_pitch_camera.mp4")) as container:
        for i, frame in enumerate(container.decode(video=0)):
            if i in wanted:
                rgb = cv2.resize(frame.to_ndarray(format="rgb24"), (1536, 864), interpolation=cv2.INTER_AREA)
                out.append((f"frame{i:03d}", rgb, WIDE_CAMERA_LENS))
    return out


def _ffmpeg(source: str) -> np.ndarray:
    import subprocess

    w, h = SIZE
    raw = subprocess.run(["ffmpeg", "-v", "error", "-f", "lavfi", "-i", f"{source}=size={w}x{h}", "-frames:v", "1",
                          "-f", "rawvideo", "-pix_fmt", "rgb24", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(h, w, 3).copy()


def _real_frames(data: Path) -> list[tuple[str, np.ndarray, tuple]]:
    from glradial.evaluation.real_eval import read_rgb, self_consistent_items, self_consistent_truth

    out = []
    for j, (stem, own_k1) in enumerate(OWN_K1.items()):
        frame = read_rgb(data / "real_football" / f"{stem}.png")
        own = (own_k1, float(manifold_k2(own_k1)))
        lenses = _lens_draws(6, 300 + j, (-0.75, -0.2))
        for i, (applied, scale, distorted) in enumerate(self_consistent_items(frame, lenses)):
            out.append((f"{stem}/{i}", distorted, self_consistent_truth(applied, own, scale)))
    return out


def _procedural(n_per: int = 8) -> list[tuple[str, np.ndarray, tuple]]:
    from glradial.synthesis.stadium import stadium_panorama

    out = []
    for j, (seed, lighting) in enumerate(HIGH_STADIUMS):
        pano = stadium_panorama(seed, size=(4096, 2048), **({"lighting": lighting} if lighting else {}))
        for i, (frame, lens) in enumerate(_views(pano, n_per, 500 + j, hfov=(55.0, 90.0), tilt=(-30.0, -8.0), pan=(-40.0, 40.0))):
            out.append((f"stadium{seed}/{i}", frame, lens))
    return out


def centred_fit(lens, size: tuple[int, int] = SIZE, views: int = 12) -> tuple[float, float]:
    """The centred ``(k1, k2)`` a checkerboard calibration reports for an off-centre ``lens`` (a
    :class:`glradial.Lens` with ``cx, cy``), as the shared wide camera's was measured: OpenCV
    ``calibrateCamera`` with the principal point fixed at the centre, square pixels, no tangential
    terms, k3 = 0, on ``views`` planar 13 x 7 grids seen by a pinhole (hfov 70 deg) in poses that
    together cover the frame, their points moved by ``lens``; converted to width-normalised units
    (``k1 = k1_cv (W / f)^2``, ``k2 = k2_cv (W / f)^4``). A centred lens gives itself back."""
    import cv2

    width, height = size
    focal = width / (2.0 * math.tan(math.radians(35.0)))
    camera = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
    gx, gy = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-0.3, 0.3, 7))
    board = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1).astype(np.float32)
    rng = np.random.default_rng(3)
    objects, images = [], []
    for _ in range(views):
        rvec = rng.uniform(-0.35, 0.35, 3) * np.array([1.0, 1.0, 0.3])
        tvec = np.array([rng.uniform(-0.35, 0.35), rng.uniform(-0.2, 0.2), rng.uniform(0.9, 1.3)])
        flat = cv2.projectPoints(board, rvec, tvec, camera, None)[0].reshape(-1, 2)
        seen = lens.distort_points(flat, size)
        inside = np.all((seen >= 0) & (seen <= [width - 1, height - 1]), axis=1)
        if inside.sum() >= 20:
            objects.append(board[inside])
            images.append(seen[inside].astype(np.float32).reshape(-1, 1, 2))
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_FIX_ASPECT_RATIO
             | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3)
    _, k, dist, _, _ = cv2.calibrateCamera(objects, images, size, camera.copy(), np.zeros(5), flags=flags)
    return float(dist.ravel()[0] * (width / k[0, 0]) ** 2), float(dist.ravel()[1] * (width / k[0, 0]) ** 4)


def offcentre_views(panoramas, n_per: int = 8, rng_base: int = 900, tilt=(-30.0, -8.0),
                    pan=(-40.0, 40.0)) -> list[tuple[str, np.ndarray, tuple]]:
    """``(name, frame, centred lens)``: ``n_per`` views (hfov 55-90 deg, ``tilt``, ``pan``) of each
    ``(label, panorama)`` of ``panoramas`` through strong lenses (k1 -0.8..-0.1, k2 on or above the
    manifold) whose principal point is :data:`OFFCENTRE_OFFSET` of the width off centre, each scored
    against the centred lens a checkerboard calibration reports (:func:`centred_fit`); draws from
    ``rng_base + j`` (poses, offsets) and ``rng_base + 50 + j`` (lenses) for the ``j``-th panorama."""
    from glradial import distort
    from glradial.lens.lens import Lens
    from glradial.synthesis.crops import CropParams, CropRenderer

    out = []
    for j, (label, pano) in enumerate(panoramas):
        rng = np.random.default_rng(rng_base + j)
        lenses = []
        for k1, k2 in _lens_draws(n_per, rng_base + 50 + j, (-0.8, -0.1)):
            radius, angle = rng.uniform(*OFFCENTRE_OFFSET), rng.uniform(0.0, 2.0 * math.pi)
            lenses.append(Lens(k1, k2, float(radius * math.cos(angle)), float(radius * math.sin(angle))))
        params = [CropParams(float(rng.uniform(*pan)), float(rng.uniform(*tilt)), float(rng.uniform(-1.5, 1.5)),
                             float(rng.uniform(55.0, 90.0)), 0.0, 0.0) for _ in lenses]
        with CropRenderer(pano, size=SIZE, supersample=2) as renderer:
            frames = renderer.render(params)[..., :3]
        for i, (lens, frame) in enumerate(zip(lenses, frames)):
            out.append((f"{label}/{i}", distort(np.ascontiguousarray(frame), lens, fit="crop"), centred_fit(lens)))
    return out


def stadiums(seeds) -> Iterator[tuple[str, np.ndarray]]:
    """``(label, panorama)`` of the procedural stadiums ``seeds`` (4096 x 2048), one at a time."""
    from glradial.synthesis.stadium import stadium_panorama

    return ((f"stadium{seed}", stadium_panorama(seed, size=(4096, 2048))) for seed in seeds)


def _offcentre(n_per: int = 8) -> list[tuple[str, np.ndarray, tuple]]:
    from glradial.synthesis.stadium_style import split_seeds

    return offcentre_views(stadiums(split_seeds("val", OFFCENTRE_STADIUMS, start=OFFCENTRE_SEED)), n_per)


def builders(data: Path) -> dict:
    """Every source's builder: a callable giving its ``(name, uint8 RGB frame, true lens or None)``."""
    from glradial.evaluation.real_eval import load_calibrated, read_rgb

    def negatives(kind: str):
        if kind == "test_patterns":
            return [(s, _ffmpeg(s), (0.0, 0.0)) for s in ("testsrc2", "smptehdbars", "mandelbrot")]
        if kind == "road":
            _, road_frames, road_lens = load_calibrated(ROOT / "docs" / "eval" / "road_camera.json")
            return [(f"road{i}", f, (road_lens.k1, road_lens.k2)) for i, f in enumerate(road_frames)]
        rng = np.random.default_rng(7)
        return [("blank", np.full((SIZE[1], SIZE[0], 3), 90, np.uint8), (0.0, 0.0))] + [
            (f"noise{i}", rng.integers(0, 256, (SIZE[1], SIZE[0], 3), dtype=np.uint8), (0.0, 0.0)) for i in range(3)]

    def panorama_views(name: str, n: int, seed: int, tilt: tuple[float, float]):
        pano = read_rgb(data / name)
        return [(f"view{i}", f, k) for i, (f, k) in enumerate(_views(pano, n, seed, hfov=(60.0, 90.0), tilt=tilt))]

    return {
        "wide_camera": lambda: _wide_camera(data),
        "real_stadium_views": lambda: panorama_views("real_football/stadium_01_1k_tonemapped.jpg", 24, 100, (-10.0, 8.0)),
        "field_views": lambda: panorama_views("panorama_field_2048x1024.jpg", 12, 200, (-12.0, 5.0)),
        "real_frames": lambda: _real_frames(data),
        "procedural_high": _procedural,
        "offcentre": _offcentre,
        **{kind: (lambda kind=kind: negatives(kind)) for kind in NEGATIVE_SOURCES},
    }


def build(data: Path, frames: dict | None = None) -> dict[str, list[tuple[str, np.ndarray, tuple | None]]]:
    """Every source's ``(name, uint8 RGB frame, true lens or None)``; sources already in ``frames``
    (a cache) are kept as they are."""
    frames = dict(frames or {})
    for source, make in builders(data).items():
        if source not in frames:
            frames[source] = make()
    return frames


def _cached(path: Path | None, make):
    if path is not None and path.exists():
        with open(path, "rb") as f:
            return pickle.load(f)
    value = make()
    if path is not None:
        with open(path, "wb") as f:
            pickle.dump(value, f)
    return value


def collect(frames: dict, sources: list[str]) -> dict:
    """The :class:`~glradial.estimation.trust.FrameEvidence` of every frame (one CNN session)."""
    from glradial.estimation.net_lines import NetLinesEstimator

    estimator = NetLinesEstimator(threads=1)
    out = {}
    for source in sources:
        out[source] = [(name, estimator.evidence_batch([frame])[0], truth) for name, frame, truth in frames[source]]
        print(f"  {source}: {len(out[source])} frames", file=sys.stderr)
    return out


def frame_rows(items: list, trust) -> list[dict]:
    """One row per ``(name, evidence, true lens)`` of ``items`` judged by ``auto`` under ``trust``:
    name, reason, the answer's source (``lines``/``net``), stated bound, error, the identity lens's
    error (leaving the lens in), the answer's own shift from no lens (px at 1920, the maximum
    displacement), doubtful, and the verdict: ``left, would help`` (doubtful, error below the
    identity's), ``corrected, worse`` (not doubtful, error above it), ``left`` or ``corrected``."""
    from glradial.estimation.trust import shift_px

    rows = []
    for name, ev, truth in items:
        e = judge(ev, "auto", trust)
        k = np.array(truth, np.float64)
        err = float(max_displacement_px(np.array([e.k1, e.k2]), k))
        ident = float(max_displacement_px(np.zeros(2), k))
        verdict = ("left, would help" if err < ident else "left") if e.doubtful else (
            "corrected, worse" if err > ident else "corrected")
        rows.append({"name": name, "reason": e.reason, "source": e.method, "bound": e.uncertainty_px, "error": err,
                     "identity": ident, "shift": shift_px((e.k1, e.k2)), "doubtful": e.doubtful, "verdict": verdict})
    return rows


def score(evidence: dict, trust) -> dict:
    """Per source and over the pitch sources: the figures of the module docstring."""
    rows = {}
    for source, items in evidence.items():
        per = frame_rows(items, trust)
        rows[source] = _figures(*(np.array([r[key] for r in per]) for key in ("error", "identity", "bound", "doubtful")),
                                [r["reason"] for r in per])
    pitch = [s for s in evidence if s not in NOT_PITCH_SOURCES]
    if pitch:
        rows["all pitch views"] = _merge([rows[s] for s in pitch])
    return rows


def listing(evidence: dict, trust) -> str:
    """Markdown of every doubtful or made-worse frame of the pitch sources (``--list``)."""
    lines = ["| source | frame | reason | answer | stated bound px | error px | no lens px | answer's shift px | verdict |",
             "| --- | --- | --- | --- | ---: | ---: | ---: | ---: | --- |"]
    for source, items in evidence.items():
        if source in NOT_PITCH_SOURCES:
            continue
        for r in frame_rows(items, trust):
            if r["doubtful"] or r["verdict"] == "corrected, worse":
                lines.append(f"| {source} | {r['name']} | {r['reason']} | {r['source']} | {r['bound']:.1f} | {r['error']:.1f} | "
                             f"{r['identity']:.1f} | {r['shift']:.1f} | {r['verdict']} |")
    return "\n".join(lines)


def _figures(err, ident, bound, doubt, reasons) -> dict:
    inside = err <= bound
    return {"n": len(err), "median": float(np.median(err)), "p90": float(np.percentile(err, 90)),
            "identity_median": float(np.median(ident)), "doubtful": float(doubt.mean()),
            "doubtful_within_bound": float(doubt[inside].mean()) if inside.any() else math.nan,
            "coverage": float(inside.mean()), "median_bound": float(np.median(bound)),
            "left_would_help": float((doubt & (err < ident)).mean()),
            "corrected_worse": float((~doubt & (err > ident)).mean()),
            "reasons": {r: reasons.count(r) for r in sorted(set(reasons))},
            "_raw": (err.tolist(), ident.tolist(), bound.tolist(), doubt.tolist(), reasons)}


def _merge(rows: list[dict]) -> dict:
    parts = [np.concatenate([np.asarray(r["_raw"][i]) for r in rows]) for i in range(4)]
    reasons = sum((list(r["_raw"][4]) for r in rows), [])
    return _figures(parts[0], parts[1], parts[2], parts[3].astype(bool), reasons)


def markdown(rows: dict) -> str:
    head = ("| source | n | median / p90 px | no lens px (median) | doubtful | doubtful within bound | coverage "
            "| median bound px | left, would help | corrected, worse | reasons |\n" + "| --- |" + " ---: |" * 9 + " --- |")
    lines = [head]
    for source, r in rows.items():
        reasons = ", ".join(f"{k} {v}" for k, v in r["reasons"].items())
        lines.append(f"| {source} | {r['n']} | {r['median']:.1f} / {r['p90']:.1f} | {r['identity_median']:.0f} | "
                     f"{100 * r['doubtful']:.0f} % | {100 * r['doubtful_within_bound']:.0f} % | {100 * r['coverage']:.0f} % | "
                     f"{r['median_bound']:.1f} | {100 * r['left_would_help']:.0f} % | {100 * r['corrected_worse']:.0f} % | {reasons} |")
    return "\n".join(lines)


def cache_options(parser: argparse.ArgumentParser, frames: str, evidence: str | None = None) -> None:
    """The options of a bench over cached frames and evidence: ``--data`` (the shared data), ``--frames``
    and ``--evidence`` (pickles, defaults ``frames`` and ``evidence``), ``--trust`` (another calibration)."""
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    parser.add_argument("--frames", type=Path, default=Path(frames))
    parser.add_argument("--evidence", type=Path, default=Path(evidence) if evidence else None,
                        help="the estimator's evidence (delete it whenever the fit or FrameEvidence change)")
    parser.add_argument("--trust", type=Path, default=None, help="judge with this calibration (default: the shipped one)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    cache_options(parser, "/tmp/pitch_views_frames.pkl")
    parser.add_argument("--sources", default="")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--list", action="store_true",
                        help="also list every doubtful or made-worse frame of the pitch sources (reason, bound, error)")
    args = parser.parse_args(argv)
    cached = _cached(args.frames, lambda: build(args.data))
    frames = build(args.data, cached)
    if args.frames is not None and len(frames) > len(cached):  # a source added since the cache was made
        with open(args.frames, "wb") as f:
            pickle.dump(frames, f)
    sources = [s for s in args.sources.split(",") if s] or list(frames)
    evidence = _cached(args.evidence, lambda: collect(frames, sources))
    missing = [s for s in sources if s not in evidence]
    if missing:
        evidence.update(collect(frames, missing))
        if args.evidence is not None:
            with open(args.evidence, "wb") as f:
                pickle.dump(evidence, f)
    evidence = {s: evidence[s] for s in sources if s in evidence}
    trust = load_trust(args.trust) if args.trust else shipped_trust()
    rows = score(evidence, trust)
    print(markdown(rows))
    write_figure("pitch_views", {s: {k: v for k, v in r.items() if k != "_raw"} for s, r in rows.items()})
    if args.list:
        print("\n" + listing(evidence, trust))
    if args.json:
        args.json.write_text(json.dumps({s: {k: v for k, v in r.items() if k != "_raw"} for s, r in rows.items()}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
