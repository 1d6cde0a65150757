"""The training stream: determinism per seed, worker processes, labels, shutdown."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from glradial import lensfuncs
from glradial.crop_stream import PAPER_NEWTON_STEPS, crop_batches, plan_batch
from glradial.crops import CropRenderer, render_crops, sample_crop_params

PANO = str(Path(__file__).parent / "data" / "panorama_field_2048x1024.jpg")


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
