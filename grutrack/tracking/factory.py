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
#: tracker name -> preset used when --config is not given
DEFAULT_PRESET = {"ekf": "ekf"}


def build_tracker(name: str = "ekf", config: str | Path | None = None) -> Tracker:
    """A :class:`Tracker` for ``name`` with the preset ``config`` (default: the preset named ``name``)."""
    if name not in TRACKERS:
        raise ConfigError(f"unknown tracker '{name}' (available: {', '.join(TRACKERS)})")
    cfg = load_tracker_config(config or DEFAULT_PRESET[name])
    return Tracker(cfg, ekf_groups(cfg))


def ekf_groups(cfg: TrackerConfig) -> list[TrackGroup]:
    """One track group per state-space model in use, each with per-class (7, d, d) Q, R, P0 tables.

    Classes of other groups keep zero rows in a group's tables; they are never indexed there.
    """
    from grutrack.motion.defaults import load_motion_config
    from grutrack.motion.models import make_model
    from grutrack.tracking.ekf_backend import KalmanBackend

    motion = load_motion_config(cfg.motion_config, cfg.model_override or None)
    groups = []
    for model_name in sorted({m["model"] for m in motion.values()}):
        members = np.array([motion[c]["model"] == model_name for c in TRACKING_CLASSES])
        first = motion[TRACKING_CLASSES[int(np.argmax(members))]]
        model = make_model(model_name, **first["params"])
        tables = {}
        for key in ("Q", "R", "P0"):
            d = first[key].shape[0]
            tables[key] = np.stack([motion[c][key] if members[i] else np.zeros((d, d))
                                    for i, c in enumerate(TRACKING_CLASSES)])
        backend = KalmanBackend(model, tables["Q"], tables["R"], tables["P0"], yaw_flip=cfg.yaw_flip)
        groups.append(TrackGroup(backend, members))
    return groups
