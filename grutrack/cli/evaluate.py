"""``grutrack evaluate``: official tracking metrics of a submission, as a metrics JSON (``--dataset nuscenes``
(default): nuscenes-devkit TrackingEval or the fast evaluator; ``--dataset av2``: the official AV2 tracking
evaluation, HOTA)."""

from __future__ import annotations

import argparse
import sys
import time

from grutrack.cli.common import add_dataset_args
from grutrack.errors import ConfigError

# Only argument definitions at module level: building the parser must not import numpy or the devkit
# (tests/test_cli_imports.py); the fast evaluator's command never imports the devkit's NuScenes class.

EVALUATORS = ("devkit", "fast", "official")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack evaluate``."""
    p = sub.add_parser("evaluate", help="official tracking metrics of a submission",
                       description="Score a tracking submission with the official nuScenes evaluation "
                                   "(tracking_nips_2019) or, with --dataset av2, the official AV2 tracking "
                                   "evaluation (HOTA, 50 m, drivable-area ROI), and write a metrics JSON "
                                   "(overall and per class).")
    add_dataset_args(p, "split with ground truth: val, mini_val, ... or custom")
    p.add_argument("--submission", required=True, help="tracking submission: JSON (nuscenes) or pickle (av2)")
    p.add_argument("--out", required=True, help="metrics JSON to write")
    p.add_argument("--evaluator", default=None, choices=EVALUATORS,
                   help="nuscenes: devkit (nuscenes-devkit TrackingEval, reference, the default) or fast "
                        "(grutrack's exact vectorised re-implementation); av2: official (the only one)")
    g = p.add_argument_group("av2 only")
    g.add_argument("--rate", type=float, default=2.0, help="evaluated frame rate of the labels (default 2 Hz)")
    g.add_argument("--max-range", type=int, default=50, help="evaluation range around the ego, metres (default 50)")
    g.add_argument("--workers", type=int, default=None,
                   help="worker processes of the evaluator (default: the cores this process may use)")
    g.add_argument("--trackeval-dir", default=None,
                   help="keep TrackEval's summary files and curves in this folder (default: not written)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Dispatch to the dataset's evaluation, under the toolkit's thread policy: the evaluators' sums then run
    in the same order however the command is started, so the same submission gives the same figures to the
    last digit (multi-threaded BLAS reductions differ in their last bits)."""
    from grutrack.threads import apply_thread_policy

    apply_thread_policy(torch_too=False)
    return {"nuscenes": run_nuscenes, "av2": run_av2}[args.dataset](args)


def run_av2(args: argparse.Namespace) -> int:
    """AV2: official evaluation of a tracking pickle; metrics JSON with the Table I average."""
    from grutrack.evaluation import av2_eval

    if args.evaluator not in (None, "official"):
        raise ConfigError(f"--evaluator {args.evaluator} is for nuScenes; AV2 has the official evaluator only")
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers must be at least 1")
    doc = av2_eval.evaluate_submission(args.dataroot, args.split, args.submission, rate_hz=args.rate,
                                       max_range_m=args.max_range, workers=args.workers,
                                       trackeval_dir=args.trackeval_dir)
    doc.write(args.out)
    print(av2_eval.format_summary(doc))
    print(f"wrote {args.out} (official AV2 evaluator, ROI {'on' if doc.settings['drivable_area_roi'] else 'off'}"
          f", {doc.settings['workers']} worker(s), {doc.seconds:.1f} s)")
    return 0


def run_nuscenes(args: argparse.Namespace) -> int:
    """Evaluate, write the metrics JSON, print a summary table."""
    from grutrack.data.nuscenes import open_nuscenes, split_scene_names
    from grutrack.evaluation.nuscenes_eval import devkit_tracking_eval, format_summary, metrics_document

    if not args.version:
        raise ConfigError("--version is required with --dataset nuscenes (e.g. v1.0-trainval, v1.0-mini)")
    args.evaluator = args.evaluator or "devkit"
    if args.evaluator not in ("devkit", "fast"):
        raise ConfigError(f"--evaluator {args.evaluator} is for AV2; nuScenes has devkit and fast")
    nusc = open_nuscenes(args.dataroot, args.version)
    split_scene_names(nusc, args.split)  # clear error for an unknown split before the devkit asserts
    t0 = time.perf_counter()
    sub = _valid_submission(nusc, args.split, args.submission)   # the checks leaderboard-zip makes
    if args.evaluator == "devkit":
        summary = devkit_tracking_eval(args.dataroot, args.version, args.split, args.submission,
                                       progress=sys.stderr.isatty())
    else:
        from grutrack.evaluation.fast_amota import fast_tracking_eval

        summary = fast_tracking_eval(nusc, sub, args.split)
    doc = metrics_document(summary, dataset="nuscenes", version=args.version, split=args.split,
                           evaluator=args.evaluator, submission=args.submission)
    doc.seconds = round(time.perf_counter() - t0, 3)
    doc.write(args.out)
    print(format_summary(doc))
    print(f"wrote {args.out} ({args.evaluator} evaluator, {doc.seconds:.1f} s)")
    return 0


def _valid_submission(nusc, split: str, path: str) -> dict:
    """The submission, checked against the official format for exactly the split's samples (one-line
    :class:`InputFormatError` otherwise, as ``leaderboard-zip`` gives)."""
    from grutrack.data.nuscenes import load_scenes
    from grutrack.export.leaderboard import load_valid_submission

    return load_valid_submission(path, [f.token for s in load_scenes(nusc, split) for f in s.frames])
