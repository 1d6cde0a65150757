"""Figure for docs/LINES.md: what the line fit sees on a frame (each chain in its own colour, the
fit's reading in the caption).

Usage: ``python bench/lines_figure.py --frame IMAGE --out PNG [--checkout PATH] [--k1 K1 --k2 K2]``

``--checkout``: run the detection and fit of another checkout of glradial (e.g. main, for a before /
after pair); ``--k1/--k2``: apply this lens to the frame first (``glradial.distort``, ``fit="crop"``);
the CNN's reading is the hint and prior, as in ``estimate(method="auto")``. ``--template``: draw the
synthetic pitch of tests/pitch_template.py (box view, 640 x 360) instead of ``--frame``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frame")
    parser.add_argument("--template", action="store_true")
    parser.add_argument("--out", required=True)
    parser.add_argument("--title", default="", help="a line of text above the caption")
    parser.add_argument("--checkout", default=str(Path(__file__).resolve().parents[1]))
    parser.add_argument("--k1", type=float)
    parser.add_argument("--k2", type=float, default=0.0)
    args = parser.parse_args()
    sys.path.insert(0, args.checkout)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from glradial.estimation.line_fit import fit_lines
    from glradial.estimation.lines import detect_chains
    from glradial.estimation.net_lines import NetLinesEstimator
    from glradial.lens.lens import lens_to_pixels

    if args.template:
        from pitch_template import BOX_VIEW, homography, render

        frame = render(homography(size=(640, 360), **BOX_VIEW), (640, 360))
    else:
        frame = np.ascontiguousarray(cv2.imread(args.frame, cv2.IMREAD_COLOR)[:, :, ::-1])
    if args.k1 is not None:
        from glradial.remapping.remap import distort

        frame = distort(frame, args.k1, args.k2, fit="crop", backend="cpu")
    estimator = NetLinesEstimator(threads=1)
    net = tuple(float(v) for v in estimator.run(estimator.preprocess(frame)[None])[0])
    evidence = detect_chains(frame, lens_hint=net)
    fit = fit_lines(evidence, prior=net)
    image = np.ascontiguousarray(frame[:, :, ::-1] // 2 + 40)
    rng = np.random.default_rng(2)
    for chain in evidence.chains:
        colour = tuple(int(v) for v in rng.integers(80, 256, 3))
        for q in np.round(lens_to_pixels(chain.points, evidence.size)).astype(int):
            cv2.circle(image, tuple(q), 2 if frame.shape[1] > 700 else 1, colour, -1)
    families = getattr(fit, "families", 0)
    text = f"{len(evidence.chains)} chains, fit k1 {fit.k1:+.3f} k2 {fit.k2:+.3f} ({'ok' if fit.ok else 'no fit'})"
    if args.k1 is not None:
        from glradial.lens.metrics import max_displacement_px

        error = float(max_displacement_px(np.array([fit.k1, fit.k2]), np.array([args.k1, args.k2])))
        text += f", true {args.k1:+.3f} {args.k2:+.3f}: {error:.1f} px off at 1920"
    if families:
        text += f", {families} vanishing-point famil{'y' if families == 1 else 'ies'}"
    scale = frame.shape[1] / 1280
    for row, line in enumerate([args.title, text] if args.title else [text]):
        cv2.putText(image, line, (8, int((24 + 22 * row) * scale) + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.6 * scale + 0.1,
                    (255, 255, 255), 1, cv2.LINE_AA)
    cv2.imwrite(args.out, image)
    print(text)


if __name__ == "__main__":
    main()
