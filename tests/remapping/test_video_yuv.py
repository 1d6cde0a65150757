"""Pass 2 in YUV: planar YUV video corrected plane by plane (glradial.remapping.planes), no RGB.

Oracles:
* the lens model itself, evaluated by hand at each chroma sample's position in the frame (not
  through Lens.maps): planes holding a linear ramp must come out as the ramp at the source
  position of each sample within 0.55 levels (bilinear from float32 maps: exact on a ramp, up to
  rounding to the integer sample); chroma taken as sited half a luma pixel off misses by more
  than twice as much;
* scipy.ndimage.map_coordinates (order 1, float64) at the positions of the float64 reference maps,
  on a textured plane where bilinear interpolation is not exact: within rounding, where the
  RGB path's fixed-point maps (1/32 px) miss by more;
* the RGB path (decode to RGB, correct with glradial.correct, convert back): on a real frame in a
  lossless codec both outputs differ by no more than the RGB round trip itself loses with the
  identity lens (measured: mean 1.07 levels of luma bias at 1280x720 and chroma p99 up to 5 levels,
  while the YUV path's identity is exact);
* ffprobe for what was written (pix_fmt kept).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import av
import numpy as np
import pytest

import glradial
import glradial.video.video_pipeline as pipeline
from glradial.lens.lens import Lens, Plane
from glradial.media.video_io import EncodeOptions, VideoReader, VideoWriter, frame_planes, yuv_layout
from glradial.remapping.planes import black, chroma_siting, remap_planes, yuv_planes

FFMPEG = shutil.which("ffmpeg")
pytestmark = pytest.mark.skipif(FFMPEG is None, reason="needs the ffmpeg command (make setup installs it)")
FRAME = Path(__file__).resolve().parents[2] / "glradial" / "data" / "usl_broadcast_0195.jpg"
LENS = Lens(-0.25, 0.05)
#: output scale of the ramp test (a fit number: p_u = SCALE q), so that a siting error shows everywhere
SCALE = 1.5


def _source_position(lens: Lens, size: tuple[int, int], x: np.ndarray, y: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the corrected frame's point (x, y) (pixels, centres at integers) samples the input:
    p_d = p_u (1 + k1 r^2 + k2 r^4) with p_u = scale * q, width-normalised about the centre
    ((W-1)/2, (H-1)/2)."""
    width, height = size
    u, v = scale * (x - (width - 1) / 2) / width, scale * (y - (height - 1) / 2) / width
    r2 = u * u + v * v
    gain = 1 + lens.k1 * r2 + lens.k2 * r2 * r2
    return u * gain * width + (width - 1) / 2, v * gain * width + (height - 1) / 2


@pytest.mark.parametrize("size, shift, siting", [((160, 90), (1, 1), "left"), ((161, 91), (1, 1), "left"),
                                                 ((160, 90), (1, 0), "left"), ((159, 90), (1, 1), "center")])
def test_planes_follow_the_lens_at_their_sited_positions(size, shift, siting):
    lattices = yuv_planes(size, shift, siting)
    assert lattices[0] == Plane.full(size)
    slope = 50.0  # levels of a uint16 ramp per luma pixel
    planes, expected = [], []
    for lattice in lattices:
        i, j = np.meshgrid(np.arange(lattice.width), np.arange(lattice.height))
        x, y = lattice.x0 + lattice.step_x * i, lattice.y0 + lattice.step_y * j
        planes.append((2000 + slope * x + 0.4 * slope * y).astype(np.uint16))  # integers on every lattice: an exact ramp
        sx, sy = _source_position(LENS, size, x, y, SCALE)
        # where the plane's samples surround the source (beyond them the edge sample is repeated)
        inside = (sx >= lattice.x0) & (sx <= x.max()) & (sy >= lattice.y0) & (sy <= y.max())
        expected.append((2000 + slope * sx + 0.4 * slope * sy, inside))
    out = [np.zeros_like(p) for p in planes]
    remap_planes(planes, LENS, lattices, out, fill=(0, 0, 0), fit=SCALE)
    errors = []
    for plane, (value, inside) in zip(out, expected):
        errors.append(np.abs(plane.astype(float) - value)[inside])
        # bilinear from float32 maps is exact on a ramp: rounding to an integer (0.5) plus the
        # maps' float32 error (~1e-4 px at this size: 0.005 levels of the ramp)
        assert errors[-1].max() < 0.55, errors[-1].max()
    # the chroma taken as sited half a luma pixel across: off by (P' - 1) / 2 luma px, P' the
    # map's stretch (~SCALE): 0.25 px or 12 levels of the ramp
    if shift[0]:
        wrong = Plane(**{**lattices[1].__dict__, "x0": lattices[1].x0 + (0.5 if siting == "left" else -0.5)})
        shifted = [np.zeros_like(p) for p in planes]
        remap_planes(planes, LENS, [lattices[0], wrong, wrong], shifted, fill=(0, 0, 0), fit=SCALE)
        value, inside = expected[1]
        miss = np.abs(shifted[1].astype(float) - value)[inside]
        assert np.percentile(miss, 90) > 2 * np.percentile(errors[1], 90)


@pytest.mark.parametrize("dtype, top", [(np.uint8, 255), (np.uint16, 1023)])
def test_planes_are_bilinear_at_the_exact_source_positions(dtype, top):
    """Against scipy's order-1 interpolation (float64) at the float64 reference maps, on blurred
    noise: within rounding (0.5) plus the float32 maps' position error (<= 1e-4 px here) times the
    steepest gradient; OpenCV's fixed-point maps (the RGB path's, 1/32 px) miss that bound."""
    cv2 = pytest.importorskip("cv2")
    ndimage = pytest.importorskip("scipy.ndimage")
    size, lens = (480, 270), Lens(-0.3, 0.04)
    lattices = yuv_planes(size, (1, 1), "left")
    rng = np.random.default_rng(7)
    planes = []
    for lattice in lattices:
        noise = cv2.GaussianBlur(rng.random((lattice.height, lattice.width)), (0, 0), 1.2)
        planes.append(np.rint(top * (noise - noise.min()) / np.ptp(noise)).astype(dtype))
    out = [np.zeros_like(p) for p in planes]
    remap_planes(planes, lens, lattices, out, fill=(0, 0, 0))
    for plane, lattice, result in zip(planes, lattices, out):
        map_x, map_y = lens.maps(size, plane=lattice, dtype=np.float64)
        reference = ndimage.map_coordinates(plane.astype(np.float64), [map_y, map_x], order=1, mode="nearest")
        gradient = max(np.abs(np.diff(plane.astype(float), axis=a)).max() for a in (0, 1))
        bound = 0.5 + 2e-4 * gradient + 1e-6
        assert np.abs(result - reference).max() <= bound
        fixed = cv2.remap(plane, *cv2.convertMaps(map_x.astype(np.float32), map_y.astype(np.float32), cv2.CV_16SC2),
                          cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        assert np.abs(fixed - reference).max() > bound  # the test tells the two apart


def _clip(path: Path, pix_fmt: str, size: tuple[int, int], codec: str = "ffv1", extra: tuple[str, ...] = ()) -> Path:
    """The real broadcast frame, scaled to ``size``, 2 frames, lossless unless ``codec`` says otherwise."""
    subprocess.run([FFMPEG, "-v", "error", "-y", "-loop", "1", "-i", str(FRAME), "-vf", f"scale={size[0]}:{size[1]}",
                    "-frames:v", "2", "-c:v", codec, "-pix_fmt", pix_fmt, *extra, str(path)], check=True)
    return path


def _planes(path: Path) -> tuple[list[np.ndarray], str]:
    with av.open(str(path)) as container:
        frame = next(container.decode(video=0))
        return [plane.copy() for plane in frame_planes(frame)], frame.format.name


def _correct(source: Path, target: Path, space: str, lens=(LENS.k1, LENS.k2), monkeypatch=None, **options) -> None:
    if space == "rgb":
        monkeypatch.setattr(pipeline, "correction_space", lambda *args: ("rgb", "forced by the test"))
    pipeline.correct_video(source, target, lambda _i: lens, backend="cpu", progress=False, **options)
    monkeypatch.undo()


@pytest.mark.parametrize("pix_fmt, size, direction", [("yuv420p", (320, 180), "undistort"), ("yuv420p", (321, 181), "undistort"),
                                                      ("yuv422p10le", (320, 180), "undistort"), ("yuv420p", (320, 180), "distort")])
def test_yuv_path_agrees_with_the_rgb_path_on_a_real_frame(tmp_path, monkeypatch, pix_fmt, size, direction):
    source = _clip(tmp_path / "in.mkv", pix_fmt, size)
    original, _ = _planes(source)
    outputs = {}
    for space in ("yuv", "rgb"):
        _correct(source, tmp_path / f"id_{space}.mkv", space, (0.0, 0.0), monkeypatch)
        _correct(source, tmp_path / f"{space}.mkv", space, monkeypatch=monkeypatch, direction=direction)
        outputs[space], written = _planes(tmp_path / f"{space}.mkv")
        assert written == pix_fmt
    identity_yuv, _ = _planes(tmp_path / "id_yuv.mkv")
    identity_rgb, _ = _planes(tmp_path / "id_rgb.mkv")
    assert all(np.array_equal(a, b) for a, b in zip(identity_yuv, original))  # no conversion: exact
    _correct(source, tmp_path / "copied.mkv", "yuv", None, monkeypatch)  # a frame passed through uncorrected
    assert all(np.array_equal(a, b) for a, b in zip(_planes(tmp_path / "copied.mkv")[0], original))
    level = 4 if pix_fmt.endswith("10le") else 1  # one 8-bit level
    for a, b, kept, lost in zip(outputs["yuv"], outputs["rgb"], original, identity_rgb):
        difference = np.abs(a.astype(float) - b)
        round_trip = np.abs(lost.astype(float) - kept)
        assert difference.mean() <= round_trip.mean() + 0.3 * level, (difference.mean(), round_trip.mean())
        assert np.percentile(difference, 99) <= np.percentile(round_trip, 99) + 2 * level
    # and the correction did something: far from the uncorrected frame
    assert np.abs(outputs["yuv"][0].astype(float) - original[0]).mean() > 5 * level


@pytest.mark.parametrize("pix_fmt, full_range", [("yuv420p", False), ("yuvj420p", True), ("yuv420p10le", False)])
def test_pixels_without_source_are_black_in_the_sources_range(tmp_path, pix_fmt, full_range):
    codec = ("mjpeg", "-q:v", "2") if pix_fmt == "yuvj420p" else ("ffv1",)
    source = _clip(tmp_path / "in.mkv", pix_fmt, (96, 54), codec[0], codec[1:])
    scale = 1.3  # zoomed in: a third of the output (the corners first) has no source
    pipeline.correct_video(source, tmp_path / "out.mkv", lambda _i: LENS, fit=scale, backend="cpu", progress=False)
    planes, written = _planes(tmp_path / "out.mkv")
    expected = black(yuv_layout(pix_fmt)[2], full_range)
    # the pixels with no source, as the RGB path finds them (its fill: 0 where a white frame turns black)
    empty = glradial.correct(np.full((54, 96), 255, np.uint8), LENS, fit=scale, backend="cpu") == 0
    assert 0.2 < empty.mean() < 0.5 and empty[0, 0]
    if pix_fmt == "yuvj420p":  # MJPEG output is lossy: black within a few levels
        assert chroma_siting("mjpeg") == "center" and written == "yuvj420p"
        assert abs(np.median(planes[0][empty]) - expected[0]) <= 3
        assert abs(int(planes[1][0, 0]) - expected[1]) <= 3 and abs(int(planes[2][0, 0]) - expected[2]) <= 3
    else:
        assert written == pix_fmt
        assert np.all(planes[0][empty] == expected[0])  # exactly black: the fill, not interpolated
        assert np.mean(planes[0][~empty] == expected[0]) < 0.01  # and the picture is not
        assert [int(p[0, 0]) for p in planes[1:]] == list(expected[1:])


def test_the_choice_between_yuv_and_rgb_is_explicit(tmp_path):
    source = _clip(tmp_path / "in.mkv", "yuv420p", (64, 36))
    with VideoReader(source) as reader:
        info = reader.info
    space = pipeline.correction_space
    with VideoWriter(tmp_path / "a.mkv", info, options=EncodeOptions(codec="ffv1")) as same:
        assert space(info, same, "cpu", {}) == ("yuv", "")
        assert space(info, same, "cpu", {"inverse": "exact"})[0] == "yuv"
        assert space(info, same, "gl", {})[0] == "rgb"
        assert space(info, same, "cpu", {"fill": 3})[0] == "rgb"
        interlaced = type(info)(**{**info.__dict__, "field_order": 3})
        assert "interlaced" in space(interlaced, same, "cpu", {})[1]
        same.abort()
    with VideoWriter(tmp_path / "b.mkv", info, options=EncodeOptions(codec="ffv1", pix_fmt="yuv444p")) as other:
        assert space(info, other, "cpu", {}) == ("rgb", "the output is yuv444p, not yuv420p")
        other.abort()
    for pix_fmt in ("gbrp", "yuva420p", "nv12", "yuv420p10be", "rgb24"):
        assert yuv_layout(pix_fmt) is None, pix_fmt
    assert yuv_layout("yuv420p") == (1, 1, 8) and yuv_layout("yuv422p10le") == (1, 0, 10)
    assert yuv_layout("yuv444p") == (0, 0, 8) and yuv_layout("no_such_format") is None


def test_remap_planes_refuses_mismatched_planes():
    lattices = yuv_planes((64, 36), (1, 1))
    planes = [np.zeros((36, 64), np.uint8), np.zeros((18, 32), np.uint8), np.zeros((18, 32), np.uint8)]
    with pytest.raises(ValueError, match="plane 1 must be a 32×18"):
        remap_planes(planes, LENS, lattices, [planes[0], np.zeros((18, 31), np.uint8), planes[2]], fill=(16, 128, 128))
    with pytest.raises(ValueError, match="one lattice, output and fill per plane"):
        remap_planes(planes, LENS, lattices, planes, fill=(16, 128))
    with pytest.raises(ValueError, match="siting must be one of"):
        yuv_planes((64, 36), (1, 1), "top")
    with pytest.raises(ValueError, match="plane width must be a positive integer"):
        Plane(0, 18)
    with pytest.raises(ValueError, match="step_x"):
        Plane(32, 18, step_x=0.0)
    with pytest.raises(TypeError, match="x0 must be a real number"):
        Plane(32, 18, x0="left")
