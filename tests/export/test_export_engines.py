"""Graphics-engine hand-off (issue 27): OpenTrackIO samples against the standard's own schema (the
fixture in tests/data/opentrackio, BSD-3), mm coefficients back to glradial's, each engine's own
formula (written here from its documentation, independently of glradial.export) against glradial's
mapping, the UDP packet over 127.0.0.1, overscan, Unreal-layout ST maps and the CLI."""

from __future__ import annotations

import json
import math
import socket
import struct
from fractions import Fraction
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from glradial.cli import main
from glradial.export import engines, opentrackio, opentrackio_udp, overscan
from glradial.export.stmap import lens_stmap, unreal_stmap
from glradial.lens import Lens

DATA = Path(__file__).parents[1] / "data" / "opentrackio"
SIZE = (1920, 1080)
LENSES = [Lens(-0.2, 0.02), Lens(-0.35, 0.12), Lens(0.1, 0.0), Lens(-0.15, 0.01, 0.012, -0.008)]


@pytest.fixture(scope="module")
def schema() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(json.loads((DATA / "schema.json").read_text()))


def _grid(width: int, height: int, n: int = 9) -> np.ndarray:
    xs, ys = np.linspace(-0.5, width - 0.5, n), np.linspace(-0.5, height - 0.5, n)
    return np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)


def test_fixture_schema_is_the_one_glradial_ships_and_accepts_the_standards_examples(schema):
    from importlib import resources

    shipped = resources.files("glradial.data").joinpath("opentrackio_schema.json").read_text()
    assert json.loads(shipped) == json.loads((DATA / "schema.json").read_text())
    for example in sorted((DATA / "examples").glob("*.json")):
        schema.validate(json.loads(example.read_text()))
    broken = json.loads((DATA / "examples" / "complete_dynamic_example.json").read_text())
    broken["lens"]["distortion"][0]["overscan"] = 0.5  # the oracle can fail: overscan < 1
    assert list(schema.iter_errors(broken))


def test_samples_validate_and_mm_coefficients_come_back(schema):
    camera = opentrackio.TrackingCamera(SIZE, 9.59, 8.5, rate=Fraction(30000, 1001), timecode="09:59:59;28")
    lenses = [LENSES[0], LENSES[1], LENSES[3], LENSES[0]]
    samples = opentrackio.track_samples(lenses, camera, uncertainty_px=[2.0, np.nan, 12.0, 1.0],
                                        doubtful=[False, False, True, False], shots=[0, 0, 1, 1])
    for model in (opentrackio.MODEL_UD, opentrackio.MODEL_DU):
        samples += opentrackio.track_samples(lenses[:2], camera, model=model)
    for sample in samples:
        schema.validate(sample)
        assert sample["timing"]["sampleRate"] == {"num": 30000, "denom": 1001}
    # drop-frame timecode: 09:59:59;28 + 2 frames = 10:00:00;00 (a tenth minute drops nothing)
    assert samples[2]["timing"]["timecode"]["hours"] == 10 and samples[2]["timing"]["timecode"]["frames"] == 0
    assert samples[2]["tracker"]["status"].endswith("DOUBTFUL") and samples[2]["custom"]["glradial"]["shot"] == 1
    for lens, sample in zip(lenses, samples):
        distortion = sample["lens"]["distortion"][0]
        assert distortion["model"] == "Brown-Conrady U-D" and len(distortion["radial"]) == 6
        back = engines.lens_from_openlensio(distortion["radial"], 9.59, (sample["lens"]["projectionOffset"]["x"],
                                                                          sample["lens"]["projectionOffset"]["y"]))
        assert abs(back.k1 - lens.k1) < 1e-9 and abs(back.k2 - lens.k2) < 1e-9
        assert abs(back.cx - lens.cx) < 1e-12 and abs(back.cy - lens.cy) < 1e-12
    with pytest.raises(ValueError, match="k2="):
        engines.lens_from_openlensio([0.001, 0.002], 9.59)
    with pytest.raises(ValueError, match="pixel_aspect"):
        engines.openlensio_radial(Lens(-0.1, 0.0, pixel_aspect=1.1), 9.59)
    with pytest.raises(ValueError, match="sensor_width_mm"):
        opentrackio.TrackingCamera(SIZE, 0.0, 8.0)


def _openlensio_distort(points: np.ndarray, radial, offset, w_mm: float, size) -> np.ndarray:
    """OpenLensIO eq. (5) with ΔC = 0 and the U-D model R (eq. 17, odd coefficients over even),
    pixel <-> mm by eq. (18): ε = (pixel + 0.5 - W / 2) · w / W."""
    width, height = size
    mm = w_mm / width
    eps = np.stack([(points[:, 0] + 0.5 - width / 2) * mm, (points[:, 1] + 0.5 - height / 2) * mm], 1) - offset
    r2 = np.sum(eps**2, 1, keepdims=True)
    k = radial
    factor = (1 + k[0] * r2 + k[2] * r2**2 + k[4] * r2**3) / (1 + k[1] * r2 + k[3] * r2**2 + k[5] * r2**3)
    out = eps * factor + offset
    return np.stack([out[:, 0] / mm + width / 2 - 0.5, out[:, 1] / mm + height / 2 - 0.5], 1)


def test_openlensio_formula_maps_points_as_glradial():
    points = _grid(*SIZE)
    for lens in LENSES:
        obj, _ = opentrackio.lens_object(lens, opentrackio.TrackingCamera(SIZE, 9.59, 8.0))
        offset = np.array([obj["projectionOffset"]["x"], obj["projectionOffset"]["y"]])
        ours = lens.distort_points(points, SIZE)
        theirs = _openlensio_distort(points, obj["distortion"][0]["radial"], offset, 9.59, SIZE)
        assert np.abs(theirs - ours).max() < 1e-6
        # D-U: the same formula maps distorted to undistorted, within the stated fit error
        fitted, error = opentrackio.lens_object(lens, opentrackio.TrackingCamera(SIZE, 9.59, 8.0), model=opentrackio.MODEL_DU)
        undistorted = lens.undistort_points(points, SIZE)
        theirs = _openlensio_distort(points, fitted["distortion"][0]["radial"], offset, 9.59, SIZE)
        gap = np.hypot(*(theirs - undistorted).T).max()
        assert gap <= error + 1e-9 and error < 0.1, (gap, error)


def test_unreal_spherical_is_opencv_projection_of_glradial():
    points = _grid(*SIZE)
    for lens in LENSES:
        u = engines.unreal_spherical(lens, SIZE, 1500.0)
        fx, fy = u["FxFy"][0] * SIZE[0], u["FxFy"][1] * SIZE[1]
        cx, cy = u["PrincipalPoint"][0] * SIZE[0] - 0.5, u["PrincipalPoint"][1] * SIZE[1] - 0.5
        x, y = (points[:, 0] - cx) / fx, (points[:, 1] - cy) / fy  # undistorted, focal units
        r2 = x * x + y * y
        radial = 1 + u["K1"] * r2 + u["K2"] * r2**2 + u["K3"] * r2**3
        xd = x * radial + 2 * u["P1"] * x * y + u["P2"] * (r2 + 2 * x * x)
        yd = y * radial + u["P1"] * (r2 + 2 * y * y) + 2 * u["P2"] * x * y
        theirs = np.stack([fx * xd + cx, fy * yd + cy], 1)
        assert np.abs(theirs - lens.distort_points(points, SIZE)).max() < 1e-6


def test_3de4_radial_degree4_undistorts_within_its_stated_error():
    points = _grid(*SIZE, 21)
    for lens in LENSES:
        p = engines.tde4_radial_deg4(lens, SIZE)
        c2, c4 = p["Distortion - Degree 2"], p["Quartic Distortion - Degree 4"]
        centre = np.array([(SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2]) + p["lens_center_offset_px"]
        unit = 0.5 * math.hypot(*SIZE)  # 3DE4: diagonally normalised, r = 1 at a corner
        d = (points - centre) / unit
        r2 = np.sum(d * d, 1, keepdims=True)
        theirs = d * (1 + c2 * r2 + c4 * r2**2) * unit + centre
        gap = np.hypot(*(theirs - lens.undistort_points(points, SIZE)).T).max()
        assert gap <= p["fit_max_error_px"] + 1e-9, (gap, p["fit_max_error_px"])
    assert engines.tde4_radial_deg4(Lens(-0.05, 0.0), SIZE)["fit_max_error_px"] < 0.05


def test_udp_packet_over_localhost_parses_back():
    camera = opentrackio.TrackingCamera((640, 360), 9.59, 8.0, rate=Fraction(25))
    samples = opentrackio.track_samples([LENSES[0]] * 3, camera)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(5)
        sent = opentrackio_udp.send_payloads([opentrackio.encode_sample(s) for s in samples], receiver.getsockname())
        datagrams = [receiver.recv(65536) for _ in range(sent)]
    assert sent == 3
    for i, data in enumerate(datagrams):
        # the header by the documented layout, read here with struct directly
        ident, _, encoding, sequence, offset, length, checksum = struct.unpack("!4sBBHIHH", data[:16])
        assert (ident, encoding, sequence, offset, length) == (b"OTrk", 1, i + 1, 0, 0x8000 | (len(data) - 16))
        s1 = s2 = 0
        for byte in data[:14] + data[16:]:
            s1, s2 = (s1 + byte) % 255, (s2 + (s1 + byte) % 255) % 255
        assert checksum == (s2 << 8) | s1
        packet = opentrackio_udp.parse_packet(data)
        assert json.loads(packet.payload) == samples[i]
    corrupt = bytearray(datagrams[0])
    corrupt[40] ^= 0x01
    with pytest.raises(ValueError, match="checksum"):
        opentrackio_udp.parse_packet(bytes(corrupt))
    big = opentrackio_udp.packets(b"x" * 4000, 7)
    assert len(big) == 3 and [opentrackio_udp.parse_packet(b).last for b in big] == [False, False, True]
    assert b"".join(opentrackio_udp.parse_packet(b).payload for b in big) == b"x" * 4000


def test_sample_receiver_joins_segments_and_drops_an_incomplete_payload():
    """Datagrams sent from a plain socket (a payload in two segments, one missing its first segment):
    the receiver keeps each datagram and gives back the whole payloads only."""
    whole, broken = opentrackio_udp.packets(b"a" * 2000, 1), opentrackio_udp.packets(b"b" * 2000, 2)
    with opentrackio_udp.SampleReceiver() as receiver:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender:
            for data in [*whole, broken[1], *opentrackio_udp.packets(b'{"c": 3}', 3)]:
                sender.sendto(data, receiver.address)
        assert receiver.wait_for(4) == 4
    assert receiver.payloads() == [b"a" * 2000, b'{"c": 3}']
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        with pytest.raises(OSError, match=f"127.0.0.1:{taken.getsockname()[1]}"):
            opentrackio_udp.SampleReceiver(taken.getsockname())


def test_cbor_payload_round_trips(tmp_path):
    cbor2 = pytest.importorskip("cbor2")
    camera = opentrackio.TrackingCamera((640, 360), 9.59, 8.0)
    samples = opentrackio.track_samples([LENSES[0], LENSES[2]], camera)
    path = opentrackio.write_samples(tmp_path / "s.cbor", samples, cbor=True)
    with open(path, "rb") as handle:
        assert [cbor2.load(handle), cbor2.load(handle)] == samples


def test_overscanned_distort_fills_the_frame():
    size = (320, 180)
    for lens in (Lens(-0.3, 0.05), Lens(-0.15, 0.01, 0.02, -0.01), Lens(0.1, 0.0)):
        factor = overscan.overscan_factor(lens, size)
        render = np.full(overscan.overscan_size(size, factor)[::-1], 200, np.uint8)
        out = overscan.distort_overscanned(render, lens, size, factor, interpolation="linear")
        assert out.shape == size[::-1] and out.min() == 200, (lens, factor)
        if factor > 1.0:  # less overscan leaves empty pixels: the check can fail
            less = 1 + (factor - 1) * 0.5
            smaller = np.full(overscan.overscan_size(size, less)[::-1], 200, np.uint8)
            assert overscan.distort_overscanned(smaller, lens, size, less).min() < 200
    # a centred lens: both characterisations agree, and the value is where the corner goes
    lens = Lens(-0.3, 0.05)
    corner = lens.undistort_points(np.array([[-0.5, -0.5]]), size)[0]
    expected = 2 * max(abs(corner[0] - (size[0] - 1) / 2), abs(corner[1] - (size[1] - 1) / 2) * size[0] / size[1]) / size[0]
    assert abs(overscan.overscan_factor(lens, size) - expected) < 1e-6
    assert overscan.overscan_factor(Lens(0.1, 0.0), size) == 1.0


def test_unreal_stmap_layout_and_origin():
    size, lens = (96, 54), Lens(-0.25, 0.03)
    top = unreal_stmap(lens, size)
    assert top.shape == (54, 96, 4) and top.dtype == np.float32
    nuke_u = lens_stmap(lens, size, direction="undistort")
    nuke_d = lens_stmap(lens, size, direction="distort")
    assert np.abs(top[..., 0] - nuke_u[..., 0]).max() < 1e-6 and np.abs(1 - top[..., 1] - nuke_u[..., 1]).max() < 1e-6
    assert np.abs(top[..., 2] - nuke_d[..., 0]).max() < 1e-6 and np.abs(1 - top[..., 3] - nuke_d[..., 1]).max() < 1e-6
    bottom = unreal_stmap(lens, size, origin="bottom-left")
    assert np.array_equal(bottom[..., 1], nuke_u[..., 1]) or np.abs(bottom[..., 1] - nuke_u[..., 1]).max() < 1e-6


def test_cli_convert_engines(capsys):
    base = ["convert", "--from", "glradial", "--size", "1920x1080", "--sensor-width-mm", "9.59", "--focal-mm", "8", "--json"]
    assert main([*base, "--to", "opentrackio", "--", "-0.2", "0.02"]) == 0
    lens_obj = json.loads(capsys.readouterr().out)
    schema = json.loads((DATA / "schema.json").read_text())["properties"]["lens"]
    jsonschema.validate(lens_obj, schema)
    assert lens_obj["pinholeFocalLength"] == 8.0 and lens_obj["distortion"][0]["overscan"] > 1
    assert main([*base, "--to", "unreal", "--", "-0.2", "0.02"]) == 0
    unreal = json.loads(capsys.readouterr().out)
    assert abs(unreal["FxFy"][0] - 8 / 9.59) < 1e-12
    assert main([*base, "--to", "3de4-radial-deg4", "--", "-0.2", "0.02"]) == 0
    captured = capsys.readouterr()
    assert "largest error" in captured.err and json.loads(captured.out)["fit_max_error_px"] < 1
    assert main(["convert", "--from", "glradial", "--to", "opentrackio", "--size", "1920x1080", "--", "-0.2", "0.02"]) == 2
    assert "--sensor-width-mm" in capsys.readouterr().err and "--focal-mm" in capsys.readouterr().err + "--focal-mm"


def _clip(path: Path, frames: int = 6) -> Path:
    """A 64x36 test-pattern clip at 25 fps with timecode 01:00:00:00 (ffmpeg's lavfi source)."""
    import shutil
    import subprocess

    ffmpeg = shutil.which("ffmpeg")
    if ffmpeg is None:
        pytest.skip("ffmpeg is not installed")
    subprocess.run([ffmpeg, "-v", "error", "-y", "-f", "lavfi", "-i", "testsrc2=size=64x36:rate=25", "-frames:v", str(frames),
                    "-c:v", "ffv1", "-timecode", "01:00:00:00", str(path)], check=True)
    return path


def test_cli_correct_writes_one_valid_sample_per_frame(tmp_path, schema, capsys, monkeypatch):
    source = _clip(tmp_path / "in.mov")
    out, samples = tmp_path / "out.mov", tmp_path / "s.jsonl"
    argv = ["correct", str(source), str(out), "--k1", "-0.2", "--k2", "0.02", "--backend", "cpu", "--opentrackio",
            str(samples), "--sensor", "2/3-inch", "--focal-mm", "9"]
    assert main(argv) == 0
    lines = [json.loads(line) for line in samples.read_text().splitlines()]
    assert len(lines) == 6
    for i, sample in enumerate(lines):
        schema.validate(sample)
        assert sample["timing"]["sequenceNumber"] == i and sample["timing"]["timecode"]["frames"] == i
    assert lines[0]["static"]["camera"]["activeSensorPhysicalDimensions"] == {"width": 9.59, "height": 5.39}
    capsys.readouterr()
    # missing numbers: refused before any work, naming the option
    argv2 = ["correct", str(source), str(tmp_path / "o2.mov"), "--k1", "-0.2", "--opentrackio", str(tmp_path / "t.jsonl")]
    assert main(argv2) == 2
    assert "--focal-mm" in capsys.readouterr().err and not (tmp_path / "o2.mov").exists()
    argv3 = ["correct", str(source), str(tmp_path / "o3.mov"), "--k1", "-0.2", "--focal-mm", "9"]
    assert main(argv3) == 2 and "need(s) --opentrackio" in capsys.readouterr().err  # a camera option alone


def test_cli_side_outputs_never_overwrite_the_input_through_a_link(tmp_path, capsys):
    """``--opentrackio`` and ``--sidecar`` naming INPUT through a symbolic link are refused before any
    work, as OUTPUT is: the input stays intact and nothing is written."""
    source = _clip(tmp_path / "in.mov")
    before = source.read_bytes()
    link = tmp_path / "link.jsonl"
    link.symlink_to(source)
    out = tmp_path / "out.mov"
    argv = ["correct", str(source), str(out), "--k1", "-0.2", "--opentrackio", str(link), "--sensor", "2/3-inch",
            "--focal-mm", "9", "-y"]
    assert main(argv) == 2
    assert "--opentrackio" in capsys.readouterr().err
    link_csv = tmp_path / "link.csv"
    link_csv.symlink_to(source)
    assert main(["correct", str(source), str(out), "--auto", "--sidecar", str(link_csv), "-y"]) == 2
    assert "--sidecar" in capsys.readouterr().err
    assert source.read_bytes() == before and not out.exists()


def test_cli_distort_overscan_fills_the_frame_and_half_the_overscan_does_not(tmp_path, capsys):
    """``glradial distort --overscan``: a uniform overscanned render (the pixel pitch kept) comes out
    as a full distorted frame, no pixel empty, at the lens's own factor; at half its overscan the
    corners are empty (the check can fail)."""
    from glradial.media.image_io import read_image, write_image

    lens, size = Lens(-0.25, 0.05), (320, 180)
    factor = overscan.overscan_factor(lens, size)
    assert factor > 1.02
    render = tmp_path / "render.png"
    write_image(render, np.full((*overscan.overscan_size(size, factor)[::-1], 3), 200, np.uint8))
    argv = ["--k1", "-0.25", "--k2", "0.05", "--size", "320x180", "-q"]
    assert main(["distort", str(render), str(tmp_path / "full.png"), *argv, "--overscan"]) == 0
    assert f"overscan {factor:.6f}" in capsys.readouterr().out
    full = read_image(tmp_path / "full.png")
    assert full.shape == (180, 320, 3) and full.min() == 200
    half = 1.0 + (factor - 1.0) / 2
    assert main(["distort", str(render), str(tmp_path / "half.png"), *argv, "--overscan", repr(half)]) == 0
    assert (read_image(tmp_path / "half.png") == 0).all(axis=-1).sum() > 0
    for extra, message in ((["--fit", "crop"], "replaces --fit"), (["--backend", "gl"], "cv2.remap"),
                           (["--inverse", "drap"], "replaces --inverse"), (["--overscan", "0.9"], "factor >= 1")):
        assert main(["distort", str(render), str(tmp_path / "x.png"), *argv, "--overscan", *extra]) == 2
        assert message in capsys.readouterr().err
    assert main(["distort", str(render), str(tmp_path / "x.png"), "--k1", "-0.25", "--size", "320x180"]) == 2
    assert "--size is for --overscan" in capsys.readouterr().err
