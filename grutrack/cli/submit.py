"""``grutrack submit`` (a tracker output validated against the official format, written to its submission path
with a provenance manifest) and ``grutrack leaderboard-zip`` (the nuScenes leaderboard zip, validated first)."""

from __future__ import annotations

import argparse

from grutrack.cli.common import add_dataset_args, dataset_of
from grutrack.documents import FileRecord, Manifest
from grutrack.errors import ConfigError
from grutrack.provenance import config_hash, sha256_file


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``submit`` and ``leaderboard-zip``."""
    p = sub.add_parser(
        "submit",
        help="validate a tracker output and write the submission with a manifest",
        description="Validate a tracker output against the official format (nuScenes: every sample "
        "of the split, field by field, and nuscenes-devkit's loader; AV2: the "
        "tracking-challenge pickle layout, exactly the split's frames at --rate), write it to --out atomically "
        "and write a manifest naming the detections, checkpoint, tracker config (with its hash) "
        "and package version that produced it.",
    )
    add_dataset_args(p, "split the tracks are for")
    p.add_argument("--tracks", required=True, help="tracker output (grutrack track --out)")
    p.add_argument("--out", required=True, help="submission file to write")
    p.add_argument(
        "--manifest",
        default=None,
        help="manifest JSON (default: <out stem>.manifest.json; 'none': write no manifest, and the "
        "provenance arguments below are not needed)",
    )
    _provenance_args(p, required=False, beside="--tracks")
    p.set_defaults(func=run_submit)

    p = sub.add_parser(
        "manifest",
        help="write the provenance manifest of a submission (checked first)",
        description="Check a submission against the official format for the split and write the "
        "manifest naming its hash and counts and the detections, checkpoint, tracker "
        "config (with its hash) and package version that produced it (what `grutrack "
        "submit` writes beside the submission).",
    )
    add_dataset_args(p, "split of the submission")
    p.add_argument("--submission", required=True, help="the submission (grutrack submit --out)")
    p.add_argument("--out", default=None, help="manifest JSON (default: <submission stem>.manifest.json)")
    _provenance_args(p, required=True, beside="--submission")
    p.set_defaults(func=run_manifest)

    p = sub.add_parser(
        "leaderboard-zip",
        help="zip a nuScenes submission for the leaderboard (validated first)",
        description="Validate a nuScenes tracking submission against the official format for the "
        "split (grutrack's checks and nuscenes-devkit's loader), then write a zip "
        "holding it, atomically.",
    )
    p.add_argument("--submission", required=True, help="tracking submission JSON")
    p.add_argument("--dataroot", required=True, help="nuScenes dataroot")
    p.add_argument("--version", required=True, help="nuScenes version (v1.0-test for the test split)")
    p.add_argument("--split", required=True, help="split (test)")
    p.add_argument("--out", required=True, help="zip to write")
    p.set_defaults(func=run_zip)


def _provenance_args(p: argparse.ArgumentParser, required: bool, beside: str) -> None:
    """What produced the tracks: detections, tracker and its resolved config (default: the one `grutrack track`
    wrote beside the file of the flag ``beside``), checkpoint, code version."""
    p.add_argument("--detections", required=required, help="detections the tracks were made from")
    p.add_argument(
        "--tracker-config",
        default=None,
        help=f"resolved tracker preset YAML used (default: <{beside} stem>.tracker.yaml, what `grutrack "
        f"track` writes beside its --out)",
    )
    p.add_argument("--tracker", required=required, help="tracker name (ekf, grukf, greedy, ab3dmot)")
    p.add_argument("--checkpoint", default=None, help="GRU-KF model used (grukf)")
    p.add_argument("--code-version", default=None, help="code version of the tracking stage (from the workflow)")


def _write_manifest(args: argparse.Namespace, submission: str, counts: dict[str, int], out: str) -> None:
    """The manifest of ``submission`` from the provenance arguments, written atomically."""
    from grutrack.io import read_yaml

    cfg = read_yaml(args.tracker_config, "tracker config")
    Manifest(
        dataset=args.dataset,
        split=args.split,
        submission=FileRecord.of(submission),
        tracker=args.tracker,
        tracker_config=FileRecord.of(args.tracker_config, config_hash(cfg)),
        dataroot=args.dataroot,
        version=args.version,
        detections=FileRecord.of(args.detections),
        checkpoint=FileRecord.of(args.checkpoint),
        code_version=args.code_version,
        counts=counts,
    ).write(out)


def _tracker_config(given: str | None, beside: str) -> str | None:
    """``--tracker-config`` as given, else the config `grutrack track` wrote beside ``beside`` when it is there
    (:func:`grutrack.pipeline.presets.used_config_path`), else None."""
    default = _used_config(beside)
    return given or (str(default) if default.is_file() else None)


def _used_config(beside: str):
    """``<beside stem>.tracker.yaml``: where `grutrack track --out BESIDE` writes the tracker config it used."""
    from grutrack.pipeline.presets import used_config_path

    return used_config_path(beside)


def run_submit(args: argparse.Namespace) -> int:
    """Validate, write, manifest."""
    args.tracker_config = _tracker_config(args.tracker_config, args.tracks)
    missing = [
        f
        for f, v in (
            ("--detections", args.detections),
            ("--tracker-config", args.tracker_config),
            ("--tracker", args.tracker),
        )
        if v is None
    ]
    if args.manifest != "none" and missing:
        hint = "" if args.tracker_config else f"; no {_used_config(args.tracks)} beside the tracks"
        raise ConfigError(f"{', '.join(missing)}: needed for the manifest (or give --manifest none){hint}")
    counts = dataset_of(args).write_submission(args.tracks, args.split, args.out)
    wrote = f"wrote {args.out} ({', '.join(f'{v} {k}' for k, v in counts.items())})"
    if args.manifest != "none":
        manifest = args.manifest or str(Manifest.path_for(args.out))
        _write_manifest(args, args.out, counts, manifest)
        wrote += f" and {manifest}"
    print(wrote)
    return 0


def run_manifest(args: argparse.Namespace) -> int:
    """Check the submission, write its manifest."""
    args.tracker_config = _tracker_config(args.tracker_config, args.submission)
    if args.tracker_config is None:
        raise ConfigError(
            f"--tracker-config: not given, and no {_used_config(args.submission)} beside "
            f"the submission (grutrack track --out X writes the tracker config it used to "
            f"<X stem>.tracker.yaml: give that file)"
        )
    counts = dataset_of(args).check_submission(args.submission, args.split)
    out = args.out or str(Manifest.path_for(args.submission))
    _write_manifest(args, args.submission, counts, out)
    print(f"wrote {out} ({args.submission}: {', '.join(f'{v} {k}' for k, v in counts.items())})")
    return 0


def run_zip(args: argparse.Namespace) -> int:
    """Validate and zip."""
    from grutrack.datasets import DatasetOptions
    from grutrack.datasets.nuscenes import NuScenesDataset
    from grutrack.export.leaderboard import build_zip

    tokens = NuScenesDataset(DatasetOptions(args.dataroot, args.version)).sample_tokens(args.split)
    info = build_zip(args.submission, tokens, args.out)
    print(
        f"wrote {args.out}: {info['member']} ({info['samples']} samples, {info['boxes']} boxes; validated), "
        f"sha256 {sha256_file(args.out)}"
    )
    return 0
