"""The job options of ``correct``, ``distort``, ``estimate``, ``calibrate`` (and ``crops``) and the
run of a job from the command line:

``glradial correct|distort|estimate|calibrate IN [IN ...] --out-dir DIR [--workers N | --ray [ADDRESS]]``

IN is a file, a folder, a glob or ``@LIST`` (:mod:`glradial.jobs.inputs`); each output lands in
DIR under its input's file name (:mod:`glradial.jobs.tasks`); DIR/manifest.json, DIR/report.csv and
DIR/report.json close the job. ``--workers N`` (a local process pool, the default, one worker per
core) or ``--ray`` (Ray on this machine) or ``--ray ADDRESS`` (``auto``, ``ray://head:10001``: a
cluster). Exit status 1 when an input failed (the summary lists them).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..commands import UsageError, non_negative_int, positive_float, positive_int, show_progress
from ..threads import cores
from .tasks import JOB_COMMANDS, CommandWork, planned_outputs

__all__ = ["add_job_options", "wants_job", "check_one_file_form", "run_job_command", "JOB_OPTIONS", "runner_factory", "closing", "command_options"]

#: the options a job adds to a command (never handed to the command's own run)
JOB_OPTIONS = ("out_dir", "workers", "ray", "retries", "gpus_per_worker", "threads_per_worker")
#: options that name one output file or stream: a job refuses them (each input has its own outputs)
SINGLE_OUTPUTS = ("sidecar", "opentrackio", "send", "overlay", "topview")
#: what argparse adds that is not an option of the command
_NOT_OPTIONS = ("func", "_subparser", "command", "quiet", "paths", "input", "output", "inputs", "overwrite")
LOCAL = "local"


def add_job_options(parser: argparse.ArgumentParser, command: str) -> None:
    """``--out-dir --workers --ray --retries --threads-per-worker --gpus-per-worker`` (``crops``: no ``--out-dir``, it has ``--out``)."""
    group = parser.add_argument_group("many inputs: a job (docs/CLI.md, 'Jobs over many files')")
    if command != "crops":
        group.add_argument("--out-dir", metavar="DIR",
                           help="run over every INPUT (files, folders, globs, @LIST: a file of paths), each output in DIR under its "
                                "input's file name (estimate, calibrate: NAME.json); DIR/manifest.json lets a rerun skip what is "
                                "complete; DIR/report.csv and report.json close the job")
    group.add_argument("--workers", type=positive_int, metavar="N",
                       help="local worker processes (default: one per core); with --ray: the number of Ray actors "
                            "(default: one per CPU of the cluster)")
    group.add_argument("--ray", nargs="?", const=LOCAL, metavar="ADDRESS",
                       help="run on Ray: alone (or 'local'), Ray started on this machine; ADDRESS (auto, ray://head:10001) joins a cluster "
                            "(needs pip install 'glradial[cluster]')")
    group.add_argument("--retries", type=non_negative_int, default=None, metavar="N",
                       help="attempts after a failure (an error or the worker's death) before an input is recorded as failed (default 1)")
    group.add_argument("--threads-per-worker", type=positive_int, metavar="T",
                       help="each worker's threads (OpenCV, onnxruntime, FFmpeg codecs and scaling, llvmpipe, BLAS); with --ray "
                            "also the CPUs Ray reserves for each actor (default: cores // workers, at least 1; docs/CLI.md)")
    group.add_argument("--gpus-per-worker", type=positive_float, metavar="G",
                       help="with --ray: GPUs Ray reserves for each actor (0.5: two actors share one; the GL context then runs on "
                            "the node's GPU where its EGL driver is NVIDIA's)")


def wants_job(args: argparse.Namespace) -> bool:
    """Whether the command line is a job (``--out-dir``, or ``crops`` with ``--workers``/``--ray``)."""
    if args.command == "crops":
        return args.workers is not None or args.ray is not None
    return getattr(args, "out_dir", None) is not None


def check_one_file_form(args: argparse.Namespace) -> None:
    """Without ``--out-dir``: the job options are refused and the one-file form's paths counted."""
    given = [f"--{name.replace('_', '-')}" for name in JOB_OPTIONS[1:] if getattr(args, name, None) is not None]
    if given:
        raise UsageError(f"{', '.join(given)} run(s) a job: give --out-dir DIR" if args.command != "crops" else
                         f"{', '.join(given)} need(s) --workers N or --ray")
    paths = getattr(args, "paths", None)
    if paths is None:
        return
    wanted = 2 if args.command in ("correct", "distort") else 1
    if len(paths) != wanted:
        form = "INPUT OUTPUT" if wanted == 2 else "one IMG|VIDEO"
        raise UsageError(f"give {form} (got {len(paths)} paths), or many inputs with --out-dir DIR")


def command_options(args: argparse.Namespace) -> dict:
    """The command's own options (what makes two runs the same job), without paths and job options."""
    return {k: v for k, v in sorted(vars(args).items()) if k not in _NOT_OPTIONS + JOB_OPTIONS and not k.startswith("job_")
            and k != "json"}


def runner_factory(work, args: argparse.Namespace, tasks: int):
    """A function that makes the job's runner: Ray actors (``--ray``) or local processes."""
    if args.ray is None:
        if args.gpus_per_worker is not None:
            raise UsageError("--gpus-per-worker is for --ray (Ray reserves GPUs for its actors)")
        workers = min(args.workers or cores(), tasks)
        from .pool import ProcessRunner

        return lambda: ProcessRunner(work, workers, args.threads_per_worker)
    from .ray_runner import INSTALL_HINT, ray_available

    if not ray_available():
        raise UsageError(INSTALL_HINT)
    from .ray_runner import RayRunner

    if os.path.exists(args.ray):
        raise UsageError(f"--ray took the input {args.ray!r} as its ADDRESS: put --ray after the inputs, or write --ray local")
    address = None if args.ray == LOCAL else args.ray
    workers = min(args.workers, tasks) if args.workers else None
    return lambda: RayRunner(work, address, workers, threads_per_worker=args.threads_per_worker,
                             gpus_per_worker=args.gpus_per_worker or 0.0)


def run_job_command(args: argparse.Namespace) -> int:
    """Run the job the command line asks for; the exit status (1 when an input failed)."""
    from .runner import run_job

    if args.command == "crops":
        from .crop_shards import crop_job

        inputs, work, options, planned = crop_job(args)
        out_dir = args.out
    else:
        inputs, work, options, planned = _command_job(args)
        out_dir = args.out_dir
    summary = run_job(args.command, inputs, out_dir, runner_factory(work, args, len(inputs)), options, planned,
                      retries=1 if args.retries is None else args.retries, overwrite=bool(getattr(args, "overwrite", False)),
                      progress=show_progress(args))
    return closing(args.command, summary, Path(out_dir))


def _command_job(args: argparse.Namespace):
    """``(inputs, work, options, planned)`` of ``correct``/``distort``/``estimate``/``calibrate`` over many inputs."""
    if args.command not in JOB_COMMANDS:
        raise UsageError(f"'{args.command}' does not run over many inputs (--out-dir is for {', '.join(JOB_COMMANDS)})")
    given = [f"--{name.replace('_', '-')}" for name in SINGLE_OUTPUTS if getattr(args, name, None)]
    if given:
        raise UsageError(f"{', '.join(given)} names one output; in a job each input's outputs go to --out-dir")
    from .inputs import expand_inputs

    inputs = expand_inputs(args.paths if args.command != "estimate" else args.inputs)
    options = command_options(args)
    return inputs, CommandWork(args.command, options), options, lambda source: planned_outputs(args.command, options, source)


def closing(command: str, summary, out_dir: Path) -> int:
    """The closing summary (stdout) and the exit status."""
    if summary.report is None:
        return 0
    print(f"{command}: {len(summary.done)} done, {len(summary.skipped)} already complete, {len(summary.failed)} failed "
          f"({summary.frames} frames, {summary.seconds:.1f} s); report: {summary.report[0]}", flush=True)
    if summary.failed:
        from .manifest import Manifest

        entries = Manifest(out_dir, command, {}).entries
        for name in summary.failed:
            print(f"  failed: {entries[name]['input']}: {entries[name]['error']}", flush=True)
    return 1 if summary.failed else 0
