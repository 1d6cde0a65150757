"""Jobs over many files: ``glradial correct --auto`` of N videos (an archive's: a few seconds each,
640x360 H.264 by default) on the local process pool and on Ray actors, with 1 and 2 workers and
each worker's thread budget (``--threads-per-worker``, :mod:`glradial.threads`), and the per-file
overhead of each runner on tasks that do nothing. Writes docs/figures/bench_jobs.json.

    python bench/bench_jobs.py [--videos 8] [--frames 100] [--size 640x360] [--codec h264] [--noop 40]

Configurations, as ``RUNNER_WORKERSxTHREADS``: ``1x2`` (one worker with both cores: what one worker
gives alone), ``2x1`` (two workers, each its share: the default), ``1x1`` and ``2x2`` (two workers
each with all cores, oversubscribed: about what a worker did before it had a budget, when only
OpenCV and OpenMP were sized). ``speedup`` is ``1x2``'s time over ``2x1``'s.
What is timed: the job (:func:`glradial.jobs.runner.run_job`) with its runner already started
(pool processes spawned, Ray actors created, each worker warmed by one task of its own: imports,
ONNX session; Ray itself started once, as a cluster would be), so the speed-up is the work's; the
start-up and warm-up is reported beside it (``start_s``), and so is the workers' stop (``stop_s``). The overhead per file is the
time per no-op task (a task that writes one byte) with 2 workers, and Ray's minus the pool's. The
memory of one worker is its peak resident set (VmHWM) after the video job, and after one clip of
``--memory-size`` (1080p by default). The machine may be shared:
the load average before and after each measurement is recorded beside it, since other processes'
load depresses a speed-up (most where the kernel's autogroup gives each session, not each
process, a share: ``sched_autogroup``), and so are the cores the workers used (their CPU seconds over the run's).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
from figures import write_figure

from glradial.cli import build_parser
from glradial.jobs.command_line import command_options
from glradial.jobs.pool import ProcessRunner
from glradial.jobs.runner import run_job
from glradial.jobs.tasks import CommandWork, planned_outputs
from glradial.media.video_io import VideoInfo, VideoWriter
from glradial.threads import cores, share_of_cores

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class NoopWork:
    """A task that does nothing but write one byte: what remains is the runner's cost per file."""

    def __call__(self, source: str, staging: Path) -> dict:
        (staging / Path(source).name).write_bytes(b"1")
        return {"frames": 0}


def make_videos(folder: Path, count: int, frames: int, size: tuple[int, int], codec: str = "h264") -> list[Path]:
    """``count`` pans over the shipped field panorama, each from another place: H.264 (yuv420p, .mp4,
    as broadcast archives are) or FFV1 (gbrp, .mkv, lossless)."""
    pano = cv2.imread(str(ROOT / "tests" / "data" / "panorama_field_2048x1024.jpg"))[:, :, ::-1]
    pix_fmt, suffix = {"h264": ("yuv420p", ".mp4"), "ffv1": ("gbrp", ".mkv")}[codec]
    paths = []
    folder.mkdir(exist_ok=True)
    for k in range(count):
        path = folder / f"clip{k}{suffix}"
        x0 = 100 + (120 * k) % 840
        step = min(3.0, (pano.shape[1] - 480 - x0) / max(frames, 1))
        with VideoWriter(path, VideoInfo.of(size, 25, codec=codec, pix_fmt=pix_fmt)) as writer:
            for i in range(frames):
                x = int(x0 + step * i)
                writer.write(cv2.resize(pano[400:670, x : x + 480], size, interpolation=cv2.INTER_AREA))
        paths.append(path)
    return paths


def autogroup() -> str | None:
    """Whether the kernel groups CPU time by session (autogroup): then, on a machine busy with other
    sessions, all of one job's workers share one session's share, and a second worker gains little."""
    try:
        return Path("/proc/sys/kernel/sched_autogroup_enabled").read_text().strip()
    except OSError:
        return None


def peak_rss_mb(pids: list[int]) -> list[float]:
    """VmHWM (peak resident set) of each process, MB."""
    peaks = []
    for pid in pids:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                peaks.append(int(line.split()[1]) / 1024)
    return peaks


def warm_up(runner, inputs: list[Path], out: Path, options: dict, command: str) -> float:
    """Give each worker one task (its imports, model and caches loaded) without closing the runner; seconds."""
    close, runner.close = runner.close, lambda kill=False: None
    start = time.perf_counter()
    try:
        copies = []
        for i in range(len(runner.slots)):
            copies.append(out.parent / f"warm{i}{inputs[0].suffix}")
            shutil.copyfile(inputs[0], copies[-1])
        run_job(command, copies, out, lambda: runner, options, lambda s: planned_outputs(command, options, s), progress=False)
    finally:
        runner.close = close
        shutil.rmtree(out, ignore_errors=True)
    return time.perf_counter() - start


def cpu_seconds(pids: list[int]) -> float:
    """User + system CPU time of the processes and their waited-for children, s."""
    total = 0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # a helper process that ended
            continue
        total += sum(int(v) for v in fields[11:15])  # utime, stime, cutime, cstime
    return total / os.sysconf("SC_CLK_TCK")


def helpers(workers: list[int]) -> list[int]:
    """This process's descendants other than ``workers``: the runner's own processes (Ray's GCS,
    raylet, agents and idle workers; none for the pool)."""
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parents[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    found, frontier = set(), {os.getpid()}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return sorted(found - set(workers))


def timed_job(make, work, inputs: list[Path], out: Path, options: dict, command: str = "correct") -> dict:
    """Start the runner and warm each worker (timed), run the job on it (timed), note the workers' peak memory."""
    load_before = os.getloadavg()[0]
    runner = make()
    started = warm_up(runner, inputs, out, options, command)
    close = runner.close
    memory: list[float] = []

    pids = runner.pids()
    cpu_end: list[float] = []

    def close_noting_memory(kill: bool = False) -> None:
        cpu_end.append(cpu_seconds(pids))
        cpu_end.append(time.perf_counter())  # the job's work is over: stopping the workers is timed apart
        memory.extend(peak_rss_mb(pids))
        close(kill)

    runner.close = close_noting_memory
    others = helpers(pids)
    cpu, others_cpu, start = cpu_seconds(pids), cpu_seconds(others), time.perf_counter()
    summary = run_job(command, inputs, out, lambda: runner, options, lambda s: planned_outputs(command, options, s), progress=False)
    seconds, stopped = cpu_end[1] - start, time.perf_counter() - cpu_end[1]
    cpu = cpu_end[0] - cpu
    others_cpu = cpu_seconds([pid for pid in others if Path(f"/proc/{pid}").exists()]) - others_cpu
    assert not summary.failed and len(summary.done) == len(inputs), summary
    shutil.rmtree(out)
    return {"start_s": round(started, 2), "run_s": round(seconds, 2), "stop_s": round(stopped, 2), "workers_cpu_s": round(cpu, 2),
            "cores_used": round(cpu / seconds, 2), "runner_processes_cpu_s": round(others_cpu, 2), "worker_peak_rss_mb": [round(m) for m in memory],
            "load_before": round(load_before, 2), "load_after": round(os.getloadavg()[0], 2)}


def configurations(runner: str) -> list[tuple[int, int]]:
    """``(workers, threads per worker)`` measured: one worker with all cores, two with their share,
    one with one thread, and (the pool only: Ray does not place actors beyond its CPUs) two with all cores."""
    every, share = cores(), share_of_cores(2)
    found = [(1, every), (2, share), (1, 1)] + ([(2, every)] if runner == "pool" else [])
    return list(dict.fromkeys(found))


def runner_maker(name: str, work, workers: int, threads: int | None = None):
    """A function that makes the ``name`` runner ("pool" or "ray") of ``workers`` workers of ``threads`` threads."""
    if name == "pool":
        return lambda: ProcessRunner(work, workers, threads)
    from glradial.jobs.ray_runner import RayRunner

    return lambda: RayRunner(work, None, workers, threads_per_worker=threads)


def runner_figures(name: str, work, videos: list[Path], folder: Path, options: dict, args: argparse.Namespace) -> dict:
    """One runner's figures: every configuration in turn ``--repeats`` times (the fastest run of each
    kept), ``NAME_speedup`` (one worker with all cores over two with their share), the per-file
    cost of no-op tasks with 2 workers, and one worker's peak memory on a ``--memory-size`` clip."""
    results: dict = {}
    for _ in range(args.repeats):
        for workers, threads in configurations(name):
            timing = timed_job(runner_maker(name, work, workers, threads), work, videos, folder / "out", options)
            key = f"{name}_{workers}x{threads}"
            print(key, timing, flush=True)
            if key not in results or timing["run_s"] < results[key]["run_s"]:
                results[key] = timing
    one, two = configurations(name)[:2]
    results[f"{name}_speedup"] = round(results[f"{name}_{one[0]}x{one[1]}"]["run_s"] / results[f"{name}_{two[0]}x{two[1]}"]["run_s"], 3)
    noop_inputs = [folder / f"n{i}.txt" for i in range(args.noop)]
    for path in noop_inputs:
        path.write_bytes(b"0")
    timing = timed_job(runner_maker(name, NoopWork(), 2), NoopWork(), noop_inputs, folder / "out", {"noop": True}, command="noop")
    results[f"noop_{name}_ms_per_file"] = round(1000 * timing["run_s"] / args.noop, 1)
    results[f"{name}_2_start_s"] = timing["start_s"]
    big = make_videos(folder / f"big_{name}", 1, 30, tuple(int(v) for v in args.memory_size.split("x")), args.codec)
    timing = timed_job(runner_maker(name, work, 1), work, big, folder / "out", options)
    results[f"{name}_worker_peak_rss_mb_{args.memory_size}"] = timing["worker_peak_rss_mb"][0]
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--videos", type=int, default=8)
    parser.add_argument("--frames", type=int, default=100, help="frames per video (25 fps)")
    parser.add_argument("--size", default="640x360")
    parser.add_argument("--codec", choices=("h264", "ffv1"), default="h264", help="the videos' codec (the output keeps it)")
    parser.add_argument("--noop", type=int, default=40, help="no-op tasks for the per-file overhead")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each configuration, in turn; the fastest is kept")
    parser.add_argument("--memory-size", default="1920x1080", help="frame size of the clip one worker's memory is measured on")
    args = parser.parse_args()
    size = tuple(int(v) for v in args.size.split("x"))
    import ray

    folder = Path(tempfile.mkdtemp(prefix="bench_jobs."))
    try:
        videos = make_videos(folder, args.videos, args.frames, size, args.codec)
        work = CommandWork("correct", command_options(build_parser().parse_args(["correct", "x", "--out-dir", "d", "--auto", "--backend", "cpu"])))
        results: dict = {"videos": args.videos, "frames": args.frames, "size": list(size), "codec": args.codec,
                         "command": "correct --auto --backend cpu", "cores": cores(), "repeats": args.repeats, "sched_autogroup": autogroup()}
        results.update(runner_figures("pool", work, videos, folder, work.options, args))  # before Ray starts: its daemons take CPU
        start = time.perf_counter()
        ray.init(address="local", num_cpus=cores(), include_dashboard=False, log_to_driver=False, configure_logging=False)
        results["ray_init_s"] = round(time.perf_counter() - start, 2)
        results.update(runner_figures("ray", work, videos, folder, work.options, args))
        results["ray_overhead_ms_per_file"] = round(results["noop_ray_ms_per_file"] - results["noop_pool_ms_per_file"], 1)
        print(results, flush=True)
        write_figure("bench_jobs", results)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
        ray.shutdown()


if __name__ == "__main__":
    sys.exit(main())
