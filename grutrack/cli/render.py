"""``grutrack render``: bird's-eye frames of a tracking run with the evaluator's own decisions (TP, FP, missed
ground truth, id switches) marked; PNG per frame, a GIF per scene and ``counts.json``."""

from __future__ import annotations

import argparse

from grutrack.cli.common import add_dataset_args
from grutrack.errors import ConfigError


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack render``."""
    p = sub.add_parser(
        "render",
        help="bird's-eye renders of tracks with the evaluator's decisions",
        description="Draw each frame of the chosen scenes (nuScenes) or logs (AV2) from above "
        "(ego-centred, fixed scale, range rings): ground truth, raw detections, tracks "
        "coloured by id with a trail and a heading mark, and the evaluation's own "
        "matching (nuScenes: per class at its best-MOTA threshold, 2 m centre distance; "
        "AV2: the official evaluator's CLEAR matching at the tuned score thresholds): "
        "false-positive tracks, missed ground truth and id switches, with the frame's "
        "counts. Writes DIR/<scene>/frame_NNN.png (NNN from 001), DIR/<scene>.gif and "
        "DIR/counts.json.",
    )
    add_dataset_args(p, "split with ground truth: val, mini_val, ... or custom")
    p.add_argument("--submission", required=True, help="tracking submission: JSON (nuscenes) or pickle (av2)")
    p.add_argument(
        "--detections",
        default=None,
        help="detections drawn faint: detection submission JSON (nuscenes) or LT3D table (av2)",
    )
    which = p.add_mutually_exclusive_group(required=True)
    which.add_argument("--scene", nargs="+", metavar="NAME", help="scene name(s), e.g. scene-0103, or AV2 log id(s)")
    which.add_argument(
        "--worst", type=int, metavar="K", help="the K scenes with the most id switches + false positives + misses"
    )
    p.add_argument("--no-animation", action="store_true", help="PNG frames only, no GIF")
    p.add_argument(
        "--rerun",
        action="store_true",
        help="also write DIR/<scene>.rrd, a Rerun recording for interactive 3D viewing "
        "(optional: pip install grutrack[rerun])",
    )
    p.add_argument("--out", required=True, help="output folder")
    g = p.add_argument_group("av2 only (as grutrack evaluate --dataset av2)")
    g.add_argument("--max-range", type=int, default=50, help="evaluation range around the ego, metres (default 50)")
    g.add_argument(
        "--workers",
        type=int,
        default=1,
        help="worker processes of the evaluator's threshold tuning (default 1; same counts)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render and print where the files went."""
    if args.worst is not None and args.worst < 1:
        raise ConfigError("--worst must be at least 1")
    if args.rerun:  # before any work: the optional package may be missing
        from grutrack.render.rerun_log import import_rerun

        import_rerun()
    if args.max_range < 1:
        raise ConfigError(f"--max-range must be a positive number of metres, got {args.max_range}")
    if args.workers < 1:
        raise ConfigError("--workers must be at least 1")
    from grutrack.cli.common import dataset_of
    from grutrack.render import render
    from grutrack.threads import apply_thread_policy

    apply_thread_policy(torch_too=False)  # the evaluation's sums as `grutrack evaluate` makes them
    doc = render(
        dataset_of(args),
        args.split,
        args.submission,
        args.out,
        scene_names=args.scene,
        worst=args.worst,
        detections=args.detections,
        animation=not args.no_animation,
        rerun=args.rerun,
        max_range_m=args.max_range,
        workers=args.workers,
    )
    for s in doc["scenes"]:
        print(
            f"{s['name']}: {len(s['frames'])} frames, {s['errors']} IDS + FP + FN"
            + (f", {s['animation']}" if s["animation"] else "")
            + (f", {s['rerun']}" if s.get("rerun") else "")
        )
    print(f"wrote {args.out}/counts.json ({doc['seconds']:.1f} s)")
    return 0
