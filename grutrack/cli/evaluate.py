"""``grutrack evaluate``: official tracking metrics of a submission, as a metrics JSON (``--dataset nuscenes``
(default): nuscenes-devkit TrackingEval or the fast evaluator; ``--dataset av2``: the official AV2 tracking
evaluation, HOTA)."""

from __future__ import annotations

import argparse

from grutrack.cli.common import add_dataset_args

# Only argument definitions at module level: building the parser must not import numpy or the devkit
# (tests/test_cli_imports.py); the fast evaluator's command never imports the devkit's NuScenes class.

EVALUATORS = ("devkit", "fast", "official")   # the datasets' evaluators (grutrack.datasets), for --help


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
    g.add_argument("--max-range", type=int, default=50, help="evaluation range around the ego, metres (default 50)")
    g.add_argument("--workers", type=int, default=None,
                   help="worker processes of the evaluator (default: the cores this process may use)")
    g.add_argument("--trackeval-dir", default=None,
                   help="keep TrackEval's summary files and curves in this folder (default: not written)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate with the dataset's evaluator, write the metrics JSON, print a summary table; under the toolkit's
    thread policy, so that the evaluators' sums run in the same order however the command is started and the
    same submission gives the same figures to the last digit (multi-threaded BLAS reductions differ in their
    last bits)."""
    from grutrack.cli.common import dataset_of
    from grutrack.threads import apply_thread_policy

    apply_thread_policy(torch_too=False)
    ds = dataset_of(args)
    doc = ds.evaluate(args.submission, args.split, args.evaluator, max_range_m=args.max_range,
                      workers=args.workers, trackeval_dir=args.trackeval_dir)
    doc.write(args.out)
    print(ds.format_summary(doc))
    how = f"{doc.evaluator} evaluator"
    if doc.settings:
        how += (f", ROI {'on' if doc.settings.get('drivable_area_roi') else 'off'}, "
                f"{doc.settings.get('workers')} worker(s)")
    print(f"wrote {args.out} ({how}, {doc.seconds:.1f} s)")
    return 0
