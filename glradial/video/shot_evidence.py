"""Gathering a shot's evidence while its frames are decoded: the per-frame estimate, the line
chains and the frame-to-frame matches of the sampled frames, and the zoom measured between them
(:class:`ShotCollector`, fed by :mod:`glradial.video.video_pipeline`, read by :func:`glradial.video.shot_fit.fit_shot`).

Memory per shot is that of its evidence (chains and matched points), never of its frames: only the
previous sample's small gray copy is kept.
"""

from __future__ import annotations

import math
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..estimation.lines import detect_chains
from ..lens.lens import Lens, as_lens
from .frame_motion import match_frames, motion_gray, track_corners, zoom_of
from .shot_fit import ShotEvidence, ShotSample

__all__ = ["ShotCollector", "ANCHOR_TRAVEL", "ANCHOR_REACH", "MAX_ANCHORS", "FEW_CHAINS"]

#: a sample becomes an anchor once the camera has moved this far (frame widths of new picture,
#: :func:`_shift`) from the last anchor; every later sample is matched with every anchor it has
#: moved at least this far from, not only with its neighbour. A wide pair shows a wrong lens far
#: more clearly than the small steps between consecutive samples (the misfit of a wrong lens grows
#: with the rotation between the two frames).
ANCHOR_TRAVEL = 0.15
#: ...and at most this far (frame widths): beyond it the two frames overlap too little to match
ANCHOR_REACH = 0.6
#: anchors kept (the oldest is dropped): memory and matching time stay bounded on a long shot
MAX_ANCHORS = 4
#: a sample whose line detection finds fewer chains than this gets a per-frame estimate of its own,
#: whatever ``estimate_every`` says: a shot of such samples has no joint fit and is read by its
#: estimates, and a zoom read that way needs them at several zooms to follow it
#: (:func:`glradial.video.shot_fit.fit_shot`). Samples with lines keep the cheaper rhythm.
FEW_CHAINS = 4


@dataclass
class _Anchor:
    """An earlier sample kept for wide pairs: its index, gray copy, the homography from it to the
    latest sample (hint-undistorted lens units) and the picture brought into view since (frame widths)."""

    sample: int
    gray: np.ndarray
    moved: np.ndarray = field(default_factory=lambda: np.eye(3))
    travel: float = 0.0


class ShotCollector:
    """Evidence of one shot, sample by sample. ``estimator`` maps a uint8 RGB frame to a lens (a
    :class:`glradial.LensEstimate` states its uncertainty); it runs on every ``estimate_every``-th
    sample (and the first) and on every sample with fewer than :data:`FEW_CHAINS` line chains, the
    chains and matches on every sample: with the previous sample, and
    with every kept anchor sample it has moved :data:`ANCHOR_TRAVEL` to :data:`ANCHOR_REACH` from.
    The surest per-frame estimate so far (smallest ``uncertainty_px``; the latest when none states
    one) is the hint of the line detector (chains are linked and cut at corners in the frame
    undistorted with it) and of the matcher: a later, less sure estimate does not replace it."""

    def __init__(self, estimator: Callable[[np.ndarray], Lens], estimate_every: int = 1) -> None:
        if estimate_every < 1:
            raise ValueError(f"estimate_every must be >= 1 sample, got {estimate_every}")
        self.estimator, self.estimate_every = estimator, estimate_every
        self.evidence = ShotEvidence()
        self.estimates: list[tuple[int, Lens]] = []
        self._previous: np.ndarray | None = None
        self._hint: tuple[float, float] = (0.0, 0.0)
        self._hint_px = math.inf
        self._anchors: list[_Anchor] = []
        self._corners: dict[int, np.ndarray | None] = {}  # sample -> its track_corners, once found
        self._moving: list[Future] = []

    def due(self, n: int) -> bool:
        """Whether the ``n``-th sample of the shot (0 = its first) gets the per-frame estimate
        whatever its chains (every ``estimate_every``-th)."""
        return n % self.estimate_every == 0

    def add(self, index: int, frame: np.ndarray, estimated: Callable[[], Lens] | None = None,
            motion: Executor | None = None) -> None:
        """Add the sampled frame ``index`` (uint8 RGB, any size up to the estimate width).
        ``estimated``: where the sample is :meth:`due`, a call that returns ``estimator(frame)``
        computed ahead (e.g. a future's ``result`` from a worker thread), used in its place.
        ``motion``: a one-thread executor that finds the sample's matches and zoom (with the hint
        of this moment) while the caller goes on; :meth:`finish` waits for them."""
        if not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise ValueError(f"frame must be a uint8 H x W x 3 RGB array, got {getattr(frame, 'dtype', type(frame).__name__)} "
                             f"{getattr(frame, 'shape', '')}")
        n = len(self.evidence.samples)
        estimate = self._estimate(index, frame, estimated) if self.due(n) else None
        chains = detect_chains(frame, lens_hint=self._hint)
        if estimate is None and (chains is None or len(chains.chains) < FEW_CHAINS):
            estimate = self._estimate(index, frame)  # little to read but the estimate itself
        self.evidence.samples.append(ShotSample(index, chains, estimate))
        if motion is None:
            self._motion(n, frame, self._hint)
        else:
            self._moving.append(motion.submit(self._motion, n, frame, self._hint))

    def finish(self) -> ShotEvidence:
        """The shot's evidence, once the matches handed to a ``motion`` executor are found."""
        moving, self._moving = self._moving, []
        for job in moving:
            job.result()
        return self.evidence

    def _motion(self, n: int, frame: np.ndarray, hint: tuple[float, float]) -> None:
        """Sample ``n``'s matches with the earlier samples (lens ``hint``) and its zoom."""
        gray = motion_gray(frame)
        zoom = self.evidence.zoom[-1] if self.evidence.zoom else 0.0
        if self._previous is not None and self._previous.shape == gray.shape:
            zoom += self._step(n, gray, hint)
        self.evidence.zoom.append(zoom)
        self._previous = gray
        if not self._anchors or self._anchors[-1].travel >= ANCHOR_TRAVEL:
            self._anchors = (self._anchors + [_Anchor(n, gray)])[-MAX_ANCHORS:]
        kept = {n} | {a.sample for a in self._anchors}  # the samples later ones are matched with
        self._corners = {i: c for i, c in self._corners.items() if i in kept}

    def _estimate(self, index: int, frame: np.ndarray, estimated: Callable[[], Lens] | None = None) -> Lens:
        """The per-frame estimate of sample ``index`` (``estimated()`` where given), kept; the
        surest so far becomes the hint."""
        found = estimated() if estimated is not None else self.estimator(frame)
        estimate = as_lens(found)  # a plain (k1, k2) as the centred lens
        self.estimates.append((index, estimate))
        sure = float(getattr(estimate, "uncertainty_px", math.inf))
        if sure <= self._hint_px:  # the surest estimate so far guides the detector and matcher
            self._hint, self._hint_px = (estimate.k1, estimate.k2), sure
        return estimate

    def _step(self, n: int, gray: np.ndarray, hint: tuple[float, float]) -> float:
        """Match sample ``n`` with the previous sample and with its anchors; the log zoom since the
        previous sample (0 when they do not match: the anchors are then dropped, their motion lost)."""
        step = self._pair(n - 1, self._previous, n, gray, None, hint)
        if step is None:
            self._anchors = []
            return 0.0
        log_zoom = math.log(zoom_of(step))
        shift = _shift(step)
        self.evidence.travel += shift
        self.evidence.pan += shift - abs(log_zoom)
        for anchor in self._anchors:
            anchor.moved, anchor.travel = step @ anchor.moved, anchor.travel + shift
            if anchor.sample != n - 1 and ANCHOR_TRAVEL <= anchor.travel <= ANCHOR_REACH:
                self._pair(anchor.sample, anchor.gray, n, gray, anchor.moved, hint)
        self._anchors = [a for a in self._anchors if a.travel <= ANCHOR_REACH]
        return log_zoom

    def _pair(self, i: int, a: np.ndarray, j: int, b: np.ndarray, guess: np.ndarray | None,
              hint: tuple[float, float]) -> np.ndarray | None:
        """Match samples ``i`` and ``j``, keep the pair as evidence and return its homography
        (``hint``-undistorted lens units), or ``None`` (no match or no usable homography)."""
        if i not in self._corners:
            self._corners[i] = track_corners(a)
        matches = match_frames(a, b, hint, guess, self._corners[i])
        if matches is None:
            return None
        h = matches.homography
        if h is None or not math.isfinite(zoom_of(h)):
            return None
        self.evidence.pairs.append((i, j, matches))
        return h / h[2, 2]


def _shift(h: np.ndarray) -> float:
    """New picture a homography brings into view (frame widths): the frame centre's shift plus
    the |log scale|."""
    moved = h @ np.array([0.0, 0.0, 1.0])
    return float(np.hypot(*(moved[:2] / moved[2]))) + abs(math.log(zoom_of(h)))
