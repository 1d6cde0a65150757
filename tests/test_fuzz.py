"""Bad input across the public API: each call must raise ValueError or TypeError (or a documented
subclass: GLUnavailableError, ModelLoadError) whose message names the argument, never another
exception type, a hang or a silently wrong result; the CLI prints exactly one
``glradial: error: ...`` line naming the option. One test id per bad call.

Also: the GL and CPU backends give the same answer or the same error at the edges of the numeric
policy (glradial.remapping.remap.check_numeric_policy), and the NetLinesEstimator validates models at load.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from glradial import Lens, Remapper, cli, correct, distort, fit_scale
from glradial.estimation.net_lines import ModelLoadError, NetLinesEstimator, default_model_path
from glradial.export.stmap import lens_stmap, read_stmap
from glradial.lens.lens import corner_radius, frame_size, lens_to_pixels, pixels_to_lens
from glradial.synthesis.crops import CropParams, CropRenderer, render_crops, sample_crop_params
from glradial.synthesis.stadium import StadiumRenderer, stadium_panorama
from glradial.synthesis.stadium_style import sample_style

U8 = np.zeros((18, 32, 3), np.uint8)
F32 = np.zeros((18, 32, 3), np.float32)
PANO = np.zeros((32, 64, 3), np.uint8)
NAN = float("nan")
INF = float("inf")
PARAMS = [CropParams(0.0, 0.0, 0.0, 60.0, -0.1, 0.0)]


def _with_pixel(value: float) -> np.ndarray:
    frame = F32.copy()
    frame[5, 7, 1] = value
    return frame


# -- bad calls: (id, call(env), exception types, words the message must contain) -------------------
CASES: list[tuple[str, object, tuple[type, ...], str]] = []


def case(name, call, error, words):
    CASES.append((name, call, error if isinstance(error, tuple) else (error,), words))


# frames, coefficients, fit, fill and options of correct / distort on both backends
BAD_FRAMES = [
    ("list", [[0, 1], [2, 3]], TypeError, "frame must be a NumPy array"),
    ("none", None, TypeError, "frame must be a NumPy array"),
    ("empty", np.zeros((0, 32, 3), np.uint8), ValueError, "frame is empty"),
    ("1d", np.zeros(32, np.uint8), ValueError, "frame must be"),
    ("5d", np.zeros((1, 2, 18, 32, 3), np.uint8), ValueError, "frame must be"),
    ("empty_batch", np.zeros((0, 18, 32, 3), np.uint8), ValueError, "frame"),
    ("2ch", np.zeros((18, 32, 2), np.uint8), ValueError, "frame must be"),
    ("int64", np.zeros((18, 32, 3), np.int64), TypeError, "frame dtype"),
    ("float16", np.zeros((18, 32, 3), np.float16), TypeError, "frame dtype"),
    ("nan_pixel_float64", _with_pixel(NAN).astype(np.float64), ValueError, "frame contains NaN"),
    ("bool", np.zeros((18, 32), bool), TypeError, "frame dtype"),
    ("nan_pixel", _with_pixel(NAN), ValueError, "frame contains NaN"),
    ("inf_pixel", _with_pixel(INF), ValueError, "frame contains NaN"),
    ("neg_inf_pixel", _with_pixel(-INF), ValueError, "frame contains NaN"),
]
BAD_LENSES = [
    ("k1_nan", NAN, 0.0, ValueError, "k1"),
    ("k2_inf", 0.0, INF, ValueError, "k2"),
    ("k1_str", "0.1", 0.0, TypeError, "k1"),
    ("k2_str", 0.1, "0.1", TypeError, "k2"),
    ("k1_bool", True, 0.0, TypeError, "k1"),
    ("k1_complex", 1j, 0.0, TypeError, "k1"),
    ("k1_beyond_float32", 1e39, 0.0, ValueError, "k1"),
    ("k2_beyond_float32", 0.0, -1e39, ValueError, "k2"),
    ("k1_1e300", 1e300, 0.0, ValueError, "k1"),
    ("fold_over", -1.5, 0.0, ValueError, "folds over"),
]
BAD_OPTIONS = [
    ("fit_1e300", {"fit": 1e300}, ValueError, "fit"),
    ("fit_1e-300", {"fit": 1e-300}, ValueError, "fit"),
    ("fit_zero", {"fit": 0.0}, ValueError, "fit"),
    ("fit_negative", {"fit": -1.0}, ValueError, "fit"),
    ("fit_nan", {"fit": NAN}, ValueError, "fit"),
    ("fit_word", {"fit": "wide"}, ValueError, "fit"),
    ("fit_bool", {"fit": True}, ValueError, "fit"),
    ("fill_nan", {"fill": NAN}, ValueError, "fill"),
    ("fill_str", {"fill": "black"}, TypeError, "fill"),
    ("fill_two", {"fill": (1, 2)}, ValueError, "fill"),
    ("fill_negative_u8", {"fill": -1}, ValueError, "fill"),
    ("fill_256_u8", {"fill": 256}, ValueError, "fill"),
    ("fill_bool", {"fill": True}, TypeError, "fill"),
    ("interpolation", {"interpolation": "lanczos"}, ValueError, "interpolation"),
    ("interpolation_none", {"interpolation": None}, ValueError, "interpolation"),
    ("backend", {"backend": "vulkan"}, ValueError, "backend"),
]
for fn in (correct, distort):
    for backend in ("gl", "cpu"):
        tag = f"{fn.__name__}-{backend}"
        for name, frame, error, words in BAD_FRAMES:
            case(f"{tag}-frame-{name}", lambda env, fn=fn, f=frame, b=backend: fn(f, -0.1, 0.0, backend=b), error, words)
        for name, k1, k2, error, words in BAD_LENSES:
            case(f"{tag}-lens-{name}", lambda env, fn=fn, a=k1, c=k2, b=backend: fn(U8, a, c, backend=b), error, words)
        for name, options, error, words in BAD_OPTIONS:
            if name == "backend" and backend == "cpu":
                continue
            kwargs = {"backend": backend, **options}
            case(f"{tag}-{name}", lambda env, fn=fn, kw=kwargs: fn(U8, -0.1, 0.0, **kw), error, words)
        case(f"{tag}-fill_1e40_float32", lambda env, fn=fn, b=backend: fn(F32, -0.1, 0.0, fill=1e40, backend=b), ValueError, "fill")
        if fn is correct:
            case(f"{tag}-fit_overflow", lambda env, b=backend: correct(U8, 1e30, 1e30, fit=1e5, backend=b), ValueError, "fit")
    case(f"{fn.__name__}-inverse", lambda env, fn=fn: fn(U8, -0.1, 0.0, inverse="newton"), (ValueError, TypeError), "inverse")
for backend in ("gl", "cpu"):  # the inverse's Drap-Lefevre seed b4 = 55 k1^4 ... overflows float32
    case(f"distort-{backend}-lens-k1_huge_inverse", lambda env, b=backend: distort(U8, 1e12, 0.0, backend=b), ValueError, ("k1", "overflows"))

# Lens and its converters
case("lens-k1-nan", lambda env: Lens(NAN, 0.0), ValueError, "k1")
case("lens-k2-list", lambda env: Lens(0.0, [0.1]), TypeError, "k2")
case("lens-rescale-1e-200", lambda env: Lens(-0.2, 0.05).rescale(1e-200), ValueError, "s=")
case("lens-rescale-inf", lambda env: Lens(-0.2, 0.05).rescale(INF), ValueError, "s must be finite")
case("lens-rescale-zero", lambda env: Lens(-0.2, 0.05).rescale(0), ValueError, "s must be positive")
case("lens-rescale-nan", lambda env: Lens(-0.2, 0.05).rescale(NAN), ValueError, "s must be finite")
case("lens-rescale-str", lambda env: Lens(-0.2, 0.05).rescale("2"), TypeError, "s must be a real number")
case("lens-fit-full-1e308", lambda env: Lens(1e308, 1e308).fit_scale((32, 18), "full"), ValueError, "fit")
case("lens-fit-crop-1e308", lambda env: Lens(-1e308, 1e308).fit_scale((32, 18), "crop"), ValueError, "fit")
case("lens-fit-unknown", lambda env: Lens(-0.1, 0).fit_scale((32, 18), "zoom"), ValueError, "fit")
case("lens-fit-direction", lambda env: Lens(-0.1, 0).fit_scale((32, 18), "crop", "sideways"), ValueError, "direction")
case("lens-fit-size", lambda env: Lens(-0.1, 0).fit_scale((0, 18), "crop"), ValueError, "width")
case("lens-maps-dtype", lambda env: Lens(-0.1, 0).maps((32, 18), dtype=np.int32), TypeError, "dtype")
case("lens-maps-inverse", lambda env: Lens(-0.1, 0).maps((32, 18), "distort", inverse="x"), ValueError, "inverse")
case("lens-maps-scale", lambda env: Lens(-0.1, 0).maps((32, 18), scale=-2.0), ValueError, "scale")
case("lens-maps-fold", lambda env: Lens(-1.5, 0).maps((32, 18)), ValueError, "folds over")
case("lens-inverse-method", lambda env: Lens(-0.1, 0).inverse_radius(0.3, method="newton"), ValueError, "method")
case("lens-points-shape", lambda env: Lens(-0.1, 0).distort_points(np.zeros((3, 3)), (32, 18)), ValueError, "points")
case("lens-points-dtype", lambda env: Lens(-0.1, 0).distort_points(np.array([["a", "b"]]), (32, 18)), TypeError, "points")
case("lens-to-ffmpeg-range", lambda env: Lens(-10.0, 0).to_ffmpeg((1920, 1080)), ValueError, "k1")
case("lens-to-pixel-size", lambda env: Lens(-0.1, 0).to_pixel((1920,)), TypeError, "size")
case("lens-to-pixel-float-size", lambda env: Lens(-0.1, 0).to_pixel((1920.5, 1080)), TypeError, "width")
case("lens-from-pixel-nan", lambda env: Lens.from_pixel(NAN, 0.0, (1920, 1080)), ValueError, "k1")
case("lens-from-ffmpeg-str", lambda env: Lens.from_ffmpeg("a", 0.0, (1920, 1080)), TypeError, "k1")
case("lens-to-opencv-focal", lambda env: Lens(-0.1, 0).to_opencv((1920, 1080), focal=-5.0), ValueError, "focal")
case("lens-to-opencv-focal-nan", lambda env: Lens(-0.1, 0).to_opencv((1920, 1080), focal=NAN), ValueError, "focal")
case("lens-from-opencv-shape", lambda env: Lens.from_opencv(np.eye(2), [0, 0, 0, 0], (32, 18)), ValueError, "camera_matrix")
case("lens-from-opencv-nan", lambda env: Lens.from_opencv(np.full((3, 3), NAN), [0, 0, 0, 0], (32, 18)), ValueError, "camera_matrix")
case("lens-from-opencv-skew", lambda env: Lens.from_opencv([[32, 1, 15.5], [0, 32, 8.5], [0, 0, 1]], [0, 0, 0, 0], (32, 18)), ValueError, "camera_matrix")
case("lens-from-opencv-focal", lambda env: Lens.from_opencv([[-32, 0, 15.5], [0, 32, 8.5], [0, 0, 1]], [0, 0, 0, 0], (32, 18)), ValueError, "focal")
case("lens-from-opencv-dist-count", lambda env: Lens.from_opencv([[32, 0, 15.5], [0, 32, 8.5], [0, 0, 1]], [0, 0, 0], (32, 18)), ValueError, "dist_coeffs")
case("lens-from-opencv-dist-str", lambda env: Lens.from_opencv([[32, 0, 15.5], [0, 32, 8.5], [0, 0, 1]], ["a"] * 4, (32, 18)), TypeError, "dist_coeffs")
case("lens-from-opencv-tangential", lambda env: Lens.from_opencv([[32, 0, 15.5], [0, 32, 8.5], [0, 0, 1]], [0, 0, 0.1, 0], (32, 18)), ValueError, "p1")
case("frame_size-str", lambda env: frame_size("1920x1080"), TypeError, "size")
case("frame_size-negative", lambda env: frame_size((-1, 5)), ValueError, "width")
case("frame_size-bool", lambda env: frame_size((True, 5)), TypeError, "width")
case("corner_radius-zero", lambda env: corner_radius((32, 0)), ValueError, "height")
case("pixels_to_lens-size", lambda env: pixels_to_lens(np.zeros((2, 2)), (0, 0)), ValueError, "width")
case("lens_to_pixels-size", lambda env: lens_to_pixels(np.zeros((2, 2)), None), TypeError, "size")
case("fit_scale-lens-str", lambda env: fit_scale("lens", (32, 18)), TypeError, "lens")
case("fit_scale-lens-three", lambda env: fit_scale((0.1, 0.2, 0.3), (32, 18)), TypeError, "lens")
case("fit_scale-1e308", lambda env: fit_scale((1e308, 1e308), (32, 18), "full"), ValueError, "fit")
case("stmap-direction", lambda env: lens_stmap(Lens(-0.1, 0), (32, 18), direction="up"), ValueError, "direction")
case("stmap-size", lambda env: lens_stmap(Lens(-0.1, 0), (32, -18)), ValueError, "height")
case("read_stmap-corrupt", lambda env: read_stmap(Path(__file__).parent / "data" / "README.md"), ValueError, "README.md")
case("read_stmap-missing", lambda env: read_stmap("/nonexistent/map.tif"), FileNotFoundError, "map.tif")

# crops
case("CropParams-tilt", lambda env: CropParams(0, 95, 0, 60, -0.1, 0), ValueError, "tilt")
case("CropParams-hfov", lambda env: CropParams(0, 0, 0, 180, -0.1, 0), ValueError, "hfov")
case("CropParams-nan", lambda env: CropParams(NAN, 0, 0, 60, -0.1, 0), ValueError, "pan")
case("CropParams-str", lambda env: CropParams(0, 0, "x", 60, -0.1, 0), TypeError, "roll")
case("sample_crop_params-n", lambda env: sample_crop_params(-1, 0), ValueError, "n must be")
case("sample_crop_params-seed-str", lambda env: sample_crop_params(3, seed="a"), TypeError, "seed must be an integer >= 0, got 'a' (str)")
case("sample_crop_params-seed-float", lambda env: sample_crop_params(3, seed=1.5), TypeError, "seed must be an integer >= 0, got 1.5")
case("sample_crop_params-seed-none", lambda env: sample_crop_params(3, seed=None), TypeError, "seed must be an integer >= 0, got None")
case("sample_crop_params-seed-negative", lambda env: sample_crop_params(3, seed=-1), ValueError, "seed must be an integer >= 0, got -1")
case("sample_crop_params-range", lambda env: sample_crop_params(2, 0, k1=(0.1, -0.1)), ValueError, "k1")
case("sample_crop_params-range-type", lambda env: sample_crop_params(2, 0, pan="wide"), TypeError, "pan")
case("sample_crop_params-unknown", lambda env: sample_crop_params(2, 0, zoom=(1, 2)), (ValueError, TypeError), "zoom")
case("render_crops-empty-panorama", lambda env: render_crops(np.zeros((0, 0, 3), np.uint8), PARAMS, size=(32, 18)), ValueError, "panorama")
case("render_crops-3to1-panorama", lambda env: render_crops(np.zeros((10, 30, 3), np.uint8), PARAMS, size=(32, 18)), ValueError, "panorama")
case("render_crops-5ch-panorama", lambda env: render_crops(np.zeros((16, 32, 5), np.uint8), PARAMS, size=(32, 18)), ValueError, "panorama")
case("render_crops-int32-panorama", lambda env: render_crops(np.zeros((16, 32, 3), np.int32), PARAMS, size=(32, 18)), TypeError, "panorama")
case("render_crops-nan-panorama", lambda env: render_crops(np.full((16, 32, 3), NAN, np.float32), PARAMS, size=(32, 18)), ValueError, "panorama")
case("render_crops-out_size-20000", lambda env: render_crops(PANO, PARAMS, out_size=(20000, 20000)), ValueError, "out_size")
case("render_crops-size", lambda env: render_crops(PANO, PARAMS, size=(0, 18)), ValueError, "width")
case("render_crops-inverse", lambda env: render_crops(PANO, PARAMS, size=(32, 18), inverse="series"), ValueError, "inverse")
case("render_crops-supersample-0", lambda env: render_crops(PANO, PARAMS, size=(32, 18), supersample=0), ValueError, "supersample")
case("render_crops-supersample-9", lambda env: render_crops(PANO, PARAMS, size=(32, 18), supersample=9), ValueError, "supersample")
case("render_crops-supersample-str", lambda env: render_crops(PANO, PARAMS, size=(32, 18), supersample="best"), ValueError, "supersample")
case("render_crops-params-type", lambda env: render_crops(PANO, [(0, 0, 0, 60, -0.1, 0)], size=(32, 18)), TypeError, "params[0]")
case("render_crops-params-scalar", lambda env: render_crops(PANO, PARAMS[0], size=(32, 18)), TypeError, "params")
case("CropRenderer-ctx", lambda env: CropRenderer(PANO, size=(32, 18), ctx="x"), TypeError, "ctx")
case("CropRenderer-newton_steps", lambda env: CropRenderer(PANO, size=(32, 18), newton_steps=0), ValueError, "newton_steps")
case("CropRenderer-anisotropy", lambda env: CropRenderer(PANO, size=(32, 18), anisotropy=0.5), ValueError, "anisotropy")
case("CropRenderer-series_inverse", lambda env: CropRenderer(PANO, size=(32, 18), series_inverse="yes"), TypeError, "series_inverse")


def _crop_out(env, out):
    with CropRenderer(PANO, size=(32, 18)) as renderer:
        return renderer.render(PARAMS, out=out)


case("CropRenderer-render-out", lambda env: _crop_out(env, np.zeros((1, 18, 32, 3), np.float32)), ValueError, "out")

# stadium
case("stadium-size-small", lambda env: stadium_panorama(1, (4, 2)), ValueError, "size")
case("stadium-size-str", lambda env: stadium_panorama(1, ("a", 2)), TypeError, "size")
case("stadium-size-none", lambda env: stadium_panorama(1, None), TypeError, "size")
case("stadium-lighting", lambda env: stadium_panorama(1, (64, 32), lighting="disco"), (ValueError, TypeError), "lighting")
case("stadium-unknown-style", lambda env: stadium_panorama(1, (64, 32), colour="red"), (ValueError, TypeError), "colour")
case("StadiumRenderer-ctx", lambda env: StadiumRenderer("ctx"), TypeError, "ctx")


def _stadium(env, **kwargs):
    with StadiumRenderer() as renderer:
        return renderer.render(kwargs.pop("style", sample_style(1)), **kwargs)


case("StadiumRenderer-style", lambda env: _stadium(env, style="night"), TypeError, "style")
case("StadiumRenderer-rows", lambda env: _stadium(env, size=(64, 32), rows=(10, 5)), ValueError, "rows")
case("StadiumRenderer-rows-beyond", lambda env: _stadium(env, size=(64, 32), rows=(0, 33)), ValueError, "rows")
case("StadiumRenderer-out", lambda env: _stadium(env, size=(64, 32), out=np.zeros((32, 64, 4), np.uint8)), ValueError, "out")


# Remapper
def _texture_call(env, **kwargs):
    ctx = env["ctx"]
    source = ctx.texture((32, 18), 4)
    target_texture = ctx.texture((32, 18), 4)
    target = ctx.framebuffer(color_attachments=[target_texture])
    args = {"source": source, "target": target, "lens": -0.1, "k2": 0.0}
    args.update(kwargs)
    remapper = Remapper(ctx)
    try:
        remapper.render_texture(**args)
    finally:
        remapper.release()
        for obj in (target, target_texture, source):
            obj.release()


case("Remapper-ctx-str", lambda env: Remapper(ctx="x"), TypeError, "ctx")
case("Remapper-ctx-int", lambda env: Remapper(ctx=1), TypeError, "ctx")
case("render_texture-source-none", lambda env: _texture_call(env, source=None), TypeError, "source")
case("render_texture-target-none", lambda env: _texture_call(env, target=None), TypeError, "target")
case("render_texture-target-texture", lambda env: _texture_call(env, target=env["ctx"].texture((4, 4), 4)), TypeError, "target")
case("render_texture-texture_unit-negative", lambda env: _texture_call(env, texture_unit=-1), ValueError, "texture_unit")
case("render_texture-texture_unit-huge", lambda env: _texture_call(env, texture_unit=10**6), ValueError, "texture_unit")
case("render_texture-texture_unit-float", lambda env: _texture_call(env, texture_unit=1.5), TypeError, "texture_unit")
case("render_texture-viewport-short", lambda env: _texture_call(env, viewport=(0, 0, 4)), TypeError, "viewport")
case("render_texture-viewport-zero", lambda env: _texture_call(env, viewport=(0, 0, 0, 4)), ValueError, "width")
case("render_texture-viewport-float", lambda env: _texture_call(env, viewport=(0.5, 0, 4, 4)), TypeError, "viewport")
case("render_texture-scale", lambda env: _texture_call(env, scale=0.0), ValueError, "scale")
case("render_texture-scale-1e300", lambda env: _texture_call(env, scale=1e300), ValueError, "scale")
case("render_texture-fill", lambda env: _texture_call(env, fill=(0, 0, 0)), ValueError, "fill")
case("render_texture-direction", lambda env: _texture_call(env, direction="forward"), ValueError, "direction")
case("render_texture-k1", lambda env: _texture_call(env, lens=1e39), ValueError, "k1")


def _remapper_call(env, method="correct", frame=U8, **kwargs):
    with Remapper(env["ctx"]) as remapper:
        return getattr(remapper, method)(frame, kwargs.pop("k1", -0.1), 0.0, **kwargs)


case("Remapper-out-shape", lambda env: _remapper_call(env, out=np.zeros((18, 32, 4), np.uint8)), ValueError, "out")
case("Remapper-out-dtype", lambda env: _remapper_call(env, out=np.zeros((18, 32, 3), np.float32)), ValueError, "out")
case("Remapper-too-large", lambda env: _remapper_call(env, frame=np.zeros((1, 40000), np.uint8)), ValueError, "texture limit")
case("Remapper-distort-k1", lambda env: _remapper_call(env, "distort", k1=NAN), ValueError, "k1")
case("Remapper-distort-fill", lambda env: _remapper_call(env, "distort", fill=[1, 2, 3, 4]), ValueError, "fill")


def _released(env):
    remapper = Remapper(env["ctx"])
    remapper.release()
    remapper.correct(U8, -0.1, 0.0)


# estimator: bad frames and arguments
def _est(env):
    return env["estimator"]


case("NetLinesEstimator-threads-zero", lambda env: NetLinesEstimator(threads=0), ValueError, "threads")
case("NetLinesEstimator-threads-str", lambda env: NetLinesEstimator(threads="2"), ValueError, "threads")
case("NetLinesEstimator-threads-bool", lambda env: NetLinesEstimator(threads=True), ValueError, "threads")
case("NetLinesEstimator-mirror_average", lambda env: NetLinesEstimator(mirror_average="no"), TypeError, "mirror_average")
case("estimate-str", lambda env: _est(env).estimate("frame.png"), TypeError, "frame")
case("estimate-tiny", lambda env: _est(env).estimate(np.zeros((1, 1, 3), np.uint8)), ValueError, "frame")
case("estimate-2ch", lambda env: _est(env).estimate(np.zeros((36, 64, 2), np.uint8)), ValueError, "frame")
case("estimate-int16", lambda env: _est(env).estimate(np.zeros((36, 64, 3), np.int16)), TypeError, "frame")
case("estimate-float-range", lambda env: _est(env).estimate(np.full((36, 64, 3), 2.0, np.float32)), ValueError, "frame")
case("estimate-float-nan", lambda env: _est(env).estimate(np.full((36, 64, 3), NAN, np.float32)), ValueError, "frame")
case("estimate_batch-item", lambda env: _est(env).estimate_batch([np.zeros((36, 64, 3), np.uint8), None]), TypeError, "frames[1]")
case("estimator-run-shape", lambda env: _est(env).run(np.zeros((1, 10, 10, 3), np.uint8)), ValueError, "images")
for _name in ("n_by_3", "symbolic", "nan_output", "two_outputs", "float_input", "rank3_input", "rank3_output",
              "size_disagrees", "bad_input_size", "wrong_names", "corrupt_bundled", "garbage_checksum", "not_onnx"):
    case(f"NetLinesEstimator-model-{_name}", lambda env, n=_name: NetLinesEstimator(env["models"][n], threads=1), ModelLoadError, "")
case("NetLinesEstimator-model-missing", lambda env: NetLinesEstimator(env["models"]["n_by_3"].with_name("absent.onnx")), FileNotFoundError, "model file not found")


@pytest.fixture(scope="module")
def env(gl_ctx, tmp_path_factory):
    return {"ctx": gl_ctx, "estimator": NetLinesEstimator(threads=1), "models": _make_models(tmp_path_factory.mktemp("models"))}


@pytest.mark.parametrize("call, errors, words", [pytest.param(c, e, w, id=n) for n, c, e, w in CASES])
def test_bad_call(env, ctx, call, errors, words):
    with pytest.raises(Exception) as info:
        call(env)
    err = info.value
    assert isinstance(err, errors), f"{type(err).__name__}: {err}"
    assert isinstance(err, (ValueError, TypeError, FileNotFoundError)), f"{type(err).__name__}: {err}"
    for word in (words if isinstance(words, tuple) else (words,)):
        assert word in str(err), f"{word!r} not in {err}"


def test_case_count():
    assert len(CASES) + len(CLI_CASES) >= 200


# -- the CLI: one line, exit 1 (bad input) or 2 (usage) ------------------------------------------
def _cli_files(tmp: Path) -> dict[str, str]:
    import cv2

    good = tmp / "good.png"
    cv2.imwrite(str(good), np.full((36, 64, 3), 100, np.uint8))
    data = good.read_bytes()
    (tmp / "trunc.png").write_bytes(data[: len(data) // 2])
    (tmp / "bad.mp4").write_bytes(b"not a video at all" * 10)
    (tmp / "empty.png").write_bytes(b"")
    from fractions import Fraction

    from glradial.media.video_io import EncodeOptions, VideoInfo, VideoWriter

    with VideoWriter(tmp / "clip.mp4", VideoInfo.of((64, 36), Fraction(25)), options=EncodeOptions(codec="libx264")) as writer:
        for value in range(0, 250, 50):
            writer.write(np.full((36, 64, 3), value, np.uint8))
    return {"good": str(good), "trunc": str(tmp / "trunc.png"), "bad_video": str(tmp / "bad.mp4"),
            "empty": str(tmp / "empty.png"), "video": str(tmp / "clip.mp4"), "tmp": str(tmp)}


CLI_CASES = [
    ("correct-k1-nan", "correct {good} {tmp}/o.png --k1 nan", 2, "--k1"),
    ("correct-k1-word", "correct {good} {tmp}/o.png --k1 big", 2, "--k1"),
    ("correct-k1-1e39", "correct {good} {tmp}/o.png --k1 1e39", 1, "k1"),
    ("correct-fold", "correct {good} {tmp}/o.png --k1 -1.5", 1, "folds over"),
    ("correct-missing-input", "correct {tmp}/nope.png {tmp}/o.png --k1 -0.1", 1, "nope.png"),
    ("correct-trunc-png", "correct {trunc} {tmp}/o.png --k1 -0.1", 1, "trunc.png"),
    ("correct-empty-png", "correct {empty} {tmp}/o.png --k1 -0.1", 1, "empty.png"),
    ("correct-bad-video", "correct {bad_video} {tmp}/o.mp4 --k1 -0.1", 1, "bad.mp4"),
    ("correct-out-ext", "correct {good} {tmp}/o.bmpx --k1 -0.1", 2, "o.bmpx"),
    ("correct-out-folder", "correct {good} {tmp}/no/such/o.png --k1 -0.1", 1, "no/such"),
    ("correct-model-n3", "correct {good} {tmp}/o.png --auto --model {model_n_by_3}", 1, "N×2"),
    ("correct-model-missing", "correct {good} {tmp}/o.png --auto --model {tmp}/none.onnx", 1, "none.onnx"),
    ("estimate-trunc", "estimate {trunc}", 1, "trunc.png"),
    ("estimate-bad-video", "estimate {bad_video}", 1, "bad.mp4"),
    ("estimate-threads", "estimate {good} --threads 0", 2, "--threads"),
    ("estimate-model-corrupt", "estimate {good} --model {model_corrupt_bundled}", 1, "SHA-256"),
    ("stadium-bmpx", "stadium --seed 1 --size 64x32 --out {tmp}/x.bmpx", 1, ".bmpx"),
    ("stadium-video", "stadium --seed 1 --size 64x32 --out {tmp}/x.mp4", 1, "--out"),
    ("stadium-size", "stadium --seed 1 --size 4x2 --out {tmp}/x.png", 1, "size"),
    ("stmap-size", "stmap --k1 -0.1 --size 0x10 --out {tmp}/m.tif", 2, "--size"),
    ("stmap-ext", "stmap --k1 -0.1 --size 32x18 --out {tmp}/m.png", 1, "m.png"),
    ("convert-ffmpeg-range", "convert --from glradial --to ffmpeg --size 1920x1080 -10 0", 1, "k1"),
    ("convert-values", "convert --from glradial --to opencv --size 1920x1080 0.1 0.2 0.3", 2, "two values"),
    ("crops-count", "crops {good} --count 0 --out {tmp}/c --seed 0", 2, "--count"),
    ("crops-not-panorama", "crops {good} --count 2 --out {tmp}/c --seed 0 --size 32x18", 1, "2:1"),
    ("crops-corrupt-panorama", "crops {trunc} --count 2 --out {tmp}/c2 --seed 0", 1, "trunc.png"),
    ("stmap-out-folder", "stmap --k1 -0.1 --size 32x18 --out {tmp}/none/m.tif", 1, "none"),
    # an unwritable folder (procfs refuses new files, even to root): the user's path and the errno
    # symbol, never the temporary file's name (checked for every case below)
    ("correct-out-unwritable", "correct {good} /proc/o.png --k1 -0.1", 1, "cannot write '/proc/o.png': cannot create a file in its folder: No such file or directory (ENOENT)"),
    ("stmap-out-unwritable", "stmap --k1 -0.1 --size 32x18 --out /proc/m.tif", 1, "cannot write '/proc/m.tif'"),
    ("stadium-out-unwritable", "stadium --seed 1 --size 64x32 --out /proc/s.png", 1, "cannot write '/proc/s.png'"),
    # options of --auto on a video are refused, not ignored, where they cannot apply
    ("correct-every-without-auto", "correct {bad_video} {tmp}/o.mp4 --k1 -0.2 --every 3", 2, "--every needs --auto"),
    ("correct-apply-doubtful-without-auto", "correct {bad_video} {tmp}/o.mp4 --k1 -0.2 --apply-doubtful", 2, "--apply-doubtful needs --auto"),
    ("correct-every-on-an-image", "correct {good} {tmp}/o.png --auto --every 3", 2, "--every is for videos"),
    ("correct-max-uncertainty-on-an-image", "correct {good} {tmp}/o.png --auto --max-uncertainty 5", 2, "--max-uncertainty is for videos"),
    ("correct-sidecar-txt", "correct {bad_video} {tmp}/o.mp4 --auto --sidecar {tmp}/side.txt", 2, "--sidecar '{tmp}/side.txt' must end in .csv or .json"),
    # a preset the encoder does not know: one line naming it and the encoder's presets (x264's own
    # "x264 [error]" lines silenced); an encoder without presets refuses --preset instead of ignoring it
    ("correct-preset-unknown", "correct {video} {tmp}/o.mp4 --k1 -0.2 --preset ludicrous", 1,
     "--preset 'ludicrous' is not a preset of libx264 (ultrafast superfast veryfast faster fast medium slow slower veryslow placebo)"),
    ("correct-preset-ffv1", "correct {video} {tmp}/o.mkv --k1 -0.2 --codec ffv1 --preset slow", 1,
     "--preset 'slow': encoder ffv1 has no presets"),
    ("correct-sequence-out-unwritable", "correct {video} /proc/f_%04d.png --k1 -0.1", 1, "cannot write '/proc/f_%04d.png': cannot create a folder"),
    ("correct-out-folder-is-a-file", "correct {good} {good}/o.png --k1 -0.1", 1, "good.png' is a file, not a folder"),
]


@pytest.fixture(scope="module")
def cli_env(env, tmp_path_factory):
    files = _cli_files(tmp_path_factory.mktemp("cli"))
    files.update({f"model_{k}": str(v) for k, v in env["models"].items()})
    return files


@pytest.mark.parametrize("argv, code, words", [pytest.param(a, c, w, id=n) for n, a, c, w in CLI_CASES])
def test_cli_bad_call(cli_env, capfd, argv, code, words):
    status = cli.main(argv.format(**cli_env).split())
    out, err = capfd.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert status == code, err
    assert len(lines) == 1 and lines[0].startswith("glradial: error: "), err
    assert "error: error" not in lines[0] and ".tmp" not in lines[0] and "[Errno" not in lines[0]
    assert words.format(**cli_env) in lines[0], lines[0]


# -- the numeric policy: GL and CPU agree at the edges ------------------------------------------
EDGE_LENSES = [(-0.3, 0.1, "same"), (1e6, 0.0, "same"), (0.0, 1e12, "same"), (3e38, 0.0, "same"),
               (1e5, 0.0, "full"), (-0.2, 0.0, 1e-30), (-0.2, 0.0, 1e30), (1e9, 0.0, "same"), (2e9, 0.0, "same")]


@pytest.mark.parametrize("k1, k2, fit", EDGE_LENSES)
@pytest.mark.parametrize("fn", [correct, distort], ids=["correct", "distort"])
def test_backends_agree_or_both_refuse(ctx, fn, k1, k2, fit):
    """Same answer (within one level of 255 on 99 % of pixels: float32 shader vs float64 maps,
    fixed-point remap) or the same ValueError message from both backends."""
    y, x = np.mgrid[0:18, 0:32]
    # smooth (at most ~12 levels between neighbours), so OpenCV's 1/32-pixel fixed-point maps stay within a level
    frame = np.stack([8 * x, 12 * y, 128 + 100 * np.sin(x / 5.0) * np.cos(y / 4.0)], axis=-1).astype(np.uint8)
    results = {}
    for backend in ("gl", "cpu"):
        try:
            results[backend] = fn(frame, k1, k2, fit=fit, backend=backend)
        except ValueError as err:
            results[backend] = str(err)
    gl, cpu = results["gl"], results["cpu"]
    assert type(gl) is type(cpu), results
    if isinstance(gl, str):
        assert gl == cpu
    else:
        close = np.abs(gl.astype(int) - cpu.astype(int)) <= 1
        assert close.mean() >= 0.99, f"{close.mean():.3f} of pixels agree"


# -- model validation ------------------------------------------------------------------------------
def _graph(tmp: Path, name: str, *, out_channels=2, hw=(216, 384), meta=None, input_type=None, input_rank=4,
           output_rank=2, nan=False, two_outputs=False, names=("image", "k")) -> Path:
    """A tiny ONNX model: the mean of each colour channel over the frame (/ 255), the first
    ``out_channels`` of them as the output (so a constant frame of level v gives v / 255)."""
    import onnx
    from onnx import TensorProto, helper

    in_name, out_name = names
    dims = ["N", *hw, 3] if input_rank == 4 else ["N", hw[0], 3]
    inp = helper.make_tensor_value_info(in_name, input_type or TensorProto.UINT8, dims)
    nodes = [
        helper.make_node("Cast", [in_name], ["f"], to=TensorProto.FLOAT),
        helper.make_node("ReduceMean", ["f"], ["m"], axes=list(range(1, input_rank - 1)), keepdims=0),
        helper.make_node("Constant", [], ["scale"], value=helper.make_tensor("scale", TensorProto.FLOAT, [], [NAN if nan else 1 / 255])),
        helper.make_node("Mul", ["m", "scale"], ["ms"]),
        helper.make_node("Constant", [], ["starts"], value=helper.make_tensor("starts", TensorProto.INT64, [1], [0])),
        helper.make_node("Constant", [], ["ends"], value=helper.make_tensor("ends", TensorProto.INT64, [1], [out_channels])),
        helper.make_node("Constant", [], ["axes"], value=helper.make_tensor("axes", TensorProto.INT64, [1], [1])),
        helper.make_node("Slice", ["ms", "starts", "ends", "axes"], ["sliced"]),
    ]
    if output_rank == 3:
        nodes.append(helper.make_node("Unsqueeze", ["sliced", "axes"], [out_name]))
        out_dims = ["N", 1, out_channels]
    else:
        nodes.append(helper.make_node("Identity", ["sliced"], [out_name]))
        out_dims = ["N", out_channels]
    out_infos = [helper.make_tensor_value_info(out_name, TensorProto.FLOAT, out_dims)]
    if two_outputs:
        nodes.append(helper.make_node("Identity", ["sliced"], ["extra"]))
        out_infos.append(helper.make_tensor_value_info("extra", TensorProto.FLOAT, ["N", out_channels]))
    graph = helper.make_graph(nodes, name, [inp], out_infos)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    for key, value in (meta or {}).items():
        model.metadata_props.append(onnx.StringStringEntryProto(key=key, value=value))
    path = tmp / f"{name}.onnx"
    onnx.save(model, str(path))
    return path


def _make_models(tmp: Path) -> dict[str, Path]:
    from onnx import TensorProto

    models = {
        "valid": _graph(tmp, "valid", hw=(36, 64)),
        "valid_symbolic_meta": _graph(tmp, "valid_symbolic_meta", hw=("H", "W"), meta={"input_size": "64,36"}),
        "n_by_3": _graph(tmp, "n_by_3", out_channels=3, hw=(36, 64)),
        "symbolic": _graph(tmp, "symbolic", hw=("H", "W")),
        "nan_output": _graph(tmp, "nan_output", hw=(36, 64), nan=True),
        "two_outputs": _graph(tmp, "two_outputs", hw=(36, 64), two_outputs=True),
        "float_input": _graph(tmp, "float_input", hw=(36, 64), input_type=TensorProto.FLOAT),
        "rank3_input": _graph(tmp, "rank3_input", hw=(36, 64), input_rank=3),
        "rank3_output": _graph(tmp, "rank3_output", hw=(36, 64), output_rank=3),
        "size_disagrees": _graph(tmp, "size_disagrees", hw=(36, 64), meta={"input_size": "64,40"}),
        "bad_input_size": _graph(tmp, "bad_input_size", hw=("H", "W"), meta={"input_size": "big"}),
        "wrong_names": _graph(tmp, "wrong_names", hw=(36, 64), meta={"glradial_format": "1"}, names=("x", "y")),
    }
    bundled = default_model_path()
    corrupt = tmp / "corrupt_bundled.onnx"
    data = bytearray(bundled.read_bytes())
    rng = np.random.default_rng(0)
    for index in rng.choice(np.arange(len(data) // 2, len(data)), 200, replace=False):  # weights, not the header
        data[index] ^= 0xFF
    corrupt.write_bytes(bytes(data))
    shutil.copy(bundled.with_suffix(".sha256"), corrupt.with_suffix(".sha256"))
    models["corrupt_bundled"] = corrupt
    garbage = tmp / "garbage_checksum.onnx"
    shutil.copy(models["valid"], garbage)
    garbage.with_suffix(".sha256").write_text("")
    models["garbage_checksum"] = garbage
    not_onnx = tmp / "not_onnx.onnx"
    not_onnx.write_bytes(b"\x00\x01 this is not a protobuf" * 50)
    models["not_onnx"] = not_onnx
    return models


def test_valid_user_model_without_checksum_loads_and_gives_one_lens_per_frame(env):
    """The test graph outputs the mean R and G levels / 255: constant frames give known lenses.
    mirror_average=False with two frames gives two lenses (it used to give three for an N×3 model)."""
    frames = [np.full((72, 128, 3), level, np.uint8) for level in (51, 204)]
    for name in ("valid", "valid_symbolic_meta"):
        estimator = NetLinesEstimator(env["models"][name], threads=1, mirror_average=False)
        assert estimator.input_size == (64, 36)
        lenses = estimator.estimate_batch(frames)
        assert len(lenses) == 2
        for lens, level in zip(lenses, (51, 204)):
            assert math.isclose(lens.k1, level / 255, abs_tol=1e-6) and math.isclose(lens.k2, level / 255, abs_tol=1e-6)


@pytest.mark.parametrize(
    "name, words",
    [("n_by_3", "N×2"), ("symbolic", "symbolic"), ("nan_output", "non-finite"), ("two_outputs", "1 input and 1 output"),
     ("float_input", "uint8"), ("rank3_input", "uint8 N×H×W×3"), ("rank3_output", "N×2"), ("size_disagrees", "disagrees"),
     ("bad_input_size", "input_size"), ("wrong_names", "'image'"), ("corrupt_bundled", "SHA-256"),
     ("garbage_checksum", "checksum"), ("not_onnx", "cannot load")],
)
def test_bad_models_name_the_problem(env, name, words):
    with pytest.raises(ModelLoadError, match=None) as info:
        NetLinesEstimator(env["models"][name], threads=1)
    assert words in str(info.value) and env["models"][name].name in str(info.value)


# -- a write that fails in the file system names the output and the errno ----------------------------
def test_write_on_a_full_disk_names_path_and_enospc(tmp_path, monkeypatch, capfd):
    """ENOSPC simulated where a full disk reports it at the latest (flushing the file to disk)."""
    import errno

    from glradial.media import atomic

    def full_disk(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(atomic.os, "fsync", full_disk)
    target = tmp_path / "x.png"
    status = cli.main(["stadium", "--seed", "1", "--size", "64x32", "--out", str(target)])
    lines = [line for line in capfd.readouterr().err.splitlines() if line.strip()]
    assert status == 1 and len(lines) == 1, lines
    assert str(target) in lines[0] and "ENOSPC" in lines[0] and "No space left" in lines[0]
    assert list(tmp_path.iterdir()) == []  # no output, no temporary file


def test_file_size_limit_from_the_kernel_names_path_and_errno(tmp_path, capfd):
    """A real kernel refusal: RLIMIT_FSIZE in a forked child makes write() fail with EFBIG."""
    import resource
    import signal

    from test_gl_threads_fork import in_child

    target = tmp_path / "x.png"

    def child() -> int:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2048, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
        noise = np.random.default_rng(0).integers(0, 256, (128, 128, 3), dtype=np.uint8)  # ~49 kB as PNG
        try:
            from glradial.media.image_io import write_image

            write_image(target, noise)
        except OSError as err:
            print(f"MESSAGE {err}", flush=True)
            return 0
        return 1

    assert in_child(child) == 0
    message = capfd.readouterr().out
    assert str(target) in message and "EFBIG" in message, message
    assert list(tmp_path.iterdir()) == []


def test_encoder_statistics_are_silenced(cli_env, capfd):
    """x265 prints its statistics on stderr when its context is freed: a quiet run prints nothing there."""
    out = Path(cli_env["tmp"]) / "x265.mkv"
    status = cli.main(["-q", "correct", cli_env["video"], str(out), "--k1", "-0.2", "--codec", "libx265", "--preset", "superfast"])
    import gc

    gc.collect()
    err = capfd.readouterr().err
    assert status == 0 and out.is_file() and err == "", err


def test_native_stderr_is_silenced_only_inside_the_block(capfd):
    from glradial.media.native_stderr import silenced

    os.write(2, b"before\n")
    with silenced():
        os.write(2, b"libpng error: chatter\n")  # what a native library does: straight to fd 2
        with silenced():  # nested
            os.write(2, b"more chatter\n")
        os.write(2, b"still chatter\n")
    os.write(2, b"after\n")
    assert capfd.readouterr().err == "before\nafter\n"


def test_fork_inside_a_silenced_block_gives_the_child_its_stderr(capfd):
    from test_gl_threads_fork import in_child

    from glradial.media.native_stderr import silenced

    def child() -> int:
        os.write(2, b"child speaks\n")
        return 0

    with silenced():
        assert in_child(child) == 0
    assert "child speaks" in capfd.readouterr().err
