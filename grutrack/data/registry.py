"""Registry of detection sources (``grutrack/configs/detections.yaml``): where each published detection file
lives, its expected SHA-256, the name it gets under ``detections/raw/<source>/`` and its format.

The registry only describes files; downloading is :mod:`grutrack.data.download`, conversion is
:mod:`grutrack.data.nusc_convert` / :mod:`grutrack.data.lt3d_convert`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from grutrack.errors import ConfigError

REGISTRY_PATH = Path(__file__).resolve().parents[1] / "configs" / "detections.yaml"
KEYS = ("dataset", "detector", "split", "description", "page", "url", "host", "filename", "sha256", "format", "member")
FORMATS = ("nuscenes_json", "nuscenes_json_zip", "lt3d")


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
    """All sources of a registry YAML, checked against ``grutrack/configs/schemas/registry.schema.yaml`` (the
    one config loader); raises :class:`ConfigError` naming the file and key."""
    from grutrack.config_loader import load_config

    raw, source = load_config("registry", path)
    return {name: _entry(source, name, entry) for name, entry in raw["sources"].items()}


def get_source(name: str, path: str | Path = REGISTRY_PATH) -> DetectionSource:
    """The source called ``name``; the error lists the known names."""
    reg = load_registry(path)
    if name not in reg:
        raise ConfigError(f"unknown detection source '{name}' (known: {', '.join(sorted(reg))}; see {path})")
    return reg[name]


def _entry(path: str, name: str, entry: dict) -> DetectionSource:
    """One schema-checked entry; a zip source must name its member, a plain file must not."""
    if (entry["format"] == "nuscenes_json_zip") != (entry["member"] is not None):
        raise ConfigError(
            f"{path}: sources.{name}.member names the file inside the archive: required with format "
            f"nuscenes_json_zip, null otherwise"
        )
    return DetectionSource(name=name, **{k: entry[k] for k in KEYS})
