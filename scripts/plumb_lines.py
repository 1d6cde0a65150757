"""Measure a real picture's own radial lens by the plumb-line method, independently of glradial's
estimator: hand-picked stretches of lines that are straight in the world (pitch markings), refined
to sub-pixel ridge points in the picture, and the lens ``(k1, k2)`` (width-normalised, DESIGN.md;
about the picture's centre, or about a centre fitted too) that makes them straight, by least
squares. Nothing of :mod:`glradial.estimation` is used
(no chain detection, no priors, no CNN): only the lens model itself
(:func:`glradial.lens.lensfuncs.undistort_point_exact`).

Used for the source pictures of issue 35's two-shot clips (``scripts/make_clips.py --set twoshot``),
whose truth must include the pictures' own lens. The stretches live in ``scripts/plumb_lines.json``
(per picture: ``lines``, each a list of segments ``[x0, y0, x1, y1]`` in the picture's pixels,
centres at integers, drawn by eye a few px from the painted line; a line may skip what hides it,
e.g. a goal's net; a video's frame is named by ``video``, ``frame`` and the ``width`` it is
measured at; ``free_centre``: the lens's centre is fitted too, else it is the picture's centre).

Run: ``python scripts/plumb_lines.py [--data ../shared/data/real_football] [--wide
../shared/data/real_wide_camera] [--overlay DIR]``: prints
each picture's lens, its 1-sigma and the lines' RMS straightness (px) before and after.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's glradial
from glradial.lens.lensfuncs import undistort_point_exact  # noqa: E402

LINES = Path(__file__).with_name("plumb_lines.json")
#: half-width of the search across a drawn segment (px), the sampling step along it (px), the
#: contrast a ridge needs over its surroundings (grey levels) and the distance (px) from its line's
#: smooth fit beyond which a point is dropped (a player, a net)
SEARCH_PX, STEP_PX, MIN_CONTRAST, OUTLIER_PX = 8.0, 2.0, 12.0, 1.2


def ridge_points(grey: np.ndarray, segment: tuple[float, float, float, float]) -> np.ndarray:
    """Sub-pixel centres of the bright line near ``segment`` (``N x 2`` px): at every
    :data:`STEP_PX` along it, the intensity-weighted centroid of the profile across it above its
    median, where the peak stands :data:`MIN_CONTRAST` out and lies inside the search band."""
    x0, y0, x1, y1 = segment
    length = float(np.hypot(x1 - x0, y1 - y0))
    along = np.array([x1 - x0, y1 - y0]) / length
    normal = np.array([-along[1], along[0]])
    t = np.arange(0.0, length + 1e-9, STEP_PX)
    s = np.arange(-SEARCH_PX, SEARCH_PX + 1e-9, 0.5)
    centres = np.array([x0, y0]) + t[:, None] * along
    xy = centres[:, None, :] + s[None, :, None] * normal
    profile = cv2.remap(grey, xy[..., 0].astype(np.float32), xy[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
    base = np.median(profile, axis=1, keepdims=True)
    weight = np.clip(profile - base, 0.0, None) ** 2
    peak = np.argmax(profile, axis=1)
    good = ((profile.max(axis=1) - base[:, 0]) >= MIN_CONTRAST) & (peak > 2) & (peak < len(s) - 3)
    offset = (weight * s).sum(axis=1) / np.maximum(weight.sum(axis=1), 1e-12)
    return (centres + offset[:, None] * normal)[good]


def _clean(points: np.ndarray) -> np.ndarray:
    """Drop points further than :data:`OUTLIER_PX` from a quadratic through the line's points
    (along its principal direction), twice."""
    for _ in range(2):
        if len(points) < 8:
            return points
        centre = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - centre)
        u, v = (points - centre) @ vt[0], (points - centre) @ vt[1]
        keep = np.abs(v - np.polyval(np.polyfit(u, v, 2), u)) <= OUTLIER_PX
        points = points[keep]
    return points


def straightness(lines: list[np.ndarray], lens: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Distances (px) of every point from its line's total-least-squares line, after undistorting
    the points with ``lens`` = ``(k1, k2[, cx, cy])`` (width-normalised, about the picture's centre
    offset by ``(cx, cy)`` widths)."""
    width, height = size
    centre = np.asarray(lens[2:4], np.float64) if len(lens) == 4 else np.zeros(2)
    out = []
    for points in lines:
        p = (points + 0.5 - np.array([width / 2, height / 2])) / width - centre
        p_u, _ = undistort_point_exact(p, float(lens[0]), float(lens[1]))
        centred = p_u - p_u.mean(axis=0)
        normal = np.linalg.svd(centred, full_matrices=False)[2][1]
        out.append(centred @ normal * width)
    return np.concatenate(out)


def measure(picture: np.ndarray, drawn: list[list[list[float]]], free_centre: bool = False) -> dict:
    """The picture's own lens from its drawn lines (module docstring): ``k1``, ``k2`` (and the centre
    ``cx``, ``cy``, widths from the picture's centre, with ``free_centre``), their 1-sigma, the points
    used and the RMS straightness before (no lens) and after (px)."""
    grey = cv2.cvtColor(picture, cv2.COLOR_RGB2GRAY).astype(np.float32)
    size = (picture.shape[1], picture.shape[0])
    lines = [np.concatenate([_clean(ridge_points(grey, tuple(seg))) for seg in line]) for line in drawn if line]
    lines = [p for p in lines if len(p) >= 8]
    names = ("k1", "k2", "cx", "cy")[: 4 if free_centre else 2]
    fit = least_squares(lambda lens: straightness(lines, lens, size), np.zeros(len(names)), x_scale=0.05)
    residual = fit.fun
    dof = max(len(residual) - 2 * len(lines) - len(names), 1)
    sigma = np.sqrt(np.diag(np.linalg.pinv(fit.jac.T @ fit.jac)) * float(residual @ residual) / dof)
    rms = lambda r: float(np.sqrt(np.mean(r * r)))  # noqa: E731
    return {**{n: float(v) for n, v in zip(names, fit.x)}, **{f"{n}_sigma": float(v) for n, v in zip(names, sigma)},
            "lines": len(lines), "points": int(sum(len(p) for p in lines)),
            "rms_before_px": rms(straightness(lines, np.zeros(2), size)), "rms_after_px": rms(residual),
            "_points": lines}


def picture_of(entry: dict, name: str, data: Path, wide: Path) -> np.ndarray:
    """The RGB picture an entry of ``plumb_lines.json`` names (a still in ``data``, or a frame of a
    video in ``wide`` at its ``width``)."""
    if "video" not in entry:
        image = cv2.imread(str(data / name), cv2.IMREAD_COLOR)
        if image is None:
            raise SystemExit(f"cannot read {data / name}")
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    from glradial.media.video_io import VideoReader

    with VideoReader(wide / entry["video"], order="rgb") as reader:
        for index, image in enumerate(reader):
            if index == entry["frame"]:
                height = round(image.shape[0] * entry["width"] / image.shape[1])
                return cv2.resize(image, (entry["width"], height), interpolation=cv2.INTER_AREA)
    raise SystemExit(f"{wide / entry['video']} has no frame {entry['frame']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/real_football")
    parser.add_argument("--wide", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/real_wide_camera")
    parser.add_argument("--overlay", type=Path, help="write each picture with its ridge points here (PNG)")
    args = parser.parse_args()
    for name, entry in json.loads(LINES.read_text()).items():
        picture = picture_of(entry, name, args.data, args.wide)
        drawn = entry["lines"]
        result = measure(picture, drawn, bool(entry.get("free_centre")))
        image = cv2.cvtColor(picture, cv2.COLOR_RGB2BGR)
        if args.overlay:
            args.overlay.mkdir(parents=True, exist_ok=True)
            big = cv2.resize(image, None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)
            for line in drawn:
                for x0, y0, x1, y1 in line:
                    cv2.line(big, (round(2 * x0), round(2 * y0)), (round(2 * x1), round(2 * y1)), (255, 0, 0), 1)
            for points in result["_points"]:
                for x, y in points:
                    cv2.circle(big, (round(2 * x + 0.5), round(2 * y + 0.5)), 1, (0, 0, 255), -1)
            cv2.imwrite(str(args.overlay / f"{Path(name).stem}.png"), big)
        print(json.dumps({"picture": name, **{k: v for k, v in result.items() if not k.startswith("_")}}))


if __name__ == "__main__":
    main()
