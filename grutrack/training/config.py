"""Training configuration (YAML under ``grutrack/configs/training/``), validated against its JSON Schema by the
one config loader (:mod:`grutrack.config_loader`).

The network's options are one section, ``network`` (the fields of the network's architecture,
:class:`~grutrack.motion.grukf.GRUKFConfig`, that a config may set; the schema names them, describes them and
gives the default of each optional one). A network option given at the top level, as configs and overrides written
before the section have them (``{gap_bins: 5}``), is read as that option of the section."""

from __future__ import annotations

from dataclasses import MISSING, dataclass, fields
from functools import cache
from pathlib import Path

from grutrack.config_loader import read_config, schema, validate
from grutrack.errors import ConfigError


@dataclass(frozen=True)
class TrainConfig:
    """See ``grutrack/configs/training/grukf.yaml`` for the meaning of every field. ``network``: the network's
    options, every key of the schema's ``network`` section (the defaults of those left out filled in); the
    architecture they make is :func:`grutrack.training.network.network_config`."""

    mode: str
    epochs: int
    lr: float
    weight_decay: float
    seed: int
    device: str
    network: dict
    tracker_preset: str
    motion_config: str
    gt_match_distance: float
    loss_weights: tuple
    prediction_weight: float
    resample_profiles: tuple
    matched_box: str
    val_every: int
    checkpoint_every: int
    sources: tuple = ()  # extra training sources (grutrack/training/sources.py), mappings
    scenes_per_step: int = 1  # scenes per optimizer step (1: the paper's), the network batched over them
    validation_scenes: int = 0  # training-split scenes held out for validation when no --val-split is given
    validation_draws: int = 1  # simulated detection sets per resample profile on those scenes
    select_checkpoint: str = "last"  # model.pt: "last", "best_val_amota" or "best_val_amota_1se" (selection.py)
    resample_mix: str = "epoch"  # resampled profiles take turns by "epoch" or are mixed over the "scene"s
    training_classes: str = "tracked"  # the classes whose tracks train the network: "tracked" or "own_model"
    gt_term_gate: float = 0.0  # metres: a held GT farther than this from the track gives no GT term (0: off)
    centre_huber_delta: float = 0.0  # metres: x, y residuals beyond it cost linearly, not squared (0: squared)
    lr_min: float = 0.0  # the cosine schedule's floor: the learning rate of the last step
    yaw_loss: str = "heading"  # the yaw residual wrapped as a "heading" (2 pi) or an "axis" (pi)
    grad_clip_norm: float = 0.0  # the L2 norm a step's gradient is clipped to (0: not clipped, the paper's)


@cache
def _network_schema() -> dict:
    """The schema of the ``network`` section: ``{option: schema node}``."""
    return schema("training")["properties"]["network"]["properties"]


def network_options(section: dict) -> dict:
    """The network section with every option of the schema, in its order: the given value, else the option's
    schema default (an option the section lacks and the schema has no default for stays out, for validation to
    name)."""
    return {
        k: section[k] if k in section else node["default"]
        for k, node in _network_schema().items()
        if k in section or "default" in node
    }


def nested(raw: dict) -> dict:
    """``raw`` with the network options given at the top level (the layout before the ``network`` section)
    moved into the section, where they take the place of the section's own value."""
    flat = {k: raw[k] for k in _network_schema() if k in raw}
    section = raw.get("network")
    if not flat or not isinstance(section, (dict, type(None))):
        return raw
    return {**{k: v for k, v in raw.items() if k not in flat}, "network": {**(section or {}), **flat}}


def config_record(d: dict) -> dict:
    """A training config as a checkpoint or training.yaml of any version records it (``asdict`` of its
    :class:`TrainConfig`), in the current layout: the network options in their section with the defaults of those
    left out, and the defaults of the keys that version did not have yet (the behaviour it had)."""
    out = {**{f.name: f.default for f in fields(TrainConfig) if f.default is not MISSING}, **nested(d)}
    out["network"] = network_options(out.get("network") or {})
    return out


def _as_float(v):
    """``v``, or the float a numeric string spells (``'1e-5'``); anything else unchanged (then refused)."""
    if isinstance(v, str):
        try:
            return float(v.strip())
        except ValueError:
            return v
    return v


def _floats(raw: dict, props: dict) -> dict:
    """``raw`` with the values of the keys the schema ``props`` types as numbers read as floats when they spell
    one (PyYAML reads ``1e-5``, which has no decimal point, as a string)."""
    return {k: _as_float(v) if props.get(k, {}).get("type") == "number" else v for k, v in raw.items()}


def load_train_config(
    name_or_path: str | Path = "grukf", overrides: dict | None = None, flags: dict | None = None
) -> TrainConfig:
    """Load a training config by name or path, apply ``overrides`` (key -> value; the network's options at the
    top level or in a ``network`` mapping), and validate against ``grutrack/configs/schemas/training.schema.yaml``.

    ``flags`` (key -> command-line flag) names where an override came from: a bad override is blamed on its
    flag, not on the file."""
    raw, source = read_config("training", name_or_path)
    over = nested(overrides or {})
    raw = nested(raw)
    if isinstance(over.get("network"), dict) and isinstance(raw.get("network"), dict):
        over = {**over, "network": {**raw["network"], **over["network"]}}
    raw.update(over)
    return config_from_dict(raw, source, flags)


def config_from_dict(raw: dict, source: str = "<dict>", flags: dict | None = None) -> TrainConfig:
    """Validate a training config dict; unknown, missing or ill-typed keys raise :class:`ConfigError`."""
    names = [f.name for f in fields(TrainConfig)]
    props = schema("training")["properties"]
    raw = _floats(nested(raw), props)
    if isinstance(raw.get("network"), dict):
        raw["network"] = _floats(raw["network"], _network_schema())
    if isinstance(raw.get("loss_weights"), list):
        raw["loss_weights"] = [_as_float(x) for x in raw["loss_weights"]]
    validate("training", raw, source, flags)
    vals = dict(raw)
    vals["network"] = network_options(raw["network"])
    vals["loss_weights"] = tuple(float(x) for x in raw["loss_weights"])
    vals["resample_profiles"] = tuple(str(x) for x in raw["resample_profiles"])
    vals["sources"] = tuple(dict(x) for x in raw.get("sources", []))
    for k, node in props.items():
        if node.get("type") == "number" and k in raw:
            vals[k] = float(raw[k])
    network_classes = vals["network"]["network_classes"]
    if vals.get("training_classes") == "own_model" and network_classes == "all":
        where = (flags or {}).get("training_classes", f"{source}: 'training_classes'")
        raise ConfigError(
            f"{where} 'own_model' needs network.network_classes 'ss_model' or 'own_model' (with 'all' "
            f"every class is tracked with the network's one SS model, not the one it would be trained "
            f"with)"
        )
    return TrainConfig(**{k: vals[k] for k in names if k in vals})
