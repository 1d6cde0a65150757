"""The per-frame lens of a video (a lens track) and its sidecar file, written by ``correct --auto``
and ``estimate VIDEO`` and read back by ``correct --lens-track``.

CSV format (one header line, then one row per frame, frames 0, 1, 2 ... in order; ``.json``
holds the same rows as a list of objects under ``"frames"``):

======================  ====================================================================
column                  meaning
======================  ====================================================================
``frame``               frame index, 0 = first decoded frame (required)
``time_s``              presentation time of the frame in seconds from the stream start
``shot``                shot id (0, 1, ...), a cut starts a new one
``k1``, ``k2``          the lens the frame is corrected with (width-normalised, docs/DESIGN.md) (required)
``cx``, ``cy``          its principal point's offset from the image centre, image widths (0: centred)
``pixel_aspect``        its ``fy / fx`` (1: square pixels); these three as in :class:`glradial.Lens`
                        and optional on reading (defaults 0, 0, 1)
``uncertainty_px``      stated uncertainty of that lens (~p90 of the maximum displacement error,
                        px at 1920 wide); empty when the estimator states none
``doubtful``            1 when the frame's shot is doubtful (see ``reason``), else 0
``reason``              why the shot is doubtful, machine-readable (``no_geometry``,
                        ``uncertain``, ``fold_over``; tracks without it: uncertainty above the
                        run's threshold); empty when it is not
``applied``             1 when the frame was corrected with ``k1``, ``k2``; 0 when it was passed
                        through uncorrected (a doubtful shot, by default)
``method``              how the frame's raw estimate was made (``net``, ``lines``); empty when
                        the frame was not estimated
``k1_raw``, ``k2_raw``  the raw estimate on this frame (empty when not estimated)
``raw_uncertainty_px``  the uncertainty the estimator stated for it
``weight``              weight of the raw estimate (1 where one was made; tracks of older
                        versions: its robustness weight in their smoothing, 0 = rejected)
======================  ====================================================================

Reading (:func:`load_lens_track`) needs only ``frame``, ``k1`` and ``k2``: edit those and feed
the file back; an ``applied`` column is honoured (0 = the frame passes through uncorrected, and its
lens is then not checked), so a track read back corrects exactly as the run that wrote it. Every row is checked (one row per frame in order, finite coefficients, a lens that
does not fold over on the frame, non-negative uncertainties); the first bad row raises
:class:`~glradial.errors.LensTrackError` (a ``ValueError``) naming the file and the line.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import math
import os
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import LensTrackError
from ..lens.lens import Lens
from ..media.atomic import atomic_write_text
from ..schemas import schema, validate

__all__ = ["DOUBTFUL_PX", "LensTrack", "load_lens_track"]

#: a shot whose smoothed lens is less sure than this (median stated uncertainty over the shot,
#: px at 1920 wide, ~p90) is doubtful: ``correct --auto`` warns about it. 10 px is the p90 target
#: of the line-aware estimator on real frames (issue 17) and about the p90 of the CNN alone on its
#: procedural test set; above it, correcting can easily do more harm than good.
DOUBTFUL_PX = 10.0

COLUMNS = ["frame", "time_s", "shot", "k1", "k2", "cx", "cy", "pixel_aspect", "uncertainty_px", "doubtful", "reason", "applied", "method",
           "k1_raw", "k2_raw", "raw_uncertainty_px", "weight"]


@dataclass
class LensTrack:
    """Per-frame lenses of one video (arrays indexed by frame) and how they were obtained.

    ``rate`` frames per second (exact), ``size`` (W, H); ``uncertainty_px`` and
    ``raw_uncertainty_px`` are NaN where unknown; ``raw`` and ``weight`` NaN on frames that were not
    estimated; ``method`` "" there. ``doubtful_px`` is the threshold that marks a shot doubtful
    when ``doubtful`` (bool per frame) is not given; ``reason`` (per frame) says why; ``applied``
    (bool per frame, default all) whether the frame is corrected or passed through. ``geometry``
    (N x 3: ``cx``, ``cy``, ``pixel_aspect`` per frame, default centred and square) completes each
    frame's :class:`~glradial.lens.lens.Lens` with ``lens`` (N x 2: k1, k2).
    """

    rate: Fraction
    size: tuple[int, int]
    shot: np.ndarray
    lens: np.ndarray
    raw: np.ndarray
    weight: np.ndarray
    time_s: np.ndarray | None = None
    uncertainty_px: np.ndarray | None = None
    raw_uncertainty_px: np.ndarray | None = None
    method: list[str] = field(default_factory=list)
    doubtful_px: float = DOUBTFUL_PX
    doubtful: np.ndarray | None = None
    reason: list[str] = field(default_factory=list)
    applied: np.ndarray | None = None
    geometry: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.shot)
        if self.geometry is None:
            self.geometry = np.tile([0.0, 0.0, 1.0], (n, 1))
        if not self.reason:
            self.reason = [""] * n
        if self.applied is None:
            self.applied = np.ones(n, dtype=bool)
        if self.time_s is None:
            self.time_s = np.arange(n) / float(self.rate)
        if self.uncertainty_px is None:
            self.uncertainty_px = np.full(n, np.nan)
        if self.raw_uncertainty_px is None:
            self.raw_uncertainty_px = np.full(n, np.nan)
        if not self.method:
            self.method = [""] * n
        if self.doubtful is None:
            self.doubtful = np.isin(self.shot, [s for s in np.unique(self.shot)
                                                if self.shot_uncertainty(int(s)) > self.doubtful_px])
            self.reason = ["uncertain" if d else "" for d in self.doubtful]

    @property
    def fps(self) -> float:
        return float(self.rate)

    @property
    def n_frames(self) -> int:
        return len(self.shot)

    def lens_at(self, frame: int) -> tuple[float, float]:
        """The lens of ``frame``; :class:`~glradial.errors.LensTrackError` (a ``ValueError``) past the
        end of the track (the video is longer)."""
        if not 0 <= frame < self.n_frames:
            raise LensTrackError(f"the lens track has {self.n_frames} frames; the video has more (frame {frame})")
        return float(self.lens[frame, 0]), float(self.lens[frame, 1])

    def lens_for(self, frame: int) -> Lens | None:
        """The lens ``frame`` is corrected with, or ``None`` when it passes through uncorrected."""
        lens = self.full_lens(frame)  # LensTrackError past the end of the track
        return lens if self.applied[frame] else None

    def full_lens(self, frame: int) -> Lens:
        """The whole :class:`~glradial.lens.lens.Lens` of ``frame`` (principal point and pixel
        aspect included), whether or not it is applied."""
        k1, k2 = self.lens_at(frame)
        cx, cy, aspect = (float(v) for v in self.geometry[frame])
        return Lens(k1, k2, cx, cy, aspect)

    def lenses(self) -> list[Lens]:
        """:meth:`full_lens` of every frame."""
        return [self.full_lens(i) for i in range(self.n_frames)]

    def shot_uncertainty(self, shot: int) -> float:
        """Median stated uncertainty (px at 1920) of a shot's smoothed lenses; NaN if unknown."""
        values = self.uncertainty_px[self.shot == shot]
        values = values[np.isfinite(values)]
        return float(np.median(values)) if len(values) else math.nan

    def doubtful_shots(self) -> list[int]:
        """Shots marked doubtful (tracks without marks: median uncertainty above :attr:`doubtful_px`)."""
        return [int(s) for s in np.unique(self.shot[self.doubtful])]

    def rows(self) -> list[dict]:
        out = []
        for i in range(self.n_frames):
            estimated = not math.isnan(self.raw[i, 0])
            out.append(
                {
                    "frame": i,
                    "time_s": round(float(self.time_s[i]), 6),
                    "shot": int(self.shot[i]),
                    "k1": float(self.lens[i, 0]),
                    "k2": float(self.lens[i, 1]),
                    "cx": float(self.geometry[i, 0]),
                    "cy": float(self.geometry[i, 1]),
                    "pixel_aspect": float(self.geometry[i, 2]),
                    "uncertainty_px": _number(self.uncertainty_px[i]),
                    "doubtful": int(bool(self.doubtful[i])),
                    "reason": self.reason[i],
                    "applied": int(bool(self.applied[i])),
                    "method": self.method[i],
                    "k1_raw": float(self.raw[i, 0]) if estimated else None,
                    "k2_raw": float(self.raw[i, 1]) if estimated else None,
                    "raw_uncertainty_px": _number(self.raw_uncertainty_px[i]) if estimated else None,
                    "weight": float(self.weight[i]) if estimated else None,
                }
            )
        return out

    def per_shot(self) -> list[dict]:
        """One row per shot: first/last frame, the median smoothed lens, its median uncertainty
        (px at 1920, None if unknown), whether it is doubtful and why, whether its lens was applied,
        and the methods used."""
        shots = []
        for shot in np.unique(self.shot):
            frames = np.flatnonzero(self.shot == shot)
            k = np.median(self.lens[frames], axis=0)
            sure = self.shot_uncertainty(int(shot))
            methods = sorted({self.method[i] for i in frames if self.method[i]})
            shots.append({
                "shot": int(shot), "first_frame": int(frames[0]), "last_frame": int(frames[-1]),
                "k1": float(k[0]), "k2": float(k[1]), "uncertainty_px": _number(sure),
                "doubtful": bool(self.doubtful[frames].any()), "reason": self.reason[frames[0]],
                "applied": bool(self.applied[frames].all()), "methods": methods,
            })
        return shots

    def save(self, path: str | os.PathLike) -> Path:
        """Write the sidecar atomically: ``.json`` -> JSON, anything else -> CSV (module docstring)."""
        path = Path(path)
        rows = self.rows()
        if path.suffix.lower() == ".json":
            document = {
                "fps": self.fps,
                "rate": f"{self.rate.numerator}/{self.rate.denominator}",
                "size": list(self.size),
                "convention": "width-normalised k1, k2 (image width = 1, centre origin); p_d = p_u (1 + k1 r^2 + k2 r^4); "
                "uncertainty_px: ~p90 of the maximum displacement error, px at 1920 wide",
                "doubtful_px": self.doubtful_px,
                "shots": self.per_shot(),
                "frames": rows,
            }
            return atomic_write_text(path, json.dumps(document, indent=1) + "\n")
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: ("" if value is None else (f"{value:.8g}" if isinstance(value, float) else value)) for key, value in row.items()})
        return atomic_write_text(path, buffer.getvalue())


def _number(value: float) -> float | None:
    return None if value is None or not math.isfinite(float(value)) else float(value)


def _rows(path: Path) -> list[tuple[int, dict]]:
    """(line number, row) pairs of a CSV or JSON track; a JSON track is checked against the
    ``lens_track`` schema as a whole (:mod:`glradial.schemas`)."""
    if path.suffix.lower() == ".json":
        try:
            document = json.loads(path.read_text())
        except ValueError:
            raise LensTrackError(f"lens track {str(path)!r}: not a JSON document") from None
        validate(document, "lens_track", f"lens track {str(path)!r}", error_type=LensTrackError)
        return [(i + 1, row) for i, row in enumerate(document["frames"])]
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        missing = {"frame", "k1", "k2"} - set(reader.fieldnames or [])
        if missing:
            raise LensTrackError(f"lens track {str(path)!r} line 1: the header lacks the column(s) {', '.join(sorted(missing))}")
        return [(reader.line_num, row) for row in reader]


@functools.lru_cache(maxsize=1)
def _number_columns() -> frozenset[str]:
    """The columns of a row (``lens_track`` schema, ``$defs/row``) that hold numbers."""
    def numeric(spec: dict) -> bool:
        kinds = spec.get("type", [])
        return "enum" in spec or bool({"number", "integer"} & set([kinds] if isinstance(kinds, str) else kinds))

    return frozenset(name for name, spec in schema("lens_track")["$defs"]["row"]["properties"].items() if numeric(spec))


def _typed_row(row: dict, where: str, checked: bool) -> dict:
    """The given cells of a row: numbers parsed from a CSV's text (a JSON's kept), empty cells and
    nulls left out, checked against the schema's row (``LensTrackError`` naming the line and the
    column; also for a number that is not finite, which a schema cannot say). ``checked``: the row
    was checked with its document (a JSON track) already."""
    numbers, typed = _number_columns(), {}
    for name, value in row.items():
        if name is None or value is None or (isinstance(value, str) and not value.strip()):
            continue
        if name in numbers and isinstance(value, str):
            try:
                value = float(value)
            except ValueError:
                raise LensTrackError(f"{where}: {name} {value.strip()!r} is not a number") from None
        if name in numbers and isinstance(value, float) and not math.isfinite(value):
            raise LensTrackError(f"{where}: {name} must be finite, got {row[name]!r}")
        typed[name] = value
    if not checked:
        validate(typed, "lens_track", where, "row", error_type=LensTrackError)
    return typed


def load_lens_track(path: str | os.PathLike, rate: Fraction, size: tuple[int, int]) -> LensTrack:
    """Read and check a lens track (module docstring) for a video of frame ``size`` (W, H) and
    ``rate``; :class:`~glradial.errors.LensTrackError` (a ``ValueError``) naming the file and the
    line of the first bad row."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"lens track {str(path)!r} does not exist")
    rows = _rows(path)
    if not rows:
        raise LensTrackError(f"lens track {str(path)!r} has no rows")
    n = len(rows)
    lens, shot, sure = np.empty((n, 2)), np.zeros(n, dtype=np.int64), np.full(n, np.nan)
    geometry = np.tile([0.0, 0.0, 1.0], (n, 1))
    method, applied = [""] * n, np.ones(n, dtype=bool)
    for index, (line, raw) in enumerate(rows):
        where = f"lens track {str(path)!r} line {line}"
        row = _typed_row(raw, where, checked=path.suffix.lower() == ".json")
        if row["frame"] != index:
            raise LensTrackError(f"{where}: frame {raw.get('frame')!r}, expected {index} (one row per frame, in order from 0)")
        geometry[index] = [row.get("cx", 0.0), row.get("cy", 0.0), row.get("pixel_aspect", 1.0)]
        applied[index] = row.get("applied", 1) != 0
        try:
            frame_lens = Lens(row["k1"], row["k2"], *geometry[index])
            if applied[index]:
                frame_lens.check_frame(size)
        except ValueError as err:
            raise LensTrackError(f"{where}: {err}") from None
        lens[index] = (row["k1"], row["k2"])
        shot[index] = int(row.get("shot", 0))
        sure[index] = row.get("uncertainty_px", np.nan)
        method[index] = str(row.get("method") or "")
    return LensTrack(rate, size, shot, lens, np.full((n, 2), np.nan), np.full(n, np.nan),
                     uncertainty_px=sure, method=method, applied=applied, geometry=geometry)
