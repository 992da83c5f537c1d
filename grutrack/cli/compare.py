"""``grutrack compare-tracks``: a tracking submission against a reference one, box for box (a reproduced tracker
against the original code's own output); exits 1 when they differ."""

from __future__ import annotations

import argparse

from grutrack.cli.common import add_dataset_args
from grutrack.errors import ConfigError, InputFormatError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``compare-tracks``."""
    p = sub.add_parser(
        "compare-tracks",
        help="compare a tracking submission with a reference one, box for box",
        description="Pair every box of a reference nuScenes tracking submission with a box of the "
        "same class in the submission (centre and size within --tolerance metres), "
        "per sample, and compare box counts, scores, yaws and the partition of boxes "
        "into tracks (tracking ids may differ and may restart per scene; velocity, "
        "pitch / roll and meta are not compared). Exit status 0 when identical, 1 "
        "otherwise.",
    )
    add_dataset_args(p, "split whose samples are compared: mini_val, val, ... or a custom split")
    p.add_argument("--reference", required=True, help="reference tracking submission (JSON)")
    p.add_argument("--submission", required=True, help="tracking submission to check (JSON)")
    p.add_argument("--tolerance", type=float, default=1e-6, help="metres (and radians for yaw); default 1e-6")
    p.set_defaults(func=run)


def _results(path: str) -> dict:
    """A tracking submission, checked against the format's description (any samples: the comparison pairs the
    split's)."""
    from grutrack.export.nuscenes_json import check_document
    from grutrack.io import read_json

    doc = read_json(path, "tracking submission")
    check_document(doc, path)
    return doc


def run(args: argparse.Namespace) -> int:
    """Print the comparison's figures; 0 when identical, else 1."""
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.evaluation.track_parity import compare_tracks

    if args.dataset != "nuscenes" or not args.version:
        raise ConfigError("compare-tracks needs --dataset nuscenes and --version (e.g. v1.0-mini)")
    if not args.tolerance > 0:
        raise ConfigError(f"--tolerance must be a positive number of metres, got {args.tolerance}")
    scenes = load_scenes(open_nuscenes(args.dataroot, args.version), args.split)
    ref, ours = _results(args.reference), _results(args.submission)
    try:
        parity = compare_tracks(ref, ours, {f.token: s.token for s in scenes for f in s.frames}, args.tolerance)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputFormatError(
            f"{args.reference} / {args.submission}: a box lacks a well-formed field "
            f"(translation, size, rotation, tracking_id, tracking_name, tracking_score): "
            f"{exc}"
        ) from exc
    print(parity.summary())
    print("identical" if parity.identical else "different")
    return 0 if parity.identical else 1
