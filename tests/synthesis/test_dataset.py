"""The crops dataset writer and the `glradial crops` command: content, splits, atomicity, resume."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from glradial.synthesis.crops import render_crops
from glradial.synthesis.dataset import SPLITS, assign_splits, read_labels, write_crops_dataset

SIZE, OUT = (64, 36), (32, 32)


@pytest.fixture()
def pano_files(tmp_path: Path, field_panorama: np.ndarray) -> list[Path]:
    """Four distinct 512x256 panoramas written as PNG files."""
    small = cv2.resize(field_panorama, (512, 256), interpolation=cv2.INTER_AREA)
    variants = [small, small[:, ::-1], np.roll(small, 128, axis=1), small[:, :, ::-1]]
    paths = []
    for i, image in enumerate(variants):
        path = tmp_path / "panos" / f"pano{i}.png"
        path.parent.mkdir(exist_ok=True)
        cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR))
        paths.append(path)
    return paths


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_dataset_content_labels_and_splits(ctx, tmp_path, pano_files) -> None:
    out = tmp_path / "ds"
    summary = write_crops_dataset(pano_files, out, count=10, seed=5, size=SIZE, out_size=OUT, splits=(0.5, 0.25, 0.25))
    assert summary.written == 10 and summary.skipped == 0
    rows, params = read_labels(out / "labels.csv")
    assert [int(r["index"]) for r in rows] == list(range(10))
    # One split per panorama; 4 panoramas at 0.5/0.25/0.25 -> 2/1/1 panoramas.
    split_of: dict[str, set[str]] = {}
    for r in rows:
        split_of.setdefault(r["panorama_id"], set()).add(r["split"])
        assert r["file"].startswith(r["split"] + "/") and r["seed"] == "5"
    assert all(len(s) == 1 for s in split_of.values())
    assert sorted(next(iter(s)) for s in split_of.values()) == ["test", "train", "train", "val"]
    # Every image is the crop its row describes (an independent render of the same panorama file).
    for r, p in zip(rows, params):
        image = cv2.cvtColor(cv2.imread(str(out / r["file"])), cv2.COLOR_BGR2RGB)
        pano = cv2.cvtColor(cv2.imread(r["panorama"]), cv2.COLOR_BGR2RGB)
        want = render_crops(pano, [p], size=SIZE, out_size=OUT)[0]
        assert image.shape == (32, 32, 3) and np.abs(image.astype(int) - want).max() <= 1  # PNG is lossless
    assert (out / "manifest.json").is_file()
    assert not list(out.rglob(".*tmp*"))


def test_dataset_is_deterministic(ctx, tmp_path, pano_files) -> None:
    write_crops_dataset(pano_files, tmp_path / "a", count=6, seed=9, size=SIZE, out_size=OUT)
    write_crops_dataset(pano_files, tmp_path / "b", count=6, seed=9, size=SIZE, out_size=OUT)
    a, b = _tree(tmp_path / "a"), _tree(tmp_path / "b")
    assert a.keys() == b.keys()
    assert a == b  # byte-identical: images, labels and manifest (which name the inputs, not the folder)
    c = write_crops_dataset(pano_files, tmp_path / "c", count=6, seed=10, size=SIZE, out_size=OUT)
    assert _tree(c.out_dir)["labels.csv"] != a["labels.csv"]


def test_interrupted_write_leaves_no_partial_files_and_resumes(ctx, tmp_path, pano_files, monkeypatch) -> None:
    write_crops_dataset(pano_files, tmp_path / "whole", count=12, seed=3, size=SIZE, out_size=OUT)
    out = tmp_path / "cut"
    from glradial.media import atomic, image_io

    real_write = image_io.atomic_write_bytes
    calls = {"n": 0}

    def failing_write(path, data):
        calls["n"] += 1
        if calls["n"] == 6:
            # Simulate a crash in the middle of writing: a partial file, then the interruption.
            with atomic.atomic_path(path) as tmp:
                tmp.write_bytes(data[: len(data) // 2])
                raise KeyboardInterrupt
        return real_write(path, data)

    monkeypatch.setattr(image_io, "atomic_write_bytes", failing_write)
    with pytest.raises(KeyboardInterrupt):
        write_crops_dataset(pano_files, out, count=12, seed=3, size=SIZE, out_size=OUT)
    monkeypatch.setattr(image_io, "atomic_write_bytes", real_write)
    images = sorted(p for p in out.rglob("*.png"))
    assert len(images) == 5  # the five finished ones, no partial sixth, no temporary file
    assert not list(out.rglob(".*"))
    assert not (out / "labels.csv").exists()  # the labels file marks completion
    for p in images:
        assert cv2.imread(str(p)) is not None
    summary = write_crops_dataset(pano_files, out, count=12, seed=3, size=SIZE, out_size=OUT)
    assert summary.skipped == 5 and summary.written == 7
    assert _tree(out) == _tree(tmp_path / "whole")


def test_full_disk_names_the_image_and_the_errno(ctx, tmp_path, pano_files, monkeypatch) -> None:
    """ENOSPC where a full disk reports it at the latest (flushing the file); the third file written
    is the second crop (the manifest is the first)."""
    import errno
    import os

    from glradial.media import atomic

    calls = {"n": 0}
    real_fsync = atomic.os.fsync

    def full_disk(fd):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_fsync(fd)

    monkeypatch.setattr(atomic.os, "fsync", full_disk)
    out = tmp_path / "ds"
    with pytest.raises(OSError) as info:
        write_crops_dataset(pano_files[:1], out, count=3, seed=0, size=SIZE, out_size=OUT)
    second = out / "train" / "0000001.png"
    assert info.value.errno == errno.ENOSPC and str(second) in str(info.value) and "ENOSPC" in str(info.value)
    assert sorted(p.name for p in (out / "train").iterdir()) == ["0000000.png"]  # no partial or temporary file


def test_resume_with_other_settings_is_refused(ctx, tmp_path, pano_files) -> None:
    write_crops_dataset(pano_files[:2], tmp_path / "ds", count=2, seed=1, size=SIZE, out_size=OUT)
    with pytest.raises(ValueError, match="seed"):
        write_crops_dataset(pano_files[:2], tmp_path / "ds", count=2, seed=2, size=SIZE, out_size=OUT)


def test_bad_panoramas_are_refused_before_anything_is_written(tmp_path, pano_files, capsys) -> None:
    from glradial.cli import main

    fake = tmp_path / "fake.png"
    fake.write_text("not an image")
    square = tmp_path / "square.png"
    cv2.imwrite(str(square), np.zeros((40, 40, 3), np.uint8))
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((3, 5), np.uint8))
    for bad, words in ((fake, "cannot read panorama"), (square, "2:1"), (empty, "2:1"), (tmp_path / "none.png", "does not exist")):
        out = tmp_path / "cr"
        # the bad file last: the good ones before it must not start a dataset either
        argv = ["crops", str(pano_files[0]), str(bad), "--count", "2", "--out", str(out), "--seed", "0", "--size", "64x36"]
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert words in err and str(bad) in err, err
        assert not out.exists()
    # the folder is free for a run with other inputs
    assert main(["crops", str(pano_files[1]), "--count", "2", "--out", str(tmp_path / "cr"), "--seed", "0", "--size", "64x36"]) == 0


def test_a_first_run_that_fails_before_its_first_crop_leaves_nothing(ctx, tmp_path, pano_files, monkeypatch) -> None:
    # A panorama whose header is fine but whose pixels cannot be decoded passes the up-front check.
    truncated = tmp_path / "truncated.png"
    truncated.write_bytes(pano_files[0].read_bytes()[:200])
    out = tmp_path / "cr"
    with pytest.raises(ValueError, match="cannot read panorama"):
        write_crops_dataset([truncated], out, count=2, seed=0, size=SIZE, out_size=OUT)
    assert not out.exists()
    # In an existing folder, only what the run made goes; the folder and its other files stay.
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="cannot read panorama"):
        write_crops_dataset([truncated], out, count=2, seed=0, size=SIZE, out_size=OUT)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    summary = write_crops_dataset(pano_files[:1], out, count=2, seed=0, size=SIZE, out_size=OUT)
    assert summary.written == 2


def test_a_manifest_without_crops_does_not_bind_the_folder(ctx, tmp_path, pano_files) -> None:
    # What a run killed (SIGKILL) between its manifest and its first crop leaves.
    killed = tmp_path / "killed"
    write_crops_dataset(pano_files[:2], killed, count=2, seed=1, size=SIZE, out_size=OUT)
    for path in sorted(killed.rglob("*"), reverse=True):
        if path.name != "manifest.json":
            path.unlink() if path.is_file() else path.rmdir()
    summary = write_crops_dataset(pano_files[2:], killed, count=2, seed=7, size=SIZE, out_size=OUT)
    assert summary.written == 2 and summary.skipped == 0
    write_crops_dataset(pano_files[2:], tmp_path / "clean", count=2, seed=7, size=SIZE, out_size=OUT)
    assert _tree(killed) == _tree(tmp_path / "clean")  # the new manifest replaced the old one
    with pytest.raises(ValueError, match="other settings"):  # now it holds crops: other settings are refused
        write_crops_dataset(pano_files[2:], killed, count=2, seed=8, size=SIZE, out_size=OUT)


@pytest.mark.parametrize("count", [1, 2, 3, 7, 20, 218])
def test_assign_splits_partitions_panoramas(count) -> None:
    names = assign_splits(count, (0.8, 0.1, 0.1), seed=4)
    assert len(names) == count and set(names) <= set(SPLITS)
    assert names == assign_splits(count, (0.8, 0.1, 0.1), seed=4)
    assert names.count("train") >= 1
    if count >= 3:
        assert names.count("val") >= 1 and names.count("test") >= 1
    if count == 218:  # the paper's panorama count
        assert (names.count("val"), names.count("test")) == (22, 22)


def test_assign_splits_rejects_bad_fractions() -> None:
    with pytest.raises(ValueError, match="sum"):
        assign_splits(5, (0.5, 0.5, 0.5), seed=0)


def test_cli_crops(ctx, tmp_path, pano_files, capsys) -> None:
    from glradial.cli import main

    out = tmp_path / "cli"
    argv = ["crops", *map(str, pano_files[:3]), "--count", "6", "--out", str(out), "--seed", "2", "--size", "64x36", "--out-size", "32x32"]
    assert main(argv) == 0
    assert "wrote 6 crops" in capsys.readouterr().out
    with open(out / "labels.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 6 and {r["out_w"] for r in rows} == {"32"}
    assert main(argv) == 0  # resume: nothing left to do
    assert "wrote 0 crops" in capsys.readouterr().out
    assert main(["crops", str(pano_files[0]), "--count", "0", "--out", str(out), "--seed", "1"]) == 2
    bad = tmp_path / "bad.png"
    cv2.imwrite(str(bad), np.zeros((10, 30, 3), np.uint8))
    assert main(["crops", str(bad), "--count", "1", "--out", str(tmp_path / "x"), "--seed", "1", "--size", "64x36"]) == 1
    assert "2:1" in capsys.readouterr().err


def test_cli_crops_supersample(ctx, tmp_path, pano_files, capsys) -> None:
    from glradial.cli import main

    # 128x72 -> 32x32 is 4 x 2.25 frame pixels per output pixel: "auto" takes 2 x 1 samples.
    out = tmp_path / "aa"
    argv = ["crops", str(pano_files[0]), "--count", "2", "--out", str(out), "--seed", "3", "--size", "128x72",
            "--out-size", "32x32", "--supersample", "auto"]
    assert main(argv) == 0
    rows, params = read_labels(out / "labels.csv")
    pano = cv2.cvtColor(cv2.imread(str(pano_files[0])), cv2.COLOR_BGR2RGB)
    want = render_crops(pano, params, size=(128, 72), out_size=(32, 32), supersample=(2, 1))
    plain = render_crops(pano, params, size=(128, 72), out_size=(32, 32))
    got = np.stack([cv2.cvtColor(cv2.imread(str(out / r["file"])), cv2.COLOR_BGR2RGB) for r in rows])
    assert np.array_equal(got, want) and not np.array_equal(got, plain)
    assert json.loads((out / "manifest.json").read_text())["supersample"] == [2, 1]
    # A bad value is refused by name, before anything is written.
    for bad in ("0", "9", "2x1"):
        assert main([*argv[:5], str(tmp_path / "never"), *argv[6:-1], bad]) == 2
        assert "supersample" in capsys.readouterr().err
    assert not (tmp_path / "never").exists()
    with pytest.raises(ValueError, match="supersample"):
        write_crops_dataset(pano_files[:1], tmp_path / "never", count=1, seed=0, supersample="area")
    assert not (tmp_path / "never").exists()
