"""Render the stadium gallery: docs/stadium_gallery_panoramas.png and docs/stadium_gallery_crops.png.

Usage: python docs/make_stadium_gallery.py [--seeds 0 1 2 ...] [--pano-size 1024x512] [--crop-pano 4096x2048]

Panoramas: a grid of small equirectangular panoramas (seed, camera kind and lighting in the label).
Crops: 16:9 frames (k = 0 and one barrel lens) at several horizontal fields of view, rendered by
glradial.synthesis.crops from larger panoramas of a few seeds, the way the training data is made.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from glradial.synthesis.crops import CropParams, render_crops
from glradial.synthesis.stadium import StadiumRenderer, project_point
from glradial.synthesis.stadium_style import HALF_WIDTH, sample_style

DOCS = Path(__file__).resolve().parent


def _label(image: np.ndarray, text: str) -> np.ndarray:
    out = image.copy()
    cv2.rectangle(out, (0, 0), (min(out.shape[1], 9 * len(text) + 8), 20), (0, 0, 0), -1)
    cv2.putText(out, text, (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def _size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[2, 3, 4, 0, 13, 20, 32, 45])
    parser.add_argument("--crop-seeds", type=int, nargs="+", default=[2, 45, 9, 13])
    parser.add_argument("--pano-size", type=_size, default=(1024, 512))
    parser.add_argument("--crop-pano", type=_size, default=(4096, 2048))
    args = parser.parse_args()

    renderer = StadiumRenderer()
    tiles = []
    for seed in args.seeds:
        style = sample_style(seed)
        t0 = time.time()
        pano = renderer.render(style, args.pano_size)
        print(f"seed {seed}: {args.pano_size[0]}x{args.pano_size[1]} in {time.time() - t0:.1f} s")
        tiles.append(_label(pano, f"seed {seed}: {style.camera_kind}, {style.lighting}, stripes {style.stripe_pattern}"))
    rows = [np.hstack(tiles[i:i + 2]) for i in range(0, len(tiles) - 1, 2)]
    grid = np.vstack(rows)
    cv2.imwrite(str(DOCS / "stadium_gallery_panoramas.png"), cv2.cvtColor(grid, cv2.COLOR_RGB2BGR))

    crop_rows = []
    for seed in args.crop_seeds:
        style = sample_style(seed)
        w, h = args.crop_pano
        _, lat_line = project_point(style, (0.0, HALF_WIDTH, 0.0))
        _, lat_centre = project_point(style, (0.0, 0.0, 0.0))
        # only the rows the crops can see are rendered (lat from -60 to +35 degrees)
        y0, y1 = int((0.5 - 35.0 / 180.0) * h), int((0.5 + 60.0 / 180.0) * h)
        t0 = time.time()
        pano = renderer.render(style, (w, h), rows=(y0, y1))
        print(f"seed {seed}: {w}x{h} rows {y0}-{y1} in {time.time() - t0:.1f} s")
        tilt = float(np.clip(lat_centre + 6.0, -15.0, 0.0))
        params = [
            CropParams(0.0, tilt, 0.0, 60.0, 0.0, 0.0),
            CropParams(-20.0, tilt, 1.0, 30.0, 0.0, 0.0),
            CropParams(10.0, float(np.clip(lat_line, -15, 0)), -1.0, 15.0, 0.0, 0.0),
            CropParams(0.0, tilt, 0.0, 45.0, -0.4, 0.019 * -0.4 + 0.805 * 0.16),
        ]
        crops = render_crops(pano, params, size=(1280, 720), out_size=(480, 270))
        labels = ["hfov 60, k=0", "hfov 30, k=0", "hfov 15, k=0", "hfov 45, k1=-0.4"]
        crop_rows.append(np.hstack([_label(c, f"seed {seed}: {t}") for c, t in zip(crops, labels)]))
    cv2.imwrite(str(DOCS / "stadium_gallery_crops.png"), cv2.cvtColor(np.vstack(crop_rows), cv2.COLOR_RGB2BGR))
    renderer.release()


if __name__ == "__main__":
    main()
