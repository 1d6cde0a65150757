"""Per-frame detections in and pitch positions out: MOTChallenge CSV boxes read and checked, the
positions written atomically.

MOTChallenge (MOT15-MOT20 ``det.txt``/``gt.txt``): one box a line, ``frame,id,left,top,width,height,
conf[,x,y,z[,...]]``, frames counted from 1, boxes in pixels of the frame (left/top the box's top-left
corner); ``id`` is -1 for untracked detections. The point a box stands on is its bottom centre,
``(left + width / 2, top + height)``.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .atomic import atomic_write_text

__all__ = ["Detections", "read_mot", "write_positions", "POSITION_COLUMNS"]

#: The columns of a positions file (pitch metres: origin at the centre spot, x along the touchlines,
#: y toward the far touchline; pixels of the frame; the bound in px at 1280).
POSITION_COLUMNS = ("frame", "id", "pixel_x", "pixel_y", "conf", "x_m", "y_m", "camera_doubtful", "camera_reason",
                    "camera_uncertainty_px_1280")


@dataclass(frozen=True)
class Detections:
    """Boxes of a MOTChallenge file: ``frame`` (N, counted from 1), ``ids`` (N), ``boxes`` (N x 4:
    left, top, width, height in px), ``conf`` (N) and ``lines`` (N, the file's line numbers)."""

    frame: np.ndarray
    ids: np.ndarray
    boxes: np.ndarray
    conf: np.ndarray
    lines: np.ndarray

    @property
    def feet(self) -> np.ndarray:
        """N x 2 pixels: each box's bottom centre."""
        return np.c_[self.boxes[:, 0] + self.boxes[:, 2] / 2, self.boxes[:, 1] + self.boxes[:, 3]]

    def check_inside(self, size: tuple[int, int], name: str = "DETECTIONS") -> None:
        """``ValueError`` naming the first box whose bottom centre lies outside a ``size = (W, H)`` frame
        (by more than one pixel: boxes clipped at the border are fine)."""
        width, height = size
        feet = self.feet
        out = (feet[:, 0] < -1) | (feet[:, 0] > width) | (feet[:, 1] < -1) | (feet[:, 1] > height)
        if out.any():
            i = int(np.flatnonzero(out)[0])
            raise ValueError(f"{name} line {self.lines[i]}: the box's bottom centre ({feet[i, 0]:.1f}, {feet[i, 1]:.1f}) "
                             f"lies outside the {width}x{height} frame ({int(out.sum())} boxes do)")


def _row(fields: list[str], line: int, name: str) -> tuple[int, int, float, float, float, float, float]:
    if len(fields) < 7:
        raise ValueError(f"{name} line {line}: expected frame,id,left,top,width,height,conf[,...] (MOTChallenge), "
                         f"got {len(fields)} fields: {','.join(fields)!r}")
    try:
        frame, ident = float(fields[0]), float(fields[1])
        left, top, width, height, conf = (float(v) for v in fields[2:7])
    except ValueError:
        raise ValueError(f"{name} line {line}: not numbers: {','.join(fields[:7])!r}") from None
    if not (frame >= 1 and frame == int(frame)) or ident != int(ident):
        raise ValueError(f"{name} line {line}: frame must be a whole number >= 1 (MOTChallenge counts from 1) and id "
                         f"a whole number, got frame={fields[0]!r} id={fields[1]!r}")
    if not all(math.isfinite(v) for v in (left, top, width, height, conf)) or width <= 0 or height <= 0:
        raise ValueError(f"{name} line {line}: the box must be finite with a positive width and height, got "
                         f"left={left} top={top} width={width} height={height}")
    return int(frame), int(ident), left, top, width, height, conf


def read_mot(path: str | os.PathLike) -> Detections:
    """The boxes of a MOTChallenge CSV file (module docstring); ``ValueError`` naming the file, the line
    and the value that is not a box; blank lines and ``#`` comments are skipped."""
    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(f"detections file {str(source)!r} does not exist")
    rows, lines = [], []
    with source.open(newline="", encoding="utf-8") as handle:
        for number, fields in enumerate(csv.reader(handle), start=1):
            fields = [f.strip() for f in fields]
            if not fields or not any(fields) or fields[0].startswith("#"):
                continue
            rows.append(_row(fields, number, str(source)))
            lines.append(number)
    if not rows:
        raise ValueError(f"{str(source)!r} holds no detection (MOTChallenge: frame,id,left,top,width,height,conf)")
    a = np.array(rows, dtype=np.float64)
    return Detections(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6], a[:, 6], np.array(lines))


def write_positions(path: str | os.PathLike, rows: list[tuple]) -> Path:
    """Write ``rows`` (each :data:`POSITION_COLUMNS`) as a CSV file with a header, atomically; an
    empty cell where a value is ``None`` or NaN."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(POSITION_COLUMNS)
    for row in rows:
        writer.writerow(["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else
                         (f"{v:.3f}" if isinstance(v, float) else v) for v in row])
    return atomic_write_text(path, buffer.getvalue())
