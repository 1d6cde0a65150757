"""Interlaced video: each field corrected on its own geometry, field order detected and kept.

Oracle: two different smooth progressive scenes A and B (the instants of the two fields). Each is
distorted with the lens as a whole frame (what the camera saw at its instant); the interlaced frame
takes its top field (even rows) from distorted A and its bottom field (odd rows) from distorted B.
Correcting it field by field must give A's even rows and B's odd rows: each field's PSNR ≥ 34 dB in
the interior (measured ~55 dB on these smooth scenes: bilinear on a field samples every other line).
The same clip corrected as progressive frames mixes the instants (~15 dB), so the test can fail.
A field's principal-point offset (a quarter of a field line) moves the displacement field only
slightly, which no PSNR on smooth content resolves: :func:`test_field_lens_matches_the_frame_geometry`
checks it analytically instead. Field order: ffprobe's stream ``field_order`` and frame flags.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess

import numpy as np
import pytest

import glradial
from glradial.cli import main
from glradial.media.video_io import FIELD_ORDER_CODES, VideoInfo, VideoReader, VideoWriter
from glradial.remapping.fields import field_lens

SIZE = (320, 180)
LENS = (-0.25, 0.05)


def scene(phase: float) -> np.ndarray:
    width, height = SIZE
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    red = 128 + 90 * np.sin(2 * np.pi * (x / 83 + phase)) * np.cos(2 * np.pi * y / 61)
    green = 128 + 90 * np.cos(2 * np.pi * (x / 71 - y / 67 + phase))
    blue = 60 + 150 * (x + 2 * y) / (width + 2 * height)
    return np.dstack([red, green, blue]).round().clip(0, 255).astype(np.uint8)


def interlaced_clip(path, fields: str, frames: int = 2) -> list[tuple[np.ndarray, np.ndarray]]:
    info = dataclasses.replace(VideoInfo.of(SIZE, 25, codec="ffv1", pix_fmt="gbrp"), field_order=FIELD_ORDER_CODES[fields])
    truth = []
    with VideoWriter(path, info) as writer:
        for i in range(frames):
            top, bottom = scene(0.1 * i), scene(0.1 * i + 0.37)
            woven = glradial.distort(top, *LENS, backend="cpu")
            woven[1::2] = glradial.distort(bottom, *LENS, backend="cpu")[1::2]
            writer.write(woven)
            truth.append((top, bottom))
    return truth


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    error = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return 10 * np.log10(255.0**2 / max(error, 1e-12))


def probe(path) -> tuple[str, list[dict]]:
    out = subprocess.run(["ffprobe", "-v", "error", "-show_entries", "stream=field_order",
                          "-show_entries", "frame=interlaced_frame,top_field_first", "-of", "json", str(path)],
                         capture_output=True, text=True, check=True).stdout
    data = json.loads(out)
    return data["streams"][0].get("field_order", "unknown"), data["frames"]


def field_psnrs(path, truth) -> list[tuple[float, float]]:
    lens = glradial.Lens(*LENS)
    mx, my = lens.maps(SIZE, "undistort")
    inside = (mx >= 3) & (mx <= SIZE[0] - 4) & (my >= 3) & (my <= SIZE[1] - 4)
    inside[:4] = inside[-4:] = False  # an output pixel at the frame's edge has taps in the distorted
    inside[:, :4] = inside[:, -4:] = False  # frame's fill (where the scene ends)
    with VideoReader(path) as reader:
        frames = list(reader)
    assert len(frames) == len(truth)
    return [(psnr(got[0::2][inside[0::2]], top[0::2][inside[0::2]]), psnr(got[1::2][inside[1::2]], bottom[1::2][inside[1::2]]))
            for got, (top, bottom) in zip(frames, truth)]


@pytest.mark.parametrize("fields, ffprobe_order", [("tff", "tt"), ("bff", "bb")])
def test_interlaced_clip_is_corrected_field_by_field_and_keeps_its_order(tmp_path, fields, ffprobe_order):
    source, out = tmp_path / "in.mkv", tmp_path / "out.mkv"
    truth = interlaced_clip(source, fields)
    assert probe(source)[0] == ffprobe_order
    assert main(["correct", str(source), str(out), "--k1", str(LENS[0]), "--k2", str(LENS[1]), "--backend", "cpu", "-q"]) == 0
    for top, bottom in field_psnrs(out, truth):
        assert top >= 34.0 and bottom >= 34.0, (top, bottom)
    assert probe(out)[0] == ffprobe_order
    # the oracle can fail: the same clip corrected as whole frames mixes the two instants
    progressive = tmp_path / "progressive.mkv"
    assert main(["correct", str(source), str(progressive), "--k1", str(LENS[0]), "--k2", str(LENS[1]),
                 "--backend", "cpu", "--field-order", "progressive", "-q"]) == 0
    assert min(min(pair) for pair in field_psnrs(progressive, truth)) < 30.0
    assert probe(progressive)[0] == "progressive"


def test_forced_field_order_is_written_with_frame_flags(tmp_path):
    """--field-order bff on a progressive H.264 source: the encoder codes interlaced bottom field
    first (frame flags, ffprobe) and the stream says so."""
    source, out = tmp_path / "in.mkv", tmp_path / "out.mkv"
    with VideoWriter(source, VideoInfo.of(SIZE, 25, codec="libx264")) as writer:
        writer.write(scene(0.0))
        writer.write(scene(0.2))
    assert probe(source)[0] == "progressive"
    assert main(["correct", str(source), str(out), "--k1", "-0.1", "--field-order", "bff", "--backend", "cpu", "-q"]) == 0
    order, frames = probe(out)
    assert order == "bb" and frames and all(f["interlaced_frame"] == 1 and f["top_field_first"] == 0 for f in frames), (order, frames)


def test_field_lens_matches_the_frame_geometry():
    """A field's lens maps field row i to the same place as the frame's lens maps frame row 2i + p:
    the undistorted point of every field pixel equals that of its frame pixel (analytic check)."""
    lens = glradial.Lens(-0.3, 0.07, cx=0.02, cy=-0.015, pixel_aspect=1.02)
    width, height = 96, 54
    frame_points = lens.undistort_points(np.array([[x, y] for y in range(height) for x in range(0, width, 7)], float), (width, height))
    for parity in (0, 1):
        field = field_lens(lens, (width, height), parity)
        rows = [(x, i) for i in range((height - parity + 1) // 2) for x in range(0, width, 7)]
        got = field.undistort_points(np.array(rows, float), (width, height // 2))
        want = frame_points.reshape(height, -1, 2)[parity::2].reshape(-1, 2)
        got[:, 1] = got[:, 1] * 2 + parity  # field rows -> frame rows
        np.testing.assert_allclose(got, want, atol=1e-6)
