"""Subcommands of the ``glradial`` command, one module each.

Contract (read by :mod:`glradial.cli`): a module ``glradial/commands/<name>.py`` exposes

* ``add_parser(subparsers) -> argparse.ArgumentParser``: adds its subparser (named ``<name>``) with a
  help text that documents every option and its units, and
* ``run(args) -> int``: does the work, returns the exit status (0 on success).

Modules import heavy libraries (moderngl, onnxruntime, torch) inside ``run``, never at import time,
so that ``glradial --help`` stays fast. ``run`` reports bad input by raising :class:`UsageError`
(wrong combination of options: exit 2), :class:`CliError`, ``ValueError``, ``TypeError`` or ``OSError``
(exit 1); the CLI prints one line ``glradial: error: <message>`` and no traceback. Outputs are written
atomically (:mod:`glradial.media.atomic`, :mod:`glradial.media.image_io`, :mod:`glradial.media.video_io`).

Shared helpers for command modules live here: :func:`parse_size`, :func:`positive_int`,
:func:`show_progress`, :func:`add_lens_options` / :func:`lens_from_args` (the lens given on the
command line) and :func:`read_lens_file`.
"""

from __future__ import annotations

import argparse
import functools
import json
import re
from pathlib import Path

from ..errors import Error

__all__ = [
    "CliError", "UsageError", "parse_size", "positive_int", "positive_float", "show_progress",
    "add_lens_options", "lens_from_args", "read_lens_file", "OPENCV_API_HINT", "InputPaths", "note", "cached_estimator", "keep_estimators", "estimators_kept",
    "MODEL_HELP", "PITCH_HELP",
]

_SIZE = re.compile(r"^\s*(\d+)\s*[xX×,]\s*(\d+)\s*$")


class CliError(Error):
    """A user-facing error: the CLI prints its message on one line and exits with status 1."""


class UsageError(CliError):
    """A wrong combination of options: printed with a pointer to ``--help``, exit status 2."""


class InputPaths(argparse.Action):
    """A command's positional paths (``nargs="+"``), kept as a list in ``dest``; the one-file form
    reads ``args.input`` (the first) and, where the command has ``OUTPUT``, ``args.output`` (the
    second). With ``--out-dir`` (a job, :mod:`glradial.jobs`) every path is an input."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        setattr(namespace, self.dest, list(values))
        namespace.input = values[0]
        namespace.output = values[1] if len(values) > 1 else None


def note(args: argparse.Namespace, *, replace: bool = True, **facts: object) -> None:
    """Record ``facts`` (frames, shots, the lens ...) for a job's report when the command runs as
    one input of a job (:mod:`glradial.jobs.tasks` gives ``args.job_facts``); else nothing.
    ``replace=False`` keeps facts already recorded (an estimate's lens over the one applied)."""
    store = getattr(args, "job_facts", None)
    if store is not None:
        store.update(facts if replace else {k: v for k, v in facts.items() if k not in store})


#: whether :func:`cached_estimator` keeps its estimators (set in a job's worker, :func:`keep_estimators`)
_KEEP = {"estimators": False}


def keep_estimators(keep: bool = True) -> None:
    """Keep the estimators the commands make for the rest of the process (a job's worker: its ONNX
    sessions serve every file it gets); a one-file command makes its own and frees it."""
    _KEEP["estimators"] = bool(keep)


def estimators_kept() -> bool:
    return _KEEP["estimators"]


def cached_estimator(model: str | None = None, threads: int | None = None):
    """The :class:`glradial.Estimator` of ``model`` (None: the bundled one) with ``threads``: made
    once per process where :func:`keep_estimators` was called, else a new one."""
    return _kept_estimator(model, threads) if _KEEP["estimators"] else _new_estimator(model, threads)


def _new_estimator(model: str | None, threads: int | None):
    from ..camera.estimator import Estimator

    return Estimator(model, threads=threads)


_kept_estimator = functools.lru_cache(maxsize=4)(_new_estimator)


def parse_size(text: str) -> tuple[int, int]:
    """argparse type for ``WxH`` (pixels), e.g. ``1920x1080`` -> ``(1920, 1080)``."""
    match = _SIZE.match(text)
    if not match:
        raise argparse.ArgumentTypeError(f"size must be WIDTHxHEIGHT in pixels, e.g. 1920x1080, got {text!r}")
    width, height = int(match.group(1)), int(match.group(2))
    if width <= 0 or height <= 0:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return width, height


def _int_at_least(text: str, minimum: int, kind: str) -> int:
    """Parse ``text`` as an integer ``>= minimum``; the error names ``kind`` (e.g. "positive")."""
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < minimum:
        raise argparse.ArgumentTypeError(f"expected a {kind} integer, got {text!r}") from None
    return value


def positive_int(text: str) -> int:
    """argparse type for an integer >= 1."""
    return _int_at_least(text, 1, "positive")


def non_negative_int(text: str) -> int:
    """argparse type for an integer >= 0 (seeds)."""
    return _int_at_least(text, 0, "non-negative")


def positive_float(text: str) -> float:
    """argparse type for a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """argparse type for a finite number (rejects nan/inf)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def show_progress(args: argparse.Namespace) -> bool | None:
    """Whether to draw progress bars: ``None`` (auto: when stderr is a terminal) unless ``--quiet``."""
    return False if getattr(args, "quiet", False) else None


LENS_FILE_HELP = (
    "JSON file with the lens: {\"k1\": .., \"k2\": .., \"cx\": .., \"cy\": .., \"pixel_aspect\": ..} "
    "(glradial units; what 'glradial estimate --json' prints, cx, cy, pixel_aspect optional; or the output of "
    "'glradial convert --json'), or an OpenCV "
    "calibration {\"camera_matrix\": 3x3, \"dist_coeffs\": [k1, k2, 0, 0(, 0)], \"size\": [W, H]} "
    "(size: the calibration's frame size in pixels; default the frame's own); any other key is refused"
)

#: ``--model`` of the commands that run the bundled estimator (estimate; correct and live with --auto)
MODEL_HELP = "use this ONNX model instead of the bundled one"
#: ``--pitch`` (estimate; correct --auto on images), each command saying first when it applies
PITCH_HELP = ("also fit the whole camera to the pitch template and combine its lens with the line fit/CNN answer where the "
              "template fits (docs/CAMERA.md: 3.75 -> 3.0 px on the Bundesliga clips; about 0.2-0.3 s more per frame); "
              "--no-pitch: the line fit/CNN answer alone")

#: the number keys of glradial's own lens format (the rest of ``schemas/lens_file`` ``numbers``
#: describes a line of 'glradial estimate --json', ignored here)
LENS_KEYS = ("k1", "k2", "cx", "cy", "pixel_aspect")


def add_lens_options(group: argparse._ArgumentGroup, *, k1_required: bool = False) -> None:
    """Add ``--k1 --k2 --cx --cy --pixel-aspect --lens`` to ``group`` (read by :func:`lens_from_args`)."""
    group.add_argument("--k1", type=finite_float, help="radial coefficient k1 (width-normalised, unitless)")
    group.add_argument("--k2", type=finite_float, help="radial coefficient k2 (width-normalised, unitless; default 0)")
    group.add_argument("--cx", type=finite_float, help="principal point's offset right of the image centre, in image "
                       "widths (default 0; OpenCV: (cx_px - (W-1)/2) / W)")
    group.add_argument("--cy", type=finite_float, help="principal point's offset below the image centre, in image "
                       "widths (default 0; OpenCV: (cy_px - (H-1)/2) / W)")
    group.add_argument("--pixel-aspect", type=positive_float, metavar="FY/FX",
                       help="pixel aspect fy / fx of an OpenCV calibration (default 1: square pixels)")
    group.add_argument("--lens", metavar="JSON", help=LENS_FILE_HELP)


def lens_given(args: argparse.Namespace) -> bool:
    """Whether any of :func:`add_lens_options`'s options was given."""
    return any(getattr(args, name) is not None for name in ("k1", "k2", "cx", "cy", "pixel_aspect", "lens"))


def lens_from_args(args: argparse.Namespace, size: tuple[int, int] | None = None):
    """The :class:`glradial.Lens` of ``--lens FILE`` or ``--k1 --k2 --cx --cy --pixel-aspect``
    (``size``: the frame's, for an OpenCV calibration file without its own size)."""
    from ..lens.lens import Lens

    numbers = {"k1": args.k1, "k2": args.k2, "cx": args.cx, "cy": args.cy, "pixel_aspect": args.pixel_aspect}
    if args.lens is not None:
        given = [f"--{name.replace('_', '-')}" for name, value in numbers.items() if value is not None]
        if given:
            raise UsageError(f"--lens cannot be combined with {', '.join(given)}")
        return read_lens_file(args.lens, size)
    if args.k1 is None and args.k2 is None:
        raise UsageError("give the lens with --k1 (and --k2, --cx, --cy, --pixel-aspect) or --lens FILE")
    return Lens(**{name: value for name, value in numbers.items() if value is not None})


def read_lens_file(path: str, size: tuple[int, int] | None = None):
    """A :class:`glradial.Lens` from a JSON file (formats: :data:`LENS_FILE_HELP`; checked against
    the ``lens_file`` schema, :mod:`glradial.schemas`)."""
    from ..lens.lens import Lens
    from ..schemas import validate

    source = Path(path)
    if not source.is_file():
        raise FileNotFoundError(f"lens file {str(source)!r} does not exist")
    try:
        document = json.loads(source.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"lens file {str(source)!r} is not JSON: {err}") from None
    if not isinstance(document, dict):
        raise ValueError(f"lens file {str(source)!r} must hold a JSON object, got {type(document).__name__}")
    if "glradial" in document:  # 'glradial convert --json': its k1, k2 are in the --to convention
        validate(document, "lens_file", f"lens file {str(source)!r} ('glradial convert --json' output)", "convert")
        return Lens(*document["glradial"])
    if "camera_matrix" in document or "dist_coeffs" in document:
        if "camera_matrix" not in document or "dist_coeffs" not in document:
            raise ValueError(f"lens file {str(source)!r}: an OpenCV calibration needs both camera_matrix and dist_coeffs")
        validate(document, "lens_file", f"lens file {str(source)!r} (an OpenCV calibration)", "opencv")
        calibrated = document.get("size", size)
        if calibrated is None:
            raise ValueError(f"lens file {str(source)!r}: an OpenCV calibration needs \"size\": [W, H] (pixels)")
        try:
            return Lens.from_opencv(document["camera_matrix"], document["dist_coeffs"], tuple(calibrated))
        except ValueError as err:
            raise ValueError(_cli_advice(source, str(err))) from None
    if "k1" not in document:
        raise ValueError(
            f"lens file {str(source)!r} has neither \"k1\" nor an OpenCV \"camera_matrix\": keys {sorted(document)}"
        )
    validate(document, "lens_file", f"lens file {str(source)!r} (glradial's numbers)", "numbers")
    return Lens(**{name: document[name] for name in LENS_KEYS if name in document})


#: the Python API's advice in :meth:`glradial.Lens.from_opencv`'s error, which each command words its own way
OPENCV_API_HINT = "Pass approximate=True to keep k1, k2 only."


def _cli_advice(source: Path, message: str) -> str:
    """``message`` of :meth:`Lens.from_opencv` with the Python-only advice replaced by command-line advice."""
    if OPENCV_API_HINT not in message:
        return f"lens file {str(source)!r}: {message}"
    return f"lens file {str(source)!r}: " + message.replace(
        OPENCV_API_HINT,
        "Set p1, p2, k3 ... to 0 in the file to keep k1, k2 only (an approximation), or get centred numbers with "
        "'glradial convert --from opencv --to width --approximate --size WxH --focal FX K1 K2 P1 P2 K3'.",
    )
