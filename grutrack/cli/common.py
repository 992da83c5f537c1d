"""Arguments shared by the sub-commands that read a dataset split, the one place a command turns them into a
dataset (:func:`dataset_of`), and argument types shared by several commands (:func:`seed`)."""

from __future__ import annotations

import argparse

from grutrack.datasets import DATASETS  # names only: the dataset modules are imported when one is opened

#: the largest seed: the simulators' random streams take a seed as 32 bits, so a larger or negative one would
#: alias another
MAX_SEED = 2**32 - 1


def seed(text: str) -> int:
    """``--seed`` values: an integer in [0, MAX_SEED] (argparse ``type``)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected an integer in [0, {MAX_SEED}], got {text!r}")
    return value


def add_dataset_args(p: argparse.ArgumentParser, split_help: str, repeat: bool = False) -> None:
    """--dataset, --dataroot, --version, --split (``repeat``: once or more, a list) and the AV2 reading options,
    as every dataset-reading command takes them."""
    p.add_argument("--dataset", default="nuscenes", choices=tuple(DATASETS), help="dataset (default: nuscenes)")
    p.add_argument(
        "--dataroot",
        required=True,
        help="nuScenes dataroot (holds <version>/) or AV2 sensor root (holds <split>/<log_id>/)",
    )
    p.add_argument("--version", default=None, help="nuScenes version, e.g. v1.0-trainval, v1.0-mini (nuScenes only)")
    p.add_argument("--split", required=True, help=split_help, **({"action": "append"} if repeat else {}))
    g = p.add_argument_group("av2 only")
    g.add_argument(
        "--rate",
        type=float,
        default=2.0,
        help="frames per second tracked and evaluated: annotation sweeps sub-sampled to this rate (default 2)",
    )
    g.add_argument(
        "--all-categories",
        action="store_true",
        help="all 26 AV2 competition categories (default: the 7 classes of Table I)",
    )


def dataset_of(args: argparse.Namespace):
    """The :class:`grutrack.datasets.Dataset` the arguments name."""
    from grutrack.datasets import DatasetOptions, open_dataset

    return open_dataset(
        args.dataset,
        DatasetOptions(
            dataroot=args.dataroot, version=args.version, rate_hz=args.rate, all_categories=args.all_categories
        ),
    )
