"""Provenance of generated files: content hashes and the hash of a resolved configuration (the manifest that
sits beside each submission is :class:`grutrack.documents.Manifest`)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

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
