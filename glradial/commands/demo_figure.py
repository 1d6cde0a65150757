"""The figure and report both sources of ``glradial demo`` share (:mod:`glradial.commands.demo`): the
distorted and corrected frames with their reference lines (chords between line ends on the distorted
frame, true straight positions on the corrected one) and enlarged close-ups, the estimate printed
beside the true lens, and the lines' distance from straight. Pixels are frame pixels (x right,
y down, pixel centres at integers)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Callable

import numpy as np

from ..lens.lens import Lens
from ..lens.metrics import max_displacement_px


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



# -- report ---------------------------------------------------------------------------------------
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
    from ..estimation.net_lines import NetLinesEstimator

    estimate = NetLinesEstimator(model).estimate(frame, method=args.method)
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
    from ..estimation.net_lines import default_model_path

    path = default_model_path()
    return path if path.is_file() else None


def distance_to_chord(points: np.ndarray) -> float:
    """Largest distance (pixels) of a polyline's points from the straight line through its ends."""
    a, b = points[0], points[-1]
    direction = (b - a) / max(float(np.hypot(*(b - a))), 1e-9)
    offset = points - a
    return float(np.max(np.abs(offset[:, 0] * direction[1] - offset[:, 1] * direction[0])))
