"""The ``glradial`` command: argparse front end over ``glradial/commands/<name>.py``.

Every subcommand module exposes ``add_parser(subparsers)`` and ``run(args) -> int`` (see
:mod:`glradial.commands`). A module that is missing or fails to import does not break the others:
its subcommand is still listed and says why it cannot run.

Exit status: 0 success, 1 bad input or failed work (one line ``glradial: error: ...`` on stderr),
2 wrong usage (argparse errors and conflicting options), 130 interrupted (Ctrl-C), 143 terminated
(SIGTERM), 129 hung up (SIGHUP): the two signals unwind like Ctrl-C, so outputs (written
atomically) and temporary files are removed and nothing half-written is left. SIGINT stops a run
also when the process inherited it ignored (as it stops ffmpeg). ``-q/--quiet`` may
stand anywhere on the command line. Set ``GLRADIAL_DEBUG=1`` to get tracebacks.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import re
import signal
import sys
import threading
from typing import Sequence

from . import __version__
from .commands import CliError, UsageError
from .jobs.command_line import add_job_options, check_one_file_form, run_job_command, wants_job
from .jobs.tasks import JOB_COMMANDS

__all__ = ["main", "build_parser", "COMMANDS", "messages_to_stderr"]

#: subcommands in the order ``glradial --help`` lists them
COMMANDS = ("correct", "distort", "live", "estimate", "calibrate", "convert", "stmap", "crops", "stadium", "demo", "evaluate")

PROG = "glradial"


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line: ``glradial: error: ... (see 'PROG --help')``, and
    which takes negative numbers in exponent notation (``-8.1e-08``) as values, not options."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _unavailable(name: str, reason: str):
    def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
        parser = subparsers.add_parser(name, help=f"(unavailable: {reason})", description=f"unavailable: {reason}")
        parser.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
        return parser

    def run(args: argparse.Namespace) -> int:
        raise CliError(f"the '{name}' command is unavailable: {reason}")

    return add_parser, run


def build_parser() -> argparse.ArgumentParser:
    """The full parser; each subparser's ``func`` default is its module's ``run``."""
    parser = _Parser(
        prog=PROG,
        description=(
            "Radial lens distortion for sports-broadcast video. 'correct' removes a lens from images, "
            "folders and videos (given, per-frame track, or --auto: estimated); 'distort' puts it into "
            "graphics, the exact inverse (key and fill: alpha kept and interpolated premultiplied; "
            "OpenEXR floats; interlaced fields). 'estimate' reads the lens from frames (method auto: the "
            "pitch-line fit where it is surer than the CNN; how well, per source: README.md); each "
            "estimate states a 90 % bound and whether it is doubtful ('correct --auto' leaves a doubtful one "
            "uncorrected). "
            "Also: convert coefficients, export STMaps, render training crops and stadiums. "
            "Coefficients (k1, k2) are width-normalised: image width = 1, origin at the image centre, "
            "p_d = p_u (1 + k1 r^2 + k2 r^4)."
        ),
        epilog="Run 'glradial COMMAND --help' for the options of a command. GLRADIAL_DEBUG=1 shows tracebacks.",
    )
    parser.add_argument("--version", action="version", version=f"glradial {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars (they are drawn only on a terminal anyway)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"{__package__}.commands.{name}")
            add_parser, run = module.add_parser, module.run
        except ModuleNotFoundError as err:
            if err.name != f"{__package__}.commands.{name}":
                add_parser, run = _unavailable(name, f"missing module {err.name}")
            elif name == "evaluate":
                continue  # optional command
            else:
                add_parser, run = _unavailable(name, "not installed in this build")
        except Exception as err:  # a broken module must not break the other commands
            add_parser, run = _unavailable(name, f"{type(err).__name__}: {_one_line(err)}")
        sub = add_parser(subparsers)
        if name in JOB_COMMANDS + ("crops",) and getattr(run, "__module__", "") == f"{__package__}.commands.{name}":
            add_job_options(sub, name)
        # -q after the command too; SUPPRESS keeps a -q given before the command
        sub.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="no progress bars")
        sub.set_defaults(func=run, _subparser=sub)
    return parser


class _MessageFormatter(logging.Formatter):
    """A library message as the command line shows it: progress (INFO) as it is, a warning or an
    error prefixed ``glradial: warning:`` / ``glradial: error:``."""

    def format(self, record: logging.LogRecord) -> str:
        text = record.getMessage()
        return text if record.levelno < logging.WARNING else f"{PROG}: {record.levelname.lower()}: {text}"


@contextlib.contextmanager
def messages_to_stderr(level: int = logging.INFO):
    """While the block runs, glradial's log messages (the ``glradial`` logger and its children: an
    evaluation's progress, a video's warnings) at ``level`` and above go to ``sys.stderr`` as the
    command line shows them (:class:`_MessageFormatter`); also for the training scripts in ``net/``.
    The library itself only logs: an application that embeds it configures ``logging`` its own way."""
    logger = logging.getLogger("glradial")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(_MessageFormatter())
    before = logger.level
    logger.addHandler(handler)
    if logger.getEffectiveLevel() > level:
        logger.setLevel(level)
    try:
        yield
    finally:
        handler.flush()
        logger.removeHandler(handler)
        logger.setLevel(before)


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread so that everything unwinds as on Ctrl-C."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _terminate(signum: int, _frame: object) -> None:
    raise Terminated(signum)


@contextlib.contextmanager
def _signals_unwind():
    """SIGTERM and SIGHUP raise :class:`Terminated` and SIGINT ``KeyboardInterrupt`` while the command
    runs (main thread only), SIGINT also where the process was started with it ignored (Python then
    leaves it ignored: a background job of a script, some CI runners), so that it always stops a run
    and leaves nothing half-written, as it stops ffmpeg."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    wanted = {signal.SIGTERM: _terminate, **({signal.SIGHUP: _terminate} if hasattr(signal, "SIGHUP") else {})}
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        wanted[signal.SIGINT] = signal.default_int_handler
    previous = {signum: signal.signal(signum, handler) for signum, handler in wanted.items()}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``) and return the exit status."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help, --version, usage errors
        return stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 2)
    if not getattr(args, "command", None):
        parser.print_help(sys.stderr)
        return 2
    debug = bool(os.environ.get("GLRADIAL_DEBUG"))
    try:
        with _signals_unwind(), messages_to_stderr():
            if hasattr(args, "workers"):  # a command that runs as a job over many inputs
                if wants_job(args):
                    return run_job_command(args)
                check_one_file_form(args)
            return int(args.func(args) or 0)
    except Terminated as stop:
        sys.stderr.write(f"\n{PROG}: stopped by {signal.Signals(stop.signum).name}\n")
        return 128 + stop.signum
    except KeyboardInterrupt:
        sys.stderr.write(f"\n{PROG}: interrupted\n")
        return 130
    except UsageError as err:
        sys.stderr.write(f"{PROG}: error: {_one_line(err)} (see '{args._subparser.prog} --help')\n")
        return 2
    except BrokenPipeError:
        return 1
    except Exception as err:
        if debug:
            raise
        if isinstance(err, (CliError, ValueError, TypeError, OSError)):
            message = _one_line(err)
        else:
            message = f"{type(err).__name__}: {_one_line(err)}"
        sys.stderr.write(f"{PROG}: error: {message}\n")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
