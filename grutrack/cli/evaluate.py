"""``grutrack evaluate``: official nuScenes tracking metrics of a submission, as a metrics JSON."""

from __future__ import annotations

import argparse
import json
import time

from grutrack.data.nuscenes import open_nuscenes, split_scene_names
from grutrack.errors import InputFormatError
from grutrack.evaluation.nuscenes_eval import (devkit_tracking_eval, format_summary, metrics_document,
                                               write_metrics)

EVALUATORS = ("devkit", "fast")


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack evaluate``."""
    p = sub.add_parser("evaluate", help="official tracking metrics of a submission",
                       description="Score a tracking submission with the official nuScenes evaluation "
                                   "(tracking_nips_2019) and write a metrics JSON (overall and per class).")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot (holds <version>/)")
    p.add_argument("--version", required=True, help="dataset version, e.g. v1.0-trainval, v1.0-mini")
    p.add_argument("--split", required=True, help="split with ground truth: val, mini_val, ... or custom")
    p.add_argument("--submission", required=True, help="tracking-submission JSON")
    p.add_argument("--out", required=True, help="metrics JSON to write")
    p.add_argument("--evaluator", default="devkit", choices=EVALUATORS,
                   help="devkit: nuscenes-devkit TrackingEval (reference); fast: grutrack's exact vectorised "
                        "re-implementation (default: devkit)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate, write the metrics JSON, print a summary table."""
    nusc = open_nuscenes(args.dataroot, args.version)
    split_scene_names(nusc, args.split)  # clear error for an unknown split before the devkit asserts
    t0 = time.perf_counter()
    if args.evaluator == "devkit":
        _check_submission_tokens(nusc, args.split, args.submission)
        summary = devkit_tracking_eval(args.dataroot, args.version, args.split, args.submission)
    else:
        from grutrack.evaluation.fast_amota import fast_tracking_eval

        summary = fast_tracking_eval(nusc, args.submission, args.split)
    doc = metrics_document(summary, dataset="nuscenes", version=args.version, split=args.split,
                           evaluator=args.evaluator, submission=args.submission)
    doc["seconds"] = round(time.perf_counter() - t0, 3)
    write_metrics(args.out, doc)
    print(format_summary(doc))
    print(f"wrote {args.out} ({args.evaluator} evaluator, {doc['seconds']:.1f} s)")
    return 0


def _check_submission_tokens(nusc, split: str, path: str) -> None:
    """Fail with a clear message when the submission does not hold exactly the split's samples."""
    from grutrack.data.nuscenes import load_scenes

    try:
        res = json.loads(open(path).read())["results"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputFormatError(f"{path}: not a tracking submission with a 'results' object ({exc})") from exc
    tokens = {f.token for s in load_scenes(nusc, split) for f in s.frames}
    missing, extra = tokens - set(res), set(res) - tokens
    if missing or extra:
        raise InputFormatError(f"{path}: 'results' must hold exactly the {len(tokens)} samples of split "
                               f"'{split}' ({len(missing)} missing, {len(extra)} from other splits)")
