"""``grutrack train``: semi-supervised training of the GRU-Kalman filter."""

from __future__ import annotations

import argparse
from pathlib import Path

from grutrack.errors import ConfigError

# Only argument definitions at module level: building the parser must not import numpy or torch
# (tests/test_cli_imports.py).


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack train``."""
    p = sub.add_parser("train", help="train the GRU-Kalman filter (semi-supervised, EKF pseudo-labels)",
                       description="Run the tracker online over the training scenes with the GRU-KF, associate "
                                   "tracks with ground truth, use a parallel EKF's posterior as pseudo-label "
                                   "where a track has none, one AdamW step per scene. Writes model.pt, last.pt "
                                   "(resumable) and train_log.csv into --out.")
    p.add_argument("--dataroot", required=True, help="nuScenes(-format) dataroot")
    p.add_argument("--version", required=True, help="dataset version, e.g. v1.0-trainval, v1.0-mini")
    p.add_argument("--split", required=True, help="training split with ground truth (train, mini_train, ...)")
    p.add_argument("--detections", required=True, help="detection JSON of the training split (real or simulated)")
    p.add_argument("--config", default="grukf", help="training config name or YAML path (default: grukf)")
    p.add_argument("--out", required=True, help="output folder for checkpoints and the CSV log")
    p.add_argument("--val-split", default=None, help="validation split for AMOTA every val_every steps")
    p.add_argument("--val-detections", default=None, help="detection JSON of the validation split")
    p.add_argument("--mode", choices=("semi_supervised", "supervised"), default=None,
                   help="override the config's mode")
    p.add_argument("--epochs", type=int, default=None, help="override the config's epochs")
    p.add_argument("--val-every", type=int, default=None, help="override the config's val_every")
    p.add_argument("--seed", type=int, default=None, help="override the config's seed")
    p.add_argument("--resume", action="store_true", help="continue from --out/last.pt")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Train; prints the final checkpoint and the last logged figures."""
    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.threads import apply_thread_policy
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer
    from grutrack.training.validation import make_validator

    overrides = {k: v for k, v in (("mode", args.mode), ("epochs", args.epochs), ("val_every", args.val_every),
                                   ("seed", args.seed)) if v is not None}
    cfg = load_train_config(args.config, overrides)
    apply_thread_policy()
    if (args.val_split is None) != (args.val_detections is None):
        raise ConfigError("--val-split and --val-detections go together")
    nusc = open_nuscenes(args.dataroot, args.version)
    scenes = load_scenes(nusc, args.split, with_gt=True)
    dets = load_detections(args.detections, [f.token for s in scenes for f in s.frames])
    validate = None
    trainer = Trainer(cfg, scenes, dets, args.out, progress=not args.no_progress)
    if args.val_split:
        val_scenes = load_scenes(nusc, args.val_split)
        val_dets = load_detections(args.val_detections, [f.token for s in val_scenes for f in s.frames])
        validate = make_validator(nusc, args.val_split, val_scenes, val_dets, trainer.tracker_cfg, cfg.device)
    trainer.validate = validate
    if args.resume:
        trainer.resume(Path(args.out) / "last.pt")
    final = trainer.run()
    last = trainer.log_rows[-1] if trainer.log_rows else {}
    print(f"wrote {final} after {trainer.state.step} steps (loss {last.get('loss')}, "
          f"val AMOTA {last.get('val_amota') or 'n/a'}); log: {Path(args.out) / 'train_log.csv'}")
    return 0
