"""Jobs on a real Ray cluster (``--ray ADDRESS``): one local Ray head for the module (two CPUs, so
two actors; a small object store; no dashboard), jobs run by the ``glradial`` command in a
subprocess that joins it, as a user's would. Outputs equal the one-file commands' (correct --auto,
calibrate); an actor's process killed by its pid mid-task leaves no partial output and the job
completes; a corrupt input is recorded while the others complete; a second run does nothing and
says so; Ctrl-C leaves the manifest consistent. Ray pins the head to the machine's reachable
address, not 127.0.0.1 (``ray._private.services.resolve_ip_for_localhost``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from job_inputs import ROOT, corrupt, ignore_sigint, image, pan_video, panorama, pitch_view, rows_of, wait_for_a_done_input
from test_jobs import same_output

from glradial.cli import main

ray = pytest.importorskip("ray", reason="the job tests on Ray need the cluster extra: pip install -e '.[cluster]'")
pytestmark = pytest.mark.slow  # a Ray head takes 9-13 s to start on this loaded 2-core machine


@pytest.fixture(scope="module")
def address():
    start = time.perf_counter()
    context = ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=80 * 1024 * 1024,
                       _node_ip_address="127.0.0.1", log_to_driver=False, configure_logging=False)
    print(f"Ray head up in {time.perf_counter() - start:.1f} s")
    yield context.address_info["gcs_address"]
    ray.shutdown()


@pytest.fixture(scope="module")
def media(tmp_path_factory) -> dict[str, Path]:
    folder, pano = tmp_path_factory.mktemp("media"), panorama()
    return {"v0": pan_video(folder / "v0.mkv", pano), "v1": pan_video(folder / "v1.mkv", pano, x0=600),
            "i0": image(folder / "i0.png", pano), "i1": image(folder / "i1.png", pano, 40), "bad": corrupt(folder / "bad.png")}


def glradial(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "glradial", *args], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=ignore_sigint)


def busy_actor_pid(deadline: float) -> int | None:
    """The pid of a Ray worker process running a job task (Ray titles it ``ray::JobWorker.run``)."""
    while time.monotonic() < deadline:
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
            except OSError:
                continue
            if title.startswith(b"ray::JobWorker.run"):
                return int(pid)
        time.sleep(0.05)
    return None


def test_correct_auto_on_ray_with_a_killed_worker_and_a_corrupt_input(tmp_path, address, media):
    out = tmp_path / "out"
    names = ("v0", "v1", "i0", "i1", "bad")
    job = glradial("correct", *(str(media[k]) for k in names), "--auto", "--backend", "cpu", "--out-dir", str(out),
                   "--ray", address)
    time.sleep(1.0)
    killed = busy_actor_pid(time.monotonic() + 120)
    assert killed is not None, "no actor ever ran a task"
    os.kill(killed, signal.SIGKILL)
    said, err = job.communicate(timeout=600)
    assert job.returncode == 1, err
    assert "4 done, 0 already complete, 1 failed" in said and f"failed: {media['bad']}" in said
    rows = rows_of(out)
    assert rows["bad.png"]["status"] == "failed" and "corrupt" in rows["bad.png"]["error"]
    assert any(rows[media[k].name]["attempts"] == "2" for k in names[:4]), "the killed task was not retried"
    assert all(not row["worker"].endswith(f":{killed}") for row in rows.values() if row["status"] == "done")
    assert rows["v0.mkv"]["frames"] == "10" and rows["v0.mkv"]["shots"] == "1"
    expected = {"manifest.json", "report.csv", "report.json", "v0.mkv", "v0.mkv.lens.csv", "v1.mkv", "v1.mkv.lens.csv",
                "i0.png", "i1.png"}
    assert set(os.listdir(out)) == expected  # no partial file, no staging folder
    for key in ("v0", "i0"):  # the others' outputs come from the same code on the same actors
        single = tmp_path / f"single_{media[key].name}"
        assert main(["correct", str(media[key]), str(single), "--auto", "--backend", "cpu"]) == 0
        same_output(out / media[key].name, single)
        if key.startswith("v"):
            assert (out / f"{media[key].name}.lens.csv").read_bytes() == Path(f"{single}.lens.csv").read_bytes()


def test_calibrate_on_ray_then_a_rerun_does_nothing(tmp_path, address, capsys):
    views = [tmp_path / "view0.png", tmp_path / "view1.png"]
    cams = [pitch_view(path, pan) for path, pan in zip(views, (0.0, 3.0))]
    out = tmp_path / "cal"
    job = glradial("calibrate", str(tmp_path / "view*.png"), "--out-dir", str(out), "--ray", address)
    said, err = job.communicate(timeout=600)
    assert job.returncode == 0, err
    for view, cam in zip(views, cams):
        assert main(["calibrate", str(view), "--json"]) == 0
        alone = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
        assert json.loads((out / f"{view.name}.json").read_text()) == alone
        assert alone[0]["focal"] == pytest.approx(cam.focal, rel=0.01)
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    again = glradial("calibrate", str(tmp_path / "view*.png"), "--out-dir", str(out), "--ray", address)
    said, err = again.communicate(timeout=300)
    assert again.returncode == 0 and "nothing to do: all 2 input(s) already complete" in said, err
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before


def test_ctrl_c_on_ray_leaves_the_manifest_consistent(tmp_path, address, media):
    out = tmp_path / "out"
    long = pan_video(tmp_path / "long.mkv", panorama(), n=60)  # last, so that work remains when the signal comes
    inputs = [str(media[k]) for k in ("v0", "v1", "i0")] + [str(long)]
    job = glradial("correct", *inputs, "--k1", "-0.2", "--backend", "cpu", "--out-dir", str(out), "--ray", address, "--workers", "1")
    wait_for_a_done_input(out, job, 300)
    job.send_signal(signal.SIGINT)
    _, err = job.communicate(timeout=120)
    assert job.returncode == 130, err
    entries = json.loads((out / "manifest.json").read_text())["entries"]
    done = sorted(n for n, e in entries.items() if e["status"] == "done")
    assert done and all(e["status"] in ("done", "pending") for e in entries.values())
    assert sorted(os.listdir(out)) == sorted(["manifest.json", "report.csv", "report.json", *done])
    for name in done:
        single = tmp_path / f"single_{name}"
        assert main(["correct", str(next(p for p in inputs if Path(p).name == name)), str(single), "--k1", "-0.2", "--backend", "cpu"]) == 0
        same_output(out / name, single)


def test_an_actor_gets_its_share_of_the_cpus_as_its_thread_budget(address):
    """Two actors on the two-CPU head: each reserves 1 CPU and runs with a budget of 1 thread (Ray's
    OMP_NUM_THREADS and glradial's own pools agree); one actor given 2 threads reserves both CPUs."""
    from glradial.jobs.ray_runner import RayRunner
    from glradial.jobs.tasks import CommandWork

    work = CommandWork("estimate", {})
    for workers, threads, expected in ((2, None, 1), (1, 2, 2)):
        runner = RayRunner(work, None, workers, threads_per_worker=threads)
        try:
            seen = ray.get([slot[0].threads.remote() for slot in runner.slots])
            assert seen == [{"budget": expected, "OMP_NUM_THREADS": str(expected), "LP_NUM_THREADS": str(expected),
                             "cv2": expected}] * workers
            assert ray.available_resources().get("CPU", 0) == 2 - workers * expected
        finally:
            runner.close()
