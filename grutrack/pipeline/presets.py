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
    cfg = resolve(kind, base, overrides)
    h = config_hash(cfg)
    header = (f"# Resolved {kind} config, written by grutrack {__version__}: base '{base}' with overrides "
              f"{json.dumps(overrides or {}, sort_keys=True)}.\n# config hash {h}\n")
    write_text_atomic(path, header + yaml.safe_dump(cfg, sort_keys=False, default_flow_style=None, width=120))
    return h
