"""Resolved configurations: a shipped tracker preset or training config plus the overrides from the workflow
config, validated by the same code that reads presets, written as a YAML file the CLI takes with ``--config``."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from grutrack import __version__
from grutrack.config_loader import merge, read_config
from grutrack.errors import ConfigError
from grutrack.io import write_text_atomic
from grutrack.provenance import config_hash

KINDS = ("tracker", "training")


def resolve_tracker(base: str, overrides: dict | None = None) -> dict:
    """Tracker preset ``base`` (name or path) with ``overrides``, validated; raises naming the key."""
    from grutrack.tracking.config import config_from_dict

    raw = merge(read_config("tracker", base)[0], overrides or {})
    config_from_dict(raw, f"tracker preset '{base}' with overrides {json.dumps(overrides or {})}")
    return raw


def resolve_training(base: str, overrides: dict | None = None) -> dict:
    """Training config ``base`` (name or path) with ``overrides`` (top-level keys), validated."""
    from grutrack.training.config import config_from_dict

    raw = merge(read_config("training", base)[0], overrides or {})
    config_from_dict(raw, f"training config '{base}' with overrides {json.dumps(overrides or {})}")
    return raw


def resolve(kind: str, base: str, overrides: dict | None = None) -> dict:
    """Dispatch on ``kind`` (tracker or training)."""
    if kind not in KINDS:
        raise ConfigError(f"unknown config kind '{kind}' (expected {' or '.join(KINDS)})")
    return (resolve_tracker if kind == "tracker" else resolve_training)(base, overrides)


def write_resolved(path: str | Path, kind: str, base: str, overrides: dict | None = None) -> str:
    """Write the resolved config as YAML (atomically) with a header naming its origin; returns its hash."""
    origin = f"base '{base}' with overrides {json.dumps(overrides or {}, sort_keys=True)}"
    return write_config(path, kind, resolve(kind, base, overrides), origin)


def write_config(path: str | Path, kind: str, cfg: dict, origin: str) -> str:
    """Write the resolved ``kind`` config ``cfg`` as YAML (atomically) with a header saying where it comes from
    (``origin``) and its hash; returns the hash (:func:`grutrack.provenance.config_hash`)."""
    h = config_hash(cfg)
    header = f"# Resolved {kind} config, written by grutrack {__version__}: {origin}.\n# config hash {h}\n"
    write_text_atomic(path, header + yaml.safe_dump(cfg, sort_keys=False, default_flow_style=None, width=120))
    return h


def used_config_path(out: str | Path) -> Path:
    """Where ``grutrack track --out OUT`` writes the tracker config it ran: ``<OUT stem>.tracker.yaml`` beside
    OUT (``tracks.json`` -> ``tracks.tracker.yaml``), where ``submit`` and ``manifest`` look for it."""
    return Path(out).with_suffix(".tracker.yaml")


def used_tracker_config(tracker: str, config: str | Path | None, matched_box: str) -> dict:
    """The raw preset ``grutrack track --tracker TRACKER --config CONFIG`` ran, as ``resolve-config tracker``
    writes one: ``config`` (None: the preset the tracker defaults to) with ``output.matched_box`` as the tracker
    used it (the GRU-KF without ``--config`` takes it from its checkpoint)."""
    from grutrack.tracking.factory import DEFAULT_PRESET

    raw, _ = read_config("tracker", config or DEFAULT_PRESET[tracker])
    return merge(raw, {"output": {"matched_box": matched_box}})
