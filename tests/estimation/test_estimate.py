"""glradial.estimation.net_lines: the onnxruntime NetLinesEstimator (errors, preprocessing) and the shipped model's quality."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import glradial
from glradial.estimation.net_lines import ModelLoadError, NetLinesEstimator, default_model_path

SHIPPED = default_model_path()
needs_shipped = pytest.mark.skipif(not SHIPPED.is_file(), reason="no shipped model in glradial/models")


def test_missing_model_file_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="model file not found"):
        NetLinesEstimator(tmp_path / "nope.onnx")


def test_corrupt_model_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"\x08\x07this is not a protobuf" * 10)
    with pytest.raises(ModelLoadError, match="cannot load ONNX model"):
        NetLinesEstimator(bad)


def test_bad_threads_argument(tmp_path):
    with pytest.raises(ValueError, match="threads"):
        NetLinesEstimator(tmp_path / "x.onnx", threads=0)


@needs_shipped
def test_shipped_model_metadata_and_bad_frames():
    est = NetLinesEstimator(threads=1)
    width, height = est.input_size
    assert est.metadata["input_layout"] == "NHWC uint8 RGB"
    assert abs(width / height - 16 / 9) < 0.05
    assert SHIPPED.stat().st_size < 30e6
    with pytest.raises(TypeError, match="NumPy array"):
        est.estimate([[1, 2], [3, 4]])
    with pytest.raises(ValueError, match="H×W or H×W×C"):
        est.estimate(np.zeros((10, 10, 2), np.uint8))
    with pytest.raises(TypeError, match="dtype"):
        est.estimate(np.zeros((90, 160, 3), np.int32))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        est.estimate(np.full((90, 160, 3), 2.0, np.float32))
    with warnings.catch_warnings():  # any shape is estimated in its own geometry, without Python warnings
        warnings.simplefilter("error")
        square = est.estimate(np.zeros((100, 100, 3), np.uint8))
    assert square.doubtful and square.reason == "blank_frame"


@needs_shipped
def test_shipped_model_gives_finite_lens_and_consistent_paths(field_panorama):
    frame = np.ascontiguousarray(field_panorama[300:300 + 405, 500:500 + 720])  # a 16:9 view of a real photo
    est = NetLinesEstimator(threads=1)
    lens = est(frame, method="net")
    assert isinstance(lens, glradial.Lens)
    assert np.isfinite([lens.k1, lens.k2]).all()
    assert -1.5 < lens.k1 < 1.0
    # batch, float input and the module-level function give the same numbers
    batch = est.estimate_batch([frame, frame[::-1]], method="net")
    assert batch[0] == lens
    assert glradial.estimate(frame, method="net").k1 == pytest.approx(lens.k1, abs=1e-6)
    as_float = est(frame.astype(np.float32) / 255.0, method="net")
    assert as_float.k1 == pytest.approx(lens.k1, abs=1e-6)


@needs_shipped
def test_shipped_model_beats_the_mean_baseline_on_held_out_stadiums():
    """A real check: on crops of a test-split stadium (never trained on), the model's distortion
    loss must be well below that of always predicting the training mean."""
    from glradial.synthesis.crops import CropRenderer, sample_crop_params
    from glradial.synthesis.stadium import split_seeds, stadium_panorama

    # A 1024x512 stadium (the training ones are 4096x2048) is cheap to render; hfov >= 45 deg keeps
    # its crops as sharp as the network input needs (45 deg of 1024 px = 128 px = the input width).
    seed = split_seeds("test", 1)[0]
    pano = stadium_panorama(seed, size=(1024, 512))
    params = sample_crop_params(40, 123, size=(1280, 720), hfov=(45.0, 60.0))
    with CropRenderer(pano, size=(1280, 720), out_size=(384, 216)) as renderer:
        frames = renderer.render(params)[..., :3]
    labels = np.array([(p.k1, p.k2) for p in params])
    pred = np.array([(lens.k1, lens.k2) for lens in NetLinesEstimator(threads=1).estimate_batch(list(frames), method="net")])
    radii = np.linspace(0.0, 0.7, 64)

    def dl(y, k):
        d = radii * radii * radii * (y[:, :1] - k[:, :1]) + radii**5 * (y[:, 1:] - k[:, 1:])
        return (d * d).sum(axis=1)

    # the paper's distribution's mean: k1 ~ U[-0.7, 0.3], k2 = 0.019 k1 + 0.805 k1^2 (+ zero-mean noise)
    mean = np.array([[-0.2, 0.019 * -0.2 + 0.805 * (0.04 + 1 / 12)]])
    model_dl, baseline_dl = dl(labels, pred).mean(), dl(labels, np.repeat(mean, len(labels), 0)).mean()
    # An untrained or broken model sits at ~1x the baseline (its median |k1 error| at ~0.25, the
    # spread of U[-0.7, 0.3] around its mean). The shipped model measured 0.06x and 0.047 here
    # (docs/MODEL.md); the bounds leave room for a retrained model while still failing a broken one.
    assert model_dl < 0.5 * baseline_dl, (model_dl, baseline_dl)
    assert np.median(np.abs(pred[:, 0] - labels[:, 0])) < 0.15


@needs_shipped
def test_mirror_average_is_the_mean_of_frame_and_mirror(field_panorama):
    """The default estimate averages the single-pass outputs of the frame and its left-right mirror,
    so it is the same for a frame and its mirror image (a radial lens is mirror-symmetric)."""
    single = NetLinesEstimator(threads=1, mirror_average=False)
    width, height = single.input_size
    # twice the input size: the area resize (an integer factor) commutes with mirroring exactly
    frame = np.ascontiguousarray(field_panorama[200:200 + 2 * height, 300:300 + 2 * width])
    mirror = np.ascontiguousarray(frame[:, ::-1])
    a, b = single(frame, method="net"), single(mirror, method="net")
    assert (a.k1, a.k2) != (b.k1, b.k2)  # the network alone is not mirror-invariant
    averaged = NetLinesEstimator(threads=1)
    both = averaged.estimate_batch([frame, mirror], method="net")
    for lens in both:
        assert lens.k1 == pytest.approx((a.k1 + b.k1) / 2, abs=1e-6)
        assert lens.k2 == pytest.approx((a.k2 + b.k2) / 2, abs=1e-6)
    with pytest.raises(TypeError, match="mirror_average"):
        NetLinesEstimator(mirror_average="yes")
