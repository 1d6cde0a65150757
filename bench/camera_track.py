"""The camera followed through a shot (issue 44): ``glradial.tracking.camera_track`` against calibrating
each frame alone (``glradial.calibrate``, what ``glradial calibrate VIDEO`` did per frame), in one
process, on one thread.

Usage: ``python bench/camera_track.py [--wide-frames N] [--clip-frames N] [--peer-frames N] [--no-write]``

Clips (validation only: nothing here is fitted or tuned on them):

* ``wide``: the first N frames of the shared real static wide camera
  (``real_wide_camera/wide_pitch_camera.mp4``, 3072x1728, resized to 1920x1080: the 1080p timing).
  No labels; static, so any movement of the projected keypoints between frames is jitter.
* ``bundesliga_2e57b9``, ``bundesliga_42ba34``: a virtual broadcast camera over one labelled frame
  of each Bundesliga match (``broadcast_bundesliga``, resized to 1280x720 as its README says), made by
  :func:`glradial.video.clips.render_shot` (a rotation-and-zoom homography of the picture, pinhole,
  the picture's field of view read from its labels' homography, 2 grey levels of noise per frame): a
  third still (zoom 1.1, and more where the pan needs a margin), a third panning 3 degrees right, a
  third zooming in 1.4/1.1 times. The labelled keypoints are moved with the frame by the same rotation
  and zoom.

Per clip: the share of frames answered (not doubtful) after tracking and by each frame alone (the
peer, on the first ``--peer-frames`` frames); the median keypoint jitter between consecutive frames of
the still part (px at 1280 wide: the 32 keypoints projected, those inside the frame) and their median
second difference over the moving part (a smooth pan or zoom leaves it near 0); keypoints
against the moved labels (median px at 1280) with the labels' own homography floor (RMS of the labels
about the homography fitted to them, the frame's labelling noise); ms per frame of the tracker
(:func:`track_cameras`, and the causal :class:`CameraTracker` alone) and of the peer; the causal
tracker's median ms on frames the motion alone carries (no markings measured) and their share; each
also in CPU ms of this process (one thread: what an idle core would take, on a shared machine). Writes ``docs/figures/camera_track.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
DATA = ROOT.parent / "shared" / "data"
if not DATA.exists():
    DATA = Path("/work/shared/data")
#: Grey levels of Gaussian noise added to each rendered frame (sensor noise: identical frames would
#: make every per-frame answer identical too).
NOISE = 2.0
#: One labelled frame of each Bundesliga match (the most keypoints labelled in a wide view).
BUNDESLIGA_FRAMES = ("2e57b9_9_10", "42ba34_3_7")


def wide_frames(n: int):
    import av

    with av.open(str(DATA / "real_wide_camera" / "wide_pitch_camera.mp4")) as container:
        for i, frame in enumerate(container.decode(video=0)):
            if i >= n:
                return
            yield cv2.resize(frame.to_ndarray(format="rgb24"), (1920, 1080), interpolation=cv2.INTER_AREA)


def _labels(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame (1280x720 RGB), its labelled keypoints' pixels (K x 2) and their pitch points (K x 3)."""
    data = json.loads((DATA / "broadcast_bundesliga" / "keypoints" / "keypoints.json").read_text())
    pitch = np.array([k["pitch_m"] for k in data["keypoints"]], float)
    points = data["frames"][name]
    keep = [i for i, p in enumerate(points) if p is not None]
    bgr = cv2.imread(str(DATA / "broadcast_bundesliga" / f"{name}.jpg"))
    frame = cv2.resize(bgr, (1280, 720), interpolation=cv2.INTER_CUBIC)[:, :, ::-1].copy()
    return frame, np.array([points[i] for i in keep], float), pitch[keep]


def _shots(frame: np.ndarray, hfov: float, n: int):
    from glradial.video.clips import ShotSpec

    third = n // 3
    still = ShotSpec(frame, third, (0.0, 0.0, 1.1), (0.0, 0.0, 1.1), k1=(0.0, 0.0), hfov_deg=hfov)
    pan = ShotSpec(frame, third, (0.0, 0.0, 1.1), (3.0, 0.0, 1.1), k1=(0.0, 0.0), hfov_deg=hfov)
    zoom = ShotSpec(frame, n - 2 * third, (3.0, 0.0, 1.1), (3.0, 0.0, 1.4), k1=(0.0, 0.0), hfov_deg=hfov)
    return [still, pan, zoom]


def _moved(labels: np.ndarray, size_src: tuple[int, int], hfov_src: float, pan: float, tilt: float, hfov: float,
           size: tuple[int, int]) -> np.ndarray:
    """Labelled pixels of the still -> pixels of the virtual camera's (pinhole) frame, as
    :func:`glradial.video.clips.render_shot` maps them (the inverse of its ray lookup)."""
    from glradial.lens.lens import focal_from_hfov
    from glradial.synthesis.crops import camera_rotation

    w, h = size_src
    f_src = focal_from_hfov(hfov_src) * w
    world = np.c_[labels[:, 0] - w / 2 + 0.5, labels[:, 1] - h / 2 + 0.5, np.full(len(labels), f_src)]
    cam = world @ camera_rotation(pan, tilt, 0.0)  # rays = cam @ R.T  ->  cam = rays @ R
    f_out = focal_from_hfov(hfov) * size[0]
    return np.c_[cam[:, 0] / cam[:, 2] * f_out + size[0] / 2 - 0.5, cam[:, 1] / cam[:, 2] * f_out + size[1] / 2 - 0.5]


def bundesliga_clip(name: str, n: int):
    """``(frames, per-frame moved labels, the labels' pitch points, floor px at 1280, still frames)``."""
    from glradial.camera.model import decompose_homography
    from glradial.lens.lens import focal_from_hfov, hfov_deg
    from glradial.video.clips import render_shot

    frame, labels, pitch = _labels(name)
    h, _ = cv2.findHomography(pitch[:, :2], labels, 0)
    hfov = decompose_homography(h, (1280, 720)).hfov_deg
    proj = cv2.perspectiveTransform(pitch[None, :, :2], h)[0]
    floor = float(np.sqrt(np.mean(np.sum((proj - labels) ** 2, axis=1))))
    frames, moved, still = [], [], []
    for spec in _shots(frame, hfov, n):
        for i, (img, _, zoom) in enumerate(render_shot(spec, (1280, 720))):  # zoom: the margin included
            pan, tilt, _ = spec.camera(i)
            view_hfov = hfov_deg(focal_from_hfov(hfov) * zoom)
            moved.append(_moved(labels, (1280, 720), hfov, pan, tilt, view_hfov, (1280, 720)))
            still.append(spec.start == spec.end)
            noise = np.random.default_rng(len(frames)).normal(0.0, NOISE, img.shape)  # a camera's own, per frame
            frames.append(np.clip(img + noise, 0, 255).astype(np.uint8))
    return frames, moved, pitch, floor, np.array(still)


def _projected(est, points: np.ndarray) -> np.ndarray:
    return np.full((len(points), 2), np.nan) if est.camera is None or est.doubtful else est.project(points)


def _jitter(estimates, size: tuple[int, int], still: np.ndarray) -> float:
    """Median movement (px at 1280) of the keypoints inside the frame between consecutive still frames."""
    from glradial.pitch import PitchTemplate

    kp = PitchTemplate().keypoints()
    proj = np.array([_projected(e, kp) for e in estimates])
    w, h = size
    inside = (proj[..., 0] >= 0) & (proj[..., 0] < w) & (proj[..., 1] >= 0) & (proj[..., 1] < h)
    moves = []
    for i in range(1, len(proj)):
        if still[i] and still[i - 1]:
            ok = inside[i] & inside[i - 1]
            moves.extend(np.linalg.norm(proj[i, ok] - proj[i - 1, ok], axis=1))
    return float(np.median(moves)) * 1280 / w if moves else math.nan


def _wobble(estimates, size: tuple[int, int], moving: np.ndarray) -> float:
    """Median second difference (px at 1280) of the keypoints inside the frame over consecutive
    moving frames: what a smooth pan or zoom leaves near 0 and a jittering track does not."""
    from glradial.pitch import PitchTemplate

    proj = np.array([_projected(e, PitchTemplate().keypoints()) for e in estimates])
    w, h = size
    inside = (proj[..., 0] >= 0) & (proj[..., 0] < w) & (proj[..., 1] >= 0) & (proj[..., 1] < h)
    out = []
    for i in range(1, len(proj) - 1):
        if moving[i - 1] and moving[i] and moving[i + 1]:
            ok = inside[i - 1] & inside[i] & inside[i + 1]
            out.extend(np.linalg.norm(proj[i + 1, ok] - 2 * proj[i, ok] + proj[i - 1, ok], axis=1))
    return float(np.median(out)) * 1280 / w if out else math.nan


def track(frames: list) -> tuple[list, dict]:
    """The tracked estimates (forward-backward, :func:`track_cameras`) and the timings (ms): per frame
    of the whole track, per frame of the causal tracker alone, and its median on carried frames."""
    from glradial.tracking.camera_track import CameraTracker, track_cameras

    t0 = time.perf_counter()
    out = dict(track_cameras(iter(frames), lag=25))
    total = time.perf_counter() - t0
    tracker, times, cpu, carried = CameraTracker(keep_steps=True), [], [], []
    for frame in frames:
        t, c = time.perf_counter(), time.process_time()
        tracker.push(frame)
        times.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
        if tracker.steps[-1].measured is None:  # the motion alone carried the camera
            carried.append(len(times) - 1)
    return [out[i] for i in range(len(frames))], {
        "ms_per_frame_track_cameras": 1000 * total / len(frames), "ms_per_frame_causal": 1000 * float(np.mean(times)),
        "cpu_ms_per_frame_causal": 1000 * float(np.mean(cpu)), "cpu_ms_per_frame_causal_median": 1000 * float(np.median(cpu)),
        "ms_per_carried_frame_median": 1000 * float(np.median(np.take(times, carried))) if carried else math.nan,
        "cpu_ms_per_carried_frame_median": 1000 * float(np.median(np.take(cpu, carried))) if carried else math.nan,
        "carried_share": len(carried) / len(frames)}


def peer(frames, n: int) -> tuple[list, float]:
    """Each of the first ``n`` frames calibrated alone, and the mean ms per frame."""
    import glradial

    t = time.perf_counter()
    out = [glradial.calibrate(f) for f in frames[:n]]
    return out, 1000 * (time.perf_counter() - t) / max(len(out), 1)


def _label_error(estimates, moved, pitch) -> float:
    errs = []
    for est, lab in zip(estimates, moved):
        p = _projected(est, pitch)
        inside = (lab[:, 0] >= 0) & (lab[:, 0] < 1280) & (lab[:, 1] >= 0) & (lab[:, 1] < 720)
        errs.extend(np.linalg.norm(p[inside] - lab[inside], axis=1))
    errs = np.array(errs)
    return float(np.median(errs[np.isfinite(errs)])) if np.isfinite(errs).any() else math.nan


def run_clip(name: str, frames, still, moved=None, pitch=None, floor=None, peer_frames: int = 10) -> dict:
    size = frames[0].shape[1::-1]
    estimates, times = track(frames)
    alone, ms_peer = peer(frames, peer_frames)
    row = {"clip": name, "frames": len(frames), "size": list(size),
           "answered_tracked": float(np.mean([not e.doubtful for e in estimates])),
           "answered_alone": float(np.mean([not e.doubtful for e in alone])), "alone_frames": len(alone),
           "jitter_still_median_px_1280": _jitter(estimates, size, still),
           "jitter_still_alone_median_px_1280": _jitter(alone, size, still[: len(alone)]),
           **times, "ms_per_frame_alone": ms_peer, "speedup_causal_vs_alone": ms_peer / times["ms_per_frame_causal"],
           "load_average_1min": os.getloadavg()[0]}
    if moved is not None:
        row["moving_second_difference_median_px_1280"] = _wobble(estimates, size, ~still)
        row.update({"keypoints_vs_labels_median_px_1280": _label_error(estimates, moved, pitch),
                    "keypoints_vs_labels_alone_median_px_1280": _label_error(alone, moved[: len(alone)], pitch),
                    "labels_homography_floor_rms_px_1280": floor})
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--wide-frames", type=int, default=60)
    parser.add_argument("--clip-frames", type=int, default=75)
    parser.add_argument("--peer-frames", type=int, default=10)
    parser.add_argument("--no-write", action="store_true", help="print, do not write docs/figures/camera_track.json")
    args = parser.parse_args()
    cv2.setNumThreads(1)
    rows = []
    frames = list(wide_frames(args.wide_frames))
    rows.append(run_clip("wide", frames, np.ones(len(frames), bool), peer_frames=args.peer_frames))
    print(json.dumps(rows[-1]), flush=True)
    del frames
    for name in BUNDESLIGA_FRAMES:
        frames, moved, pitch, floor, still = bundesliga_clip(name, args.clip_frames)
        rows.append(run_clip(f"bundesliga_{name.split('_')[0]}", frames, still, moved, pitch, floor, args.peer_frames))
        print(json.dumps(rows[-1]), flush=True)
    if not args.no_write:
        from figures import write_figure

        print(write_figure("camera_track", rows))


if __name__ == "__main__":
    main()
