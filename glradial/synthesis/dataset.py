"""The crops dataset writer: images plus one labels file, split by panorama, atomic, resumable.

Convention (layout of ``DIR``):

* ``DIR/manifest.json``: the settings (seed, count, sizes, inverse, supersample grid, splits, format) and the
  panoramas (id, path, split). Written first; a resumed run must have the same settings and inputs.
* ``DIR/<split>/<index:07d>.<ext>``: crop ``index`` (0 .. count-1), uint8 RGB, ``out_size``.
* ``DIR/labels.csv``: one row per crop: ``index, file, split, panorama_id, panorama, seed, pan,
  tilt, roll, hfov, k1, k2, size_w, size_h, out_w, out_h, inverse`` (angles in degrees, k in lens
  units of the ``size`` frame). Written last: its presence means the dataset is complete.

Crop ``index`` uses ``sample_crop_params(count, seed)[index]`` on panorama ``index % P`` (panoramas
in the order given), so the content of every file is fixed by the settings alone. Panoramas are
assigned to train/val/test as a whole (never one panorama in two splits): they are shuffled with
``default_rng(seed)`` and cut by the split fractions (each non-empty split gets at least one
panorama when there are enough). Every file is written to a temporary name in its folder and
renamed when complete (``glradial.media.atomic``), so an interrupted run leaves only complete files, and
a rerun skips them. The manifest binds the folder only once it holds a crop: a run that fails (or
is killed) before its first crop does not stop a later run with other settings.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import check_count
from ..lens.lens import frame_size
from ..lens.metrics import PAPER_SIZE
from ..lens.options import INVERSES, InverseMethod
from ..media.atomic import atomic_write_text
from .crops import CropParams, PanoramaRenderers, panorama_file_size, sample_crop_params, supersample_grid

SPLITS = ("train", "val", "test")
FORMATS = ("png", "jpg")
#: Crops rendered per renderer call while writing.
CHUNK = 32
LABEL_COLUMNS = (
    "index", "file", "split", "panorama_id", "panorama", "seed", "pan", "tilt", "roll", "hfov", "k1", "k2",
    "size_w", "size_h", "out_w", "out_h", "inverse",
)


@dataclass(frozen=True)
class DatasetSummary:
    """What :func:`write_crops_dataset` did: crops written now, crops already there, per-split counts."""

    out_dir: Path
    written: int
    skipped: int
    per_split: dict[str, int]
    labels: Path


def assign_splits(count: int, fractions: Sequence[float], seed: int) -> list[str]:
    """Split name of each of ``count`` panoramas (a pure function of the arguments).

    ``fractions`` (train, val, test) are >= 0 and sum to 1. Panoramas are shuffled with
    ``default_rng(seed)``; val and test get ``round(fraction * count)`` panoramas, at least one each
    when their fraction is > 0 and there are at least 3 panoramas; train gets the rest.
    """
    fractions = tuple(float(f) for f in fractions)
    if len(fractions) != 3 or any(not math.isfinite(f) or f < 0 for f in fractions) or abs(sum(fractions) - 1) > 1e-6:
        raise ValueError(f"split fractions must be three numbers >= 0 summing to 1, got {fractions}")
    sizes = [0, 0, 0]
    for s in (1, 2):
        sizes[s] = int(round(fractions[s] * count))
        if fractions[s] > 0 and count >= 3:
            sizes[s] = max(sizes[s], 1)
    if fractions[0] > 0 and count >= 1:
        while sizes[1] + sizes[2] > count - 1 and (sizes[1] or sizes[2]):
            big = 1 if sizes[1] >= sizes[2] else 2
            sizes[big] -= 1
    sizes[0] = count - sizes[1] - sizes[2]
    order = np.random.default_rng(seed).permutation(count)
    names = [""] * count
    start = 0
    for split, size in zip(SPLITS, sizes):
        for i in order[start : start + size]:
            names[int(i)] = split
        start += size
    return names


def _panorama_ids(paths: Sequence[Path]) -> list[str]:
    ids: list[str] = []
    seen: dict[str, int] = {}
    for path in paths:
        stem = path.stem
        n = seen.get(stem, 0)
        seen[stem] = n + 1
        ids.append(stem if n == 0 else f"{stem}-{n}")
    return ids


def write_crops_dataset(
    panoramas: Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    *,
    count: int,
    seed: int,
    size: tuple[int, int] = PAPER_SIZE,
    out_size: tuple[int, int] | None = None,
    inverse: InverseMethod = "exact",
    supersample: int | str = 1,
    splits: Sequence[float] = (0.8, 0.1, 0.1),
    image_format: str = "png",
    progress: Callable[[int], None] | None = None,
) -> DatasetSummary:
    """Write ``count`` crops of ``panoramas`` (image files, 2:1) to ``out_dir`` (see the module docstring).

    Every panorama is checked (:func:`~glradial.synthesis.crops.panorama_file_size`: readable, 2:1) before
    anything is written. Resumes: files already present are complete (atomic writes) and skipped; a
    ``manifest.json`` with other settings or inputs is an error (``ValueError``) once the folder
    holds a crop, and is replaced while it holds none. A first run that fails before its first crop
    removes what it made (manifest, split folders, ``out_dir``). ``progress(n)`` is called with the
    number of crops finished (written or skipped) since the last call. ``size``, ``out_size``,
    ``inverse`` and ``supersample`` are as in :class:`~glradial.synthesis.crops.CropRenderer`.
    """
    _check_settings(count, seed, image_format, inverse)
    size = frame_size(size)
    out_size = frame_size(out_size) if out_size is not None else size
    grid = supersample_grid(supersample, size, out_size)  # validated before anything is written
    paths = [Path(p) for p in panoramas]
    if not paths:
        raise ValueError("at least one panorama is needed")
    for path in paths:  # every input checked before anything is written
        panorama_file_size(path)
    ids = _panorama_ids(paths)
    split_of = assign_splits(len(paths), splits, seed)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"out_dir {str(out)!r} exists and is not a folder")
    made_out = not out.exists()
    out.mkdir(parents=True, exist_ok=True)

    manifest = _manifest(seed, count, size, out_size, inverse, grid, splits, image_format, ids, paths, split_of)
    fresh = _claim_manifest(out, manifest)

    params = sample_crop_params(count, seed, size=size)
    files = [Path(split_of[i % len(paths)]) / f"{i:07d}.{image_format}" for i in range(count)]
    made_splits = [out / split for split in sorted(set(split_of)) if not (out / split).exists()]
    try:
        written, skipped = _write_crops(out, paths, files, params, size, out_size, inverse, grid, split_of, image_format, progress)
    except BaseException:
        if fresh and not _holds_crops(out):  # a first run that failed before its first crop leaves nothing
            _undo_first_run(out, made_out, made_splits, image_format)
        raise
    labels = out / "labels.csv"
    rows = ([i, files[i].as_posix(), split_of[i % len(paths)], ids[i % len(paths)], str(paths[i % len(paths)]), seed]
            + [repr(v) for v in (p.pan, p.tilt, p.roll, p.hfov, p.k1, p.k2)]
            + [size[0], size[1], out_size[0], out_size[1], inverse] for i, p in enumerate(params))
    atomic_write_text(labels, _csv_text(LABEL_COLUMNS, rows))
    per_split = {s: sum(1 for i in range(count) if split_of[i % len(paths)] == s) for s in SPLITS}
    return DatasetSummary(out, written, skipped, per_split, labels)


def _manifest(seed: int, count: int, size: tuple[int, int], out_size: tuple[int, int], inverse: str, grid: tuple[int, int],
              splits: Sequence[float], image_format: str, ids: list[str], paths: list[Path], split_of: list[str]) -> dict:
    """What ``manifest.json`` holds: the settings and inputs a resumed run must repeat."""
    return {
        "format": "glradial-crops-1",
        "seed": int(seed),
        "count": int(count),
        "size": list(size),
        "out_size": list(out_size),
        "inverse": inverse,
        "supersample": list(grid),
        "splits": dict(zip(SPLITS, (float(f) for f in splits))),
        "image_format": image_format,
        "panoramas": [
            {"id": pid, "path": str(path), "split": split} for pid, path, split in zip(ids, paths, split_of)
        ],
    }


def _check_settings(count: object, seed: object, image_format: object, inverse: object) -> None:
    check_count("count", count)
    check_count("seed", seed, minimum=0)
    if image_format not in FORMATS:
        raise ValueError(f"image_format must be one of {FORMATS}, got {image_format!r}")
    if inverse not in INVERSES:
        raise ValueError(f"inverse must be 'exact' or 'drap', got {inverse!r}")


def _claim_manifest(out: Path, manifest: dict) -> bool:
    """Write ``manifest.json`` unless the same one is there; ``ValueError`` when another one binds
    crops already written. Returns whether this run starts the dataset (a fresh manifest)."""
    manifest_path = out / "manifest.json"
    fresh = not manifest_path.exists()
    if not fresh:
        old = json.loads(manifest_path.read_text())
        if old != manifest:
            if _holds_crops(out):
                changed = sorted(k for k in set(old) | set(manifest) if old.get(k) != manifest.get(k))
                raise ValueError(
                    f"{str(out)!r} holds a crops dataset made with other settings ({', '.join(changed)} differ); "
                    f"use another folder, the same arguments to resume, or delete the folder"
                )
            fresh = True  # left by a run that wrote no crop (killed early): it binds nothing
    if fresh:
        atomic_write_text(manifest_path, json.dumps(manifest, indent=2) + "\n")
    return fresh


def _undo_first_run(out: Path, made_out: bool, made_splits: list[Path], image_format: str) -> None:
    """Remove what a first run made (split folders, manifest, ``out``) when it wrote no crop."""
    for folder in made_splits:
        _remove_stale(folder, image_format)
        with contextlib.suppress(OSError):
            folder.rmdir()
    (out / "manifest.json").unlink(missing_ok=True)
    if made_out:
        with contextlib.suppress(OSError):
            out.rmdir()


def _csv_text(header: Sequence[str], rows) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buffer.getvalue()


def _holds_crops(out: Path) -> bool:
    """Whether ``out`` holds any finished crop (or a labels file) of a crops dataset."""
    if (out / "labels.csv").exists():
        return True
    return any(
        f.suffix[1:] in FORMATS and not f.name.startswith(".")
        for split in SPLITS if (out / split).is_dir() for f in (out / split).iterdir()
    )


def _remove_stale(folder: Path, image_format: str) -> None:
    """Remove the temporary files a killed run (SIGKILL) left in ``folder``."""
    for stale in folder.glob(f".*.tmp.{image_format}"):
        stale.unlink()


def _write_crops(
    out: Path, paths: list[Path], files: list[Path], params: list[CropParams], size: tuple[int, int],
    out_size: tuple[int, int], inverse: str, grid: tuple[int, int], split_of: list[str], image_format: str,
    progress: Callable[[int], None] | None,
) -> tuple[int, int]:
    """Render and write the crops whose file is missing -> ``(written, skipped)``."""
    count = len(files)
    for split in set(split_of):
        (out / split).mkdir(exist_ok=True)
        _remove_stale(out / split, image_format)
    written = skipped = 0
    with PanoramaRenderers(paths, size=size, out_size=out_size, inverse=inverse, supersample=grid) as renderers:  # type: ignore[arg-type]
        for p_index in range(len(paths)):
            mine = range(p_index, count, len(paths))
            todo = [i for i in mine if not (out / files[i]).is_file()]
            skipped += len(mine) - len(todo)
            if progress is not None and len(mine) > len(todo):
                progress(len(mine) - len(todo))
            for start in range(0, len(todo), CHUNK):
                chunk = todo[start : start + CHUNK]
                images = renderers.render([params[i] for i in chunk], [p_index] * len(chunk))
                for i, image in zip(chunk, images):
                    _write_image(out / files[i], image)
                    written += 1
                if progress is not None:
                    progress(len(chunk))

    return written, skipped


def _write_image(path: Path, image: np.ndarray) -> None:
    """Write the RGB crop atomically; a failed write names ``path`` and the errno (e.g. ENOSPC)."""
    from ..media.image_io import write_image

    write_image(path, image)


def read_labels(path: str | os.PathLike) -> tuple[list[dict[str, str]], list[CropParams]]:
    """Rows of a ``labels.csv`` (as strings) and the :class:`CropParams` of each row."""
    with open(path, newline="") as handle:
        rows = list(csv.DictReader(handle))
    params = [CropParams(*(float(r[k]) for k in ("pan", "tilt", "roll", "hfov", "k1", "k2"))) for r in rows]
    return rows, params
