"""Evaluate the estimators (net, lines, auto) on real frames with known lenses, side by side (no torch).

Sources (each reported separately):
    * **Real frames** (a folder of (nearly) undistorted 16:9 photographs or broadcast frames): each
      frame (centre-cropped to 16:9 if needed) is distorted with known lenses by
      :func:`glradial.distort` (exact inverse) at ``fit="crop"``: the output is still a full 16:9
      frame (no empty corners, which would add a curved border that no real frame has) and the lens
      refers to it, since a fit only zooms the undistorted source (:meth:`glradial.Lens.fit_scale`).
      Lenses come from the paper's distribution (:func:`glradial.synthesis.crops.sample_crop_params`, source
      ``NAME/paper``) and from the extended range (``NAME/extended``: k1 in [-1.0, 0.4], k2 on or
      above the manifold by ``|N(0, 0.05)|``, as real wide pitch cameras are).
    * **Real panoramas** (2:1 images in the folder): crops rendered by :class:`glradial.CropRenderer`
      with known :class:`glradial.CropParams`, paper and extended lenses (poses: pan as the paper,
      tilt :data:`PANORAMA_TILT`, field of view :data:`PANORAMA_HFOV`).
    * **Calibrated cameras** (``--calibrated FILE.json``): frames with a lens measured independently,
      ``{"name": ..., "frames": [paths], "k1": ..., "k2": ...}`` or OpenCV's ``"camera_matrix"``,
      ``"dist_coeffs"`` and ``"size"`` instead of k1, k2 (converted with
      :meth:`glradial.Lens.from_opencv`, ``approximate=True``); paths relative to the JSON file.
    * **Procedural** (``procedural=N``): crops of held-out stadiums (``split_seeds("test")``).

Metrics (:mod:`glradial.lens.metrics`): median and 90th percentile of the maximum displacement error
over the 16:9 frame (px at 1920), A-beats-B (the method's own k2 against the manifold k2 for its
k1, compared by distortion loss; ties count as not beating), the share of errors inside the stated
``uncertainty_px`` and, for auto, the share of frames where it chose the lines.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..errors import Error, check_count
from ..estimation.lens_estimate import LensEstimate, judge
from ..estimation.net_lines import view_box
from ..estimation.trust import FrameEvidence
from ..lens.lens import Lens
from ..lens.metrics import CORNER_RADIUS_16_9, PAPER_SIZE, manifold_k2, max_displacement_px
from .evaluation import a_beats_b

METHOD_NAMES = ("net", "lines", "auto")
#: Extended range of real lenses: k1 bounds, and the spread of k2 above the manifold.
EXTENDED_K1 = (-1.0, 0.4)
EXTENDED_K2_SPREAD = 0.05
#: Poses of crops from a real panorama: its camera stands at pitch level (stadium_01), so the view is
#: tilted about the horizon to show the boards and stands (the paper's downward tilt shows only
#: grass there), and a 1024-wide panorama has too few pixels for fields of view under 45 degrees.
PANORAMA_TILT = (-10.0, 10.0)
PANORAMA_HFOV = (45.0, 60.0)
#: A frame carries its own lens when the line fit reads its unmodified frame farther from no lens
#: than this (px at 1920; the CNN's 90 % error on procedural validation crops, docs/LINES.md) and
#: than the fit's own bound. The CNN's reading is not used for this: its pincushion on close-ups is
#: a known failure (issue 17).
OWN_LENS_PX = 16.0
#: Size the squashed 640×640 broadcast frames are restored to (their README: they were 16:9).
BROADCAST_SIZE = (1280, 720)


def agreed_own_lens(estimates: dict[str, LensEstimate]) -> Lens | None:
    """The frame's own lens when two independent readings agree on one: the line fit (on lines) and
    the CNN (on texture) both read the unmodified frame more than :data:`OWN_LENS_PX` from no lens,
    and closer to each other than the CNN's own bound. Then the line fit's lens (the surer one);
    else ``None``. Used by ``remove_own_lens`` to make such a frame undistorted before applying
    known lenses: the figures then measure the estimators, not the broadcast camera's lens."""
    lines, net = estimates["lines"], estimates["net"]
    if lines.method != "lines" or min(_from_no_lens(lines), _from_no_lens(net)) <= OWN_LENS_PX:
        return None
    apart = float(max_displacement_px(np.array([lines.k1, lines.k2]), np.array([net.k1, net.k2])))
    return Lens(lines.k1, lines.k2) if apart <= net.uncertainty_px else None
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")


@dataclass
class Sample:
    """One evaluated frame: its source, true lens and the three methods' estimates; for a
    self-consistent source (a frame whose own lens is unknown) ``truth`` is the applied lens and
    ``truths`` the applied lens composed with each method's reading of the unmodified frame
    (:func:`self_consistent_truth`), which the errors are measured against."""

    source: str
    truth: tuple[float, float]
    estimates: dict = field(default_factory=dict)
    truths: dict | None = None

    def truth_for(self, method: str) -> tuple[float, float]:
        """The lens ``method``'s answer is scored against."""
        return self.truths[method] if self.truths else self.truth


def self_consistent_map(r: np.ndarray, applied: tuple[float, float], own: tuple[float, float], scale: float) -> np.ndarray:
    """Distorted radius (lens units) of the ideal radius ``r`` in a frame whose own lens ``own`` (as
    read by a method) was followed by ``distort(frame, applied, fit=scale)``: ``q = P_A(s P_own(r / s))``,
    i.e. ``P_A ∘ P_own'`` with ``own' = Lens(own).rescale(s)`` (the fit zooms the source). Not a
    two-coefficient lens in general: score an answer ``k`` exactly by ``max |P(r, k) - q(r)|``."""
    from ..lens.metrics import radial_map

    inner = Lens(*own).rescale(scale)
    return radial_map(radial_map(r, np.array([inner.k1, inner.k2])), np.array(applied, np.float64))


@lru_cache(maxsize=65536)
def self_consistent_truth(applied: tuple[float, float], own: tuple[float, float], scale: float) -> tuple[float, float]:
    """The ``(k1, k2)`` nearest to :func:`self_consistent_map` in the headline metric: the minimax
    (Chebyshev) fit of the displacement over the 16:9 radius (the radii of
    :func:`glradial.lens.metrics.max_displacement`), so an answer's error against it differs from its
    exact error against the composite by at most the fit's own residual (a least-squares refit, used
    before, moved the Bundesliga median by 0.2 px and single samples by up to 2 px; docs/LINES.md)."""
    from scipy.optimize import linprog

    from ..lens.metrics import DISPLACEMENT_SAMPLES

    r = np.linspace(0.0, CORNER_RADIUS_16_9, DISPLACEMENT_SAMPLES)[1:]
    target = self_consistent_map(r, tuple(applied), tuple(own), float(scale)) - r
    basis = np.stack([r**3, r**5, -np.ones_like(r)], axis=1)  # |basis[:, :2] k - target| <= t
    bounds = np.concatenate([basis, -basis * [1, 1, -1]]), np.concatenate([target, -target])
    result = linprog([0.0, 0.0, 1.0], A_ub=bounds[0], b_ub=bounds[1], bounds=[(None, None)] * 3, method="highs")
    if not result.success:
        raise Error(f"minimax refit failed for applied={applied}, own={own}, scale={scale}: {result.message}")
    return float(result.x[0]), float(result.x[1])


def read_broadcast(path: str | Path) -> np.ndarray:
    """A squashed square broadcast frame file -> uint8 RGB restored to :data:`BROADCAST_SIZE`
    (bicubic, as its README says)."""
    import cv2

    return np.ascontiguousarray(cv2.resize(read_rgb(path), BROADCAST_SIZE, interpolation=cv2.INTER_CUBIC))


def centre_16_9(frame: np.ndarray) -> np.ndarray:
    """The frame's centred 16:9 view, the one the network sees
    (:func:`glradial.estimation.net_lines.view_box`; the whole frame if within 1 % of 16:9)."""
    x0, y0, w, h = view_box((frame.shape[1], frame.shape[0]))
    if (w, h) == (frame.shape[1], frame.shape[0]):
        return frame
    return np.ascontiguousarray(frame[y0:y0 + h, x0:x0 + w])


def extended_lenses(n: int, seed: int, size: tuple[int, int] = PAPER_SIZE) -> list[tuple[float, float]]:
    """``n`` lenses with k1 ~ U(EXTENDED_K1), k2 = manifold + |N(0, EXTENDED_K2_SPREAD)|, valid on ``size``."""
    from ..synthesis.crops import lens_covers_frame

    rng = np.random.default_rng(seed)
    out: list[tuple[float, float]] = []
    while len(out) < n:
        k1 = float(rng.uniform(*EXTENDED_K1))
        k2 = float(manifold_k2(k1) + abs(rng.normal(0.0, EXTENDED_K2_SPREAD)))
        if lens_covers_frame(k1, k2, size):
            out.append((k1, k2))
    return out


def paper_lenses(n: int, seed: int) -> list[tuple[float, float]]:
    """``n`` lenses of the paper's distribution (:func:`glradial.synthesis.crops.sample_crop_params`)."""
    from ..synthesis.crops import sample_crop_params

    return [(p.k1, p.k2) for p in sample_crop_params(n, seed)]


def read_rgb(path: str | Path) -> np.ndarray:
    """An 8-bit image file -> uint8 RGB; ``ValueError`` naming the path if unreadable."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"cannot read image {path}")
    return np.ascontiguousarray(image[:, :, ::-1])


def frames_in(folder: str | Path) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """The 8-bit images of ``folder``: ``(frames, panoramas)`` as ``(name, RGB)`` lists; images
    with a 2:1 aspect ratio are taken as equirectangular panoramas. ``ValueError`` if none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"frames folder not found: {folder}")
    frames, panoramas = [], []
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        image = read_rgb(path)
        height, width = image.shape[:2]
        if abs(width / height - 2.0) < 0.01:
            panoramas.append((path.stem, image))
        else:
            frames.append((path.stem, centre_16_9(image)))
    if not frames and not panoramas:
        raise ValueError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    return frames, panoramas


def load_calibrated(path: str | Path) -> tuple[str, list[np.ndarray], Lens]:
    """A calibrated-camera JSON (see the module docstring) -> ``(name, frames, lens)``."""
    path = Path(path)
    try:
        spec = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"calibrated camera file {path}: {err}") from None
    if not isinstance(spec, dict) or not spec.get("frames"):
        raise ValueError(f"calibrated camera file {path} must hold an object with a non-empty 'frames' list")
    frames = [read_rgb(path.parent / f) for f in spec["frames"]]
    if "k1" in spec:
        lens = Lens(spec["k1"], spec.get("k2", 0.0))
    elif "camera_matrix" in spec:
        size = tuple(spec.get("size") or frames[0].shape[1::-1])
        lens = Lens.from_opencv(spec["camera_matrix"], spec["dist_coeffs"], size, approximate=True)
    else:
        raise ValueError(f"calibrated camera file {path} needs 'k1'/'k2' or 'camera_matrix'/'dist_coeffs'")
    for i, frame in enumerate(frames):
        height, width = frame.shape[:2]
        if view_box((width, height)) != (0, 0, width, height):  # not taken whole as the 16:9 view
            raise ValueError(f"calibrated frame {spec['frames'][i]} is {width}×{height}, not 16:9 (the lens refers to the whole frame)")
    return str(spec.get("name", path.stem)), frames, lens


class Evaluator:
    """Runs the three methods on frames; one CNN session (``threads`` as :class:`glradial.Estimator`)."""

    def __init__(self, model: str | None = None, threads: int | None = None) -> None:
        from ..estimation.net_lines import NetLinesEstimator

        self.estimator = NetLinesEstimator(model, threads=threads)

    def evidence(self, frame: np.ndarray) -> FrameEvidence:
        """The frame's :class:`glradial.estimation.trust.FrameEvidence` (CNN and line fit)."""
        return self.estimator.evidence_batch([frame])[0]

    def __call__(self, frame: np.ndarray) -> dict:
        evidence = self.evidence(frame)
        return {method: judge(evidence, method) for method in METHOD_NAMES}


def _distorted(frame: np.ndarray, lenses: Iterable[tuple[float, float]]):
    from ..remapping.remap import distort

    for k1, k2 in lenses:
        yield (k1, k2), distort(frame, k1, k2, fit="crop", backend="cpu")


def panorama_crops(panorama: np.ndarray, lenses: list[tuple[float, float]], seed: int):
    """``((k1, k2), frame)`` for each lens of ``lenses``: a :data:`PAPER_SIZE` crop of ``panorama`` (RGB
    uint8, 2x supersampled) at a pose drawn from ``seed`` with :data:`PANORAMA_HFOV` and
    :data:`PANORAMA_TILT`, distorted by that lens."""
    from ..synthesis.crops import CropParams, CropRenderer, sample_crop_params

    poses = sample_crop_params(len(lenses), seed, hfov=PANORAMA_HFOV, tilt=PANORAMA_TILT)
    params = [CropParams(p.pan, p.tilt, p.roll, p.hfov, k1, k2) for p, (k1, k2) in zip(poses, lenses)]
    with CropRenderer(panorama, size=PAPER_SIZE, supersample=2) as renderer:
        frames = renderer.render(params)[..., :3]
    for p, frame in zip(params, frames):
        yield (p.k1, p.k2), np.ascontiguousarray(frame)


def procedural_frames(n: int, panoramas: int = 4, split: str = "test", seed: int = 0, size: tuple[int, int] = (4096, 2048)):
    """``n`` crops (paper distribution) of ``panoramas`` held-out procedural stadiums -> ``(lens, frame)``."""
    from ..synthesis.crops import CropRenderer, sample_crop_params
    from ..synthesis.stadium import stadium_panorama
    from ..synthesis.stadium_style import split_seeds

    per = [n // panoramas + (i < n % panoramas) for i in range(panoramas)]
    for j, (stadium, count) in enumerate(zip(split_seeds(split, panoramas), per)):
        if count == 0:
            continue
        params = sample_crop_params(count, 7919 * (seed + 1) + j)
        with CropRenderer(stadium_panorama(stadium, size), size=PAPER_SIZE) as renderer:
            frames = renderer.render(params)[..., :3]
        for p, frame in zip(params, frames):
            yield (p.k1, p.k2), np.ascontiguousarray(frame)


def broadcast_frames(folder: str | Path) -> dict[str, list[tuple[str, np.ndarray]]]:
    """The broadcast frames of ``folder`` (files ``CLIP_SEGMENT_FRAME.jpg``, squashed) by clip id,
    each restored to :data:`BROADCAST_SIZE` (:func:`read_broadcast`)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise ValueError(f"broadcast folder not found: {folder}")
    clips: dict[str, list[tuple[str, np.ndarray]]] = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES:
            clips.setdefault(path.stem.split("_")[0], []).append((path.stem, read_broadcast(path)))
    if not clips:
        raise ValueError(f"no images ({', '.join(IMAGE_SUFFIXES)}) in {folder}")
    return clips


def applied_lenses(n: int, seed: int) -> list[tuple[float, float]]:
    """``n`` known lenses to apply to a frame: alternately the paper's distribution and the
    extended range (:func:`paper_lenses`, :func:`extended_lenses`)."""
    paper, extended = paper_lenses(n, seed), extended_lenses(n, seed + 1)
    return [paper[i] if i % 2 == 0 else extended[i] for i in range(n)]


def self_consistent_items(frame: np.ndarray, lenses: Iterable[tuple[float, float]]
                          ) -> Iterator[tuple[tuple[float, float], float, np.ndarray]]:
    """``(applied, scale, distorted frame)`` for each applied lens (``distort`` at ``fit="crop"``,
    ``scale`` its fit scale): a method's reading ``own`` of the unmodified frame makes its truth
    ``self_consistent_truth(applied, own, scale)``, the one scoring of frames whose lens is unknown."""
    size = (frame.shape[1], frame.shape[0])
    for applied, distorted in _distorted(frame, lenses):
        yield applied, Lens(*applied).fit_scale(size, "crop", "distort"), distorted


def broadcast_samples(evaluator: "Evaluator", folder: str | Path, lenses: int = 3, seed: int = 0,
                      progress: Callable[[str], None] | None = None) -> list[Sample]:
    """Self-consistent samples (source ``broadcast/CLIP``) of the broadcast frames of ``folder``:
    ``lenses`` known lenses (:func:`applied_lenses`) per frame, each scored against the applied lens
    composed with the same method's reading of the unmodified frame."""
    samples: list[Sample] = []
    for clip, frames in broadcast_frames(folder).items():
        for i, (_name, frame) in enumerate(frames):
            own = evaluator(frame)
            for applied, scale, distorted in self_consistent_items(frame, applied_lenses(lenses, seed * 1000 + i)):
                truths = {m: self_consistent_truth(applied, (e.k1, e.k2), scale) for m, e in own.items()}
                samples.append(Sample(f"broadcast/{clip}", applied, evaluator(distorted), truths))
        if progress is not None:
            progress(f"broadcast/{clip}: {len(frames)} frames × {lenses} lenses")
    return samples


def run_sources(evaluator: Callable[[np.ndarray], dict], sources: dict[str, Iterable], progress: Callable[[str], None] | None = None) -> list[Sample]:
    """Evaluate every ``(lens, frame)`` of each named source."""
    samples: list[Sample] = []
    for name, items in sources.items():
        count = 0
        for truth, frame in items:
            samples.append(Sample(name, (float(truth[0]), float(truth[1])), evaluator(frame)))
            count += 1
        if progress is not None:
            progress(f"{name}: {count} frames")
    return samples


def summarise(samples: list[Sample], own_lens: set[str] = frozenset()) -> dict:
    """Per source (and ``all real`` = every non-procedural source) and method: n, median, p90,
    A beats B, share inside the stated bound, share of lines answers. ``own_lens``: frame names
    whose unmodified frame carries its own lens; with any, ``all real without own-lens frames``
    is added (sources ``NAME/...`` of those frames left out)."""
    groups: dict[str, list[Sample]] = {}
    for s in samples:
        groups.setdefault(s.source, []).append(s)
    real = [s for s in samples if not s.source.startswith("procedural")]
    if real and len(groups) > 1:
        groups["all real"] = real
        if own_lens:
            groups["all real without own-lens frames"] = [s for s in real if s.source.split("/")[0] not in own_lens]
    out: dict = {}
    for name, group in groups.items():
        out[name] = {}
        for method in METHOD_NAMES:
            truth = np.array([s.truth_for(method) for s in group])
            est = [s.estimates[method] for s in group]
            pred = np.array([(e.k1, e.k2) for e in est])
            err = max_displacement_px(pred, truth)
            bound = np.array([e.uncertainty_px for e in est])
            out[name][method] = {
                "n": len(group),
                "median_px": float(np.median(err)),
                "p90_px": float(np.percentile(err, 90)),
                "a_beats_b": a_beats_b(pred, truth),
                "inside_bound": float(np.mean(err <= bound)),
                "lines_share": float(np.mean([e.method == "lines" for e in est])),
                "doubtful": float(np.mean([e.doubtful for e in est])),
            }
    return out


def markdown(summary: dict, title: str, notes: str = "") -> str:
    """The summary as a Markdown table (one row per source and method)."""
    lines = [f"# {title}", "", notes, "",
             "| source | method | n | median px | p90 px | A beats B | inside bound | lines | doubtful |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, methods in summary.items():
        for method, m in methods.items():
            lines.append(f"| {name} | {method} | {m['n']} | {m['median_px']:.2f} | {m['p90_px']:.2f} | "
                         f"{100 * m['a_beats_b']:.1f} % | {100 * m['inside_bound']:.1f} % | {100 * m['lines_share']:.0f} % | "
                         f"{100 * m.get('doubtful', 0.0):.0f} % |")
    return "\n".join(lines) + "\n"


def plot(samples: list[Sample], out: Path, stem: str) -> list[str]:
    """Error distributions per source and method (PNG, if matplotlib is installed)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    from ..media.atomic import atomic_path

    sources = sorted({s.source for s in samples})
    cols = min(4, len(sources))
    rows = -(-len(sources) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.0 * rows), squeeze=False)
    for ax in axes.ravel()[len(sources):]:
        ax.set_visible(False)
    for ax, source in zip(axes.ravel(), sources):
        group = [s for s in samples if s.source == source]
        for method in METHOD_NAMES:
            truth = np.array([s.truth_for(method) for s in group])
            pred = np.array([(s.estimates[method].k1, s.estimates[method].k2) for s in group])
            err = np.sort(max_displacement_px(pred, truth))
            ax.plot(err, np.arange(1, len(err) + 1) / len(err), label=method)
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_title(source, fontsize=8)
        ax.set_xlabel("max displacement error, px at 1920")
        ax.grid(alpha=0.3)
    for row in axes:
        row[0].set_ylabel("share of frames")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    path = out / f"{stem}_errors.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
    return [path.name]


def _from_no_lens(estimate: LensEstimate) -> float:
    """Maximum displacement (px at 1920) of an estimate from no lens."""
    return float(max_displacement_px(np.array([estimate.k1, estimate.k2]), np.zeros(2)))


def evaluate_folder(frames_dir: str | Path | None, out: str | Path, *, calibrated: list[str] = (), lenses: int = 12,
                    procedural: int = 0, model: str | None = None, threads: int | None = None, seed: int = 0,
                    progress: Callable[[str], None] | None = print, remove_own_lens: bool = False,
                    broadcast: str | Path | None = None) -> dict:
    """Build the sources (see the module docstring), evaluate, and write ``real.md``,
    ``real_metrics.json`` and ``real_errors.png`` into ``out``. Returns the summary.
    ``remove_own_lens``: a frame whose own lens the line fit and the CNN agree on
    (:func:`agreed_own_lens`) is first corrected with it (``fit="crop"``). ``broadcast``: a folder of
    squashed broadcast frames scored self-consistently per clip (:func:`broadcast_samples`)."""
    from ..media.atomic import atomic_write_text

    check_count("lenses", lenses)
    check_count("procedural", procedural, minimum=0)
    cams = [load_calibrated(c) for c in calibrated]
    sources: dict[str, Iterable] = {}
    own: dict[str, dict] = {}
    removed: dict[str, Lens] = {}
    evaluator = None
    if frames_dir is not None:
        evaluator = folder_sources(frames_dir, model, threads, lenses, seed, remove_own_lens, sources, own, removed)
    for name, cam_frames, lens in cams:
        sources[f"calibrated/{name}"] = (((lens.k1, lens.k2), f) for f in cam_frames)
    if procedural:
        sources["procedural/test"] = procedural_frames(procedural, seed=seed)
    if not sources and broadcast is None:
        raise ValueError("nothing to evaluate: give a frames folder, a broadcast folder, a calibrated camera or procedural > 0")
    evaluator = evaluator or Evaluator(model, threads)
    samples = run_sources(evaluator, sources, progress)
    if broadcast is not None:
        samples += broadcast_samples(evaluator, broadcast, seed=seed, progress=progress)
    own_lens = {name for name, est in own.items() if name not in removed
                and est["lines"].method == "lines" and _from_no_lens(est["lines"]) > max(OWN_LENS_PX, est["lines"].uncertainty_px)}
    summary = summarise(samples, own_lens)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures = plot(samples, out, "real")
    notes = (f"Frames: {frames_dir}; {lenses} paper and {lenses} extended lenses per frame (fit='crop'), "
             f"{4 * lenses} + {4 * lenses} crops per panorama; calibrated: {', '.join(c[0] for c in cams) or 'none'}; "
             f"procedural test crops: {procedural}; broadcast clips: {broadcast or 'none'} (self-consistent: each "
             "method scored against the applied lens composed with its own reading of the unmodified frame). Errors: "
             "max displacement over the 16:9 frame, px at 1920.")
    text = markdown(summary, "Lens estimation on real frames: net, lines, auto", notes)
    text += _own_lens_text(own, removed, own_lens)
    text += "".join(f"\n![{f}]({f})\n" for f in figures)
    atomic_write_text(out / "real.md", text)
    own_json = {name: {m: e.as_dict() for m, e in est.items()} for name, est in own.items()}
    removed_json = {name: {"k1": lens.k1, "k2": lens.k2} for name, lens in removed.items()}
    atomic_write_text(out / "real_metrics.json",
                      json.dumps({"summary": summary, "own_lens": own_json, "own_lens_removed": removed_json}, indent=1))
    return summary


def folder_sources(frames_dir: str | Path, model: str | None, threads: int | None, lenses: int, seed: int,
                   remove_own_lens: bool, sources: dict[str, Iterable], own: dict[str, dict],
                   removed: dict[str, Lens]) -> Evaluator:
    """The sources of a frames folder (each frame with paper and extended lenses applied, crops of
    each panorama) into ``sources``; each frame's own estimates into ``own``, the own lenses
    removed first into ``removed``. Returns the evaluator it loaded."""
    from ..remapping.remap import correct

    frames, panoramas = frames_in(frames_dir)
    evaluator = Evaluator(model, threads)
    for i, (name, f) in enumerate(frames):
        own[name] = evaluator(f)
        found = agreed_own_lens(own[name]) if remove_own_lens else None
        if found is not None:
            removed[name] = found
            f = correct(f, found, fit="crop")
        sources[f"{name}/paper"] = _distorted(f, paper_lenses(lenses, seed * 1000 + i))
        sources[f"{name}/extended"] = _distorted(f, extended_lenses(lenses, seed * 1000 + 500 + i))
    for i, (name, pano) in enumerate(panoramas):
        count = 4 * lenses
        sources[f"{name}/paper"] = panorama_crops(pano, paper_lenses(count, seed * 1000 + 100 + i), seed + 1)
        sources[f"{name}/extended"] = panorama_crops(pano, extended_lenses(count, seed * 1000 + 600 + i), seed + 2)
    return evaluator


def _own_lens_text(own: dict[str, dict], removed: dict[str, Lens], own_lens: set[str]) -> str:
    """The report's section on each frame's own distortion ("" without frames)."""
    text = ""
    if own:
        text += ("\n## Each frame's own distortion (the floor of its figures)\n\nWhat each method reads on the "
                 "unmodified frame, and its maximum displacement from no lens (px at 1920): a frame that is not "
                 "undistorted adds about this much to every error above, since its reference lens is only the one applied.\n\n"
                 "| frame | method | k1 | k2 | displacement px | bound px | chains |\n| --- | --- | ---: | ---: | ---: | ---: | ---: |\n")
        for name, estimates in own.items():
            for method, e in estimates.items():
                text += (f"| {name} | {method} ({e.method}) | {e.k1:+.3f} | {e.k2:+.3f} | {_from_no_lens(e):.1f} | "
                         f"{e.uncertainty_px:.1f} | {e.chains} |\n")
        if removed:
            text += ("\nOwn lens removed before the known lenses were applied (the line fit and the CNN agree "
                     f"within the CNN's bound, both more than {OWN_LENS_PX:g} px from no lens; `--remove-own-lens`): "
                     + ", ".join(f"{n} (k1 {lens.k1:+.3f}, k2 {lens.k2:+.3f})" for n, lens in sorted(removed.items()))
                     + ". The line fit then reads these frames as straight by construction; the CNN's reading is "
                     "the independent check.\n")
        if own_lens:
            text += (f"\nRead as carrying their own lens (the line fit reads more than {OWN_LENS_PX:g} px and more than its "
                     "bound from no lens): "
                     f"{', '.join(sorted(own_lens))}; the row 'all real without own-lens frames' leaves them out.\n")
    return text
