"""Gathering a shot's evidence while its frames are decoded: the per-frame estimate, the line
chains and the frame-to-frame matches of the sampled frames, and the zoom measured between them
(:class:`ShotCollector`, fed by :mod:`glradial.video.video_pipeline`, read by :func:`glradial.video.shot_fit.fit_shot`).

Memory per shot is that of its evidence (chains and matched points), never of its frames: only the
previous sample's small gray copy is kept.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ..estimation.lines import detect_chains
from ..lens.lens import Lens, as_lens
from ..lens.lensfuncs import undistort_point_exact
from .frame_motion import homography_of, match_frames, motion_gray, zoom_of
from .shot_fit import ShotEvidence, ShotSample

__all__ = ["ShotCollector", "ANCHOR_TRAVEL"]

#: a sample is also matched with the last anchor sample once the camera has moved this far since
#: (frame widths of new picture, :func:`_shift`); the anchor then moves to it. A wide pair shows a
#: wrong lens far more clearly than the small steps between consecutive samples.
ANCHOR_TRAVEL = 0.15


class ShotCollector:
    """Evidence of one shot, sample by sample. ``estimator`` maps a uint8 RGB frame to a lens (a
    :class:`glradial.LensEstimate` states its uncertainty); it runs on every ``estimate_every``-th
    sample (and the first), the chains and matches on every sample: with the previous sample, and
    with an anchor sample once the camera has moved :data:`ANCHOR_TRAVEL` from it."""

    def __init__(self, estimator: Callable[[np.ndarray], Lens], estimate_every: int = 1) -> None:
        if estimate_every < 1:
            raise ValueError(f"estimate_every must be >= 1 sample, got {estimate_every}")
        self.estimator, self.estimate_every = estimator, estimate_every
        self.evidence = ShotEvidence()
        self.estimates: list[tuple[int, Lens]] = []
        self._previous: np.ndarray | None = None
        self._hint: tuple[float, float] = (0.0, 0.0)
        self._anchor: tuple[int, np.ndarray] | None = None
        self._moved = np.eye(3)
        self._since_anchor = 0.0

    def add(self, index: int, frame: np.ndarray) -> None:
        """Add the sampled frame ``index`` (uint8 RGB, any size up to the estimate width)."""
        if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"frame must be a uint8 H x W x 3 RGB array, got {getattr(frame, 'dtype', type(frame).__name__)} "
                             f"{getattr(frame, 'shape', '')}")
        n = len(self.evidence.samples)
        estimate = None
        if n % self.estimate_every == 0:
            estimate = as_lens(self.estimator(frame))  # a plain (k1, k2) as the centred lens
            self.estimates.append((index, estimate))
            self._hint = (estimate.k1, estimate.k2)
        chains = detect_chains(frame, lens_hint=self._hint)
        self.evidence.samples.append(ShotSample(index, chains, estimate))
        gray = motion_gray(frame)
        zoom = self.evidence.zoom[-1] if self.evidence.zoom else 0.0
        if self._previous is not None and self._previous.shape == gray.shape:
            step = self._pair(n - 1, self._previous, n, gray, None)
            if step is not None:
                log_zoom = math.log(zoom_of(step))
                zoom += log_zoom
                self._moved = step @ self._moved
                shift = _shift(step)
                self.evidence.travel += shift
                self.evidence.pan += shift - abs(log_zoom)
                self._since_anchor += shift
            if self._anchor is not None and self._since_anchor >= ANCHOR_TRAVEL:
                self._pair(self._anchor[0], self._anchor[1], n, gray, self._moved)
                self._anchor = None
        if self._anchor is None:
            self._anchor, self._moved, self._since_anchor = (n, gray), np.eye(3), 0.0
        self.evidence.zoom.append(zoom)
        self._previous = gray

    def _pair(self, i: int, a: np.ndarray, j: int, b: np.ndarray, guess: np.ndarray | None) -> np.ndarray | None:
        """Match samples ``i`` and ``j``, keep the pair as evidence and return its homography
        (hint-undistorted lens units), or ``None`` (no match or no usable homography)."""
        matches = match_frames(a, b, self._hint, guess)
        if matches is None:
            return None
        ua, _ = undistort_point_exact(matches.a, *self._hint)
        ub, _ = undistort_point_exact(matches.b, *self._hint)
        h = homography_of(ua, ub)
        if h is None or not math.isfinite(zoom_of(h)):
            return None
        self.evidence.pairs.append((i, j, matches))
        return h / h[2, 2]


def _shift(h: np.ndarray) -> float:
    """New picture a homography brings into view (frame widths): the frame centre's shift plus
    the |log scale|."""
    moved = h @ np.array([0.0, 0.0, 1.0])
    return float(np.hypot(*(moved[:2] / moved[2]))) + abs(math.log(zoom_of(h)))
