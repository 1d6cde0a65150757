"""Jobs over many inputs on local worker processes (``glradial COMMAND IN ... --out-dir DIR
--workers N``, glradial/jobs): inputs expanded, outputs equal to the one-file commands', a corrupt
input recorded while the rest completes, a rerun that does nothing and says so, a worker killed
mid-task, Ctrl-C leaving the manifest consistent, estimate JSON, crops shards. The same
on a real Ray cluster: tests/jobs/test_jobs_ray.py."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from job_inputs import ROOT, corrupt, ignore_sigint, image, pan_video, panorama, read_frames, rows_of, wait_for_a_done_input

from glradial.cli import build_parser, main
from glradial.jobs.command_line import command_options
from glradial.jobs.inputs import expand_inputs
from glradial.jobs.pool import ProcessRunner
from glradial.jobs.runner import run_job
from glradial.jobs.tasks import CommandWork, planned_outputs

LENS = ["--k1", "-0.2", "--k2", "0.03", "--backend", "cpu"]


@pytest.fixture(scope="module")
def media(tmp_path_factory) -> dict[str, Path]:
    folder, pano = tmp_path_factory.mktemp("media"), panorama()
    return {"v0": pan_video(folder / "v0.mkv", pano), "v1": pan_video(folder / "v1.mkv", pano, x0=600),
            "i0": image(folder / "i0.png", pano), "i1": image(folder / "i1.png", pano, 40), "bad": corrupt(folder / "bad.png")}


def same_output(a: Path, b: Path) -> None:
    """Pixels equal: images read by OpenCV, videos decoded frame by frame (lossless FFV1)."""
    if a.suffix == ".png":
        np.testing.assert_array_equal(cv2.imread(str(a), cv2.IMREAD_UNCHANGED), cv2.imread(str(b), cv2.IMREAD_UNCHANGED))
        return
    fa, fb = read_frames(a), read_frames(b)
    assert len(fa) == len(fb) > 0
    for x, y in zip(fa, fb):
        np.testing.assert_array_equal(x, y)


def test_inputs_file_folder_glob_and_list(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for name in ("a/x.png", "a/y.mkv", "a/.hidden.png", "a/notes.txt", "b/z.jpg", "b/x.png"):
        (tmp_path / name).write_bytes(b"1")
    listing = tmp_path / "b" / "list.txt"
    listing.write_text("# a comment\n\nz.jpg\n../a/y.mkv\n")
    assert expand_inputs([str(tmp_path / "a")]) == [tmp_path / "a" / "x.png", tmp_path / "a" / "y.mkv"]
    assert [p.name for p in expand_inputs([str(tmp_path / "a" / "*.png")])] == ["x.png"]
    # a list's relative paths are taken from its folder; the same file twice is one input
    assert [p.name for p in expand_inputs(["@" + str(listing), str(tmp_path / "a" / "y.mkv")])] == ["z.jpg", "y.mkv"]
    with pytest.raises(ValueError, match="same file name"):
        expand_inputs([str(tmp_path / "a" / "x.png"), str(tmp_path / "b" / "x.png")])
    with pytest.raises(FileNotFoundError, match="missing.png"):
        expand_inputs([str(tmp_path / "missing.png")])
    with pytest.raises(FileNotFoundError, match="matches no file"):
        expand_inputs([str(tmp_path / "*.exr")])
    with pytest.raises(FileNotFoundError, match="nope.txt"):
        expand_inputs(["@" + str(tmp_path / "nope.txt")])


def test_job_equals_one_file_commands_and_records_a_corrupt_input(tmp_path, media, capsys):
    out = tmp_path / "out"
    inputs = [str(media[k]) for k in ("v0", "i0", "bad")]
    assert main(["correct", *inputs, "--out-dir", str(out), "--workers", "2", *LENS]) == 1
    said = capsys.readouterr()
    assert "2 done, 0 already complete, 1 failed" in said.out and f"failed: {media['bad']}" in said.out
    assert "retrying (attempt 2 of 2)" in said.err
    for key in ("v0", "i0"):
        single = tmp_path / f"single{media[key].suffix}"
        assert main(["correct", str(media[key]), str(single), *LENS]) == 0
        same_output(out / media[key].name, single)
    rows = rows_of(out)
    assert rows["bad.png"]["status"] == "failed" and rows["bad.png"]["attempts"] == "2" and "corrupt" in rows["bad.png"]["error"]
    assert rows["v0.mkv"]["status"] == "done" and rows["v0.mkv"]["frames"] == "10" and float(rows["v0.mkv"]["k1"]) == -0.2
    assert json.loads((out / "report.json").read_text())[0]["outputs"] == ["v0.mkv"]
    # nothing of the corrupt input, no staging folder, no temporary file
    assert sorted(os.listdir(out)) == ["i0.png", "manifest.json", "report.csv", "report.json", "v0.mkv"]


def test_rerun_skips_complete_work_and_says_so(tmp_path, media, capsys):
    out = tmp_path / "out"
    command = ["correct", str(media["i0"]), str(media["i1"]), "--out-dir", str(out), "--workers", "1", "--backend", "cpu"]
    assert main([*command, "--k1", "-0.1"]) == 0
    capsys.readouterr()
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert main([*command, "--k1", "-0.1"]) == 0
    assert "nothing to do: all 2 input(s) already complete" in capsys.readouterr().out
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before
    assert main([*command, "--k1", "-0.2"]) == 0  # other options: the same inputs are redone
    assert "2 done, 0 already complete" in capsys.readouterr().out
    assert float(rows_of(out)["i0.png"]["k1"]) == -0.2
    (out / "v0.mkv").write_bytes(b"someone else's")  # an output in the way, not the job's: refused before any work
    assert main(["correct", str(media["v0"]), "--out-dir", str(out), "--k1", "-0.2", "--backend", "cpu"]) == 1
    assert "not this job's" in capsys.readouterr().err and (out / "v0.mkv").read_bytes() == b"someone else's"


class KillingRunner(ProcessRunner):
    """A process pool that kills the worker busy with a video (by its pid, SIGKILL) once its task has
    started writing: the video, because an image can be done before the kill lands (a loaded CI machine
    then saw one attempt, not two)."""

    killed: tuple[int, str] | None = None

    def wait(self, timeout: float):
        if self.killed is None:
            for slot in self.slots:
                staging = Path(slot.task.out_dir) / ".staging" if slot.task else None
                if staging is not None and slot.task.name.endswith(".mkv") and any(staging.glob(f"{slot.task.name}.*")):
                    time.sleep(0.05)
                    self.killed = (slot.process.pid, slot.task.name)
                    os.kill(slot.process.pid, signal.SIGKILL)
                    break
        return super().wait(timeout)


def test_a_worker_killed_mid_task_costs_one_attempt(tmp_path, media):
    out = tmp_path / "out"
    args = build_parser().parse_args(["correct", "x", "--out-dir", str(out), *LENS])
    options = command_options(args)
    work = CommandWork("correct", options)
    runners = []
    inputs = [media["v0"], media["i0"]]
    summary = run_job("correct", inputs, out, lambda: runners.append(KillingRunner(work, 2)) or runners[0], options,
                      lambda source: planned_outputs("correct", options, source), retries=1)
    pid, name = runners[0].killed
    assert sorted(summary.done) == ["i0.png", "v0.mkv"] and not summary.failed
    rows = rows_of(out)
    assert rows[name]["attempts"] == "2" and rows[name]["worker"] != f"{os.uname().nodename}:{pid}"
    assert sorted(os.listdir(out)) == ["i0.png", "manifest.json", "report.csv", "report.json", "v0.mkv"]
    single = tmp_path / f"single{Path(name).suffix}"
    assert main(["correct", str(media[Path(name).stem]), str(single), *LENS]) == 0
    same_output(out / name, single)


def test_ctrl_c_leaves_the_manifest_consistent(tmp_path, media):
    out = tmp_path / "out"
    long = pan_video(tmp_path / "long.mkv", panorama(), n=60)  # last, so that work remains when the signal comes
    command = [sys.executable, "-m", "glradial", "correct", str(media["v0"]), str(media["v1"]), str(media["i0"]), str(long),
               "--out-dir", str(out), "--workers", "1", *LENS]
    job = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=ignore_sigint)
    wait_for_a_done_input(out, job, 120)
    job.send_signal(signal.SIGINT)
    _, err = job.communicate(timeout=60)
    assert job.returncode == 130 and "interrupted" in err
    entries = json.loads((out / "manifest.json").read_text())["entries"]
    done = [n for n, e in entries.items() if e["status"] == "done"]
    assert done and all(e["status"] in ("done", "pending") for e in entries.values())
    # every done input's outputs are there, complete; nothing else is (no half file, no staging)
    assert sorted(os.listdir(out)) == sorted(["manifest.json", "report.csv", "report.json", *done])
    sources = {p.name: p for p in (media["v0"], media["v1"], media["i0"], long)}
    for name in done:
        single = tmp_path / f"single{Path(name).suffix}"
        assert main(["correct", str(sources[name]), str(single), "-y", *LENS]) == 0
        same_output(out / name, single)
    finished = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert finished.returncode == 0, finished.stderr
    assert f"{4 - len(done)} done, {len(done)} already complete, 0 failed" in finished.stdout


def test_estimate_writes_what_json_prints(tmp_path, media, capsys):
    """NAME.json is what the one-file command prints with --json (calibrate's: tests/jobs/test_jobs_ray.py)."""
    assert main(["estimate", str(media["i0"]), "--out-dir", str(tmp_path / "est"), "--workers", "1", "--no-pitch"]) == 0
    capsys.readouterr()
    assert main(["estimate", str(media["i0"]), "--json", "--no-pitch"]) == 0
    alone = json.loads(capsys.readouterr().out)
    assert json.loads((tmp_path / "est" / "i0.png.json").read_text()) == alone
    row = rows_of(tmp_path / "est")["i0.png"]
    assert float(row["k1"]) == alone["k1"] and row["doubtful"] == str(int(alone["doubtful"])) and row["reason"] == alone["reason"]


def test_crops_shards_are_fixed_by_the_settings(tmp_path, field_panorama):
    small = cv2.resize(field_panorama, (512, 256), interpolation=cv2.INTER_AREA)[:, :, ::-1]
    panos = [tmp_path / f"p{i}.jpg" for i in range(3)]
    for i, path in enumerate(panos):
        cv2.imwrite(str(path), np.roll(small, 40 * i, axis=1))
    command = ["crops", *map(str, panos), "--count", "7", "--seed", "3", "--size", "160x90"]
    assert main([*command, "--out", str(tmp_path / "a"), "--workers", "2"]) == 0
    assert main([*command, "--out", str(tmp_path / "b"), "--workers", "1"]) == 0
    splits, total = {}, 0
    for path in panos:
        shard_a, shard_b = tmp_path / "a" / f"{path.name}.crops", tmp_path / "b" / f"{path.name}.crops"
        labels = list(csv.DictReader(open(shard_a / "labels.csv")))
        total += len(labels)
        splits[path.name] = {row["split"] for row in labels}
        for row in labels:  # the same crops whatever the number of workers
            assert (shard_a / row["file"]).read_bytes() == (shard_b / row["file"]).read_bytes()
    assert total == 7 and all(len(s) == 1 for s in splits.values())  # one split per panorama
    assert {s for v in splits.values() for s in v} == {"train", "val", "test"}
    assert main([*command, "--out", str(tmp_path / "a"), "--workers", "2"]) == 0  # a rerun: nothing to do


def test_job_usage_errors(tmp_path, media, monkeypatch, capsys):
    image = str(media["i0"])
    assert main(["correct", image, str(tmp_path / "o.png"), "--workers", "2", *LENS]) == 2
    assert "give --out-dir DIR" in capsys.readouterr().err
    assert main(["correct", image, image, str(tmp_path / "o.png"), *LENS]) == 2
    assert "got 3 paths" in capsys.readouterr().err
    assert main(["correct", image, "--out-dir", str(tmp_path / "o"), "--auto", "--sidecar", "x.csv"]) == 2
    assert main(["correct", image, "--out-dir", str(tmp_path / "o"), "--gpus-per-worker", "1", *LENS]) == 2
    assert main(["correct", image, str(tmp_path / "o.png"), "--threads-per-worker", "1", *LENS]) == 2
    assert "--threads-per-worker run(s) a job" in capsys.readouterr().err
    assert main(["correct", image, "--out-dir", str(tmp_path / "o"), "--threads-per-worker", "0", *LENS]) == 2
    assert main(["correct", "--ray", image, str(media["i1"]), "--out-dir", str(tmp_path / "o"), *LENS]) == 2
    assert "put --ray after the inputs" in capsys.readouterr().err
    monkeypatch.setattr("glradial.jobs.ray_runner.ray_available", lambda: False)
    assert main(["correct", image, "--out-dir", str(tmp_path / "o"), "--ray", *LENS]) == 2
    assert "pip install 'glradial[cluster]'" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
