"""``glradial demo``: the whole pipeline on a real broadcast frame or a procedural stadium.

By default (--source real) a real broadcast frame shipped with glradial gets a known lens, the
lens is estimated from the distorted frame, and the frame is corrected with the estimate
(the end of this module). With --source stadium it renders a stadium panorama and a
broadcast-like 16:9 frame from it with a known lens instead. Both write DIR/demo.png: the distorted frame with
the straight chords between the ends of each visible pitch line (the painted lines bow away from
them), the corrected frame with the pitch lines' true straight positions (the painted lines lie on
them when the estimate is right), and close-ups of the four corners of both. Prints the true and
estimated coefficients and the maximum displacement error in pixels of a 1920-wide frame.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from ..lens.lens import Lens
from ..lens.metrics import PAPER_SIZE, manifold_k2, max_displacement_px
from ..lens.options import METHODS
from . import finite_float, parse_size, positive_float, positive_int

DESCRIPTION = __doc__.split("\n\n", 1)[1]

#: the demo's default camera (degrees) and lens; k2 near the Lopez-Antequera manifold of k1
DEFAULT_K1 = -0.32
DEFAULT_K2 = float(manifold_k2(DEFAULT_K1))
#: a stadium of the held-out test split (seed % 10 == 9) seen from its main broadcast camera
DEFAULT_SEED = 89


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "demo", help="apply a known lens to a real frame (or a stadium render), estimate it, correct it, draw a figure",
        description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--source", choices=("real", "stadium"), default="real",
                        help="real: the bundled real broadcast frame (default); stadium: a procedural stadium frame "
                             "(--seed, --size, --panorama-width, --hfov and --target apply to it)")
    parser.add_argument("--out", default="out/demo", metavar="DIR", help="output folder, created if missing (default: out/demo)")
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"stadium seed (default {DEFAULT_SEED}, a test-split stadium)")
    parser.add_argument("--size", type=parse_size, default=PAPER_SIZE, metavar="WxH", help="frame size in pixels (default 1280x720)")
    parser.add_argument("--panorama-width", type=positive_int, default=4096, metavar="PX",
                        help="width of the rendered panorama in pixels, height = width / 2 (default 4096)")
    parser.add_argument("--k1", type=finite_float, default=DEFAULT_K1, help=f"true k1 of the frame (width-normalised; default {DEFAULT_K1})")
    parser.add_argument("--k2", type=finite_float, default=DEFAULT_K2, help=f"true k2 of the frame (width-normalised; default {DEFAULT_K2:.4f})")
    parser.add_argument("--hfov", type=positive_float, default=50.0, help="horizontal field of view of the frame in degrees (default 50)")
    parser.add_argument("--target", type=finite_float, nargs=2, default=(-18.0, 6.0), metavar=("X", "Y"),
                        help="pitch point the camera aims at, metres from the centre spot along / across the pitch (default -18 6)")
    parser.add_argument("--model", metavar="ONNX", help="ONNX model to use instead of the bundled one")
    parser.add_argument("--method", choices=METHODS, default="auto",
                        help="estimation method (default auto: the pitch-line fit when it is surer than the CNN)")
    return parser


# -- geometry -----------------------------------------------------------------------------------
def pitch_lines() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The straight pitch markings as (name, start, end) scene points in metres (z = 0)."""
    from ..synthesis.stadium_style import HALF_LENGTH as L
    from ..synthesis.stadium_style import HALF_WIDTH as W

    box_x, box_y = L - 16.5, 20.16
    area_x, area_y = L - 5.5, 9.16
    lines = [("touchline", (-L, W), (L, W)), ("touchline", (-L, -W), (L, -W)), ("halfway line", (0, -W), (0, W))]
    for s in (-1.0, 1.0):
        lines += [
            ("goal line", (s * L, -W), (s * L, W)),
            ("penalty box", (s * box_x, -box_y), (s * box_x, box_y)),
            ("penalty box", (s * box_x, box_y), (s * L, box_y)),
            ("penalty box", (s * box_x, -box_y), (s * L, -box_y)),
            ("goal area", (s * area_x, -area_y), (s * area_x, area_y)),
        ]
    return [(name, np.array([*a, 0.0]), np.array([*b, 0.0])) for name, a, b in lines]


def world_to_crop_world(style, points: np.ndarray) -> np.ndarray:
    """Scene points (N, 3, metres) -> rays in the crop convention's world axes (x toward longitude
    +90°, y down, z toward longitude 0 on the horizon), from the panorama camera."""
    yaw = math.radians(style.yaw)
    forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    v = np.asarray(points, dtype=np.float64) - np.asarray(style.camera, dtype=np.float64)
    return np.stack([v @ right, -(v @ up), v @ forward], axis=-1)


def aim(style, target_xy: tuple[float, float]) -> tuple[float, float]:
    """(pan, tilt) in degrees that put the scene point (x, y, 0) at the frame centre."""
    w = world_to_crop_world(style, np.array([[target_xy[0], target_xy[1], 0.0]]))[0]
    pan = math.degrees(math.atan2(w[0], w[2]))
    tilt = math.degrees(math.atan2(-w[1], math.hypot(w[0], w[2])))
    return pan, tilt


def project_undistorted(params, style, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Scene points -> undistorted lens points p_u (N, 2) of the crop; NaN behind the camera."""
    rays = world_to_crop_world(style, points) @ params.rotation()  # R^T w for each row
    with np.errstate(divide="ignore", invalid="ignore"):
        p = params.focal * rays[:, :2] / rays[:, 2:3]
    p[rays[:, 2] <= 1e-6] = np.nan
    return p


def _visible_run(px: np.ndarray, size: tuple[int, int], margin: float = 2.0) -> np.ndarray | None:
    """The longest run of consecutive points inside the frame, or None if shorter than 20 % of it."""
    width, height = size
    inside = np.all(np.isfinite(px), axis=1) & (px[:, 0] >= margin) & (px[:, 0] <= width - 1 - margin)
    inside &= (px[:, 1] >= margin) & (px[:, 1] <= height - 1 - margin)
    best, start = (0, 0), None
    for i, ok in enumerate(list(inside) + [False]):
        if ok and start is None:
            start = i
        elif not ok and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    run = px[best[0] : best[1]]
    if len(run) < 2 or np.hypot(*(run[-1] - run[0])) < 0.2 * width:
        return None
    return run


# -- figure -------------------------------------------------------------------------------------
def _draw_segments(image: np.ndarray, segments: list[np.ndarray], scale: float, offset: tuple[float, float] = (0.0, 0.0),
                   color=(255, 40, 40), thickness: int = 1) -> np.ndarray:
    """Draw straight segments (first to last point of each, frame pixels) on a resized view of the
    frame: view pixel = (frame pixel + 0.5 - offset) * scale - 0.5."""
    import cv2

    out = image.copy()
    for seg in segments:
        a, b = ((np.asarray(point) + 0.5 - np.asarray(offset)) * scale - 0.5 for point in (seg[0], seg[-1]))
        cv2.line(out, tuple(int(round(v * 16)) for v in a), tuple(int(round(v * 16)) for v in b), color, thickness,
                 cv2.LINE_AA, shift=4)
    return out


def _label(panel: np.ndarray, text: str, height: int = 28) -> np.ndarray:
    import cv2

    bar = np.full((height, panel.shape[1], 3), 24, np.uint8)
    cv2.putText(bar, text, (8, height - 9), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (240, 240, 240), 1, cv2.LINE_AA)
    return np.vstack([bar, panel])


def closeup_regions(segments: list[np.ndarray], size: tuple[int, int], fraction: float) -> list[tuple[int, int]]:
    """Top-left corners (x0, y0) of four close-up windows (``fraction`` of the frame each way).

    Candidates are the four frame corners and the four edge midpoints; the four showing the most
    reference-line length win (corners first on ties: they show the strongest distortion), in
    reading order."""
    width, height = size
    cw, ch = int(round(width * fraction)), int(round(height * fraction))
    corners = [(0, 0), (width - cw, 0), (0, height - ch), (width - cw, height - ch)]
    edges = [((width - cw) // 2, 0), (0, (height - ch) // 2), (width - cw, (height - ch) // 2), ((width - cw) // 2, height - ch)]

    def length_inside(x0: int, y0: int) -> float:
        total = 0.0
        for seg in segments:
            t = np.linspace(0.0, 1.0, 200)[:, None]
            points = seg[0] + t * (seg[-1] - seg[0])
            inside = (points[:, 0] >= x0) & (points[:, 0] < x0 + cw) & (points[:, 1] >= y0) & (points[:, 1] < y0 + ch)
            total += inside.mean() * float(np.hypot(*(seg[-1] - seg[0])))
        return total

    scored = [(length_inside(*c) + 1e-3 * (i < 4), c) for i, c in enumerate(corners + edges)]
    best = [c for _, c in sorted(scored, key=lambda item: -item[0])[:4]]
    return sorted(best, key=lambda c: (c[1], c[0]))


def _closeups(image: np.ndarray, segments: list[np.ndarray], regions: list[tuple[int, int]], fraction: float,
              tile_width: int) -> np.ndarray:
    """The ``regions`` (``fraction`` of the width and height each), enlarged to ``tile_width``, with
    the segments drawn at the enlarged scale."""
    import cv2

    height, width = image.shape[:2]
    cw, ch = int(round(width * fraction)), int(round(height * fraction))
    scale = tile_width / cw
    tiles = []
    for x0, y0 in regions:
        crop = cv2.resize(image[y0 : y0 + ch, x0 : x0 + cw], (tile_width, int(round(ch * scale))), interpolation=cv2.INTER_CUBIC)
        crop = _draw_segments(crop, segments, scale, (x0, y0), thickness=1)
        crop[:, -2:] = 24
        tiles.append(crop)
    return np.hstack(tiles)


def compose_figure(distorted: np.ndarray, corrected: np.ndarray, chords: list[np.ndarray], straight: list[np.ndarray],
                   labels: tuple[str, str, str, str], panel_width: int = 960) -> np.ndarray:
    """Figure (RGB uint8): both frames with their reference lines, then the corner close-ups of each."""
    import cv2

    height, width = distorted.shape[:2]
    scale = panel_width / width
    panel = (panel_width, int(round(height * scale)))
    top = np.hstack([
        _label(_draw_segments(cv2.resize(distorted, panel, interpolation=cv2.INTER_AREA), chords, scale), labels[0]),
        _label(_draw_segments(cv2.resize(corrected, panel, interpolation=cv2.INTER_AREA), straight, scale), labels[1]),
    ])
    regions = closeup_regions(chords + straight, (width, height), 0.25)
    close_a = _label(_closeups(distorted, chords, regions, 0.25, panel_width // 2), labels[2])
    close_b = _label(_closeups(corrected, straight, regions, 0.25, panel_width // 2), labels[3])
    return np.vstack([top, close_a, close_b])


# -- run ----------------------------------------------------------------------------------------
def timed_log() -> Callable[[str], None]:
    """A printer that prefixes each line with the seconds since it was made (both demo sources)."""
    start = time.monotonic()

    def log(text: str) -> None:
        print(f"[{time.monotonic() - start:5.1f}s] {text}", flush=True)

    return log


def write_outputs(out: Path, frame: np.ndarray, corrected: np.ndarray, chords: list[np.ndarray],
                  straight: list[np.ndarray], labels: tuple[str, str, str, str], log: Callable[[str], None]) -> None:
    """Compose the figure (:func:`compose_figure`) and write ``demo.png``, ``distorted.png`` and
    ``corrected.png`` to ``out`` (both demo sources)."""
    from ..media.image_io import write_image

    figure = compose_figure(frame, corrected, chords, straight, labels)
    write_image(out / "distorted.png", frame)
    write_image(out / "corrected.png", corrected)
    write_image(out / "demo.png", figure)
    log(f"wrote {out / 'demo.png'} ({len(chords)} reference lines), {out / 'distorted.png'}, {out / 'corrected.png'}")


def estimate_and_report(frame: np.ndarray, true_lens, args: argparse.Namespace, log) -> Lens:
    """The lens the demo corrects with: the estimate of ``frame`` by ``args.method`` with the
    bundled model (or ``args.model``), printed beside the true lens with its maximum displacement
    error (px at 1920) and the uncertainty it states; the true lens when no model is shipped."""
    from ..lens.lens import corner_radius

    model = _find_model(args.model)
    if model is None:
        print("glradial demo: no model shipped (glradial/models/glradial_k1k2.onnx is missing): skipping estimation and "
              "correcting with the true lens", flush=True)
        return true_lens
    from ..estimation.estimator import Estimator

    estimate = Estimator(model).estimate(frame, method=args.method)
    size = (frame.shape[1], frame.shape[0])
    error = float(max_displacement_px((true_lens.k1, true_lens.k2), (estimate.k1, estimate.k2), radius=corner_radius(size)))
    log(f"estimated with {model.name} (method {args.method} -> {estimate.method}, {estimate.chains} line chains)")
    print(f"true      k1={true_lens.k1:+.4f} k2={true_lens.k2:+.4f}")
    print(f"estimated k1={estimate.k1:+.4f} k2={estimate.k2:+.4f} ({estimate.method}, stated uncertainty "
          f"{estimate.uncertainty_px:.1f} px)")
    print(f"max displacement error: {error:.1f} px of a 1920-wide frame")
    return estimate


def _find_model(explicit: str | None) -> Path | None:
    if explicit:
        path = Path(explicit)
        if not path.is_file():
            raise FileNotFoundError(f"model file {explicit!r} does not exist")
        return path
    from ..estimation.estimator import default_model_path

    path = default_model_path()
    return path if path.is_file() else None


def run(args: argparse.Namespace) -> int:
    from ..media.progress import Progress
    from . import show_progress

    if args.source == "real":
        return run_real(args)  # about a second: no progress bar
    bar = Progress(5, "demo", unit="steps", enabled=show_progress(args))
    try:
        return _run(args, bar)
    finally:
        bar.close()


def _run(args: argparse.Namespace, bar) -> int:
    """The demo's five steps (panorama, frame, estimate, correct, figure), one bar step each."""
    from ..remapping.remap import correct
    from ..synthesis.crops import CropParams, render_crops
    from ..synthesis.stadium import stadium_panorama
    from ..synthesis.stadium_style import sample_style

    log = timed_log()
    size = args.size
    true_lens = Lens(args.k1, args.k2)
    true_lens.check_frame(size)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    style = sample_style(args.seed)
    pano_size = (args.panorama_width, args.panorama_width // 2)
    panorama = stadium_panorama(args.seed, pano_size)
    bar.update()
    log(f"stadium {args.seed}: {pano_size[0]}x{pano_size[1]} panorama, camera '{style.camera_kind}' at "
        f"({style.camera[0]:.0f}, {style.camera[1]:.0f}, {style.camera[2]:.0f}) m")
    pan, tilt = aim(style, tuple(args.target))
    params = CropParams(pan=pan, tilt=tilt, roll=0.7, hfov=args.hfov, k1=true_lens.k1, k2=true_lens.k2)
    frame = render_crops(panorama, [params], size=size)[0]
    bar.update()
    log(f"frame {size[0]}x{size[1]}: pan {pan:.1f}°, tilt {tilt:.1f}°, roll 0.7°, hfov {args.hfov:g}°, "
        f"true k1={true_lens.k1:.4f} k2={true_lens.k2:.4f}")

    estimate = estimate_and_report(frame, true_lens, args, log)
    used, source = (estimate.k1, estimate.k2), ("estimated" if estimate is not true_lens else "true")

    bar.update()
    corrected = correct(frame, used[0], used[1], fit="same")
    bar.update()
    chords, straight, bow, residual = _reference_lines(frame, params, style, true_lens, Lens(*used))
    labels = (
        f"distorted frame, k1={true_lens.k1:.3f} k2={true_lens.k2:.3f}; red: chords between line ends",
        f"corrected ({source} k1={used[0]:.3f} k2={used[1]:.3f}); red: true straight pitch lines",
        "distorted: enlarged close-ups of the frame corners / edges with the most reference lines",
        "corrected: the same close-ups",
    )
    if chords:
        print(f"pitch lines: up to {bow:.1f} px from straight in the distorted frame, "
              f"{residual:.1f} px after correction ({size[0]}x{size[1]} pixels)")
    write_outputs(out, frame, corrected, chords, straight, labels, log)
    bar.update()
    return 0


def _reference_lines(frame: np.ndarray, params, style, true_lens: Lens, used_lens: Lens):
    """The painted lines the figure draws: ``(chords, straight, bow, residual)``: the chords between
    the ends of each visible line in the distorted frame, the lines' true straight positions in the
    corrected frame, and how far the paint is from straight before and after correction (px)."""
    from ..lens.lens import lens_to_pixels

    size = (frame.shape[1], frame.shape[0])
    chords, straight = [], []
    bow, residual = 0.0, 0.0
    for _name, a, b in pitch_lines():
        points = a + np.linspace(0.0, 1.0, 400)[:, None] * (b - a)
        p_u = project_undistorted(params, style, points, size)
        finite = np.all(np.isfinite(p_u), axis=1)
        p_d = np.full_like(p_u, np.nan)
        p_d[finite] = true_lens.distort_points(lens_to_pixels(p_u[finite], size), size)
        run_d = _visible_run(p_d, size)
        if run_d is None or painted_fraction(frame, run_d) < 0.5:
            continue  # out of the frame, too short, or hidden (behind a stand): no reference line
        chords.append(run_d)
        # corrected frame (fit "same"): the ideal picture shows the line at p_u; keep the part whose
        # source lies inside the distorted frame
        px_u = lens_to_pixels(p_u, size)
        px_u[~np.all(np.isfinite(p_d), axis=1) | ~_inside(p_d, size)] = np.nan
        run_u = _visible_run(px_u, size)
        if run_u is not None:
            straight.append(run_u)
        # how far the painted line is from straight: before (distance of the distorted points from
        # their chord) and after correction (where the corrected frame shows each point, against
        # where a perfect lens would put it)
        bow = max(bow, _distance_to_chord(run_d))
        visible = np.all(np.isfinite(px_u), axis=1)
        shown = used_lens.undistort_points(p_d[visible], size)
        residual = max(residual, float(np.nanmax(np.hypot(*(shown - px_u[visible]).T))) if visible.any() else 0.0)
    return chords, straight, bow, residual


def painted_fraction(frame: np.ndarray, px: np.ndarray, offset: float = 5.0, contrast: float = 3.0) -> float:
    """Share of the points ``px`` (N x 2, frame pixels, along one line) where ``frame`` is brighter
    by more than ``contrast`` grey levels than ``offset`` pixels to both sides of the line: near 1
    for a painted line that is in view, near 0 where the line is hidden (behind a stand)."""
    import cv2

    grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY).astype(np.float32) if frame.ndim == 3 else frame.astype(np.float32)
    px = px[np.all(np.isfinite(px), axis=1)]
    if len(px) < 3:
        return 0.0
    tangent = np.gradient(px, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], 1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-9)

    def sample(points: np.ndarray) -> np.ndarray:
        return cv2.remap(grey, points[:, 0:1].astype(np.float32), points[:, 1:2].astype(np.float32),
                         cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[:, 0]

    on = sample(px)
    off = np.maximum(sample(px + offset * normal), sample(px - offset * normal))
    return float(np.mean(on - off > contrast))


def _distance_to_chord(points: np.ndarray) -> float:
    """Largest distance (pixels) of a polyline's points from the straight line through its ends."""
    a, b = points[0], points[-1]
    direction = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
    offset = points - a
    return float(np.max(np.abs(offset[:, 0] * direction[1] - offset[:, 1] * direction[0])))


def _inside(px: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    with np.errstate(invalid="ignore"):
        return (px[:, 0] >= 0) & (px[:, 0] <= width - 1) & (px[:, 1] >= 0) & (px[:, 1] <= height - 1)


# -- the real frame (--source real) ------------------------------------------------------------
# The real-frame half of ``glradial demo`` (``--source real``, the default).
#
# A real 1280 x 720 broadcast frame shipped with glradial (``glradial/data/``, BSD-2-Clause, see the
# README there) is made the undistorted picture: its camera's own barrel lens (measured once from its
# pitch lines and recorded beside it, ``own_lens``) is removed with :func:`glradial.correct` at
# ``fit="crop"``; the reference lines were measured on that undistorted picture. A known lens is applied to it with
# :func:`glradial.distort` at ``fit="crop"`` (every pixel of the distorted frame has a source, so it
# looks like a real camera's frame), the lens is estimated from the distorted frame alone, and the
# frame is corrected with the estimate (``fit="same"``).
#
# Geometry of the reference lines (lens coordinates, docs/DESIGN.md): a point ``p`` of the original frame
# appears in the distorted frame at ``P(s p)`` (``s`` the distortion's crop scale) and, after a
# correction with the true lens, at ``s p`` in the corrected frame: a straight line of the original
# stays straight there. So the figure draws, on the distorted frame, the chord between the ends of
# each reference line (the painted line bows away from it) and, on the corrected frame, the line's
# true straight position (the painted line lies on it when the estimate is right).

#: the bundled real frame and its reference lines (package ``glradial.data``)
FRAME_NAME = "usl_broadcast_0195.jpg"
LINES_NAME = "usl_broadcast_0195.json"


def bundled_frame() -> tuple[np.ndarray, dict[str, np.ndarray], Lens]:
    """The shipped real frame made undistorted (H x W x 3 uint8 RGB: its own lens removed with
    ``correct(fit="crop")``), its reference lines ``{name: 2 x 2 end points in pixels of that
    undistorted frame}``, and the frame's own lens (both measured; see ``glradial/data/README.md``)."""
    from ..lens.lens import Lens
    from ..media.image_io import read_image
    from ..remapping.remap import correct

    data = resources.files("glradial.data")
    shipped = read_image(Path(str(data.joinpath(FRAME_NAME))))
    spec = json.loads(data.joinpath(LINES_NAME).read_text(encoding="utf-8"))
    size = (shipped.shape[1], shipped.shape[0])
    if tuple(spec["size"]) != size:
        raise ValueError(f"{LINES_NAME} describes a {spec['size']} frame, {FRAME_NAME} is {size[0]}x{size[1]}")
    own = Lens(spec["own_lens"]["k1"], spec["own_lens"]["k2"])
    frame = correct(shipped, own, fit="crop")
    lines = {name: np.asarray(ends, dtype=np.float64) for name, ends in spec["lines_after_removing_own_lens"].items()}
    return frame, lines, own


def line_positions(ends: np.ndarray, true_lens, scale: float, size: tuple[int, int], samples: int = 400):
    """Pixel positions of the points of one reference line (``ends`` 2 x 2, original pixels):
    ``(distorted, corrected)``, each ``samples x 2``: where the distorted frame shows them
    (``P(s p)``) and where a correction with the true lens shows them (``s p``)."""
    from ..lens.lens import lens_to_pixels, pixels_to_lens

    t = np.linspace(0.0, 1.0, samples)[:, None]
    p = pixels_to_lens(ends[0] + t * (ends[1] - ends[0]), size) * scale
    return true_lens.distort_points(lens_to_pixels(p, size), size), lens_to_pixels(p, size)


def run_real(args: argparse.Namespace) -> int:
    """``glradial demo --source real``: see the module docstring."""
    from ..lens.lens import Lens
    from ..remapping.remap import correct, distort
    from .demo import _distance_to_chord, estimate_and_report, timed_log, write_outputs

    log = timed_log()
    original, lines, own = bundled_frame()
    size = (original.shape[1], original.shape[0])
    true_lens = Lens(args.k1, args.k2)
    true_lens.check_frame(size)
    scale = true_lens.fit_scale(size, "crop", "distort")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frame = distort(original, true_lens.k1, true_lens.k2, fit=scale)
    log(f"real broadcast frame {FRAME_NAME} ({size[0]}x{size[1]}): its own lens k1={own.k1:.4f} k2={own.k2:.4f} "
        f"removed, the known lens k1={true_lens.k1:.4f} k2={true_lens.k2:.4f} applied (fit=crop, scale {scale:.4f})")

    estimate = estimate_and_report(frame, true_lens, args, log)
    source = "estimated" if estimate is not true_lens else "true"
    used = Lens(float(estimate.k1), float(estimate.k2))
    corrected = correct(frame, used.k1, used.k2, fit="same")

    chords, straight = [], []
    bow, residual = 0.0, 0.0
    for ends in lines.values():
        distorted_px, true_px = line_positions(ends, true_lens, scale, size)
        chords.append(distorted_px)
        straight.append(true_px)
        bow = max(bow, _distance_to_chord(distorted_px))
        shown = used.undistort_points(distorted_px, size)  # where the corrected frame shows each point
        residual = max(residual, float(np.nanmax(np.hypot(*(shown - true_px).T))))
    print(f"reference lines: up to {bow:.1f} px from straight in the distorted frame, "
          f"{residual:.1f} px after correction ({size[0]}x{size[1]} pixels)")
    labels = (
        f"real frame, known lens k1={true_lens.k1:.3f} k2={true_lens.k2:.3f} applied; red: chords between line ends",
        f"corrected ({source} k1={used.k1:.3f} k2={used.k2:.3f}); red: the lines' true straight positions",
        "distorted: enlarged close-ups where the reference lines run",
        "corrected: the same close-ups",
    )
    write_outputs(out, frame, corrected, chords, straight, labels, log)
    return 0
