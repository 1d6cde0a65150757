"""The GPU batch source on this CPU: its torch crop renderer against the GL crop renderer (the twin
test), its batches against the GL crop producer's, its device augmentation against OpenCV, and the
trainer running a few steps through each batch source (net.sources) with the speed options wired.

Tolerances of the twin: both sides compute the geometry in float32 (a few 1e-7 lens units, far
below a pixel) and read the same 8-bit mip levels bilinearly; they differ in the last bits of the
bilinear weights and of the level of detail (llvmpipe takes one level per 2 × 2 quad, in fixed
point), so on a smooth panorama (gradients of at most ~1 level per output pixel) the crops agree
to a small fraction of a level on average and within a few levels anywhere; the lens geometry is
held through sharp edges, whose 50 % crossing both renderers place within 0.05 output pixels of
the analytic position (NumPy float64, :func:`glradial.synthesis.crops.crop_lonlat`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from glradial.synthesis.crops import CropParams, CropRenderer, crop_lonlat, sample_crop_params  # noqa: E402
from net.augment import AugmentConfig, jpeg_roundtrip, motion_kernel  # noqa: E402
from net.gpu_augment import DeviceAugment, gaussian_blur, jpeg_artefacts  # noqa: E402
from net.gpu_source import GpuCropSource  # noqa: E402
from net.torch_crops import TorchCropRenderer  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
#: A seam crop (pan 170: u wraps inside it), a lens near fold-over (its series is rejected: the
#: Newton path), a barrel lens whose corners have no inverse (0 there), a pincushion lens.
SPECIAL = [CropParams(170.0, -10.0, 1.0, 50.0, -0.66, 0.34), CropParams(0.0, 0.0, 0.0, 90.0, -0.6, 0.05),
           CropParams(10.0, -5.0, 0.0, 30.0, 0.3, 0.08)]


def lonlat_grid(height: int) -> tuple[np.ndarray, np.ndarray]:
    y, x = np.mgrid[0:height, 0 : 2 * height]
    return 2 * np.pi * ((x + 0.5) / (2 * height) - 0.5), np.pi * (0.5 - (y + 0.5) / height)


@pytest.fixture(scope="module")
def smooth_panorama() -> np.ndarray:
    lon, lat = lonlat_grid(512)
    channels = [128 + 100 * np.sin(lon) * np.cos(lat), 128 + 100 * np.sin(2 * lat), 128 + 90 * np.cos(3 * lon) * np.cos(lat)]
    return np.stack(channels, -1).round().astype(np.uint8)


@pytest.mark.parametrize("out_size, supersample", [((160, 90), 1), ((96, 96), (2, 1))])
def test_torch_crops_are_the_twin_of_the_gl_crop_renderer(smooth_panorama, out_size, supersample):
    params = sample_crop_params(12, 3) + SPECIAL
    with CropRenderer(smooth_panorama, out_size=out_size, supersample=supersample) as gl:
        want = gl.render(params).astype(int)
    got = TorchCropRenderer([smooth_panorama], out_size=out_size, supersample=supersample).render(params, [0] * len(params))
    got = got.numpy().astype(int)
    assert got.shape == want.shape
    diff = np.abs(got - want)
    assert diff.reshape(len(params), -1).mean(axis=1).max() < 0.3, diff.reshape(len(params), -1).mean(axis=1)
    assert diff.max() <= 3
    # the exact inverse's invalid corners (the barrel lens) are 0 in both, at the same pixels
    assert np.array_equal((want == 0).all(-1), (got == 0).all(-1))
    assert (want[-2] == 0).all(-1).sum() > 0


def test_the_newton_path_and_the_series_path_are_both_taken():
    from net.torch_crops import crop_table

    table = crop_table(SPECIAL)
    assert list(table[:, 17]) == [1.0, 0.0, 1.0]  # the fold-over lens keeps the per-pixel Newton inverse


def crossings(values: np.ndarray, level: float) -> np.ndarray:
    """Sub-pixel position of the one crossing of ``level`` along the last axis, linearly
    interpolated (NaN where there is not exactly one): for a smooth function such as longitude."""
    out = np.full(values.shape[0], np.nan)
    for i, row in enumerate(values):
        above = row > level
        k = np.flatnonzero(above[1:] != above[:-1])
        if len(k) == 1:
            j = k[0]
            out[i] = j + (level - row[j]) / (row[j + 1] - row[j])
    return out


def edge_positions(values: np.ndarray, half: int = 6) -> np.ndarray:
    """Sub-pixel position of a filtered step along the last axis (pixel centres at integers): the
    area under the normalised profile over a window of ``2 half`` samples around its 50 % crossing
    (exact for a step blurred by any symmetric kernel; NaN where there is no single step)."""
    out = np.full(values.shape[0], np.nan)
    for i, row in enumerate(values):
        above = row > 127.5
        k = np.flatnonzero(above[1:] != above[:-1])
        if len(k) != 1 or k[0] < half or k[0] + half + 1 >= len(row):
            continue
        start = k[0] - half + 1
        window = row[start : k[0] + half + 1]
        out[i] = start - 0.5 + ((window - window[-1]) / (window[0] - window[-1])).sum()
    return out


def test_edges_land_where_the_lens_geometry_puts_them():
    # black / white steps at lon = 0 (red) and at the horizon (green): each renderer's edge position
    # against the analytic position of lon = 0 in each row and lat = 0 in each column. Both renderers
    # agree to 0.02 px; both sit within 0.12 px of the geometry: the edge estimate's own error, since
    # the panorama's step is one texel sharp and a texel spans about one output pixel here, so the
    # filtered ramp is sampled at only one or two points (a lens off by 0.01 in k1 moves the edges
    # near the frame's border by ~0.25 px, half a pixel convention error by 0.5 px)
    lon, lat = lonlat_grid(1024)
    pano = np.zeros((1024, 2048, 3), np.uint8)
    pano[..., 0] = np.where(lon > 0, 255, 0)
    pano[..., 1] = np.where(lat > 0, 255, 0)
    params = [CropParams(3.0, -4.0, 1.5, 40.0, -0.5, 0.19), CropParams(-2.0, -6.0, -1.0, 25.0, 0.2, 0.04),
              CropParams(3.0, -6.0, 0.0, 60.0, -0.3, 0.07)]
    out = (192, 108)
    with CropRenderer(pano, out_size=out) as gl:
        want = gl.render(params).astype(float)
    got = TorchCropRenderer([pano], out_size=out).render(params, [0] * len(params)).numpy().astype(float)
    for i, p in enumerate(params):
        lon_c, lat_c, _ = crop_lonlat(p, out_size=out)
        truth = crossings(lon_c, 0.0), crossings(lat_c.T, 0.0)
        edges = [(edge_positions(image[..., 0]), edge_positions(image[..., 1].T)) for image in (want[i], got[i])]
        for axis in range(2):
            ok = np.isfinite(truth[axis]) & np.isfinite(edges[0][axis]) & np.isfinite(edges[1][axis])
            assert ok.sum() > 100
            assert np.abs(edges[1][axis] - edges[0][axis])[ok].max() < 0.02
            for found in (edges[0][axis], edges[1][axis]):
                assert np.abs(found - truth[axis])[ok].max() < 0.12


def synthetic_panoramas():
    from net.data import synthetic_panorama

    return [synthetic_panorama(s, (256, 128)) for s in (0, 1)]


def test_gpu_source_batches_are_the_gl_producers_batches():
    # same seed, same options: the crop producer's batch i and the GPU source's batch i hold the same
    # lenses and views (the same plan), rendered by the two twins
    from glradial.synthesis.crop_producer import crop_batches

    panoramas = synthetic_panoramas()
    source = GpuCropSource(panoramas, batch_size=8, seed=5, out_size=(64, 36), device="cpu", panoramas_per_batch=2)
    with crop_batches(panoramas, 8, seed=5, out_size=(64, 36), panoramas_per_batch=2) as stream:
        for _ in range(2):
            want = stream.get()
            images, labels = source.next_batch()
            assert np.array_equal(labels.numpy(), want.labels)
            assert images.dtype == torch.uint8 and tuple(images.shape) == want.images.shape
            # sharp synthetic lines: bilinear last bits can move single pixels, the mean stays small
            assert np.abs(images.numpy().astype(int) - want.images).mean() < 1.0


def test_gpu_source_is_seeded():
    panoramas = synthetic_panoramas()

    def batches(seed: int, augment_seed: int) -> list:
        source = GpuCropSource(panoramas, batch_size=8, seed=seed, out_size=(64, 36), device="cpu", paired=True, panoramas_per_batch=2,
                               augment=AugmentConfig(), augment_seed=augment_seed)
        return [source.next_batch() for _ in range(2)]

    first, again = batches(1, 7), batches(1, 7)
    for (a, la), (b, lb) in zip(first, again):
        assert torch.equal(a, b) and torch.equal(la, lb)
    other = batches(1, 8)
    assert not torch.equal(first[0][0], other[0][0]) and torch.equal(first[0][1], other[0][1])
    assert not torch.equal(first[0][1], batches(2, 7)[0][1])
    assert not torch.equal(first[0][0], first[1][0])


def test_device_augmentation_keeps_pairs_together_and_uses_every_operation():
    x = torch.from_numpy(synthetic_panoramas()[0][:36, :64]).permute(2, 0, 1)[None].float().repeat(40, 1, 1, 1)
    augment = DeviceAugment(AugmentConfig(p_blur=0.5, p_motion=0.5, p_noise=0.5, p_jpeg=0.5), 0, "cpu")
    out = augment.augment(x, paired=True)
    assert out.shape == x.shape and torch.equal(out, out.round().clamp(0, 255))
    assert torch.equal(out[0::2], out[1::2])  # the same input twice: a pair's draws, noise included, agree
    assert len({tuple(o.flatten()[:50].tolist()) for o in out[0::2]}) == 20
    assert torch.equal(DeviceAugment(AugmentConfig(enabled=False), 0, "cpu").augment(x), x)
    with pytest.raises(ValueError, match="even batch"):
        augment.augment(x[:3], paired=True)
    with pytest.raises(ValueError, match="float N x 3 x H x W"):
        augment.augment(x.to(torch.uint8))


def test_device_blurs_and_jpeg_match_opencv():
    import cv2

    image = cv2.imread(str(ROOT / "tests/data/panorama_field_2048x1024.jpg"))[:, :, ::-1]
    image = np.ascontiguousarray(cv2.resize(image, (160, 90), interpolation=cv2.INTER_AREA))
    x = torch.from_numpy(image).permute(2, 0, 1)[None].float()

    def as_image(t: torch.Tensor) -> np.ndarray:
        return t[0].permute(1, 2, 0).numpy()

    for sigma in (0.4, 1.0):  # OpenCV's 8-bit path rounds in fixed point: within a level
        want = cv2.GaussianBlur(image, (0, 0), sigma).astype(float)
        assert np.abs(as_image(gaussian_blur(x, torch.tensor([sigma]))) - want).max() <= 1.0
    augment = DeviceAugment(AugmentConfig(), 0, "cpu")
    for length, angle in ((3, 0), (6, 37), (7, 120)):
        want = cv2.filter2D(image, -1, motion_kernel(length, angle)).astype(float)
        got = augment.motion_blur(x, torch.tensor([length]), torch.tensor([angle]))
        assert np.abs(as_image(got) - want).max() <= 1.0
    for quality in (30, 60, 95):  # libjpeg's integer DCT and fancy upsampling differ in the last level
        want = jpeg_roundtrip(image, quality).astype(float)
        got = as_image(jpeg_artefacts(x, torch.tensor([quality]), augment.dct))
        assert np.abs(got - want).mean() < 0.3 * np.abs(want - image).mean() + 0.5


def tiny_run(tmp_path: Path, **changes) -> Path:
    config = dict(json.loads((ROOT / "net/configs/tiny.json").read_text()), val_size=8, steps=2, **changes)
    path = tmp_path / "c.json"
    path.write_text(json.dumps(config))
    return path


@pytest.mark.parametrize("source", ["pool", "gpu"])
def test_training_runs_through_either_batch_source(tmp_path, source):
    from net.train import main

    assert main(["--config", str(tiny_run(tmp_path, source=source)), "--out", str(tmp_path / "run")]) == 0
    state = torch.load(tmp_path / "run/last.pt", map_location="cpu", weights_only=False)
    assert state["step"] == 2 and (tmp_path / "run/best.pt").exists()
    assert json.loads((tmp_path / "run/config.json").read_text())["source"] == source


def test_speed_options_wire_through(tmp_path, monkeypatch):
    from net.train import main

    compiled = []
    monkeypatch.setattr(torch, "compile", lambda module, **kw: compiled.append(module) or module)
    call = ["--config", str(tiny_run(tmp_path, source="gpu")), "--out", str(tmp_path / "run"), "--amp", "bf16",
            "--no-channels-last", "--compile"]
    assert main(call) == 0
    saved = json.loads((tmp_path / "run/config.json").read_text())
    assert (saved["amp"], saved["channels_last"], saved["compile"]) == ("bf16", False, True)
    assert len(compiled) == 1 and isinstance(compiled[0], torch.nn.Module)
    with pytest.raises(SystemExit):
        main(call[:4] + ["--amp", "fp8"])
    with pytest.raises(ValueError, match="source must be one of"):
        main(["--config", str(tiny_run(tmp_path, source="disk")), "--out", str(tmp_path / "bad")])
    assert not (tmp_path / "bad").exists()


def test_bf16_autocast_runs_the_network_in_bfloat16():
    from net.model import DistortionNet, ModelConfig
    from net.train import TrainConfig, step_loss

    cfg = TrainConfig.from_json(ROOT / "net/configs/tiny.json")
    model_cfg = ModelConfig.from_dict(cfg.model)
    model = DistortionNet(model_cfg)
    seen = []
    model.stem.register_forward_hook(lambda module, inputs, output: seen.append(output.dtype))
    x, y = torch.randn(4, 3, 36, 64), torch.zeros(4, 2)
    for amp, dtype in (("off", torch.float32), ("bf16", torch.bfloat16)):
        cfg.amp = amp
        loss, pred = step_loss(model, x, y, cfg, model_cfg, np.random.default_rng(0))
        assert seen[-1] == dtype and loss.dtype == torch.float32 and pred.dtype == torch.float32
        loss.backward()


def test_throughput_bench_runs_and_says_it_measured_a_cpu(tmp_path):
    # bench/bench_train_throughput.py (the lent session's 30 s check) on this CPU: the tiny network,
    # a note that these are no GPU figures, a rate for the step, the GPU source and training from it
    import os
    import subprocess
    import sys

    result = subprocess.run([sys.executable, str(ROOT / "bench/bench_train_throughput.py"), "--seconds", "0.2",
                             "--sources", "gpu"], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                            env={**os.environ, "GLRADIAL_FIGURES_DIR": str(tmp_path)})  # not docs/figures/
    assert (tmp_path / "bench_train_throughput_cpu.json").is_file()
    assert result.returncode == 0, result.stderr
    assert "NOTE: no CUDA device" in result.stdout
    for label in ("step (fixed batch)", "source gpu", "train gpu"):
        line = next(line for line in result.stdout.splitlines() if line.startswith(label))
        assert float(line[len(label):].split()[0]) > 0


def test_device_colour_operations_match_opencv():
    # exposure, gamma, channel gains (OpenCV's lookup table, as net.augment builds it) and saturation
    # (cv2.addWeighted with the BT.601 grey) on the same draws: within a level (rounding order)
    import cv2

    image = synthetic_panoramas()[1][:36, :64]
    x = torch.from_numpy(image).permute(2, 0, 1)[None].float()
    augment = DeviceAugment(AugmentConfig(p_blur=0, p_motion=0, p_noise=0, p_jpeg=0, p_flip_h=0, p_flip_v=0), 0, "cpu")
    draws = augment.draws(1, (36, 64))
    got = augment.apply(x, draws)[0].permute(1, 2, 0).numpy()
    gamma, gain, sat = (float(draws[k][0]) for k in ("gamma", "gain", "sat"))
    cgain = draws["cgain"][0].double().numpy()
    levels = np.arange(256) / 255.0
    lut = np.clip(np.power(levels, gamma)[:, None] * (gain * cgain)[None, :] * 255.0 + 0.5, 0, 255).astype(np.uint8)
    want = cv2.LUT(np.ascontiguousarray(image), lut.reshape(256, 1, 3))
    grey = cv2.cvtColor(cv2.cvtColor(want, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    want = cv2.addWeighted(want, sat, grey, 1.0 - sat, 0.0).astype(float)
    assert np.abs(got - want).max() <= 1.0 and np.abs(got - want).mean() < 0.2
