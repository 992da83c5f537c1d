"""``grutrack track``: detections in, official tracking submission out (``--dataset nuscenes`` (default): the
nuScenes tracking JSON; ``--dataset av2``: the AV2 tracking-challenge pickle plus the same tracks as feather)."""

from __future__ import annotations

import argparse
import sys

from grutrack.cli.common import add_dataset_args
from grutrack.tracking.names import TRACKERS

# Only argument definitions at module level: building the parser must not import numpy, torch or the devkit
# (tests/test_cli_imports.py). The dataset (grutrack.datasets) imports what it needs when it is used.


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack track``."""
    p = sub.add_parser(
        "track",
        help="track a detection file and write the official tracking submission",
        description="Run the tracker over every scene of a split and write the official "
        "tracking submission (validated, written atomically): the nuScenes tracking "
        "JSON, or for --dataset av2 the AV2 tracking-challenge pickle and a feather "
        "table of the same tracks.",
    )
    add_dataset_args(p, "split name: val, test, mini_val, ... or a custom split")
    p.add_argument(
        "--detections",
        required=True,
        help="nuScenes: official detection-submission JSON; av2: LT3D detections (.feather, .csv or a "
        "pickled DataFrame), ego frame",
    )
    p.add_argument(
        "--tracker",
        default="ekf",
        choices=TRACKERS,
        help="the motion model of a track: ekf (the preset's per-class EKF / KF), grukf (the GRU-KF), greedy (the "
        "last detection carried at its own velocity), ab3dmot (a KF whose velocity starts at 0); the preset "
        "(--config) sets pre-processing, association, lifecycle and output, so --tracker greedy --config polymot "
        "is Poly-MOT's association over greedy tracks (default: ekf)",
    )
    p.add_argument(
        "--config", default=None, help="tracker preset name or YAML path (default: the preset named like --tracker)"
    )
    p.add_argument(
        "--checkpoint",
        default=None,
        help="trained GRU-KF model (with --tracker grukf; default: the shipped pretrained network, "
        "grutrack/pretrained/grukf_default/model.pt)",
    )
    p.add_argument(
        "--device",
        default="auto",
        help="torch device for grukf: auto (the CPU; docs/results/lockstep.md#gpu), cpu, cuda",
    )
    p.add_argument(
        "--out",
        required=True,
        help="output submission: JSON (nuscenes; its meta is the detection file's) or pickle (av2; a "
        "feather table of the same tracks is written beside it, .feather)",
    )
    p.add_argument(
        "--config-out",
        default=None,
        help="where to write the resolved tracker config this run used, what `grutrack submit` and "
        "`grutrack manifest` record (default: <out stem>.tracker.yaml beside --out, where they "
        "look for it; 'none': not written)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Load the split and its detections, track, write the dataset's submission; the last line reports the
    tracking loop's frames/s."""
    from tqdm import tqdm

    from grutrack.cli.common import dataset_of
    from grutrack.threads import apply_thread_policy
    from grutrack.tracking.factory import build_tracker

    apply_thread_policy(torch_too=args.tracker == "grukf")
    shipped = args.tracker == "grukf" and args.checkpoint is None
    if shipped:
        from grutrack.training.pretrained import pretrained_dir

        args.checkpoint = str(pretrained_dir("grukf_default") / "model.pt")
    ds = dataset_of(args)
    scenes = ds.scenes(args.split)
    tracker = build_tracker(
        args.tracker,
        args.config,
        param_classes=ds.vocabulary.param_classes,
        checkpoint=args.checkpoint,
        device=args.device,
    )
    if shipped:  # said once the run is set up, so that a refused input stays one line
        print(f"grutrack track: no --checkpoint: the shipped pretrained network {args.checkpoint}", file=sys.stderr)
    dets = ds.load_detections(args.detections, args.split, scenes, tracker.cfg.measured_yaw)
    for line in dets.warnings:
        print(f"grutrack track: warning: {line}", file=sys.stderr)
    from grutrack.warmup import cold_cache_notice

    cold_cache_notice()  # a plain pip install: the first run compiles the kernels; say so
    n_frames = sum(len(s) for s in scenes)
    with tqdm(
        total=n_frames, unit="frame", desc=f"tracking {ds.name} {args.split}", disable=args.no_progress, file=sys.stderr
    ) as bar:
        run_ = tracker_run(tracker, scenes, dets.boxes, bar.update)
    counts = ds.write_tracks(args.out, scenes, run_.results, tracker.cfg.max_boxes_per_sample, meta=dets.meta)
    config_out = write_used_config(args, tracker.cfg.matched_box)
    if dets.summary:
        print(dets.summary)
    print(
        f"wrote {args.out}: {', '.join(f'{v} {k}' for k, v in counts.items())}"
        + (f"; tracker config {config_out}" if config_out else "")
    )
    print(
        f"tracking loop: {run_.frames} frames in {run_.seconds:.2f} s ({run_.fps:.1f} frames/s); "
        f"tracker start {run_.start_seconds:.2f} s"
    )
    return 0


def write_used_config(args: argparse.Namespace, matched_box: str) -> str | None:
    """Write the tracker config the run used (``--config-out``, default beside ``--out``) atomically, as
    ``resolve-config tracker`` writes one; returns its path (None with ``--config-out none``)."""
    from grutrack.pipeline.presets import used_config_path, used_tracker_config, write_config
    from grutrack.tracking.factory import DEFAULT_PRESET

    if args.config_out == "none":
        return None
    out = args.config_out or str(used_config_path(args.out))
    origin = (
        f"the config grutrack track --tracker {args.tracker} ran, preset "
        f"'{args.config or DEFAULT_PRESET[args.tracker]}'"
        + (" with the checkpoint's output.matched_box" if args.tracker == "grukf" and not args.config else "")
    )
    write_config(out, "tracker", used_tracker_config(args.tracker, args.config, matched_box), origin)
    return out


def tracker_run(tracker, scenes, dets, progress):
    """Run the tracker over the scenes (kept separate so tests can call it)."""
    from grutrack.tracking.tracker import track_scenes

    return track_scenes(tracker, scenes, dets, progress)
