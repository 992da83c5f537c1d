"""Tracker presets: YAML files under ``grutrack/configs/trackers/`` validated against a fixed schema.

A preset is named (``ekf``) or given as a path. Every key is required, unknown keys are rejected, and
per-class maps must list all 7 tracking classes: a misspelt key fails with the file and the key path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from grutrack.classes import TRACKING_CLASSES
from grutrack.errors import ConfigError

PRESET_DIR = Path(__file__).resolve().parents[1] / "configs" / "trackers"
METRICS = ("giou_3d", "giou_bev", "iou_3d", "iou_bev", "a_giou_3d", "a_giou_bev")
NMS_METHODS = ("blend", "scale")
SCORE_FILTERS = ("at_least", "above")
NMS_METRICS = ("iou_bev", "a_giou_bev")
SCORE_UPDATES = ("detection", "multiply")
TERMINATIONS = ("age", "average_score")
GEOMETRY_FILTERS = ("none", "median", "mean")
MOTION_MODELS = ("CTRA", "BICYCLE", "CA", "CV")
ALGORITHMS = ("hungarian", "greedy")
#: association.assignment: which assignment the Hungarian stages solve (see grutrack/tracking/association.py)
ASSIGNMENTS = ("most_pairs", "threshold_margin")
#: motion.ctra_form / motion.bicycle_form: "arc" (grutrack/motion/models.py CTRA, Bicycle) or "piecewise"
#: (CTRAPiecewise, BicyclePiecewise: Poly-MOT's forms)
MODEL_FORMS = ("arc", "piecewise")
#: preprocessing.measured_yaw: how a detection's quaternion becomes its yaw (grutrack/boxes.py)
MEASURED_YAWS = ("euler_z", "rotation_angle")

# schema: section -> key -> kind; "per_class_float" etc. are maps over the 7 tracking classes
SCHEMA: dict[str, dict[str, str]] = {
    "preprocessing": {"score_threshold": "per_class_unit", "nms_threshold": "unit", "nms_class_aware": "bool",
                      "measured_yaw": "measured_yaw", "score_filter": "score_filter", "nms_method": "nms_method",
                      "nms_metric": "per_class_nms_metric", "nms_scale": "per_class_scale",
                      "nms_distance_gate": "per_class_gate"},
    "association": {"algorithm": "algorithm", "assignment": "assignment", "first_metric": "per_class_metric",
                    "first_threshold": "per_class_cost", "two_stage": "bool", "second_metric": "metric",
                    "second_threshold": "per_class_cost", "max_distance": "per_class_metres",
                    "distance_gate": "per_class_gate"},
    "lifecycle": {"max_age": "per_class_posint", "min_hits": "per_class_posint", "decay_rate": "per_class_unit",
                  "punish_num": "punish", "score_update": "score_update", "termination": "termination",
                  "delete_threshold": "per_class_unit"},
    "motion": {"config": "str", "model_override": "class_model_map", "yaw_flip": "bool", "time_step": "time_step",
               "ctra_form": "model_form", "bicycle_form": "model_form",
               "geometry_filter": "per_class_geometry_filter", "geometry_window": "per_class_posint"},
    "output": {"matched_box": "matched_box", "max_boxes_per_sample": "posint"},
}


_CHOICES = {"metric": METRICS, "score_filter": SCORE_FILTERS, "nms_method": NMS_METHODS, "nms_metric": NMS_METRICS, "score_update": SCORE_UPDATES,
            "termination": TERMINATIONS, "geometry_filter": GEOMETRY_FILTERS}
_NAMED_PER_CLASS = ("per_class_metric", "per_class_nms_metric", "per_class_geometry_filter")


@dataclass(frozen=True)
class TrackerConfig:
    """A validated preset. Per-class values are (7,) arrays indexed by tracking-class label."""

    source: str
    score_threshold: np.ndarray
    nms_threshold: float
    nms_class_aware: bool
    measured_yaw: str
    algorithm: str
    assignment: str
    first_metric: tuple[str, ...]
    first_threshold: np.ndarray
    two_stage: bool
    second_metric: str
    second_threshold: np.ndarray
    max_distance: np.ndarray
    max_age: np.ndarray
    min_hits: np.ndarray
    decay_rate: np.ndarray
    punish_num: np.ndarray      # (7,) int64: predicted boxes written for at most this many missed frames
    motion_config: str
    model_override: dict[str, str]
    yaw_flip: bool
    time_step: float | None     # fixed prediction step (s), None: the timestamp difference
    ctra_form: str
    bicycle_form: str
    matched_box: str
    max_boxes_per_sample: int
    raw: dict
    # Fast-Poly options (defaults: the Poly-MOT pipeline)
    score_filter: str = "at_least"
    nms_method: str = "blend"
    nms_metric: tuple[str, ...] = ("iou_bev",) * 7
    nms_scale: np.ndarray = field(default_factory=lambda: np.ones(7))
    nms_distance_gate: np.ndarray = field(default_factory=lambda: np.zeros(7))
    distance_gate: np.ndarray = field(default_factory=lambda: np.zeros(7))
    score_update: str = "detection"
    termination: str = "age"
    delete_threshold: np.ndarray = field(default_factory=lambda: np.zeros(7))
    geometry_filter: tuple[str, ...] = ("none",) * 7
    geometry_window: np.ndarray = field(default_factory=lambda: np.ones(7, dtype=np.int64))


def preset_path(name_or_path: str | Path) -> Path:
    """Resolve a preset name (``ekf``) or a path to a YAML file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.is_file():
            raise ConfigError(f"tracker config {p} does not exist")
        return p
    cand = PRESET_DIR / f"{name_or_path}.yaml"
    if not cand.is_file():
        names = sorted(q.stem for q in PRESET_DIR.glob("*.yaml"))
        raise ConfigError(f"unknown tracker preset '{name_or_path}' (available: {', '.join(names)}; "
                          f"or give a path to a YAML file)")
    return cand


def load_tracker_config(name_or_path: str | Path = "ekf") -> TrackerConfig:
    """Load and validate a tracker preset; raises :class:`ConfigError` naming the file and key."""
    path = preset_path(name_or_path)
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from exc
    return config_from_dict(raw, str(path))


def config_from_dict(raw: dict, source: str = "<dict>") -> TrackerConfig:
    """Validate a preset given as a dict (see :data:`SCHEMA`)."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping of sections {', '.join(SCHEMA)}")
    _check_keys(source, "", raw, SCHEMA)
    v = {f"{sec}.{key}": _value(source, f"{sec}.{key}", raw[sec][key], kind)
         for sec, keys in SCHEMA.items() for key, kind in keys.items()}
    if v["association.algorithm"] == "greedy" and v["association.two_stage"]:
        raise ConfigError(f"{source}: 'association.two_stage' must be false with 'association.algorithm' greedy "
                          f"(greedy matching is one stage)")
    return TrackerConfig(
        source=source,
        score_threshold=v["preprocessing.score_threshold"], nms_threshold=v["preprocessing.nms_threshold"],
        nms_class_aware=v["preprocessing.nms_class_aware"], measured_yaw=v["preprocessing.measured_yaw"],
        algorithm=v["association.algorithm"], assignment=v["association.assignment"],
        first_metric=v["association.first_metric"], first_threshold=v["association.first_threshold"],
        two_stage=v["association.two_stage"], second_metric=v["association.second_metric"],
        second_threshold=v["association.second_threshold"], max_distance=v["association.max_distance"],
        max_age=v["lifecycle.max_age"], min_hits=v["lifecycle.min_hits"], decay_rate=v["lifecycle.decay_rate"],
        punish_num=v["lifecycle.punish_num"],
        motion_config=v["motion.config"], model_override=v["motion.model_override"],
        yaw_flip=v["motion.yaw_flip"], time_step=v["motion.time_step"], ctra_form=v["motion.ctra_form"],
        bicycle_form=v["motion.bicycle_form"], matched_box=v["output.matched_box"],
        max_boxes_per_sample=v["output.max_boxes_per_sample"], raw=raw,
        score_filter=v["preprocessing.score_filter"], nms_method=v["preprocessing.nms_method"], nms_metric=v["preprocessing.nms_metric"],
        nms_scale=v["preprocessing.nms_scale"], nms_distance_gate=v["preprocessing.nms_distance_gate"],
        distance_gate=v["association.distance_gate"], score_update=v["lifecycle.score_update"],
        termination=v["lifecycle.termination"], delete_threshold=v["lifecycle.delete_threshold"],
        geometry_filter=v["motion.geometry_filter"], geometry_window=v["motion.geometry_window"])


def _check_keys(source: str, prefix: str, given: dict, expected: dict) -> None:
    unknown = [k for k in given if k not in expected]
    missing = [k for k in expected if k not in given]
    if unknown:
        raise ConfigError(f"{source}: unknown key '{prefix}{unknown[0]}' (expected one of: "
                          f"{', '.join(prefix + k for k in expected)})")
    if missing:
        raise ConfigError(f"{source}: missing key '{prefix}{missing[0]}'")
    for k, sub in expected.items():
        if isinstance(sub, dict):
            if not isinstance(given[k], dict):
                raise ConfigError(f"{source}: '{prefix}{k}' must be a mapping with keys {', '.join(sub)}")
            _check_keys(source, f"{prefix}{k}.", given[k], sub)


def _value(source: str, key: str, val: Any, kind: str) -> Any:
    """Check and convert one value of the given kind."""
    def fail(expected: str):
        raise ConfigError(f"{source}: '{key}' must be {expected}, got {val!r}")

    if kind.startswith("per_class_"):
        if not isinstance(val, dict):
            fail(f"a mapping over the tracking classes {', '.join(TRACKING_CLASSES)}")
        _check_keys(source, f"{key}.", val, {c: None for c in TRACKING_CLASSES})
        items = [_value(source, f"{key}.{c}", val[c], kind[len("per_class_"):]) for c in TRACKING_CLASSES]
        return tuple(items) if kind in _NAMED_PER_CLASS else np.asarray(items)
    if kind == "class_model_map":
        if not isinstance(val, dict):
            fail("a mapping {class: model}")
        for c, m in val.items():
            if c not in TRACKING_CLASSES:
                raise ConfigError(f"{source}: '{key}' has unknown class '{c}' (expected one of "
                                  f"{', '.join(TRACKING_CLASSES)})")
            if str(m).upper() not in MOTION_MODELS:
                raise ConfigError(f"{source}: '{key}.{c}' must be one of {', '.join(MOTION_MODELS)}, got {m!r}")
        return {c: str(m).upper() for c, m in val.items()}
    if kind == "bool":
        return val if isinstance(val, bool) else fail("true or false")
    if kind == "str":
        return val if isinstance(val, str) and val else fail("a non-empty string")
    if kind == "matched_box":
        return val if val in ("filter", "detection") else fail("'filter' or 'detection'")
    if kind in _CHOICES:
        return val if val in _CHOICES[kind] else fail(f"one of {', '.join(_CHOICES[kind])}")
    if kind == "algorithm":
        return val if val in ALGORITHMS else fail(f"one of {', '.join(ALGORITHMS)}")
    if kind == "assignment":
        return val if val in ASSIGNMENTS else fail(f"one of {', '.join(ASSIGNMENTS)}")
    if kind == "model_form":
        return val if val in MODEL_FORMS else fail(f"one of {', '.join(MODEL_FORMS)}")
    if kind == "measured_yaw":
        return val if val in MEASURED_YAWS else fail(f"one of {', '.join(MEASURED_YAWS)}")
    if kind == "time_step":
        if val == "timestamps":
            return None
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not np.isfinite(val) or val <= 0:
            fail("'timestamps' or a positive number of seconds")
        return float(val)
    if kind == "punish":   # one integer for every class, or a map over the classes -> (7,) int64
        if isinstance(val, dict):
            return _value(source, key, val, "per_class_nonnegint").astype(np.int64)
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not float(val).is_integer() or val < 0:
            fail(f"an integer >= 0 or a mapping over the tracking classes {', '.join(TRACKING_CLASSES)}")
        return np.full(len(TRACKING_CLASSES), int(val), dtype=np.int64)
    if isinstance(val, bool) or not isinstance(val, (int, float)) or not np.isfinite(val):
        fail("a number")
    if kind == "unit":
        return float(val) if 0 <= val <= 1 else fail("a number in [0, 1]")
    if kind == "scale":
        return float(val) if val > 0 else fail("a positive scale factor")
    if kind == "gate":
        return float(val) if val >= 0 else fail("a distance in metres >= 0 (0: no gate)")
    if kind == "metres":
        return float(val) if val > 0 else fail("a positive distance in metres")
    if kind == "cost":
        return float(val) if 0 <= val <= 2 else fail("a cost threshold in [0, 2] (cost = 1 - similarity)")
    if kind in ("posint", "nonnegint"):
        lo = 1 if kind == "posint" else 0
        return int(val) if float(val).is_integer() and val >= lo else fail(f"an integer >= {lo}")
    raise AssertionError(kind)
