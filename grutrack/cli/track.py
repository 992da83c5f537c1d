"""``grutrack track``: detections in, official tracking submission out (``--dataset nuscenes`` (default): the
nuScenes tracking JSON; ``--dataset av2``: the AV2 tracking-challenge pickle plus the same tracks as feather)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from grutrack.cli.common import add_dataset_args
from grutrack.errors import ConfigError
from grutrack.tracking.names import TRACKERS

# Only argument definitions at module level: building the parser must not import numpy, torch or the devkit
# (tests/test_cli_imports.py). Each run function imports what its dataset needs.

def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack track``."""
    p = sub.add_parser("track", help="track a detection file and write the official tracking submission",
                       description="Run the tracker over every scene of a split and write the official "
                                   "tracking submission (validated, written atomically): the nuScenes tracking "
                                   "JSON, or for --dataset av2 the AV2 tracking-challenge pickle and a feather "
                                   "table of the same tracks.")
    add_dataset_args(p, "split name: val, test, mini_val, ... or a custom split")
    p.add_argument("--detections", required=True,
                   help="nuScenes: official detection-submission JSON; av2: LT3D detections (.feather, .csv or a "
                        "pickled DataFrame), ego frame")
    p.add_argument("--tracker", default="ekf", choices=TRACKERS, help="tracker (default: ekf)")
    p.add_argument("--config", default=None,
                   help="tracker preset name or YAML path (default: the preset named like --tracker)")
    p.add_argument("--checkpoint", default=None, help="trained GRU-KF model (with --tracker grukf)")
    p.add_argument("--device", default="auto", help="torch device for grukf: auto (GPU when present), cpu, cuda")
    p.add_argument("--out", required=True, help="output submission: JSON (nuscenes) or pickle (av2)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    g = p.add_argument_group("av2 only")
    g.add_argument("--rate", type=float, default=2.0,
                   help="frames per second tracked: annotation sweeps sub-sampled to this rate (default 2)")
    g.add_argument("--all-categories", action="store_true",
                   help="track all 26 AV2 competition categories (default: the 7 classes of Table I)")
    g.add_argument("--feather", default=None, help="tracks as a feather table (default: --out with .feather)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Dispatch to the dataset's tracking run."""
    return {"nuscenes": run_nuscenes, "av2": run_av2}[args.dataset](args)


def run_nuscenes(args: argparse.Namespace) -> int:
    """Load, track, export; the last line reports the tracking loop's frames/s."""
    from tqdm import tqdm

    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.export.nuscenes_json import build_submission, write_submission
    from grutrack.threads import apply_thread_policy
    from grutrack.tracking.factory import build_tracker

    apply_thread_policy(torch_too=args.tracker == "grukf")
    if not args.version:
        raise ConfigError("--version is required with --dataset nuscenes (e.g. v1.0-trainval, v1.0-mini)")
    nusc = open_nuscenes(args.dataroot, args.version)
    scenes = load_scenes(nusc, args.split)
    tokens = [f.token for s in scenes for f in s.frames]
    tracker = build_tracker(args.tracker, args.config, checkpoint=args.checkpoint, device=args.device)
    dets = load_detections(args.detections, tokens, tracker.cfg.measured_yaw)
    with tqdm(total=len(tokens), unit="frame", desc=f"tracking {args.split}", disable=args.no_progress,
              file=sys.stderr) as bar:
        run_ = tracker_run(tracker, scenes, dets, bar.update)
    sub = build_submission(run_.results, tokens, tracker.cfg.max_boxes_per_sample)
    write_submission(args.out, sub, tokens)
    n_boxes = sum(len(v) for v in sub["results"].values())
    print(f"wrote {args.out}: {len(tokens)} samples, {n_boxes} boxes, {len(scenes)} scenes")
    print(f"tracking loop: {run_.frames} frames in {run_.seconds:.2f} s ({run_.fps:.1f} frames/s)")
    return 0


def run_av2(args: argparse.Namespace) -> int:
    """AV2: logs at ``--rate``, LT3D detections, tracking in the city frame, pickle + feather out."""
    from tqdm import tqdm

    from grutrack.data import av2
    from grutrack.data.lt3d_detections import load_detections as load_lt3d
    from grutrack.export.av2_tracks import write_tracks
    from grutrack.threads import apply_thread_policy
    from grutrack.tracking.factory import build_tracker

    apply_thread_policy(torch_too=args.tracker == "grukf")
    vocab = av2.vocabulary(args.all_categories)
    scenes = av2.load_scenes(args.dataroot, args.split, rate_hz=args.rate, all_categories=args.all_categories)
    dets, stats = load_lt3d(args.detections, args.dataroot, args.split, scenes, vocab)
    if stats.empty_logs:
        print(f"grutrack track: warning: {args.detections}: {len(stats.empty_logs)} of {len(scenes)} logs have no "
              f"detection of a tracked category (first: {stats.empty_logs[0]}); their tracks are empty "
              f"(is this the detection file of split '{args.split}'?)", file=sys.stderr)
    tracker = build_tracker(args.tracker, args.config, param_classes=vocab.param_classes,
                            checkpoint=args.checkpoint, device=args.device)
    n_frames = sum(len(s) for s in scenes)
    with tqdm(total=n_frames, unit="frame", desc=f"tracking av2 {args.split}", disable=args.no_progress,
              file=sys.stderr) as bar:
        run_ = tracker_run(tracker, scenes, dets, bar.update)
    feather = Path(args.feather) if args.feather else Path(args.out).with_suffix(".feather")
    seqs = write_tracks(args.out, feather, scenes, run_.results, vocab)
    n_boxes = sum(len(f["track_id"]) for fs in seqs.values() for f in fs)
    print(f"detections: {stats.rows} rows, {stats.kept} tracked, {stats.other_category} of untracked categories, "
          f"{stats.off_frame} at sweeps that are not tracked frames (dropped)")
    print(f"wrote {args.out} and {feather}: {len(scenes)} logs, {n_frames} frames at {args.rate:g} Hz, {n_boxes} boxes")
    print(f"tracking loop: {run_.frames} frames in {run_.seconds:.2f} s ({run_.fps:.1f} frames/s)")
    return 0


def tracker_run(tracker, scenes, dets, progress):
    """Run the tracker over the scenes (kept separate so tests can call it)."""
    from grutrack.tracking.tracker import track_scenes

    return track_scenes(tracker, scenes, dets, progress)
