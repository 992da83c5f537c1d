"""Tracker presets: YAML files under ``grutrack/configs/trackers/`` validated against
``grutrack/configs/schemas/tracker.schema.yaml`` by the one config loader (:mod:`grutrack.config_loader`).

A preset is named (``ekf``) or given as a path. Each section requires its core keys; the other keys have a
``default`` in the schema (what the tracker does without them: the Poly-MOT pipeline) and may be left out, so a
preset carries only what its algorithm reads (greedy matching no assignment rule, stage thresholds or second
stage; Hungarian matching no greedy distance gate; a one-stage association no second-stage keys; age termination
no delete threshold; blend NMS no scale-NMS tables). The keys of :data:`NEEDED_WITH` have no usable default and
are required with the setting that reads them. Unknown keys are rejected and per-class maps list all 7 tracking
classes: a misspelt key fails with the file and the key path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grutrack.classes import TRACKING_CLASSES
from grutrack.config_loader import config_path, read_config, schema, validate
from grutrack.errors import ConfigError

PRESET_DIR = Path(__file__).resolve().parents[1] / "configs" / "trackers"
SECTIONS = ("preprocessing", "association", "lifecycle", "motion", "output")
#: keys required with the setting that reads them: key -> (setting, value); without it their schema default
#: is a placeholder nothing reads
NEEDED_WITH = {
    "association.first_metric": ("association.algorithm", "hungarian"),
    "association.first_threshold": ("association.algorithm", "hungarian"),
    "association.max_distance": ("association.algorithm", "greedy"),
    "association.second_metric": ("association.two_stage", True),
    "association.second_threshold": ("association.two_stage", True),
    "lifecycle.delete_threshold": ("lifecycle.termination", "average_score"),
    "motion.position_noise": ("motion.filter", "decoupled_cv"),
    "motion.size_noise": ("motion.filter", "decoupled_cv"),
}
#: where the lost-newborn keys act (the reason :func:`_check_two_stage_pairs` gives)
_STAGE_ONE = "it acts in stage 1 of the two-stage association"
#: per-class settings that are names (kept as tuples; the numeric ones become (7,) arrays)
_NAMED_PER_CLASS = (
    "per_class_metric",
    "per_class_nms_metric",
    "per_class_geometry_filter",
    "per_class_track_pose",
    "per_class_coast",
    "per_class_gate_growth",
)
#: per-class noise diagonals of the decoupled filters (``motion.position_noise``, ``motion.size_noise``)
_NOISE_PER_CLASS = ("per_class_position_noise", "per_class_size_noise")


@dataclass(frozen=True)
class TrackerConfig:
    """A validated preset. Per-class values are arrays (tuples for names) indexed by label: (7,) by tracking-class
    label as read; :func:`grutrack.tracking.factory.remap_config` re-indexes them by dataset label, (n_labels,)
    (sized by the dataset's vocabulary), the form the tracker runs on."""

    source: str
    score_threshold: np.ndarray
    nms_threshold: float | np.ndarray  # one value, or (n_labels,) per label (the kept box's class)
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
    punish_num: np.ndarray  # int64 per label: predicted boxes written for at most this many missed frames
    motion_config: str
    model_override: dict[str, str]
    yaw_flip: bool
    time_step: float | None  # fixed prediction step (s), None: the timestamp difference
    ctra_form: str
    bicycle_form: str
    matched_box: str
    max_boxes_per_sample: int
    # Fast-Poly options (defaults: the Poly-MOT pipeline)
    score_filter: str = "at_least"
    nms_method: str = "blend"
    nms_metric: tuple[str, ...] = ("iou_bev",) * 7
    nms_scale: np.ndarray = field(default_factory=lambda: np.ones(7))
    nms_distance_gate: np.ndarray = field(default_factory=lambda: np.zeros(7))
    distance_gate: np.ndarray = field(default_factory=lambda: np.zeros(7))
    # per class fixed, missed_frames (a track missed for k frames is gated at (k + 1) x distance_gate) or a speed
    # v in m/s (a track missed for t seconds is gated at distance_gate + v t)
    distance_gate_growth: tuple[str | float, ...] = ("fixed",) * 7
    size_gate: np.ndarray = field(default_factory=lambda: np.zeros(7))  # footprint-area ratio in [0, 1]; 0: off
    score_update: str = "detection"
    termination: str = "age"
    delete_threshold: np.ndarray = field(default_factory=lambda: np.zeros(7))
    geometry_filter: tuple[str, ...] = ("none",) * 7
    geometry_window: np.ndarray = field(default_factory=lambda: np.ones(7, dtype=np.int64))
    # MCTrack options (defaults: the textbook choices, the pipeline above unchanged)
    nms_order: str = "input"
    footprint: str = "yaw_rectangle"  # a detection's footprint in IoU / GIoU: yaw_rectangle or bottom_face
    ro_gdiou_weights: np.ndarray = field(default_factory=lambda: np.ones((7, 2)))
    crowded_threshold: np.ndarray = field(default_factory=lambda: np.zeros(7))  # 0: off (stage 1 as it is)
    lost_newborn_penalty: np.ndarray = field(default_factory=lambda: np.zeros(7))  # stage-1 cost added; 0: off
    crowded_skips_lost_newborns: bool = False  # lost newborns left out of crowded_threshold's test
    # per class keep or zero: the turn rate / acceleration of a coasting track (motion.coast_yaw_rate, ...)
    coast_yaw_rate: tuple[str, ...] = ("keep",) * 7
    coast_acceleration: tuple[str, ...] = ("keep",) * 7
    track_pose: tuple[str, ...] = ("predicted",) * 7
    track_pose_blend: np.ndarray = field(default_factory=lambda: np.ones(7))
    track_pose_rule: str = "own_class"
    geometry_precision: str = "float64"
    write_first_frames: int = 0
    young_track_discount: float = 0.0  # written score = score * (1 - discount ** hits)
    filter: str = "joint"
    position_noise: dict | None = None  # {"P0", "Q", "R"}: (n_labels, 4, 4) diagonal tables
    size_noise: dict | None = None  # {"P0", "Q"}: (n_labels, 4, 4), {"R"}: (n_labels, 2, 2)
    missed_update: str = "predict"
    size_steps: str = "per_frame"
    compared_size: str = "filter"
    written_velocity: str = "filter"
    # the detector's velocity checked against a track's displacement (default off; tracking/velocity_check.py)
    velocity_check_updates: int = 0
    velocity_check_difference: float = 2.0  # m/s
    velocity_check_ratio: float = 0.5
    velocity_check_window: float = 0.25  # s
    nis_limit: float = 0.0  # robust update: R * max(1, NIS / nis_limit); 0: off (motion/kalman.py)
    nis_min_hits: int = 0  # ... for tracks with at least this many matched detections before the update
    r_score_exponent: float = 0.0  # confidence-weighted noise: R / score ** r_score_exponent; 0: off


def preset_path(name_or_path: str | Path) -> Path:
    """Resolve a preset name (``ekf``) or a path to a YAML file (the one name-or-path rule)."""
    return config_path("tracker", name_or_path)


def load_tracker_config(name_or_path: str | Path = "ekf") -> TrackerConfig:
    """Load and validate a tracker preset; raises :class:`ConfigError` naming the file and key."""
    raw, source = read_config("tracker", name_or_path)
    return config_from_dict(raw, source)


def config_from_dict(raw: dict, source: str = "<dict>") -> TrackerConfig:
    """Validate a preset given as a dict against ``grutrack/configs/schemas/tracker.schema.yaml``."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: expected a mapping of sections {', '.join(SECTIONS)}")
    validate("tracker", raw, source)
    given = {f"{sec}.{key}": val for sec in SECTIONS for key, val in (raw.get(sec) or {}).items()}
    v = {
        f"{sec}.{key}": _convert(given.get(f"{sec}.{key}", default), ref)
        for sec, keys in _section_refs().items()
        for key, (ref, default) in keys.items()
    }
    for key, (setting, value) in NEEDED_WITH.items():
        if v[setting] == value and key not in given:
            raise ConfigError(f"{source}: '{key}' is required with '{setting}: {_yaml_scalar(value)}'")
    _check_model_names(v["motion.model_override"], source)
    if v["motion.velocity_check_updates"] > 0 and v["motion.filter"] == "decoupled_cv":
        raise ConfigError(
            f"{source}: 'motion.velocity_check_updates' must be 0 with 'motion.filter: decoupled_cv' (the velocity "
            f"check runs in the joint EKF and the GRU-KF; MCTrack's decoupled filters always take the velocity)"
        )
    for key in ("motion.nis_limit", "motion.r_score_exponent"):
        if v[key] > 0 and v["motion.filter"] == "decoupled_cv":
            raise ConfigError(
                f"{source}: '{key}' must be 0 with 'motion.filter: decoupled_cv' (the robust update and "
                f"confidence-weighted noise run in the joint EKF and the GRU-KF's EKF gain prior, not in MCTrack's "
                f"decoupled filters)"
            )
    for key in ("motion.coast_yaw_rate", "motion.coast_acceleration"):
        if any(c != "keep" for c in v[key]) and v["motion.filter"] == "decoupled_cv":
            raise ConfigError(
                f"{source}: '{key}' must be keep with 'motion.filter: decoupled_cv' (MCTrack's decoupled CV "
                f"filters have no turn rate or acceleration to hold)"
            )
    _check_ro_gdiou(v, given, source)
    if v["association.algorithm"] == "greedy" and v["association.two_stage"]:
        raise ConfigError(
            f"{source}: 'association.two_stage' must be false with 'association.algorithm' greedy "
            f"(greedy matching is one stage)"
        )
    if np.any(v["association.lost_newborn_penalty"] > 0):
        _check_two_stage_pairs(v, source, "'association.lost_newborn_penalty' above 0", _STAGE_ONE)
    frames, speed = gate_growth_rules(v["association.distance_gate_growth"])
    if frames.any() or np.any(speed > 0):
        _check_widening_gate(v, source)
    if np.any(v["association.size_gate"] > 0):
        _check_two_stage_pairs(
            v, source, "'association.size_gate' above 0", "it gates the pairs of the two-stage association"
        )
    if v["association.crowded_skips_lost_newborns"]:
        _check_two_stage_pairs(v, source, "'association.crowded_skips_lost_newborns: true'", _STAGE_ONE)
        if not np.any(v["association.crowded_threshold"] > 0):
            raise ConfigError(
                f"{source}: 'association.crowded_skips_lost_newborns: true' needs 'association.crowded_threshold' "
                f"above 0 for some class (it changes which stage-1 rows are crowded)"
            )
    return TrackerConfig(
        source=source,
        score_threshold=v["preprocessing.score_threshold"],
        nms_threshold=v["preprocessing.nms_threshold"],
        nms_class_aware=v["preprocessing.nms_class_aware"],
        measured_yaw=v["preprocessing.measured_yaw"],
        algorithm=v["association.algorithm"],
        assignment=v["association.assignment"],
        first_metric=v["association.first_metric"],
        first_threshold=v["association.first_threshold"],
        two_stage=v["association.two_stage"],
        second_metric=v["association.second_metric"],
        second_threshold=v["association.second_threshold"],
        max_distance=v["association.max_distance"],
        max_age=v["lifecycle.max_age"],
        min_hits=v["lifecycle.min_hits"],
        decay_rate=v["lifecycle.decay_rate"],
        punish_num=v["lifecycle.punish_num"],
        motion_config=v["motion.config"],
        model_override=v["motion.model_override"],
        yaw_flip=v["motion.yaw_flip"],
        time_step=v["motion.time_step"],
        ctra_form=v["motion.ctra_form"],
        bicycle_form=v["motion.bicycle_form"],
        matched_box=v["output.matched_box"],
        max_boxes_per_sample=v["output.max_boxes_per_sample"],
        score_filter=v["preprocessing.score_filter"],
        nms_method=v["preprocessing.nms_method"],
        nms_metric=v["preprocessing.nms_metric"],
        nms_scale=v["preprocessing.nms_scale"],
        nms_distance_gate=v["preprocessing.nms_distance_gate"],
        distance_gate=v["association.distance_gate"],
        distance_gate_growth=v["association.distance_gate_growth"],
        size_gate=v["association.size_gate"],
        score_update=v["lifecycle.score_update"],
        termination=v["lifecycle.termination"],
        delete_threshold=v["lifecycle.delete_threshold"],
        geometry_filter=v["motion.geometry_filter"],
        geometry_window=v["motion.geometry_window"],
        nms_order=v["preprocessing.nms_order"],
        footprint=v["preprocessing.footprint"],
        ro_gdiou_weights=v["association.ro_gdiou_weights"],
        crowded_threshold=v["association.crowded_threshold"],
        lost_newborn_penalty=v["association.lost_newborn_penalty"],
        crowded_skips_lost_newborns=v["association.crowded_skips_lost_newborns"],
        coast_yaw_rate=v["motion.coast_yaw_rate"],
        coast_acceleration=v["motion.coast_acceleration"],
        track_pose=v["association.track_pose"],
        track_pose_blend=v["association.track_pose_blend"],
        track_pose_rule=v["association.track_pose_rule"],
        geometry_precision=v["association.geometry_precision"],
        write_first_frames=v["lifecycle.write_first_frames"],
        young_track_discount=v["lifecycle.young_track_discount"],
        filter=v["motion.filter"],
        position_noise=v["motion.position_noise"],
        size_noise=v["motion.size_noise"],
        missed_update=v["motion.missed_update"],
        size_steps=v["motion.size_steps"],
        compared_size=v["motion.compared_size"],
        written_velocity=v["motion.written_velocity"],
        velocity_check_updates=v["motion.velocity_check_updates"],
        velocity_check_difference=v["motion.velocity_check_difference"],
        velocity_check_ratio=v["motion.velocity_check_ratio"],
        velocity_check_window=v["motion.velocity_check_window"],
        nis_limit=v["motion.nis_limit"],
        nis_min_hits=v["motion.nis_min_hits"],
        r_score_exponent=v["motion.r_score_exponent"],
    )


#: keys only MCTrack's Ro_GDIoU association reads (grutrack/tracking/ro_gdiou.py)
RO_GDIOU_KEYS = (
    "association.ro_gdiou_weights",
    "association.track_pose",
    "association.track_pose_blend",
    "association.track_pose_rule",
    "association.geometry_precision",
)
#: of those, the keys the crowded pairs of stage 1 read too (``association.crowded_threshold``)
CROWDED_KEYS = ("association.ro_gdiou_weights", "association.geometry_precision")


def _check_ro_gdiou(v: dict, given: dict, source: str) -> None:
    """MCTrack's association (``first_metric: ro_gdiou_bev`` for every class) is one Hungarian stage that scores
    every class with Ro_GDIoU: refuse a preset that asks it for two stages, a centre gate or greedy matching, or sets
    a key only it reads without it (each would be silently ignored); for some classes only,
    :func:`_check_ro_gdiou_some`."""
    ro = [c for c, m in zip(TRACKING_CLASSES, v["association.first_metric"]) if m == "ro_gdiou_bev"]
    if np.any(v["association.crowded_threshold"] > 0):
        _check_crowded(v, given, source, ro)
        return
    if not ro:
        for key in RO_GDIOU_KEYS:
            if key in given:
                raise ConfigError(
                    f"{source}: '{key}' is read only with 'association.first_metric: ro_gdiou_bev' (MCTrack's "
                    f"association{', or association.crowded_threshold above 0' if key in CROWDED_KEYS else ''}); "
                    f"remove it"
                )
        return
    if len(ro) < len(TRACKING_CLASSES):
        _check_ro_gdiou_some(v, given, source)
        return
    refused = {
        "association.algorithm": (v["association.algorithm"] != "hungarian", "hungarian"),
        "association.two_stage": (v["association.two_stage"], "false"),
        "association.distance_gate": (bool(np.any(v["association.distance_gate"] > 0)), "0 for every class"),
    }
    for key, (bad, expected) in refused.items():
        if bad:
            raise ConfigError(
                f"{source}: '{key}' must be {expected} with 'association.first_metric: ro_gdiou_bev' (MCTrack's "
                f"association is one Hungarian stage without a centre gate)"
            )


def _check_crowded(v: dict, given: dict, source: str, ro: list[str]) -> None:
    """``association.crowded_threshold`` (Ro_GDIoU for the crowded pairs of stage 1) is part of the two-stage
    Hungarian association of classes scored by another stage-1 metric: refuse it on a class whose stage 1 is
    Ro_GDIoU already, with greedy matching or Fast-Poly's dense association, and MCTrack's pose keys."""
    both = [c for c, t in zip(TRACKING_CLASSES, v["association.crowded_threshold"]) if t > 0 and c in ro]
    if both:
        raise ConfigError(
            f"{source}: 'association.crowded_threshold.{both[0]}' must be 0 when its 'association.first_metric' is "
            f"ro_gdiou_bev (stage 1 is Ro_GDIoU already)"
        )
    if ro:
        _check_ro_gdiou_some(v, given, source)
        return
    _check_stage_one(
        v,
        given,
        source,
        "crowded pairs compare the track's predicted box",
        "'association.crowded_threshold' needs",
        "it acts in stage 1 of the two-stage association",
    )


def _check_ro_gdiou_some(v: dict, given: dict, source: str) -> None:
    """Ro_GDIoU for some classes only is stage 1 of the two-stage Hungarian association, the track's predicted box
    against the detection: refuse the keys of MCTrack's pose choice (read with every class only), greedy matching,
    and Fast-Poly's dense association (alignment GIoU, or a gate on every class)."""
    _check_stage_one(
        v,
        given,
        source,
        "with some classes, stage 1 compares the track's predicted box",
        "'association.first_metric: ro_gdiou_bev' for some classes needs",
        "it is stage 1 of the two-stage association",
    )


def gate_growth_rules(growth: tuple[str | float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The per-class rules of ``association.distance_gate_growth`` (values ``fixed``, ``missed_frames`` or a speed):
    (C,) bool, the classes gated at (k + 1) x their radius after k missed frames, and (C,) float64 m/s, the speed
    their radius grows by with the missed time (0: not by speed)."""
    frames = np.array([g == "missed_frames" for g in growth], dtype=bool)
    speed = np.array([0.0 if isinstance(g, str) else float(g) for g in growth], dtype=np.float64)
    return frames, speed


def _not_compiled_two_stage(v: dict) -> bool:
    """Whether the association is greedy matching or Fast-Poly's dense association (alignment GIoU, or a gate on
    every class), not the compiled two-stage Hungarian association that the stage-1 options act in."""
    metrics = set(v["association.first_metric"]) | {v["association.second_metric"]}
    dense = bool(np.all(v["association.distance_gate"] > 0)) or any(m.startswith("a_") for m in metrics)
    return v["association.algorithm"] != "hungarian" or dense


def _check_stage_one(v: dict, given: dict, source: str, pose_why: str, what: str, why: str) -> None:
    """A Ro_GDIoU option inside stage 1 of the two-stage Hungarian association (``what`` names it in the message):
    refuse MCTrack's pose keys (``pose_why``: why they are not read), greedy matching and Fast-Poly's dense
    association (alignment GIoU, or a gate on every class; ``why``)."""
    for key in ("association.track_pose", "association.track_pose_blend", "association.track_pose_rule"):
        if key in given:
            raise ConfigError(
                f"{source}: '{key}' is read only with 'association.first_metric: ro_gdiou_bev' for every class "
                f"({pose_why}); remove it"
            )
    if _not_compiled_two_stage(v):
        raise ConfigError(
            f"{source}: {what} 'association.algorithm: hungarian', no alignment GIoU metric and no distance gate on "
            f"every class ({why})"
        )


def _check_widening_gate(v: dict, source: str) -> None:
    """``association.distance_gate_growth`` missed_frames or a speed above 0 scales the gate of the two-stage
    Hungarian association (:func:`~grutrack.tracking.association.associate`): refuse it with greedy matching and
    Fast-Poly's dense association (alignment GIoU, or a gate on every class), whose fixed gate also picks stage 2's
    rows."""
    if _not_compiled_two_stage(v):
        raise ConfigError(
            f"{source}: 'association.distance_gate_growth' missed_frames or a speed above 0 needs "
            f"'association.algorithm: hungarian', no alignment GIoU metric and no distance gate on every class "
            f"(Fast-Poly's gate is fixed)"
        )


def _check_two_stage_pairs(v: dict, source: str, what: str, why: str) -> None:
    """Keys that act on the pairs of the two-stage Hungarian association
    (:func:`~grutrack.tracking.association.associate`; ``what``: the key and its value as the message names them,
    ``why``: where they act): the lost-newborn keys in stage 1, ``association.size_gate`` in both stages. Refuse
    them with greedy matching, Fast-Poly's dense association (alignment GIoU, or a gate on every class) and
    MCTrack's one-stage Ro_GDIoU association, which would ignore them."""
    one_stage = all(m == "ro_gdiou_bev" for m in v["association.first_metric"])
    if _not_compiled_two_stage(v) or one_stage:
        raise ConfigError(
            f"{source}: {what} needs 'association.algorithm: hungarian', no "
            f"alignment GIoU metric, no distance gate on every class and a first_metric other than ro_gdiou_bev "
            f"for some class ({why})"
        )


def _check_model_names(override: dict[str, str], source: str) -> None:
    """Every model named in ``motion.model_override`` is one of :data:`grutrack.motion.models.MODELS`."""
    if not override:
        return
    from grutrack.motion.models import MODELS

    names = sorted(m.upper() for m in MODELS)
    for cls, model in override.items():
        if model not in names:
            raise ConfigError(
                f"{source}: 'motion.model_override.{cls}' must be one of {', '.join(names)} "
                f"(a motion model of grutrack/motion/models.py), not {model!r}"
            )


def _section_refs() -> dict[str, dict[str, tuple[str, Any]]]:
    """Section -> key -> (the schema definition its value follows (``per_class_unit``, ``bool``, ...), its
    default: None for a required key, one value for every class for a per-class key)."""
    refs = {}
    for sec, spec in schema("tracker")["properties"].items():
        refs[sec] = {}
        for k, node in spec["properties"].items():
            ref = node["$ref"].rsplit("/", 1)[1]
            default = node.get("default")
            if default is not None and ref.startswith("per_class_"):
                default = {c: default for c in TRACKING_CLASSES}
            refs[sec][k] = (ref, default)
    return refs


def _yaml_scalar(value) -> str:
    """A setting's value as the preset spells it (true / false, names)."""
    return str(value).lower() if isinstance(value, bool) else str(value)


def _convert(val: Any, ref: str) -> Any:
    """A validated value in the form the tracker uses: per-class maps as (7,) arrays (tuples of names),
    model overrides upper-case, ``time_step: timestamps`` as None."""
    if ref in _NOISE_PER_CLASS:
        if val is None:  # not given: the joint filter reads none
            return None
        return {
            k: np.stack([np.diag(np.asarray(val[c][k], dtype=np.float64)) for c in TRACKING_CLASSES])
            for k in val["car"]
        }
    if ref == "nms_thresholds":  # one number for every class, or (7,) per class
        return float(val) if not isinstance(val, dict) else np.array([float(val[c]) for c in TRACKING_CLASSES])
    if ref.startswith("per_class_"):
        items = [val[c] for c in TRACKING_CLASSES]
        return tuple(items) if ref in _NAMED_PER_CLASS else np.asarray(items)
    if ref == "class_model_map":
        return {c: str(m).upper() for c, m in val.items()}
    if ref == "time_step":
        return None if val == "timestamps" else float(val)
    if ref in ("unit", "scale", "gate", "metres", "speed", "seconds", "cost"):
        return float(val)
    if ref in ("posint", "nonnegint"):
        return int(val)
    if ref == "punish":  # one integer for every class, or a map over the classes -> (7,) int64
        if isinstance(val, dict):
            return np.array([int(val[c]) for c in TRACKING_CLASSES], dtype=np.int64)
        return np.full(len(TRACKING_CLASSES), int(val), dtype=np.int64)
    return val
