"""``grutrack track``: detections in, official tracking submission out."""

from __future__ import annotations

import argparse
import sys

from tqdm import tqdm

from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.export.nuscenes_json import build_submission, write_submission
from grutrack.tracking.factory import TRACKERS, build_tracker


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack track``."""
    p = sub.add_parser("track", help="track a detection file and write the official tracking submission",
                       description="Run the tracker over every scene of a split and write the official "
                                   "nuScenes tracking-submission JSON (validated, written atomically).")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot (holds <version>/)")
    p.add_argument("--version", required=True, help="dataset version, e.g. v1.0-trainval, v1.0-mini")
    p.add_argument("--split", required=True, help="split name: val, test, mini_val, ... or a custom split")
    p.add_argument("--detections", required=True, help="official nuScenes detection-submission JSON")
    p.add_argument("--tracker", default="ekf", choices=TRACKERS, help="tracker (default: ekf)")
    p.add_argument("--config", default=None,
                   help="tracker preset name or YAML path (default: the preset named like --tracker)")
    p.add_argument("--checkpoint", default=None, help="trained GRU-KF model (with --tracker grukf)")
    p.add_argument("--device", default="auto", help="torch device for grukf: auto (GPU when present), cpu, cuda")
    p.add_argument("--out", required=True, help="output submission JSON")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Load, track, export; the last line reports the tracking loop's frames/s."""
    nusc = open_nuscenes(args.dataroot, args.version)
    scenes = load_scenes(nusc, args.split)
    tokens = [f.token for s in scenes for f in s.frames]
    dets = load_detections(args.detections, tokens)
    tracker = build_tracker(args.tracker, args.config, checkpoint=args.checkpoint, device=args.device)
    with tqdm(total=len(tokens), unit="frame", desc=f"tracking {args.split}", disable=args.no_progress,
              file=sys.stderr) as bar:
        run_ = tracker_run(tracker, scenes, dets, bar.update)
    sub = build_submission(run_.results, tokens, tracker.cfg.max_boxes_per_sample)
    write_submission(args.out, sub, tokens)
    n_boxes = sum(len(v) for v in sub["results"].values())
    print(f"wrote {args.out}: {len(tokens)} samples, {n_boxes} boxes, {len(scenes)} scenes")
    print(f"tracking loop: {run_.frames} frames in {run_.seconds:.2f} s ({run_.fps:.1f} frames/s)")
    return 0


def tracker_run(tracker, scenes, dets, progress):
    """Run the tracker over the scenes (kept separate so tests can call it)."""
    from grutrack.tracking.tracker import track_scenes

    return track_scenes(tracker, scenes, dets, progress)
