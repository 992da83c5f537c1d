"""Build a ready-to-run tracker from a tracker name and preset."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grutrack.classes import TRACKING_CLASSES
from grutrack.errors import ConfigError
from grutrack.tracking.config import TrackerConfig, load_tracker_config
from grutrack.tracking.tracker import Tracker, TrackGroup

#: trackers selectable with ``--tracker``
TRACKERS: tuple[str, ...] = ("ekf",)


def build_tracker(name: str = "ekf", config: str | Path | None = None) -> Tracker:
    """A :class:`Tracker` for ``name`` with the preset ``config`` (default: the preset named ``name``)."""
    if name not in TRACKERS:
        raise ConfigError(f"unknown tracker '{name}' (available: {', '.join(TRACKERS)})")
    cfg = load_tracker_config(config or name)
    return Tracker(cfg, ekf_groups(cfg))


def ekf_groups(cfg: TrackerConfig) -> list[TrackGroup]:
    """One track group per state-space model in use, each with per-class Q, R, P0 tables."""
    from grutrack.motion.defaults import load_motion_config
    from grutrack.motion.models import make_model
    from grutrack.tracking.ekf_backend import KalmanBackend

    motion = load_motion_config(cfg.motion_config)
    model_of = {c: cfg.model_override.get(c, motion[c]["model"]) for c in TRACKING_CLASSES}
    groups = []
    for model_name in sorted(set(model_of.values())):
        model = make_model(model_name)
        members = np.array([model_of[c] == model_name for c in TRACKING_CLASSES])
        tables = {k: _class_table(motion, model_name, model.dim_x if k != "R" else 9, k) for k in ("Q", "R", "P0")}
        groups.append(TrackGroup(KalmanBackend(model, tables["Q"], tables["R"], tables["P0"]), members))
    return groups


def _class_table(motion: dict, model_name: str, d: int, key: str) -> np.ndarray:
    """(7, d, d) per-class matrices ``key`` for ``model_name`` (from the motion config)."""
    table = np.zeros((len(TRACKING_CLASSES), d, d))
    for i, c in enumerate(TRACKING_CLASSES):
        table[i] = motion[c]["params"][model_name][key] if "params" in motion[c] else motion[c][key]
    return table
