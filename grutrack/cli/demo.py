"""Sub-commands of the embedded default: ``demo-data`` (a SYNTHETIC nuScenes-format dataset),
``simulate-detections`` (detector-like detections from any split's ground truth) and ``dataset-stats``
(per-class statistics of a dataset, optionally side by side with another)."""

from __future__ import annotations

import argparse
from pathlib import Path

from grutrack.cli.common import add_dataset_args, dataset_of, seed
from grutrack.errors import InputFormatError
from grutrack.io import read_json


def add_parser(subparsers) -> None:
    """Register ``demo-data``, ``simulate-detections`` and ``dataset-stats``."""
    from grutrack.data.demo_defaults import DEFAULT_SCENES, FRAMES_PER_SCENE, VERSION

    p = subparsers.add_parser(
        "demo-data",
        help="write the SYNTHETIC nuScenes-format demo dataset",
        description="Generate a synthetic dataset in nuScenes table format (devkit-loadable, "
        "custom splits demo_train / demo_val / demo_all). Deterministic per seed.",
    )
    p.add_argument("--out", required=True, help="dataroot to write (replaced if it is a previous demo)")
    p.add_argument("--scenes", type=int, default=DEFAULT_SCENES, help=f"number of scenes (default {DEFAULT_SCENES})")
    p.add_argument(
        "--frames-per-scene",
        type=int,
        default=FRAMES_PER_SCENE,
        help=f"keyframes per scene at 2 Hz (default {FRAMES_PER_SCENE})",
    )
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--version", default=VERSION, help=f"version folder name (default {VERSION})")
    p.set_defaults(func=run_demo_data)

    p = subparsers.add_parser(
        "simulate-detections",
        help="simulate detector output from ground truth",
        description="Sample SYNTHETIC detections from the ground truth of a split with a "
        "detector profile, in the format the dataset's detections come in: "
        "nuScenes, the official detection-submission JSON; av2, an LT3D "
        "detection table (feather, ego frame) at the tracked frames (--rate).",
    )
    add_dataset_args(p, "split name (predefined, or from <version>/splits.json for nuScenes)")
    p.set_defaults(version=VERSION)
    p.add_argument(
        "--profile",
        default="centerpoint",
        help="detector profile: a shipped name (centerpoint, pointpillars, centerpoint_velfail, "
        "centerpoint_drift) or a YAML path",
    )
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="detection JSON to write")
    p.set_defaults(func=run_simulate)

    p = subparsers.add_parser(
        "dataset-stats",
        help="per-class statistics of a dataset's ground truth",
        description="Box share, mean size, speed, moving share, |yaw rate|, 0-point share per "
        "tracking class, over the union of the given splits.",
    )
    add_dataset_args(p, "split name; repeat for a union", repeat=True)
    p.set_defaults(version=VERSION)
    p.add_argument("--json", dest="json_out", help="also write the statistics to this JSON file")
    p.add_argument("--compare", help="statistics JSON (from --json) to print side by side")
    p.set_defaults(func=run_stats)


def run_demo_data(args: argparse.Namespace) -> int:
    """``grutrack demo-data``."""
    from grutrack.data.demo import generate_demo

    summary = generate_demo(
        args.out, scenes=args.scenes, frames=args.frames_per_scene, seed=args.seed, version=args.version
    )
    verb = "already up to date (left untouched):" if summary["unchanged"] else "wrote"
    print(
        f"{verb} SYNTHETIC demo dataset {summary['dataroot']}/{summary['version']}: {summary['scenes']} scenes, "
        f"{summary['samples']} samples, {summary['instances']} instances, {summary['annotations']} annotations; "
        f"splits " + ", ".join(f"{k} ({v} scenes)" for k, v in summary["splits"].items())
    )
    return 0


def run_simulate(args: argparse.Namespace) -> int:
    """``grutrack simulate-detections``."""
    from grutrack.data.detection_sim import load_profile

    profile = load_profile(args.profile)
    ds = dataset_of(args)
    counts = ds.simulate_detections(args.split, profile, args.seed, args.out)
    print(
        f"wrote {args.out}: {counts.pop('detections')} SYNTHETIC detections ({profile.name}, seed {args.seed}) "
        f"on {', '.join(f'{v} {k}' for k, v in counts.items())}, split {args.split} of {ds.describe()}"
    )
    return 0


def run_stats(args: argparse.Namespace) -> int:
    """``grutrack dataset-stats``."""
    from grutrack.data.gt_stats import format_comparison, format_table, write_stats_json

    ds = dataset_of(args)
    stats = ds.gt_statistics(args.split)
    label = f"{Path(args.dataroot).name}: {ds.describe()} {'+'.join(args.split)}"
    print(format_table(stats, title=f"ground truth of {label}, {len(stats) - 1} classes"))
    if args.json_out:
        write_stats_json(
            args.json_out,
            stats,
            {"dataset": ds.name, "dataroot": str(args.dataroot), "version": args.version, "splits": args.split},
        )
        print(f"wrote {args.json_out}")
    if args.compare:
        ref = _read_stats(Path(args.compare))
        print()
        print(f"this dataset ({label}) vs {args.compare}")
        print(format_comparison(stats, ref["classes"], ("this", "ref")))
    return 0


def _read_stats(path: Path) -> dict:
    """A statistics JSON written by ``dataset-stats --json`` (NaN stored as null)."""
    data = read_json(path, "statistics file (write one with dataset-stats --json)")
    if not isinstance(data, dict) or not isinstance(data.get("classes"), dict):
        raise InputFormatError(f"{path}: expected an object with 'classes' (written by dataset-stats --json)")
    return {
        "classes": {
            c: {k: (float("nan") if v is None else v) for k, v in row.items()} for c, row in data["classes"].items()
        }
    }
