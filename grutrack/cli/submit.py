"""``grutrack submit`` (a tracker output validated against the official format, written to its submission path
with a provenance manifest) and ``grutrack leaderboard-zip`` (the nuScenes leaderboard zip, validated first)."""

from __future__ import annotations

import argparse
import pickle
import shutil
from pathlib import Path

from grutrack.errors import ConfigError, InputFormatError
from grutrack.io import atomic_path
from grutrack.provenance import config_hash, file_record, sha256_file, write_manifest


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``submit`` and ``leaderboard-zip``."""
    p = sub.add_parser("submit", help="validate a tracker output and write the submission with a manifest",
                       description="Validate a tracker output against the official format (nuScenes: every sample "
                                   "of the split, field by field, and nuscenes-devkit's loader; AV2: the "
                                   "tracking-challenge pickle layout), write it to --out atomically and write a "
                                   "manifest naming the detections, checkpoint, tracker config (with its hash) "
                                   "and package version that produced it.")
    p.add_argument("--dataset", default="nuscenes", choices=("nuscenes", "av2"), help="dataset (default nuscenes)")
    p.add_argument("--tracks", required=True, help="tracker output (grutrack track --out)")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot or AV2 sensor root")
    p.add_argument("--version", default=None, help="nuScenes version")
    p.add_argument("--split", required=True, help="split")
    p.add_argument("--out", required=True, help="submission file to write")
    p.add_argument("--manifest", default=None, help="manifest JSON (default: <out stem>.manifest.json)")
    p.add_argument("--detections", required=True, help="detections the tracks were made from")
    p.add_argument("--tracker-config", required=True, help="resolved tracker preset YAML used")
    p.add_argument("--tracker", required=True, help="tracker name (ekf, grukf, greedy, ab3dmot)")
    p.add_argument("--checkpoint", default=None, help="GRU-KF model used (grukf)")
    p.add_argument("--code-version", default=None, help="code version of the tracking stage (from the workflow)")
    p.set_defaults(func=run_submit)

    p = sub.add_parser("leaderboard-zip", help="zip a nuScenes submission for the leaderboard (validated first)",
                       description="Validate a nuScenes tracking submission against the official format for the "
                                   "split (grutrack's checks and nuscenes-devkit's loader), then write a zip "
                                   "holding it, atomically.")
    p.add_argument("--submission", required=True, help="tracking submission JSON")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot")
    p.add_argument("--version", required=True, help="nuScenes version (v1.0-test for the test split)")
    p.add_argument("--split", required=True, help="split (test)")
    p.add_argument("--out", required=True, help="zip to write")
    p.set_defaults(func=run_zip)


def _split_tokens(dataroot: str, version: str | None, split: str) -> list[str]:
    """Sample tokens of a nuScenes split."""
    from grutrack.data.nuscenes import load_scenes, open_nuscenes

    if not version:
        raise ConfigError("--version is required for nuScenes")
    return [f.token for s in load_scenes(open_nuscenes(dataroot, version), split) for f in s.frames]


def _copy_av2(tracks: str, out: str) -> dict:
    """Check the AV2 pickle's layout ({log_id: [frame dict, ...]}) and copy it atomically."""
    try:
        with open(tracks, "rb") as f:
            seqs = pickle.load(f)
    except (OSError, pickle.UnpicklingError, EOFError) as exc:
        raise InputFormatError(f"{tracks}: cannot read the tracking pickle ({exc})") from exc
    if not isinstance(seqs, dict) or not all(isinstance(v, list) and all(isinstance(f, dict) for f in v)
                                             for v in seqs.values()):
        raise InputFormatError(f"{tracks}: expected {{log_id: [frame dict, ...]}} (AV2 tracking-challenge pickle)")
    with atomic_path(out) as tmp:
        shutil.copyfile(tracks, tmp)
    frames = sum(len(v) for v in seqs.values())
    boxes = sum(len(f.get("track_id", ())) for v in seqs.values() for f in v)
    return {"logs": len(seqs), "frames": frames, "boxes": boxes}


def run_submit(args: argparse.Namespace) -> int:
    """Validate, write, manifest."""
    if args.dataset == "nuscenes":
        from grutrack.export.leaderboard import write_validated

        counts = write_validated(args.tracks, _split_tokens(args.dataroot, args.version, args.split), args.out)
    else:
        counts = _copy_av2(args.tracks, args.out)
    import yaml

    cfg = yaml.safe_load(Path(args.tracker_config).read_text())
    manifest = args.manifest or str(Path(args.out).with_name(Path(args.out).stem + ".manifest.json"))
    write_manifest(manifest, {
        "code_version": args.code_version, "dataset": args.dataset, "dataroot": args.dataroot,
        "version": args.version, "split": args.split, "submission": file_record(args.out), **counts,
        "tracker": args.tracker,
        "tracker_config": {**file_record(args.tracker_config), "config_hash": config_hash(cfg)},
        "detections": file_record(args.detections), "checkpoint": file_record(args.checkpoint)})
    print(f"wrote {args.out} ({', '.join(f'{v} {k}' for k, v in counts.items())}) and {manifest}")
    return 0


def run_zip(args: argparse.Namespace) -> int:
    """Validate and zip."""
    from grutrack.export.leaderboard import build_zip

    info = build_zip(args.submission, _split_tokens(args.dataroot, args.version, args.split), args.out)
    print(f"wrote {args.out}: {info['member']} ({info['samples']} samples, {info['boxes']} boxes; validated), "
          f"sha256 {sha256_file(args.out)}")
    return 0
