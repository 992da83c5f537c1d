"""``grutrack evaluate``: official tracking metrics of a submission, as a metrics JSON (``--dataset nuscenes``
(default): nuscenes-devkit TrackingEval or the fast evaluator; ``--dataset av2``: the official AV2 tracking
evaluation, HOTA)."""

from __future__ import annotations

import argparse

from grutrack.cli.common import add_dataset_args

# Only argument definitions at module level: building the parser must not import numpy or the devkit
# (tests/test_cli_imports.py); the fast evaluator's command never imports the devkit's NuScenes class.

EVALUATORS = ("devkit", "fast", "official")  # the datasets' evaluators (grutrack.datasets), for --help


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack evaluate``."""
    p = sub.add_parser(
        "evaluate",
        help="official tracking metrics of a submission",
        description="Score a tracking submission with the official nuScenes evaluation "
        "(tracking_nips_2019) or, with --dataset av2, the official AV2 tracking "
        "evaluation (HOTA, 50 m, drivable-area ROI), and write a metrics JSON "
        "(overall and per class).",
    )
    add_dataset_args(p, "split with ground truth: val, mini_val, ... or custom")
    p.add_argument("--submission", required=True, help="tracking submission: JSON (nuscenes) or pickle (av2)")
    p.add_argument("--out", required=True, help="metrics JSON to write")
    p.add_argument(
        "--evaluator",
        default=None,
        choices=EVALUATORS,
        help="nuscenes: devkit (nuscenes-devkit TrackingEval, the reference; the default) or fast "
        "(grutrack's exact vectorised re-implementation, what the workflow uses; `grutrack "
        "cross-check` compares the two); av2: official (the only one)",
    )
    g = p.add_argument_group("av2 only")
    g.add_argument("--max-range", type=int, default=50, help="evaluation range around the ego, metres (default 50)")
    g.add_argument(
        "--workers",
        type=int,
        default=None,
        help="worker processes of the evaluator (default: the cores this process may use)",
    )
    g.add_argument(
        "--trackeval-dir",
        default=None,
        help="keep TrackEval's summary files and curves in this folder (default: not written)",
    )
    p.set_defaults(func=run)
    add_cross_check_parser(sub)


def add_cross_check_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack cross-check``: both nuScenes evaluators on one submission, every entry compared."""
    p = sub.add_parser(
        "cross-check",
        help="the devkit and the fast evaluator on one submission, compared",
        description="Score a nuScenes tracking submission with nuscenes-devkit TrackingEval and "
        "with the fast exact evaluator, compare every entry of their metrics summaries "
        "and write the largest difference (a cross-check JSON). The devkit takes hours on "
        "a nuScenes-val-sized split: --scenes N scores N evenly spaced scenes of "
        "the split (both evaluators on the same ones). Exit status 1 when they differ "
        "by more than 1e-9.",
    )
    add_dataset_args(p, "split with ground truth: val, mini_val, ... or custom")
    p.add_argument("--submission", required=True, help="tracking submission JSON of the split")
    p.add_argument(
        "--scenes", type=int, default=None, help="compare on this many evenly spaced scenes of the split (default: all)"
    )
    p.add_argument("--out", required=True, help="cross-check JSON to write")
    p.set_defaults(func=run_cross_check)


def run_cross_check(args: argparse.Namespace) -> int:
    """Both evaluators, the comparison written and printed; 1 when they differ."""
    from grutrack.errors import ConfigError
    from grutrack.evaluation.crosscheck import cross_check
    from grutrack.threads import apply_thread_policy

    if args.dataset != "nuscenes":
        raise ConfigError(
            f"--dataset {args.dataset}: the cross-check compares nuScenes' two evaluators; {args.dataset} has one"
        )
    if not args.version:
        raise ConfigError("--version is required (e.g. v1.0-trainval, v1.0-mini)")
    if args.scenes is not None and args.scenes < 1:
        raise ConfigError(f"--scenes {args.scenes}: expected a positive number of scenes")
    apply_thread_policy(torch_too=False)
    doc = cross_check(args.dataroot, args.version, args.split, args.submission, args.scenes)
    doc.write(args.out)
    diff = "n/a (an entry differs in kind)" if doc.max_abs_difference is None else f"{doc.max_abs_difference:.3g}"
    print(
        f"devkit vs fast on {len(doc.scenes)} of {doc.split_scenes} scenes ({doc.samples} samples): "
        f"{doc.entries} entries, max |difference| {diff} ({doc.worst_entry}); "
        f"{'EQUAL' if doc.equal else 'DIFFERENT'} at {doc.tolerance:g}; AMOTA devkit {doc.amota['devkit']} "
        f"fast {doc.amota['fast']}; {doc.seconds['devkit']:.1f} s / {doc.seconds['fast']:.1f} s"
    )
    print(f"wrote {args.out}")
    return 0 if doc.equal else 1


def run(args: argparse.Namespace) -> int:
    """Evaluate with the dataset's evaluator, write the metrics JSON, print a summary table; under the toolkit's
    thread policy, so that the evaluators' sums run in the same order however the command is started and the
    same submission gives the same figures to the last digit (multi-threaded BLAS reductions differ in their
    last bits)."""
    from grutrack.cli.common import dataset_of
    from grutrack.threads import apply_thread_policy

    apply_thread_policy(torch_too=False)
    ds = dataset_of(args)
    doc = ds.evaluate(
        args.submission,
        args.split,
        args.evaluator,
        max_range_m=args.max_range,
        workers=args.workers,
        trackeval_dir=args.trackeval_dir,
    )
    doc.write(args.out)
    if ds.is_synthetic():
        print(f"SYNTHETIC data: the scenes and ground truth of {args.dataroot} are grutrack's demo dataset")
    print(ds.format_summary(doc))
    how = f"{doc.evaluator} evaluator"
    if doc.settings:
        how += (
            f", ROI {'on' if doc.settings.get('drivable_area_roi') else 'off'}, {doc.settings.get('workers')} worker(s)"
        )
    print(f"wrote {args.out} ({how}, {doc.seconds:.1f} s)")
    return 0
