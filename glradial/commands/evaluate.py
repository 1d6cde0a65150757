"""``glradial evaluate``: evaluate an estimator model on held-out procedural stadiums
(:mod:`glradial.evaluation.evaluation`; torch-free: an installed glradial runs it)."""

from __future__ import annotations

import argparse

from . import non_negative_int, parse_size, positive_int

DESCRIPTION = """\
Render crops of held-out (test split) procedural stadiums and, with --field-panorama, of a real
panorama, estimate their lens with MODEL (default: the bundled one) and write metrics.json,
results.md and PNG plots (when matplotlib is installed) to --out: median and 90th percentile of the
maximum displacement error (pixels of a 1920-wide frame), mean distortion loss, k1/k2 errors, the
share of crops where both net coefficients beat the net's k1 with the manifold k2 (the paper's
61.2 %), errors by k1 range and field of view. Stadium panoramas are rendered once and cached in
--cache-dir."""


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of ``glradial evaluate`` (shared with ``python -m net.evaluate``)."""
    parser.add_argument("--model", help="model to evaluate (default: the bundled ONNX model)")
    parser.add_argument("--out", default="eval", help="output folder (default: ./eval)")
    parser.add_argument("--n", type=positive_int, default=800, help="test crops (default 800)")
    parser.add_argument("--test-panoramas", type=positive_int, default=8, help="held-out stadiums (default 8)")
    parser.add_argument("--split", choices=("test", "val"), default="test",
                        help="stadium split: test (reported figures, default) or val (choosing between checkpoints)")
    parser.add_argument("--panorama-size", type=parse_size, default=(4096, 2048), metavar="WxH",
                        help="stadium panorama size in pixels (default 4096x2048)")
    parser.add_argument("--field-panorama", metavar="IMAGE",
                        help="a real 2:1 panorama for the out-of-domain figure (in a checkout: "
                             "tests/data/panorama_field_2048x1024.jpg); without it the figure is left out, and the "
                             "report says so")
    parser.add_argument("--ood-n", type=non_negative_int, default=200, help="crops of --field-panorama (default 200)")
    parser.add_argument("--seed", type=non_negative_int, default=2024, help="crop seed (default 2024)")
    parser.add_argument("--cache-dir", default="data_cache", help="stadium panorama cache (default ./data_cache)")
    parser.add_argument("--threads", type=positive_int, help="onnxruntime threads (default: all cores)")
    return parser


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(
        "evaluate", help="evaluate the estimator on held-out stadium crops", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(parser)
    real = parser.add_argument_group("real frames (net, lines and auto side by side; glradial.evaluation.real_eval)")
    real.add_argument("--frames", metavar="DIR", help="instead: evaluate net, lines and auto on the (nearly) undistorted "
                      "real frames of DIR with known lenses applied (writes real.md to --out)")
    real.add_argument("--calibrated", metavar="JSON", action="append", default=[],
                      help="with --frames: also a calibrated camera (frames + known lens; see glradial.evaluation.real_eval)")
    real.add_argument("--broadcast", metavar="DIR",
                      help="also (or instead): the broadcast frames of DIR (CLIP_SEGMENT_FRAME.jpg, stored squashed, restored "
                           "to 1280x720), 3 known lenses each, scored self-consistently per clip (e.g. "
                           "../shared/data/broadcast_bundesliga)")
    real.add_argument("--procedural", type=non_negative_int, default=0, metavar="N",
                      help="with --frames: also N held-out procedural stadium crops (default 0)")
    real.add_argument("--remove-own-lens", action="store_true",
                      help="with --frames: first correct a frame whose own lens the line fit and the CNN agree on "
                           "(broadcast cameras are rarely pinhole), then apply the known lenses")
    return parser


def settings(args: argparse.Namespace, command: str):
    """The :class:`~glradial.evaluation.evaluation.EvaluationSettings` of parsed options."""
    from ..evaluation.evaluation import EvaluationSettings

    return EvaluationSettings(
        n=args.n, panoramas=args.test_panoramas, split=args.split, panorama_size=tuple(args.panorama_size),
        field_panorama=args.field_panorama, ood_n=args.ood_n, seed=args.seed, cache_dir=args.cache_dir, command=command,
    )


def run(args: argparse.Namespace) -> int:
    from ..estimation.net_lines import default_model_path
    from ..evaluation.evaluation import OnnxPredictor, evaluate, summary

    if args.frames or args.calibrated or args.broadcast:
        from ..evaluation.real_eval import evaluate_folder

        evaluate_folder(args.frames, args.out, calibrated=args.calibrated, procedural=args.procedural,
                        model=args.model, threads=args.threads, remove_own_lens=args.remove_own_lens,
                        broadcast=args.broadcast)
        print(f"wrote {args.out}/real.md", flush=True)
        return 0

    model = str(args.model or default_model_path())
    chosen = settings(args, "glradial evaluate")  # checks the options before the model loads
    predictor = OnnxPredictor(model, args.threads)
    result = evaluate(predictor, predictor.input_size, args.out, chosen, model)
    print(summary(args.out, result), flush=True)
    return 0
