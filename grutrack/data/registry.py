"""Registry of detection sources (``grutrack/configs/detections.yaml``): where each published detection file
lives, its expected SHA-256, the name it gets under ``detections/raw/<source>/`` and its format.

The registry only describes files; downloading is :mod:`grutrack.data.download`, conversion is
:mod:`grutrack.data.nusc_convert` / :mod:`grutrack.data.lt3d_convert`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from grutrack.errors import ConfigError

REGISTRY_PATH = Path(__file__).resolve().parents[1] / "configs" / "detections.yaml"
KEYS = ("dataset", "detector", "split", "description", "page", "url", "host", "filename", "sha256", "format",
        "member")
DATASETS = ("nuscenes", "av2")
HOSTS = ("direct", "browser")
FORMATS = ("nuscenes_json", "nuscenes_json_zip", "lt3d")
_SHA256 = re.compile(r"^[0-9a-f]{64}$")


@dataclass(frozen=True)
class DetectionSource:
    """One registry entry (see the header of ``detections.yaml`` for each field)."""

    name: str
    dataset: str
    detector: str
    split: str
    description: str
    page: str
    url: str | None
    host: str
    filename: str
    sha256: str | None
    format: str
    member: str | None

    def raw_path(self, out_dir: str | Path) -> Path:
        """Where the downloaded (or hand-placed) file lives inside ``out_dir``."""
        return Path(out_dir) / self.filename


def load_registry(path: str | Path = REGISTRY_PATH) -> dict[str, DetectionSource]:
    """All sources of a registry YAML, validated; raises :class:`ConfigError` naming the file and key."""
    path = Path(path)
    import yaml  # here, not at module level: every command's parser imports this module

    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path}: cannot read the detection registry ({exc})") from exc
    if not isinstance(raw, dict) or set(raw) != {"sources"} or not isinstance(raw["sources"], dict):
        raise ConfigError(f"{path}: expected one top-level key 'sources' mapping names to entries")
    return {name: _entry(path, name, entry) for name, entry in raw["sources"].items()}


def get_source(name: str, path: str | Path = REGISTRY_PATH) -> DetectionSource:
    """The source called ``name``; the error lists the known names."""
    reg = load_registry(path)
    if name not in reg:
        raise ConfigError(f"unknown detection source '{name}' (known: {', '.join(sorted(reg))}; see {path})")
    return reg[name]


def _entry(path: Path, name: str, entry) -> DetectionSource:
    """Validate one entry."""
    where = f"{path}: sources.{name}"
    if not isinstance(entry, dict):
        raise ConfigError(f"{where} must be a mapping with keys {', '.join(KEYS)}")
    unknown = [k for k in entry if k not in KEYS]
    if unknown:
        raise ConfigError(f"{where}: unknown key '{unknown[0]}' (expected: {', '.join(KEYS)})")
    missing = [k for k in KEYS if k not in entry]
    if missing:
        raise ConfigError(f"{where}: missing key '{missing[0]}'")
    for key, allowed in (("dataset", DATASETS), ("host", HOSTS), ("format", FORMATS)):
        if entry[key] not in allowed:
            raise ConfigError(f"{where}.{key} must be one of {', '.join(allowed)}, got {entry[key]!r}")
    for key in ("detector", "split", "description", "page", "filename"):
        if not isinstance(entry[key], str) or not entry[key]:
            raise ConfigError(f"{where}.{key} must be a non-empty string")
    if "/" in entry["filename"] or entry["filename"].startswith("."):
        raise ConfigError(f"{where}.filename must be a plain file name, got {entry['filename']!r}")
    if entry["url"] is not None and not re.match(r"^https?://", str(entry["url"])):
        raise ConfigError(f"{where}.url must be an http(s) URL or null, got {entry['url']!r}")
    if entry["sha256"] is not None and not _SHA256.match(str(entry["sha256"])):
        raise ConfigError(f"{where}.sha256 must be 64 lower-case hex digits or null")
    if (entry["format"] == "nuscenes_json_zip") != (entry["member"] is not None):
        raise ConfigError(f"{where}.member names the file inside the archive: required with format "
                          f"nuscenes_json_zip, null otherwise")
    return DetectionSource(name=name, **{k: entry[k] for k in KEYS})
