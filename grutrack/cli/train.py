"""``grutrack train``: semi-supervised training of the GRU-Kalman filter."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grutrack.cli.common import add_dataset_args, seed
from grutrack.training.run import synthetic_inputs, write_training_yaml  # noqa: F401  (light; re-exported)

# Only argument definitions at module level: building the parser must not import numpy or torch
# (tests/test_cli_imports.py); the training itself is grutrack.training.run.train.


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack train``."""
    p = sub.add_parser(
        "train",
        help="train the GRU-Kalman filter (semi-supervised, EKF pseudo-labels)",
        description="Run the tracker online over the training scenes with the GRU-KF, associate "
        "tracks with ground truth, use a parallel EKF's posterior as pseudo-label "
        "where a track has none, one AdamW step per scene. Writes model.pt, last.pt "
        "(resumable) and train_log.csv into --out.",
    )
    add_dataset_args(p, "training split with ground truth (train, mini_train, ...; AV2: train, val, ...)")
    p.add_argument(
        "--detections",
        required=True,
        help="detections of the training split (real or simulated): nuScenes detection JSON, or an LT3D table for AV2",
    )
    p.add_argument("--config", default="grukf", help="training config name or YAML path (default: grukf)")
    p.add_argument("--out", required=True, help="output folder for checkpoints and the CSV log")
    p.add_argument(
        "--val-split",
        default=None,
        help="validation split, scored every val_every steps by the dataset's metric (nuScenes AMOTA, AV2 "
        "HOTA); default: the config's validation_scenes held out of --split",
    )
    p.add_argument("--val-detections", default=None, help="detections of the validation split")
    p.add_argument("--mode", choices=("semi_supervised", "supervised"), default=None, help="override the config's mode")
    p.add_argument("--epochs", type=int, default=None, help="override the config's epochs")
    p.add_argument("--val-every", type=int, default=None, help="override the config's val_every")
    p.add_argument("--seed", type=seed, default=None, help="override the config's seed")
    p.add_argument(
        "--source",
        action="append",
        default=[],
        metavar="MAPPING",
        help="one more training source, a YAML mapping such as '{dataset: av2, dataroot: AV2, split: "
        "val, profile: centerpoint, seed: 1}' or '{dataset: demo, scenes: 700, "
        "frames_per_scene: 40, split: demo_all, profile: centerpoint}' (repeatable; added to the "
        "config's sources; see grutrack/training/sources.py)",
    )
    p.add_argument(
        "--no-config-sources",
        action="store_true",
        help="leave out the config's sources (the default recipe's 700-scene SYNTHETIC demo): train on "
        "--split and any --source only, e.g. a quick run or real data at the paper's scale",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from --out/last.pt (a run stopped before it saved a step starts from the beginning)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Train (:func:`grutrack.training.run.train`); prints the final checkpoint and the last logged figures."""
    from grutrack.cli.common import dataset_of
    from grutrack.threads import apply_thread_policy
    from grutrack.training.config import load_train_config
    from grutrack.training.run import train
    from grutrack.training.sources import parse_source
    from grutrack.training.trainer import TrainingInterrupted

    overrides = {
        k: v
        for k, v in (("mode", args.mode), ("epochs", args.epochs), ("val_every", args.val_every), ("seed", args.seed))
        if v is not None
    }
    if args.no_config_sources:
        overrides["sources"] = []
    cfg = load_train_config(args.config, overrides, flags={k: "--" + k.replace("_", "-") for k in overrides})
    apply_thread_policy()
    sources = [parse_source(v, i + 1) for i, v in enumerate(args.source)]  # each checked: exit 2 naming the flag
    try:
        result = train(
            cfg,
            dataset_of(args),
            args.split,
            args.detections,
            args.out,
            config_arg=args.config,
            val_split=args.val_split,
            val_detections=args.val_detections,
            sources=sources,
            resume=args.resume,
            progress=not args.no_progress,
        )
    except TrainingInterrupted as exc:
        print(f"grutrack train: {exc}", file=sys.stderr)
        return 130
    except KeyboardInterrupt:  # a second Ctrl-C, or one before training began: nothing more was saved
        print(
            f"grutrack train: interrupted; --resume continues from {Path(args.out) / 'last.pt'} (from the "
            f"beginning where the run saved none)",
            file=sys.stderr,
        )
        return 130
    print(
        f"wrote {result.final} after {result.steps} steps (last loss {result.last_loss}); log: "
        f"{Path(args.out) / 'train_log.csv'}"
    )
    rec = result.validation
    if rec is not None:
        from grutrack.documents import SELECTION_RULES

        score = "n/a" if rec.selected_amota is None else f"{rec.selected_amota:.4f}"
        print(
            f"model.pt holds step {rec.selected_step} ({SELECTION_RULES[rec.rule]}): validation {result.metric} "
            f"{score}; {rec.reference} on the same scenes: {rec.reference_amota:.4f}"
        )
    return 0
