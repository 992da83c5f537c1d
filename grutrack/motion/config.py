"""Per-class motion configuration: which state-space model each tracking class uses and its Q, R, P0.

The default file, ``grutrack/configs/motion/polymot_nusc.yaml``, holds Poly-MOT's published nuScenes values
(every key documented there with its source). :func:`load_motion_config` validates a file strictly (a missing,
unknown or misspelt key raises :class:`grutrack.errors.ConfigError` naming the file and the key) and returns,
per tracking class, numpy matrices of the right dimension for the class's model.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from grutrack.boxes import BOX_DIM
from grutrack.classes import TRACKING_CLASSES
from grutrack.config_loader import config_path, load_config
from grutrack.errors import ConfigError
from grutrack.motion.models import MODELS, MotionModel, make_model

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs" / "motion"
DEFAULT_CONFIG = CONFIG_DIR / "polymot_nusc.yaml"

# minimum eigenvalue requirement per matrix: R and P0 positive definite, Q positive semi-definite
_STRICT = {"P0": True, "R": True, "Q": False}


def resolve_config_path(path: str | Path | None = None) -> Path:
    """A config file path: None -> the default, a bare name (``polymot_nusc``) -> ``configs/motion/<name>.yaml``
    (the one name-or-path rule, :func:`grutrack.config_loader.config_path`)."""
    return DEFAULT_CONFIG if path is None else config_path("motion", path)


def _fail(path: Path, key: str, msg: str) -> ConfigError:
    return ConfigError(f"{path}: key '{key}': {msg}")


def _canonical_model(path: Path, key: str, name: str) -> str:
    """The canonical model name (a key of :data:`MODELS`: ``CTRA``, ``Bicycle``, ``CA``, ``CV``, ...) of a
    case-insensitive spelling; an unknown name is a :class:`ConfigError` naming ``key``."""
    lookup = {k.lower(): k for k in MODELS}
    if not isinstance(name, str) or name.lower() not in lookup:
        raise _fail(path, key, f"unknown motion model {name!r} (expected one of {sorted(MODELS)})")
    return lookup[name.lower()]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _matrix(path: Path, key: str, value, dim: int, strict: bool) -> np.ndarray:
    """A ``(dim, dim)`` matrix from a scalar (times I), a diagonal list or a full nested list; validated."""
    if _is_number(value):
        M = float(value) * np.eye(dim)
    elif isinstance(value, list) and all(_is_number(v) for v in value):
        if len(value) != dim:
            raise _fail(path, key, f"diagonal has {len(value)} values, the model needs {dim}")
        M = np.diag(np.asarray(value, dtype=np.float64))
    elif isinstance(value, list) and all(isinstance(r, list) and all(_is_number(v) for v in r) for r in value):
        M = np.asarray(value, dtype=np.float64) if len({len(r) for r in value}) <= 1 else None
        if M is None or M.shape != (dim, dim):
            raise _fail(path, key, f"full matrix must be {dim} x {dim}")
        if not np.allclose(M, M.T, rtol=0.0, atol=1e-12 * max(1.0, np.abs(M).max())):
            raise _fail(path, key, "matrix is not symmetric")
    else:
        raise _fail(path, key, "expected a number, a list of numbers (diagonal) or a list of lists (matrix)")
    if not np.all(np.isfinite(M)):
        raise _fail(path, key, "values must be finite")
    low = np.linalg.eigvalsh(M).min()
    if (strict and low <= 0.0) or (not strict and low < 0.0):
        kind = "positive definite" if strict else "positive semi-definite"
        raise _fail(path, key, f"matrix must be {kind} (smallest eigenvalue {low:g})")
    return M


def _noise(path: Path, where: str, node: Mapping, model: str) -> dict[str, np.ndarray]:
    """Q, R, P0 of one config node as matrices sized for ``model``."""
    dim_x = MODELS[model].dim_x
    dims = {"P0": dim_x, "Q": dim_x, "R": BOX_DIM}
    return {k: _matrix(path, f"{where}.{k}", node[k], dims[k], _STRICT[k]) for k in ("Q", "R", "P0")}


def _model_defaults(path: Path, models_node) -> dict[str, dict]:
    """Schema-checked ``models`` section -> ``{model: {"Q", "R", "P0", "params"}}``."""
    out = {}
    for given, node in models_node.items():
        where = f"models.{given}"
        name = _canonical_model(path, where, given)
        params = node["params"] if node["params"] is not None else {}
        try:
            make_model(name, **params)
        except (TypeError, ValueError) as exc:
            raise _fail(path, f"{where}.params", str(exc)) from None
        out[name] = {**_noise(path, where, node, name), "params": dict(params)}
    return out


def _overrides(path: Path, model_override) -> dict[str, str]:
    """``model_override`` (None, a model name for all classes, or ``{class: model}``) -> ``{class: model}``."""
    if model_override is None:
        return {}

    def model(key: str, name) -> str:
        return _canonical_model(path, key, name)

    if isinstance(model_override, str):
        return {cls: model("model_override", model_override) for cls in TRACKING_CLASSES}
    out = {}
    for cls, name in dict(model_override).items():
        if cls not in TRACKING_CLASSES:
            expected = list(TRACKING_CLASSES)
            raise _fail(path, f"model_override.{cls}", f"unknown tracking class (expected one of {expected})")
        out[cls] = model(f"model_override.{cls}", name)
    return out


def load_motion_config(path: str | Path | None = None, model_override=None) -> dict[str, dict]:
    """Load and validate a motion config.

    Args:
        path: a YAML file, a bare name under ``grutrack/configs/motion/``, or None for ``polymot_nusc``.
        model_override: None; a model name used for every class; or ``{class: model}``. A class switched to a
            model other than its own takes that model's defaults from the file's ``models`` section.

    Returns:
        ``{class_name: {"model": str, "Q": (d, d), "R": (9, 9), "P0": (d, d), "params": dict}}`` for the 7
        tracking classes, d the state dimension of the class's model, float64 arrays; a class with a ``moving``
        block (and no override) also has ``"moving": {"model", "Q", "R", "P0", "params", "speed" (m/s)}``, the
        model of its tracks born at or above that detected speed (:func:`_moving`).

    Raises:
        ConfigError: unreadable file, missing / unknown key, unknown model or class, wrong matrix size,
            non-symmetric or non-positive matrix; the message names the file and the key.
    """
    path = resolve_config_path(path)
    raw, _ = load_config("motion", path)  # layout and value types (grutrack/configs/schemas/motion.schema.yaml)
    defaults = _model_defaults(path, raw["models"])
    override = _overrides(path, model_override)
    out = {}
    for cls in TRACKING_CLASSES:
        where = f"classes.{cls}"
        node = raw["classes"][cls]
        own = _canonical_model(path, f"{where}.model", node["model"])
        noise = _noise(path, where, node, own)
        model = override.get(cls, own)
        if model not in defaults:
            key = f"models.{model}" if model == own else f"model_override.{cls}"
            raise _fail(
                path,
                key,
                f"no defaults for motion model {model} under 'models' (P0, Q, R, params: its constructor parameters)",
            )
        if model != own:
            noise = {k: defaults[model][k].copy() for k in ("Q", "R", "P0")}
        out[cls] = {"model": model, **noise, "params": dict(defaults[model]["params"])}
        if node.get("moving") is not None and cls not in override:  # an override sets the class's one model
            out[cls]["moving"] = _moving(path, f"{where}.moving", node["moving"], own, defaults)
    return out


def _moving(path: Path, where: str, node: Mapping, own: str, defaults: dict) -> dict:
    """A class's model for the tracks born moving (``classes.<class>.moving``): ``{"model", "Q", "R", "P0",
    "params", "speed"}``, speed in m/s (a track is born in it when its first detection's speed is at least this)."""
    model = _canonical_model(path, f"{where}.model", node["model"])
    if model == own:
        raise _fail(path, f"{where}.model", f"is the class's own model {own}; a moving model must differ from it")
    if model not in defaults:
        raise _fail(path, f"{where}.model", f"no defaults for motion model {model} under 'models' (its params)")
    return {
        "model": model,
        **_noise(path, where, node, model),
        "params": dict(defaults[model]["params"]),
        "speed": float(node["speed"]),
    }


def build_models(config: Mapping[str, dict]) -> dict[str, MotionModel]:
    """One model instance per model name used in a loaded config: ``{model_name: MotionModel}``."""
    models = {}
    for entry in config.values():
        if entry["model"] not in models:
            models[entry["model"]] = make_model(entry["model"], **entry["params"])
    return models


def class_matrices(config: Mapping[str, dict], labels: np.ndarray, key: str) -> np.ndarray:
    """Per-track noise ``(N, d, d)`` for class ``labels (N,)`` (indices into TRACKING_CLASSES), ``key`` in Q, R, P0.

    All labels must use models of one state dimension (one filter batch); raises ValueError otherwise.
    """
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    names = [TRACKING_CLASSES[i] for i in np.unique(labels)]
    shapes = {config[c][key].shape for c in names}
    if len(shapes) > 1:
        raise ValueError(f"classes {names} have {key} of different shapes {sorted(shapes)}; filter them separately")
    if not names:
        d = BOX_DIM if key == "R" else 0
        return np.zeros((0, d, d))
    table = np.zeros((len(TRACKING_CLASSES),) + shapes.pop())
    for c in names:
        table[TRACKING_CLASSES.index(c)] = config[c][key]
    return table[labels]
