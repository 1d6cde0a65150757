"""Which lens reading do the Bundesliga hand labels prefer? (validation only)

Usage: ``python bench/labels_lens.py [--frames DIR] [--json OUT]``

The self-consistent score of ``bench/bundesliga_consistency.py`` cannot say which of two readings of
a frame's own (unknown) lens is right. The hand-labelled pitch keypoints
(``DIR/keypoints/keypoints.json``, README there) can: a pitch is a plane, so with the right lens the
undistorted keypoints fit a homography to their pitch coordinates up to the click noise. Per frame
(resized to 1280 x 720 as the labels are), the labelled points are undistorted with each reading
and a plain least-squares homography (``cv2.findHomography``, method 0) is fitted; its RMS in
undistorted pixels is printed per clip for: no lens; the estimation layer's reading
(``glradial.estimate(frame, pitch=False)``); the default ``glradial.estimate`` (the camera fit's lens
fed back); the whole-camera fit's own lens (``glradial.calibrate``, where it is sure); and blends
``w * camera + (1 - w) * estimation layer``, on the frames where the camera is sure and the labels fit
a homography at all (RMS without a lens under 15 px). Also: on how many frames the camera's lens
beats the estimation layer's. Nothing is fitted to the labels; the camera fit uses the frame only.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from figures import printed_report, write_figure

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def homography_rms(k: tuple[float, float] | None, points: np.ndarray, world: np.ndarray) -> float:
    """RMS (px) of a least-squares homography from ``world`` (N x 2 metres) to ``points`` (N x 2
    pixels at 1280 x 720) undistorted with the lens ``k`` (None: as labelled)."""
    import cv2

    from glradial.lens.lens import Lens

    pixels = points if k is None else Lens(float(k[0]), float(k[1])).undistort_points(points, (1280, 720))
    homography, _ = cv2.findHomography(world, pixels, 0)
    projected = cv2.perspectiveTransform(world[None], homography)[0]
    return float(np.sqrt(np.mean(np.sum((projected - pixels) ** 2, axis=1))))


def readings(folder: Path) -> list[dict]:
    """Per labelled frame with at least 6 points: the lens readings and their homography RMS."""
    import glradial
    from glradial.evaluation.real_eval import read_broadcast

    labels = json.loads((folder / "keypoints" / "keypoints.json").read_text())
    pitch = np.array([entry["pitch_m"][:2] for entry in labels["keypoints"]], float)
    rows = []
    for path in sorted(folder.glob("*.jpg")):
        marks = labels["frames"].get(path.stem)
        seen = np.array([m is not None for m in marks]) if marks else np.zeros(0, bool)
        if seen.sum() < 6:
            continue
        points, world = np.array([m for m in marks if m is not None], float), pitch[seen]
        image = read_broadcast(path)
        camera = glradial.calibrate(image)
        row = {"frame": path.stem, "clip": path.stem.split("_")[0], "none": homography_rms(None, points, world)}
        for name, lens in (("layer", glradial.estimate(image, pitch=False)), ("default", glradial.estimate(image)),
                           ("camera", None if camera.doubtful else camera.lens)):
            row[name + "_k"] = None if lens is None else [float(lens.k1), float(lens.k2)]
            row[name] = None if lens is None else homography_rms(row[name + "_k"], points, world)
        row["points"], row["world"] = points.tolist(), world.tolist()
        rows.append(row)
        print(f"{path.stem}: none {row['none']:.2f}  layer {row['layer']:.2f}  default {row['default']:.2f}  "
              f"camera {'-' if row['camera'] is None else format(row['camera'], '.2f')}", flush=True)
    return rows


def report(rows: list[dict]) -> None:
    usable = [r for r in rows if r["camera"] is not None and r["none"] < 15]
    for clip in sorted({r["clip"] for r in usable}) + ["all"]:
        chosen = [r for r in usable if clip in ("all", r["clip"])]
        blends = []
        for w in (0.0, 0.2, 0.4, 0.6, 0.8, 1.0):
            rms = [homography_rms(tuple(w * np.array(r["camera_k"]) + (1 - w) * np.array(r["layer_k"])),
                                  np.array(r["points"]), np.array(r["world"])) for r in chosen]
            blends.append(f"w={w:.1f} {np.median(rms):.2f}")
        better = sum(r["camera"] < r["layer"] for r in chosen)
        print(f"{clip}: {len(chosen)} frames, median homography RMS px: none {np.median([r['none'] for r in chosen]):.2f}, "
              f"estimation layer {np.median([r['layer'] for r in chosen]):.2f}, default {np.median([r['default'] for r in chosen]):.2f}, "
              f"camera {np.median([r['camera'] for r in chosen]):.2f}; camera better on {better}/{len(chosen)}; "
              f"blends {' | '.join(blends)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=Path, default=ROOT.parent / "shared" / "data" / "broadcast_bundesliga")
    parser.add_argument("--json", type=Path, help="write the per-frame rows here")
    args = parser.parse_args()
    rows = readings(args.frames)
    if args.json:
        args.json.write_text(json.dumps(rows))
    with printed_report() as lines:
        report(rows)
    write_figure("labels_lens", {"report": lines})


if __name__ == "__main__":
    main()
