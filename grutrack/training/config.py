"""Training configuration (YAML under ``grutrack/configs/training/``), validated key by key."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

import yaml

from grutrack.errors import ConfigError

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs" / "training"


@dataclass(frozen=True)
class TrainConfig:
    """See ``grutrack/configs/training/grukf.yaml`` for the meaning of every field."""

    mode: str
    epochs: int
    lr: float
    weight_decay: float
    seed: int
    device: str
    ss_model: str
    four_gru: bool
    class_gain: bool
    age_bins: int
    gap_bins: int
    yaw_flip: bool
    aux_inputs: bool
    tracker_preset: str
    motion_config: str
    gt_match_distance: float
    loss_weights: tuple
    prediction_weight: float
    resample_profiles: tuple
    matched_box: str
    val_every: int
    checkpoint_every: int


def _real(v) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


_CHECKS = {
    "mode": (lambda v: v in ("semi_supervised", "supervised"), "'semi_supervised' or 'supervised'"),
    "epochs": (lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1, "an integer >= 1"),
    "lr": (lambda v: _real(v) and v > 0, "a positive number"),
    "weight_decay": (lambda v: _real(v) and v >= 0, "a number >= 0"),
    "seed": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
    "device": (lambda v: isinstance(v, str) and v != "", "a device name such as auto, cpu or cuda"),
    "ss_model": (lambda v: str(v).upper() in ("CTRA", "BICYCLE"), "CTRA or Bicycle"),
    "four_gru": (lambda v: isinstance(v, bool), "true or false"),
    "class_gain": (lambda v: isinstance(v, bool), "true or false"),
    "age_bins": (lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 100,
                 "an integer from 0 to 100"),
    "gap_bins": (lambda v: isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 100,
                 "an integer from 0 to 100"),
    "yaw_flip": (lambda v: isinstance(v, bool), "true or false"),
    "aux_inputs": (lambda v: isinstance(v, bool), "true or false"),
    "tracker_preset": (lambda v: isinstance(v, str) and v != "", "a tracker preset name or path"),
    "motion_config": (lambda v: isinstance(v, str) and v != "", "a motion config name or path"),
    "gt_match_distance": (lambda v: _real(v) and v > 0, "a positive distance in metres"),
    "loss_weights": (lambda v: isinstance(v, list) and len(v) == 9 and all(isinstance(x, (int, float)) and x >= 0
                                                                            for x in v), "9 non-negative numbers"),
    "prediction_weight": (lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0,
                          "a number >= 0"),
    "resample_profiles": (lambda v: isinstance(v, list) and all(isinstance(x, str) and x for x in v),
                          "a list of detector profile names or YAML paths (empty: no resampling)"),
    "matched_box": (lambda v: v in ("filter", "detection"), "'filter' or 'detection'"),
    "val_every": (lambda v: isinstance(v, int) and v >= 0, "an integer >= 0"),
    "checkpoint_every": (lambda v: isinstance(v, int) and v >= 0, "an integer >= 0"),
}


#: fields holding real numbers: a string that reads as one is taken as that number (PyYAML reads ``1e-5``, which
#: has no decimal point, as a string)
_FLOAT_FIELDS = ("lr", "weight_decay", "gt_match_distance", "prediction_weight")


def _as_float(v):
    """``v``, or the float a numeric string spells (``'1e-5'``); anything else unchanged (then refused)."""
    if isinstance(v, str):
        try:
            return float(v.strip())
        except ValueError:
            return v
    return v


def load_train_config(name_or_path: str | Path = "grukf", overrides: dict | None = None,
                      flags: dict | None = None) -> TrainConfig:
    """Load a training config by name or path, apply ``overrides`` (key -> value), and validate.

    ``flags`` (key -> command-line flag) names where an override came from: a bad override is blamed on its
    flag, not on the file."""
    p = Path(name_or_path)
    if not p.suffix:
        p = CONFIG_DIR / f"{name_or_path}.yaml"
    if not p.is_file():
        raise ConfigError(f"training config {p} does not exist")
    try:
        raw = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc})") from exc
    if not isinstance(raw, dict):
        raise ConfigError(f"{p}: expected a mapping of training settings, got {type(raw).__name__}")
    for k, v in (overrides or {}).items():
        flag = (flags or {}).get(k)
        if flag and k in _CHECKS and not _CHECKS[k][0](_as_float(v) if k in _FLOAT_FIELDS else v):
            raise ConfigError(f"{flag} must be {_CHECKS[k][1]}, got {v!r}")
    raw.update(overrides or {})
    return config_from_dict(raw, str(p))


def config_from_dict(raw: dict, source: str = "<dict>") -> TrainConfig:
    """Validate a training config dict; unknown, missing or ill-typed keys raise :class:`ConfigError`."""
    names = [f.name for f in fields(TrainConfig)]
    raw = {k: _as_float(v) if k in _FLOAT_FIELDS else v for k, v in raw.items()}
    if isinstance(raw.get("loss_weights"), list):
        raw["loss_weights"] = [_as_float(x) for x in raw["loss_weights"]]
    for k in raw:
        if k not in names:
            raise ConfigError(f"{source}: unknown key '{k}' (expected one of: {', '.join(names)})")
    for k in names:
        if k not in raw:
            raise ConfigError(f"{source}: missing key '{k}'")
        ok, expected = _CHECKS[k]
        if not ok(raw[k]):
            raise ConfigError(f"{source}: '{k}' must be {expected}, got {raw[k]!r}")
    vals = dict(raw)
    vals["loss_weights"] = tuple(float(x) for x in raw["loss_weights"])
    vals["resample_profiles"] = tuple(str(x) for x in raw["resample_profiles"])
    vals["lr"], vals["weight_decay"] = float(raw["lr"]), float(raw["weight_decay"])
    vals["gt_match_distance"] = float(raw["gt_match_distance"])
    vals["prediction_weight"] = float(raw["prediction_weight"])
    return TrainConfig(**{k: vals[k] for k in names})
