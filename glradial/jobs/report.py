"""A job's closing report: ``DIR/report.csv`` and ``DIR/report.json``, one row per input, for pandas
(``pandas.read_csv("DIR/report.csv")``, ``pandas.read_json("DIR/report.json")``).

Columns (:data:`COLUMNS`): ``input``, ``outputs`` (file names in DIR, ``;``-separated in the CSV),
``status`` (done, failed or pending: interrupted), ``skipped`` (1: complete from an earlier run),
``frames``, ``shots``, ``doubtful_shots`` (videos: shots left uncorrected or flagged), the lens
``k1``, ``k2`` (width-normalised; one lens: an image, or a video of one shot; else empty and per shot
in the JSON's ``shot_list``), ``uncertainty_px`` (90 % bound, px at 1920 wide; calibrate: px at 1280),
``doubtful``, ``reason``, the camera (calibrate: ``focal`` in image widths, ``hfov_deg``,
``x_m``, ``y_m``, ``z_m`` in pitch metres, ``pan_deg``, ``tilt_deg``, ``roll_deg`` of its middle sure
frame), ``seconds`` (the last attempt's), ``attempts``, ``worker`` (``host:pid``) and ``error``.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..media.atomic import atomic_write_text

__all__ = ["COLUMNS", "report_rows", "write_report"]

COLUMNS = ("input", "outputs", "status", "skipped", "frames", "shots", "doubtful_shots", "k1", "k2", "uncertainty_px",
           "doubtful", "reason", "focal", "hfov_deg", "x_m", "y_m", "z_m", "pan_deg", "tilt_deg", "roll_deg", "seconds",
           "attempts", "worker", "error")


def _shot_facts(shots: list[dict]) -> dict:
    row: dict = {"shots": len(shots), "doubtful_shots": sum(bool(s.get("doubtful")) for s in shots)}
    if len(shots) == 1:
        row.update(k1=shots[0].get("k1"), k2=shots[0].get("k2"), uncertainty_px=shots[0].get("uncertainty_px"),
                   doubtful=shots[0].get("doubtful"), reason=shots[0].get("reason"))
    return row


def _camera_facts(facts: dict) -> dict:
    camera = facts.get("camera") or {}
    x, y, z = camera.get("position_m") or (None, None, None)
    row = {key: camera.get(key) for key in ("k1", "k2", "focal", "hfov_deg", "pan_deg", "tilt_deg", "roll_deg", "uncertainty_px")}
    row.update(x_m=x, y_m=y, z_m=z, doubtful=None if not facts.get("frames") else facts.get("doubtful_frames", 0) == facts["frames"])
    return row


def report_rows(entries: dict[str, dict], skipped: set[str]) -> list[dict]:
    """One row per manifest entry (:mod:`glradial.jobs.manifest`), with ``shot_list`` kept for the JSON."""
    rows = []
    for name, entry in entries.items():
        facts = entry.get("facts") or {}
        row = {column: None for column in COLUMNS}
        row.update({key: facts.get(key) for key in ("frames", "shots", "k1", "k2", "uncertainty_px", "doubtful", "reason")})
        if "shot_list" in facts:
            row.update(_shot_facts(facts["shot_list"]))
        if "camera" in facts or "doubtful_frames" in facts:
            row.update(_camera_facts(facts))
        row.update(input=entry.get("input"), outputs=entry.get("outputs") or [], status=entry.get("status"),
                   skipped=int(name in skipped), seconds=entry.get("seconds"), attempts=entry.get("attempts"),
                   worker=entry.get("worker"), error=entry.get("error"))
        if "shot_list" in facts:
            row["shot_list"] = facts["shot_list"]
        rows.append(row)
    return rows


def write_report(out_dir: Path, rows: list[dict]) -> tuple[Path, Path]:
    """``DIR/report.csv`` and ``DIR/report.json`` (atomic); returns their paths."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        cells = [";".join(row[c]) if c == "outputs" else row[c] for c in COLUMNS]
        writer.writerow(["" if v is None else (int(v) if isinstance(v, bool) else v) for v in cells])
    paths = Path(out_dir) / "report.csv", Path(out_dir) / "report.json"
    atomic_write_text(paths[0], text.getvalue())
    atomic_write_text(paths[1], json.dumps(rows, indent=1, default=str) + "\n")
    return paths
