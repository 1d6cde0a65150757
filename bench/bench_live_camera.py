"""``glradial live --camera`` in real time over UDP, scored against hand-labelled keypoints.

Content: a labelled real broadcast frame of shared/data/broadcast_bundesliga (validation only; the
file resized to 1280 x 720 as its labels are) seen by a camera that pans (+-:data:`PAN_DEG`, there
and back) and zooms (:data:`ZOOM` x and back) about its fixed centre over ``--seconds`` seconds:
each output frame is the frame warped by ``K_t R_t K_0^-1`` (``K_0`` the focal length a plain
homography of the frame's own labels gives, :func:`glradial.camera.model.decompose_homography`),
so its true keypoints are the labels moved by the same warp; scaled to ``--size``, H.264 in MPEG-TS, sent by ``ffmpeg -re`` to ``glradial live udp://... none --camera
--sensor 2/3-inch --send ...``; a socket receives the samples.

Per run: frames sent; samples received; the share of frames sent that got a **sure** camera sample
(all frames, and from the first sure one on: the lock-on time reported apart); the keypoint RMS of
every sure sample (px of the output size): the 32 template keypoints projected with the sample's own
OpenTrackIO fields (transform, ``pinholeFocalLength`` over the sensor width, ``custom.glradial``
k1, k2), an independent reading of the OpenTrackIO conventions (pan about Z, then tilt about X,
then roll about Y; Y forward, Z up), against the moved labels inside the frame; its median and p95;
the delay p50/p95 and dropped frames (glradial's own report); the share of samples that validate
against shared/specs/opentrackio/schema.json (jsonschema). Beside them the labels' homography floor
(the RMS a plain homography fitted to the frame's own labels leaves, px at 1280).

Run: ``python bench/bench_live_camera.py [--frame 2e57b9_1_1] [--size 1280x720] [--rate 25]
[--seconds 10]``; writes docs/figures/live_camera[_WxH_Rp].json. Real time on a shared machine:
the load (``os.getloadavg``) is recorded beside the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from collections import Counter
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from bench_live import _report, stream_over_udp  # noqa: E402
from calibrate_matches import DATA as SHARED_DATA  # noqa: E402
from calibrate_matches import homography_floor as _floor  # noqa: E402
from figures import write_figure  # noqa: E402

from glradial.commands import parse_size  # noqa: E402

DATA = SHARED_DATA / "broadcast_bundesliga"

SPEC = ROOT.parent / "shared" / "specs" / "opentrackio" / "schema.json"
#: the labels' frame size (px)
LABEL_SIZE = (1280, 720)


#: the pan's amplitude (degrees) and the zoom's (focal length ratio at the middle of the clip)
PAN_DEG, ZOOM = 6.0, 1.4
#: the zoom at the ends (a little in, so that the pan shows little beyond the frame)
ZOOM_START = 1.1


def label_focal(name: str) -> float:
    """The frame's focal length (image widths) from a plain homography of its own labels."""
    from glradial.camera.model import decompose_homography

    labels = json.loads((DATA / "keypoints" / "keypoints.json").read_text())
    pitch = np.array([k["pitch_m"] for k in labels["keypoints"]], np.float64)
    truth = np.array([[np.nan, np.nan] if p is None else p for p in labels["frames"][name]], np.float64)
    ok = np.isfinite(truth).all(1)
    h, _ = cv2.findHomography(pitch[ok, :2], truth[ok], 0)
    return decompose_homography(h, LABEL_SIZE).focal


def warp_at(t: float, focal: float, size: tuple[int, int]) -> np.ndarray:
    """3 x 3 map labelled-frame px -> output px at ``t`` in [0, 1]: the camera turned by the pan
    and zoomed (module docstring), then scaled to ``size``."""
    def k(f: float) -> np.ndarray:
        return np.array([[f * LABEL_SIZE[0], 0, (LABEL_SIZE[0] - 1) / 2], [0, f * LABEL_SIZE[0], (LABEL_SIZE[1] - 1) / 2], [0, 0, 1]])

    pan = math.radians(PAN_DEG * math.sin(2 * math.pi * t))
    turn = np.array([[math.cos(pan), 0, math.sin(pan)], [0, 1, 0], [-math.sin(pan), 0, math.cos(pan)]])
    zoom = ZOOM_START + (ZOOM - ZOOM_START) * math.sin(math.pi * t)
    scale = np.diag([size[0] / LABEL_SIZE[0], size[1] / LABEL_SIZE[1], 1.0])
    return scale @ k(focal * zoom) @ turn @ np.linalg.inv(k(focal))


def moved(points: np.ndarray, warp: np.ndarray) -> np.ndarray:
    """Pixels (N x 2) through a 3 x 3 warp."""
    p = np.column_stack([points, np.ones(len(points))]) @ warp.T
    return p[:, :2] / p[:, 2:3]


def make_clip(path: Path, name: str, size: tuple[int, int], rate: int, seconds: float) -> Path:
    """The content (module docstring), cached at ``path``."""
    if path.is_file():
        return path
    from glradial.media.video_io import EncodeOptions, VideoInfo, VideoWriter

    image = cv2.resize(cv2.imread(str(DATA / f"{name}.jpg"))[:, :, ::-1], LABEL_SIZE, interpolation=cv2.INTER_CUBIC)
    frames, focal = int(round(seconds * rate)), label_focal(name)
    made = path.with_name("made_" + path.name)
    with VideoWriter(made, VideoInfo.of(size, rate, codec="libx264"), options=EncodeOptions(crf=18, preset="veryfast"),
                     overwrite=True) as writer:
        for i in range(frames):
            writer.write(cv2.warpPerspective(image, warp_at(i / max(frames - 1, 1), focal, size), size,
                                             flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE))
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(made), "-c", "copy", "-f", "mpegts", str(path)], check=True)
    made.unlink()
    return path


def otio_rotation(pan: float, tilt: float, roll: float) -> np.ndarray:
    """World -> camera rotation (rows: right, down, forward) of OpenTrackIO's pan/tilt/roll (degrees;
    intrinsic Z, X, Y; camera Y forward, Z up at zero)."""
    p, t, r = (math.radians(v) for v in (pan, tilt, roll))
    rz = np.array([[math.cos(p), -math.sin(p), 0], [math.sin(p), math.cos(p), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])
    ry = np.array([[math.cos(r), 0, math.sin(r)], [0, 1, 0], [-math.sin(r), 0, math.cos(r)]])
    axes = rz @ rx @ ry  # camera -> world: columns right, forward, up
    return np.stack([axes[:, 0], -axes[:, 2], axes[:, 1]])


def project_sample(sample: dict, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pitch points (N x 3 m) -> distorted px, from the sample's own fields (module docstring)."""
    transform = sample["transforms"][0]
    rot = otio_rotation(*(transform["rotation"][k] for k in ("pan", "tilt", "roll")))
    centre = np.array([transform["translation"][k] for k in ("x", "y", "z")])
    sensor = sample["static"]["camera"]["activeSensorPhysicalDimensions"]["width"]
    focal = sample["lens"]["pinholeFocalLength"] / sensor  # image widths
    k1, k2 = sample["custom"]["glradial"]["k1"], sample["custom"]["glradial"]["k2"]
    cam = (points - centre) @ rot.T
    uv = focal * cam[:, :2] / cam[:, 2:3]
    r2 = np.sum(uv * uv, 1, keepdims=True)
    d = uv * (1 + k1 * r2 + k2 * r2 * r2)
    return d * size[0] + (np.array(size) - 1) / 2.0


def score(samples: list[dict], name: str, size: tuple[int, int], frames: int) -> dict:
    """Keypoint RMS of the sure samples against the moved labels (module docstring)."""
    labels = json.loads((DATA / "keypoints" / "keypoints.json").read_text())
    pitch = np.array([k["pitch_m"] for k in labels["keypoints"]], np.float64)
    truth = np.array([[np.nan, np.nan] if p is None else p for p in labels["frames"][name]], np.float64)
    focal, rms = label_focal(name), []
    for s in samples:
        if s["custom"]["glradial"]["doubtful"]:
            continue
        there = moved(truth, warp_at(s["timing"]["sequenceNumber"] / max(frames - 1, 1), focal, size))
        inside = np.isfinite(there).all(1) & (there >= 0).all(1) & (there < size).all(1)
        error = project_sample(s, pitch, size)[inside] - there[inside]
        rms.append(float(np.sqrt(np.mean(np.sum(error**2, 1)))) * LABEL_SIZE[0] / size[0] if inside.sum() >= 4 else math.nan)
    rms = np.array([r for r in rms if math.isfinite(r)])
    return {"rms_median_px1280": float(np.median(rms)) if len(rms) else math.nan,
            "rms_p95_px1280": float(np.percentile(rms, 95)) if len(rms) else math.nan,
            "label_floor_px1280": _floor(pitch, truth)}


def run(clip: Path, frames: int) -> tuple[dict, list[dict]]:
    """The clip sent over UDP in real time to ``glradial live ... none --camera``: its report and samples."""
    from glradial.export.opentrackio_udp import reassemble

    stderr, received, conditions = stream_over_udp(clip, lambda video_port, sample_port: [
        f"udp://127.0.0.1:{video_port}", "none", "--camera", "--sensor", "2/3-inch", "--idle-timeout", "3",
        "--send", f"127.0.0.1:{sample_port}"])
    return {**_report(stderr), **conditions}, [json.loads(p) for p in reassemble(received)]


def summary(report: dict, samples: list[dict], name: str, size: tuple[int, int], frames: int) -> dict:
    import jsonschema

    validator = jsonschema.Draft202012Validator(json.loads(SPEC.read_text()))
    sure = sorted(s["timing"]["sequenceNumber"] for s in samples if not s["custom"]["glradial"]["doubtful"])
    first = sure[0] if sure else frames
    return {**report, "frame": name, "sent": frames, "samples": len(samples),
            "sure_share": len(sure) / frames, "first_sure_frame": first,
            "sure_share_after_lock": sum(1 for i in sure if i >= first) / max(frames - first, 1),
            "dropped_share": report["dropped"] / frames,
            "reasons": dict(Counter(s["custom"]["glradial"]["reason"] for s in samples)),
            "schema_valid_share": float(np.mean([validator.is_valid(s) for s in samples])) if samples else math.nan,
            **score(samples, name, size, frames)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frame", default="2e57b9_1_1", help="the labelled frame (shared/data/broadcast_bundesliga name)")
    parser.add_argument("--size", type=parse_size, default=(1280, 720))
    parser.add_argument("--rate", type=int, default=25)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--work", type=Path, default=Path("/tmp/glradial_bench_live_camera"))
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    tag = f"{args.size[0]}x{args.size[1]}_{args.rate}p"
    frames = int(round(args.seconds * args.rate))
    clip = make_clip(args.work / f"{args.frame}_{tag}_{args.seconds:g}s.ts", args.frame, args.size, args.rate, args.seconds)
    report, samples = run(clip, frames)
    result = summary(report, samples, args.frame, args.size, frames)
    print(json.dumps(result, indent=1))
    suffix = "" if (tuple(args.size), args.rate, args.frame) == ((1280, 720), 25, "2e57b9_1_1") else f"_{args.frame}_{tag}"
    write_figure(f"live_camera{suffix}", result)


if __name__ == "__main__":
    main()
