"""Arguments shared by the sub-commands that read a dataset split."""

from __future__ import annotations

import argparse

DATASETS = ("nuscenes", "av2")


def add_dataset_args(p: argparse.ArgumentParser, split_help: str) -> None:
    """--dataset, --dataroot, --version and --split, as every dataset-reading command takes them."""
    p.add_argument("--dataset", default="nuscenes", choices=DATASETS, help="dataset (default: nuscenes)")
    p.add_argument("--dataroot", required=True,
                   help="nuScenes dataroot (holds <version>/) or AV2 sensor root (holds <split>/<log_id>/)")
    p.add_argument("--version", default=None, help="nuScenes version, e.g. v1.0-trainval, v1.0-mini (nuScenes only)")
    p.add_argument("--split", required=True, help=split_help)
