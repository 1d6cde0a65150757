"""``glradial evaluate``: evaluate an estimator model on held-out procedural stadiums (needs torch-free
glradial only; it runs ``net.evaluate``, which ships as ``glradial.net.evaluate``)."""

from __future__ import annotations

import argparse

from . import positive_int

DESCRIPTION = """\
Render crops of held-out (test split) procedural stadiums and of the real test panorama, estimate
their lens with MODEL (default: the bundled one) and write metrics.json, results.md and PNG plots
to --out: median and 90th percentile of the maximum displacement error (pixels of a 1920-wide
frame), mean distortion loss, k1/k2 errors, the share of crops where both net coefficients beat the
net's k1 with the manifold k2 (the paper's 61.2 %), errors by k1 range and field of view."""


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "evaluate", help="evaluate the estimator on held-out stadium crops", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--model", metavar="ONNX", help="model to evaluate (default: the bundled one)")
    parser.add_argument("--out", default="eval", help="output folder (default: ./eval)")
    parser.add_argument("--n", type=positive_int, default=800, help="test crops (default 800)")
    parser.add_argument("--test-panoramas", type=positive_int, default=8, help="held-out stadiums (default 8)")
    parser.add_argument("--split", choices=("test", "val"), default="test",
                        help="stadium split: test (reported figures, default) or val (choosing between checkpoints)")
    parser.add_argument("--threads", type=positive_int, help="onnxruntime threads (default: all cores)")
    parser.add_argument("--frames", metavar="DIR", help="instead: evaluate net, lines and auto on the (nearly) undistorted "
                        "real frames of DIR with known lenses applied (glradial.real_eval; writes real.md to --out)")
    parser.add_argument("--calibrated", metavar="JSON", action="append", default=[],
                        help="with --frames: also a calibrated camera (frames + known lens; see glradial.real_eval)")
    parser.add_argument("--procedural", type=int, default=0, metavar="N",
                        help="with --frames: also N held-out procedural stadium crops (default 0)")
    return parser


def run(args: argparse.Namespace) -> int:
    from ..estimator import default_model_path

    if args.frames or args.calibrated:
        from ..real_eval import evaluate_folder

        evaluate_folder(args.frames, args.out, calibrated=args.calibrated, procedural=args.procedural,
                        model=args.model, threads=args.threads)
        print(f"wrote {args.out}/real.md", flush=True)
        return 0

    try:
        from ..net.evaluate import main
    except ImportError:  # running from a source checkout: net/ is not under glradial/
        from net.evaluate import main  # type: ignore[no-redef]
    argv = ["--model", str(args.model or default_model_path()), "--out", args.out, "--n", str(args.n),
            "--test-panoramas", str(args.test_panoramas), "--split", args.split]
    if args.threads:
        argv += ["--threads", str(args.threads)]
    return main(argv)
