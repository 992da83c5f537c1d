"""Training configuration (YAML under ``grutrack/configs/training/``), validated against its JSON Schema by the
one config loader (:mod:`grutrack.config_loader`)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from grutrack.config_loader import read_config, validate
from grutrack.errors import ConfigError


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
    gain_prior: str
    network_classes: str
    tracker_preset: str
    motion_config: str
    gt_match_distance: float
    loss_weights: tuple
    prediction_weight: float
    resample_profiles: tuple
    matched_box: str
    val_every: int
    checkpoint_every: int
    sources: tuple = ()          # extra training sources (grutrack/training/sources.py), mappings
    scenes_per_step: int = 1     # scenes per optimizer step (1: the paper's), the network batched over them
    validation_scenes: int = 0   # training-split scenes held out for validation when no --val-split is given
    select_checkpoint: str = "last"   # model.pt: "last", "best_val_amota" or "best_val_amota_1se" (selection.py)
    resample_mix: str = "epoch"  # resampled profiles take turns by "epoch" or are mixed over the "scene"s
    training_classes: str = "tracked"   # the classes whose tracks train the network: "tracked" or "own_model"
    gt_term_gate: float = 0.0    # metres: a held GT farther than this from the track gives no GT term (0: off)
    centre_huber_delta: float = 0.0   # metres: x, y residuals beyond it cost linearly, not squared (0: squared)
    lr_min: float = 0.0          # the cosine schedule's floor: the learning rate of the last step
    yaw_loss: str = "heading"    # the yaw residual wrapped as a "heading" (2 pi) or an "axis" (pi)
    coast_yaw_rate: str = "keep"   # a coasting track's turn rate: "keep" (the SS model's) or "zero"
    coast_acceleration: str = "keep"   # a coasting track's acceleration: "keep" (the SS model's) or "zero"
    grad_clip_norm: float = 0.0  # the L2 norm a step's gradient is clipped to (0: not clipped, the paper's)


#: fields holding real numbers: a string that reads as one is taken as that number (PyYAML reads ``1e-5``, which
#: has no decimal point, as a string)
_FLOAT_FIELDS = ("lr", "weight_decay", "gt_match_distance", "prediction_weight", "gt_term_gate",
                 "centre_huber_delta", "lr_min", "grad_clip_norm")


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
    """Load a training config by name or path, apply ``overrides`` (key -> value), and validate against
    ``grutrack/configs/schemas/training.schema.yaml``.

    ``flags`` (key -> command-line flag) names where an override came from: a bad override is blamed on its
    flag, not on the file."""
    raw, source = read_config("training", name_or_path)
    raw.update(overrides or {})
    return config_from_dict(raw, source, flags)


def config_from_dict(raw: dict, source: str = "<dict>", flags: dict | None = None) -> TrainConfig:
    """Validate a training config dict; unknown, missing or ill-typed keys raise :class:`ConfigError`."""
    names = [f.name for f in fields(TrainConfig)]
    raw = {k: _as_float(v) if k in _FLOAT_FIELDS else v for k, v in raw.items()}
    if isinstance(raw.get("loss_weights"), list):
        raw["loss_weights"] = [_as_float(x) for x in raw["loss_weights"]]
    validate("training", raw, source, flags)
    vals = dict(raw)
    vals["loss_weights"] = tuple(float(x) for x in raw["loss_weights"])
    vals["resample_profiles"] = tuple(str(x) for x in raw["resample_profiles"])
    vals["sources"] = tuple(dict(x) for x in raw.get("sources", []))
    for k in _FLOAT_FIELDS:
        if k in raw:
            vals[k] = float(raw[k])
    own = "network_classes" if vals["network_classes"] == "own_model" else (
        "training_classes" if vals.get("training_classes") == "own_model" else None)
    if own and vals.get("scenes_per_step", 1) > 1:
        where = (flags or {}).get("scenes_per_step", f"{source}: 'scenes_per_step'")
        raise ConfigError(f"{where} must be 1 with {own} 'own_model' (its groups of one model each call "
                          f"the network separately), got {vals['scenes_per_step']!r}")
    if vals.get("training_classes") == "own_model" and vals["network_classes"] == "all":
        where = (flags or {}).get("training_classes", f"{source}: 'training_classes'")
        raise ConfigError(f"{where} 'own_model' needs network_classes 'ss_model' or 'own_model' (with 'all' every "
                          f"class is tracked with the network's one SS model, not the one it would be trained with)")
    return TrainConfig(**{k: vals[k] for k in names if k in vals})
