"""Submission step of the workflow for nuScenes: validate a tracking JSON against the official format (grutrack's
field-by-field check and the devkit's own loader), write it to ``submissions/``, and build the leaderboard zip."""

from __future__ import annotations

import zipfile
from pathlib import Path

from grutrack.errors import InputFormatError
from grutrack.export.nuscenes_json import MAX_BOXES_PER_SAMPLE, validate_submission
from grutrack.io import atomic_path, read_json, write_json_atomic


def read_submission(path: str | Path) -> dict:
    """Parse a tracking submission JSON (a missing file, a folder or text that is not JSON: one line naming it)."""
    return read_json(path, "tracking submission")


def load_valid_submission(path: str | Path, tokens: list[str]) -> dict:
    """Read a tracking submission JSON and check it against the official format for the split's sample
    ``tokens`` (every sample, nothing else); the checks every command that reads a submission makes."""
    sub = read_submission(path)
    validate_submission(sub, tokens, where=str(path))
    return sub


def devkit_check(path: str | Path) -> None:
    """Load the file with nuscenes-devkit's ``load_prediction`` (the loader the official evaluation uses)."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.common.loaders import load_prediction
    from nuscenes.eval.tracking.data_classes import TrackingBox

    config_factory("tracking_nips_2019")  # registers the tracking class names TrackingBox checks against
    try:
        load_prediction(str(path), MAX_BOXES_PER_SAMPLE, TrackingBox, verbose=False)
    except (AssertionError, KeyError, TypeError, ValueError) as exc:
        raise InputFormatError(f"{path}: rejected by the nuscenes-devkit loader ({exc or type(exc).__name__})") from exc


def counts(sub: dict) -> dict:
    """Samples and boxes of a submission."""
    return {"samples": len(sub["results"]), "boxes": sum(len(v) for v in sub["results"].values())}


def write_validated(tracks: str | Path, tokens: list[str], out: str | Path) -> dict:
    """Validate the tracker's JSON for the split's samples and write it as the submission; returns counts."""
    sub = load_valid_submission(tracks, tokens)
    write_json_atomic(out, sub)
    devkit_check(out)
    return counts(sub)


def build_zip(submission: str | Path, tokens: list[str], out: str | Path) -> dict:
    """Validate ``submission`` again (official format, every sample of the split) and zip it atomically, the
    JSON as the archive's only member; returns the member name and counts."""
    submission = Path(submission)
    sub = load_valid_submission(submission, tokens)
    devkit_check(submission)
    with atomic_path(out) as tmp:
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.write(submission, arcname=submission.name)
    return {"member": submission.name, **counts(sub)}
