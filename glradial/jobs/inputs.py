"""A job's inputs: each command-line IN (a file, a folder, a glob or ``@LIST``) expanded to files.

Conventions: a folder gives the media files directly in it (not its sub-folders; hidden files
skipped), in name order; a glob (``*``, ``?``, ``[``; ``**`` spans folders) gives the files it
matches, in name order; ``@LIST`` names a text file of paths, one a line (blank lines and lines
starting with ``#`` skipped; a relative path is taken from the list's folder, as FFmpeg's concat
lists are), each itself a file, folder or glob. A file is taken as given whatever its extension
(the command says whether it can read it). Every output of a job is named by its input's file
name, so two inputs with the same file name are refused before any work.
"""

from __future__ import annotations

import glob
import os
from pathlib import Path
from typing import Sequence

from ..media.image_io import IMAGE_EXTENSIONS

__all__ = ["VIDEO_EXTENSIONS", "expand_inputs", "RESERVED_NAMES"]

#: container extensions a folder or a glob of a job is searched for, beside the still images
VIDEO_EXTENSIONS = frozenset({".mp4", ".m4v", ".mov", ".mxf", ".ts", ".m2ts", ".mts", ".mkv", ".webm", ".avi",
                              ".mpg", ".mpeg", ".y4m", ".flv", ".wmv", ".dv"})
#: names the job machinery writes in the output folder (no input may be named after them)
RESERVED_NAMES = ("manifest.json", "report.csv", "report.json")
_GLOB_CHARACTERS = set("*?[")


def _is_media(path: Path) -> bool:
    return path.suffix.lower() in IMAGE_EXTENSIONS or path.suffix.lower() in VIDEO_EXTENSIONS


def _folder_files(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".") and _is_media(p))


def _expand_one(item: str, base: Path | None) -> list[Path]:
    """The files of one IN (a file, a folder or a glob); ``base``: the folder of the ``@LIST`` it came from."""
    path = Path(item).expanduser()
    if base is not None and not path.is_absolute():
        path = base / path
    if path.is_dir():
        found = _folder_files(path)
        if not found:
            raise FileNotFoundError(f"input folder {str(path)!r} holds no image or video file")
        return found
    if path.is_file():
        return [path]
    if _GLOB_CHARACTERS & set(item):
        found = sorted(Path(p) for p in glob.glob(str(path), recursive=True) if Path(p).is_file())
        if not found:
            raise FileNotFoundError(f"input pattern {item!r} matches no file")
        return found
    raise FileNotFoundError(f"input {str(path)!r} does not exist (a file, a folder, a glob or @LIST)")


def _list_items(item: str) -> tuple[list[str], Path]:
    """The lines of ``@LIST`` and its folder."""
    listing = Path(item[1:]).expanduser()
    if not listing.is_file():
        raise FileNotFoundError(f"input list {str(listing)!r} (from {item!r}) does not exist")
    lines = [line.strip() for line in listing.read_text(encoding="utf-8").splitlines()]
    return [line for line in lines if line and not line.startswith("#")], listing.parent


def expand_inputs(items: Sequence[str]) -> list[Path]:
    """Every file the command-line ``items`` name (module docstring), each once, in the order given.

    Raises ``FileNotFoundError`` for an item that names nothing, ``ValueError`` for two files with
    the same name (their outputs would collide), a file named like the job's own files
    (:data:`RESERVED_NAMES`), or no file at all.
    """
    files: list[Path] = []
    for item in items:
        if item.startswith("@"):
            lines, base = _list_items(item)
            for line in lines:
                files.extend(_expand_one(line, base))
        else:
            files.extend(_expand_one(item, None))
    unique: dict[str, Path] = {}
    by_name: dict[str, Path] = {}
    for path in files:
        key = os.path.realpath(path)
        if key in unique:
            continue
        unique[key] = path
        if path.name in RESERVED_NAMES:
            raise ValueError(f"input {str(path)!r} is named like the job's own {path.name}: rename it")
        if path.name in by_name:
            raise ValueError(f"inputs {str(by_name[path.name])!r} and {str(path)!r} have the same file name: their outputs "
                             "would collide in the output folder (rename one, or run them as two jobs)")
        by_name[path.name] = path
    if not unique:
        raise ValueError(f"no input file in {list(items)!r}")
    return list(unique.values())
