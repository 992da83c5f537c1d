"""Provenance of generated files: content hashes, the hash of a resolved configuration, and the manifest that
sits beside each submission (which detections, checkpoint, tracker config and package version made it)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from grutrack import __version__
from grutrack.errors import InputFormatError
from grutrack.io import write_json_atomic

SHORT = 12  # hex digits shown in reports


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def config_hash(obj) -> str:
    """Short hash of a configuration's content (key order and YAML layout do not matter)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:SHORT]


def file_record(path: str | Path | None) -> dict | None:
    """``{"path", "sha256"}`` of an existing file, None for no file."""
    if path is None:
        return None
    return {"path": str(path), "sha256": sha256_file(path)}


def manifest_path(submission: str | Path) -> Path:
    """The manifest beside a submission: ``x.json`` -> ``x.manifest.json``."""
    p = Path(submission)
    return p.with_name(p.stem + ".manifest.json")


def write_manifest(path: str | Path, doc: dict) -> None:
    """Write a manifest atomically, stamped with the package version."""
    write_json_atomic(path, {"grutrack_version": __version__, **doc}, indent=2)


def read_manifest(path: str | Path) -> dict | None:
    """A manifest, or None when there is none."""
    p = Path(path)
    if not p.is_file():
        return None
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputFormatError(f"{p}: not a valid manifest JSON ({exc})") from exc
