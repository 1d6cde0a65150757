"""glradial.synthesis.crop_producer, the training stream: determinism per seed, worker processes, labels, pairs, shutdown."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from glradial.lens import lensfuncs
from glradial.synthesis.crop_producer import PAPER_NEWTON_STEPS, crop_batches, plan_batch
from glradial.synthesis.crops import CropRenderer, render_crops, sample_crop_params

PANO = str(Path(__file__).parents[1] / "data" / "panorama_field_2048x1024.jpg")


def test_stream_is_deterministic_and_labelled(ctx, field_panorama) -> None:
    small = field_panorama[::4, ::4].copy()  # 512x256 keeps the test fast
    panos = [small, small[:, ::-1].copy(), np.roll(small, 100, axis=1)]
    with crop_batches(panos, 6, seed=11, out_size=(32, 32), size=(128, 72)) as stream:
        a = [next(stream) for _ in range(3)]
    with crop_batches(panos, 6, seed=11, out_size=(32, 32), size=(128, 72)) as stream:
        b = [next(stream) for _ in range(3)]
    with crop_batches(panos, 6, seed=12, out_size=(32, 32), size=(128, 72)) as stream:
        c = next(stream)
    for x, y in zip(a, b):
        assert np.array_equal(x.images, y.images) and np.array_equal(x.labels, y.labels) and x.params == y.params
    assert [x.index for x in a] == [0, 1, 2]
    assert c.params != a[0].params
    batch = a[0]
    assert batch.images.shape == (6, 32, 32, 3) and batch.images.dtype == np.uint8
    assert batch.labels.dtype == np.float32 and batch.labels.shape == (6, 2)
    np.testing.assert_array_equal(batch.labels, np.array([(p.k1, p.k2) for p in batch.params], np.float32))
    assert batch.panorama.dtype == np.int64 and set(batch.panorama) <= {0, 1, 2}
    # Each image is the crop of its own panorama with its own parameters (an independent render).
    for i in range(6):
        want = render_crops(panos[batch.panorama[i]], [batch.params[i]], size=(128, 72), out_size=(32, 32))[0]
        assert np.abs(want.astype(int) - batch.images[i]).max() <= 1


def test_workers_reproduce_the_single_process_stream() -> None:
    with crop_batches([PANO], 4, seed=5, out_size=(24, 24), size=(64, 36)) as stream:
        want = [next(stream) for _ in range(3)]
    with crop_batches([PANO], 4, seed=5, out_size=(24, 24), size=(64, 36), workers=2, lp_num_threads=1) as stream:
        got = [next(stream) for _ in range(3)]
        procs = list(stream._procs)
        assert all(p.is_alive() for p in procs)
    assert not any(p.is_alive() for p in procs)  # close() joined them
    for x, y in zip(want, got):
        assert x.index == y.index and x.params == y.params
        assert np.array_equal(x.labels, y.labels) and np.array_equal(x.panorama, y.panorama)
        assert np.abs(x.images.astype(int) - y.images).max() <= 1  # same driver; threads may differ
    with pytest.raises(StopIteration):
        next(stream)


def test_worker_errors_are_raised() -> None:
    with crop_batches(["/nonexistent/pano.jpg"], 2, seed=0, out_size=(8, 8), size=(16, 9), workers=1) as stream:
        with pytest.raises(RuntimeError, match="cannot read panorama"):
            next(stream)


def test_argument_validation() -> None:
    with pytest.raises(ValueError, match="batch_size"):
        crop_batches([PANO], 0, seed=0)
    with pytest.raises(ValueError, match="empty"):
        crop_batches([], 2, seed=0)
    with pytest.raises(TypeError, match="unknown range"):
        crop_batches([PANO], 2, seed=0, ranges={"zoom": (1, 2)})
    with pytest.raises(ValueError, match="2:1"):
        next(iter(crop_batches([np.zeros((10, 30, 3), np.uint8)], 2, seed=0)))


def test_plan_is_a_function_of_seed_and_index() -> None:
    with crop_batches([PANO, PANO], 5, seed=3, out_size=(8, 8), size=(16, 9)) as stream:
        config = stream.config
    p7, w7 = plan_batch(config, 7)
    p7b, w7b = plan_batch(config, 7)
    p8, _ = plan_batch(config, 8)
    assert p7 == p7b and np.array_equal(w7, w7b) and p7 != p8


def test_paper_newton_steps_are_enough() -> None:
    """The stream's 3 Newton steps reach float64 accuracy on every lens of the paper's distribution."""
    radii = np.linspace(0.0, 0.5737, 200)  # up to the 16:9 corner radius
    params = sample_crop_params(4000, seed=99)
    worst = 0.0
    for p in params:
        b = lensfuncs.drap_coefficients(p.k1, p.k2)
        r_fold = lensfuncs.fold_radius(p.k1, p.k2)
        s = radii * radii
        r = np.clip(radii * (1 + s * (b[0] + s * (b[1] + s * (b[2] + s * b[3])))), 0, r_fold)
        for _ in range(PAPER_NEWTON_STEPS):
            f = r * lensfuncs.radial_factor(r * r, p.k1, p.k2) - radii
            r = np.clip(r - f / np.maximum(lensfuncs.radial_slope(r, p.k1, p.k2), 1e-6), 0, r_fold)
        worst = max(worst, float(np.abs(r * lensfuncs.radial_factor(r * r, p.k1, p.k2) - radii).max()))
    # float32 on the GPU resolves ~6e-8 at these radii; the Newton error must be far below that.
    assert worst < 1e-9, worst


def test_newton_steps_render_the_same(ctx, field_panorama) -> None:
    params = sample_crop_params(4, seed=21)
    with CropRenderer(field_panorama, size=(96, 54), newton_steps=3, ctx=ctx) as a, CropRenderer(
        field_panorama, size=(96, 54), ctx=ctx
    ) as b:
        assert np.abs(a.render(params).astype(int) - b.render(params)).max() <= 1


def _synthetic_panorama(seed: int) -> np.ndarray:
    """A 1024x512 stand-in: random grey blocks on a two-tone background (enough texture for corners)."""
    rng = np.random.default_rng(seed)
    pano = np.zeros((512, 1024, 3), np.uint8)
    pano[:256], pano[256:] = (90, 120, 160), (40, 130, 40)
    for _ in range(400):
        x, y = int(rng.integers(0, 1000)), int(rng.integers(0, 500))
        pano[y : y + 12, x : x + 24] = rng.integers(0, 256, 3)
    return pano


def test_paired_crops_share_the_view_and_differ_in_the_lens() -> None:
    # Radial distortion fixes the frame centre (p_d = p_u at r = 0 with unit slope), so the two crops
    # of a pair (same pose and field of view, different lens) agree there and differ towards the corners.
    with crop_batches([_synthetic_panorama(3)], 4, seed=1, out_size=(160, 90), paired=True) as stream:
        batch = next(stream)
    images, labels = batch.images, batch.labels
    assert images.shape == (4, 90, 160, 3) and labels.shape == (4, 2)
    for a, b in ((0, 1), (2, 3)):
        pa, pb = batch.params[a], batch.params[b]
        assert (pa.pan, pa.tilt, pa.roll, pa.hfov) == (pb.pan, pb.tilt, pb.roll, pb.hfov)
        assert not np.allclose(labels[a], labels[b])
        centre = np.abs(images[a, 40:50, 75:85].astype(int) - images[b, 40:50, 75:85].astype(int)).mean()
        corner = np.abs(images[a, :15, :25].astype(int) - images[b, :15, :25].astype(int)).mean()
        assert centre < 3.0 and (corner > centre or corner == 0.0), (centre, corner)
    with pytest.raises(ValueError, match="even"):
        crop_batches([PANO], 3, seed=0, paired=True)


def test_reader_gets_an_error_not_a_hang_when_a_worker_is_killed_mid_batch() -> None:
    # A worker killed by the out-of-memory killer while its queue's feeder thread is halfway
    # through writing a batch left the trainer blocked forever in the pipe read (seen with 80
    # panoramas per producer on a 24 GiB machine). A batch of 8 crops of 128x72 is 221 KB, more
    # than a pipe holds (64 KB), so once the reader stops reading the worker is always mid-batch.
    import threading
    import time

    stream = crop_batches([_synthetic_panorama(1)[::2, ::2].copy()], 8, seed=3, out_size=(128, 72), workers=1)
    try:
        stream.get(timeout=120)  # the worker is up and streaming
        deadline = time.monotonic() + 60
        while not stream._queues[0]._reader.poll(0.5) and time.monotonic() < deadline:
            pass  # wait until the next batch is (partly) in the pipe
        stream._procs[0].kill()
        outcome: list[BaseException | None] = []

        def drain() -> None:
            try:
                while True:
                    stream.get(timeout=60)
            except BaseException as err:  # noqa: BLE001 - the test inspects it
                outcome.append(err)

        reader = threading.Thread(target=drain, daemon=True)
        reader.start()
        reader.join(timeout=60)
        assert not reader.is_alive(), "get() hung on a worker that was killed mid-batch"
        assert isinstance(outcome[0], RuntimeError) and "exit code -9" in str(outcome[0]), outcome
    finally:
        stream.close()



_SCRIPT_BODY = """
import numpy as np
from glradial import crop_batches

pano = np.random.default_rng(0).integers(0, 256, (256, 512, 3), dtype=np.uint8)  # 393 KB > a 64 KiB pipe
with crop_batches([pano], 4, seed=1, size=(64, 36), out_size=(16, 16), workers=2, lp_num_threads=1) as stream:
    batch = next(stream)
print("images", batch.images.shape, int(batch.images.sum()))
"""


def _run_script(tmp_path: Path, text: str) -> "subprocess.CompletedProcess[str]":
    """Run ``text`` as ``python script.py`` with its own TMPDIR (``tmp_path / "tmp"``)."""
    import os
    import sys

    script = tmp_path / "train_script.py"
    script.write_text(text)
    (tmp_path / "tmp").mkdir()
    root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "TMPDIR": str(tmp_path / "tmp"), "PYTHONPATH": root + os.pathsep + os.environ.get("PYTHONPATH", "")}
    # 60 s: the script takes a few seconds on a loaded 2-core machine; before the fix it never ended (the
    # parent blocked writing the pickled panorama into the pipe of a worker that had died while starting).
    return subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)


def test_unguarded_script_fails_clearly_instead_of_hanging(tmp_path) -> None:
    # README's example saved as a script without a main guard: each spawned worker imports the script
    # again and starts a producer itself, which multiprocessing refuses, so the worker dies at start-up.
    done = _run_script(tmp_path, _SCRIPT_BODY)
    assert done.returncode != 0, done.stdout
    assert "died while starting" in done.stderr and 'if __name__ == "__main__":' in done.stderr, done.stderr[-3000:]
    assert not list((tmp_path / "tmp").iterdir())  # the parent's and the workers' panorama folders are gone


def test_guarded_script_streams_crops_and_leaves_no_files(tmp_path) -> None:
    body = "\n".join("    " + line for line in _SCRIPT_BODY.strip().splitlines())
    done = _run_script(tmp_path, f"def main():\n{body}\n\n\nif __name__ == '__main__':\n    main()\n")
    assert done.returncode == 0, done.stderr[-3000:]
    # The same batch rendered in this process (workers=0): the workers see the same panorama pixels.
    pano = np.random.default_rng(0).integers(0, 256, (256, 512, 3), dtype=np.uint8)
    with crop_batches([pano], 4, seed=1, size=(64, 36), out_size=(16, 16)) as stream:
        want = next(stream).images
    assert done.stdout.split() == ["images", "(4,", "16,", "16,", "3)", str(int(want.sum()))]
    assert not list((tmp_path / "tmp").iterdir())


def test_workers_get_panorama_arrays_through_files_removed_on_close() -> None:
    pano = _synthetic_panorama(4)
    stream = crop_batches([pano, PANO], 2, seed=0, out_size=(16, 16), size=(64, 36), workers=1, lp_num_threads=1)
    folder = stream._cleanup.peek()[2][0]
    files = sorted(folder.iterdir())
    assert [f.name for f in files] == ["panorama-000000.npy"]
    assert np.array_equal(np.load(files[0]), pano)
    next(stream)
    stream.close()
    assert not folder.exists()
