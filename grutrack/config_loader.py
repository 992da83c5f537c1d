"""One loader for every configuration kind the toolkit ships (tracker presets, training configs, ...): one
name-or-path rule, YAML read with the file named in every error, overrides merged key by key, and validation
against the kind's JSON Schema (``grutrack/configs/schemas/<kind>.schema.yaml``).

Errors name the file (or the command-line flag an override came from), the key path and the expectation,
which is the ``description`` of the schema node that failed: ``ekf.yaml: 'lifecycle.max_age.car' must be an
integer >= 1, got 0``.
"""

from __future__ import annotations

import copy
import difflib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from grutrack.errors import ConfigError
from grutrack.formats import expectation_of_type

CONFIG_ROOT = Path(__file__).resolve().parent / "configs"


@dataclass(frozen=True)
class ConfigKind:
    """A kind of configuration: its folder of shipped files under ``grutrack/configs/`` (None: given by path
    only), its schema, and what a user calls one (for messages)."""

    folder: str | None
    schema: str
    what: str
    holds: str  # what the file's top-level mapping holds, for "expected a mapping of ..."


KINDS: dict[str, ConfigKind] = {
    "tracker": ConfigKind(
        "trackers",
        "tracker.schema.yaml",
        "tracker preset",
        "sections preprocessing, association, lifecycle, motion, output",
    ),
    "training": ConfigKind("training", "training.schema.yaml", "training config", "training settings"),
    "motion": ConfigKind("motion", "motion.schema.yaml", "motion config", "sections models, classes"),
    "paper": ConfigKind(None, "paper.schema.yaml", "paper numbers file", "sections tables, figures"),
    "registry": ConfigKind(None, "registry.schema.yaml", "detection registry", "one key 'sources'"),
    "published": ConfigKind(
        "published", "published.schema.yaml", "published results file", "keys publication, source, results"
    ),
    "detector_profile": ConfigKind(
        "detector_profiles", "detector_profile.schema.yaml", "detector profile", "profile settings"
    ),
}


def shipped_names(kind: str) -> list[str]:
    """Names of the shipped configurations of a kind (none for a kind given by path only)."""
    folder = KINDS[kind].folder
    return sorted(p.stem for p in (CONFIG_ROOT / folder).glob("*.yaml")) if folder else []


def config_path(kind: str, name_or_path: str | Path) -> Path:
    """The one name-or-path rule: a value ending in ``.yaml`` / ``.yml``, or naming an existing file, is a
    path; anything else is the name of a shipped configuration (``grutrack/configs/<folder>/<name>.yaml``)."""
    k = KINDS[kind]
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.is_file() or len(p.parts) > 1 or k.folder is None:
        if not p.is_file():
            raise ConfigError(f"{k.what} {p} does not exist")
        return p
    cand = CONFIG_ROOT / k.folder / f"{name_or_path}.yaml"
    if not cand.is_file():
        raise ConfigError(
            f"unknown {k.what} '{name_or_path}' (available: {', '.join(shipped_names(kind))}; or "
            f"give a path to a YAML file)"
        )
    return cand


def read_config(kind: str, name_or_path: str | Path) -> tuple[dict, str]:
    """The raw mapping of a configuration file and its path (as a string, for messages)."""
    from grutrack.io import read_yaml

    path = config_path(kind, name_or_path)
    try:
        raw = read_yaml(path, KINDS[kind].what)
    except Exception as exc:  # an InputFormatError of the reader: a bad config is a ConfigError
        raise ConfigError(str(exc)) from exc
    raw = {} if raw is None else raw
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a mapping of {KINDS[kind].holds}, got {type(raw).__name__}")
    return raw, str(path)


def merge(base: dict, overrides: dict) -> dict:
    """``base`` with ``overrides`` merged in key by key (nested mappings recursively); neither is changed."""
    out = copy.deepcopy(base)
    for k, v in overrides.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


@cache
def schema(kind: str) -> dict:
    """The kind's JSON Schema (read once)."""
    from grutrack.io import parse_yaml

    return parse_yaml((CONFIG_ROOT / "schemas" / KINDS[kind].schema).read_text())


def validate(kind: str, raw: dict, source: str, flags: dict[str, str] | None = None) -> None:
    """Check ``raw`` against the kind's schema; the first error (the shallowest) raises :class:`ConfigError`.

    ``flags`` (top-level key -> command-line flag): an error under such a key is blamed on the flag."""
    errors = sorted(
        _validator(kind).iter_errors(raw),
        key=lambda e: (len(e.absolute_path), [str(p) for p in e.absolute_path], e.validator),
    )
    if errors:
        raise ConfigError(_message(_inner(errors[0]), raw, kind, source, flags or {}))


@cache
def _validator(kind: str):
    """A Draft 2020-12 validator of the kind's schema whose ``number`` is finite (YAML's .nan and .inf are not
    numbers here: NaN passes every comparison, so a range check alone would let it through)."""
    import math

    from jsonschema import Draft202012Validator, validators

    finite = Draft202012Validator.TYPE_CHECKER.redefine(
        "number", lambda _, x: isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
    )
    cls = validators.extend(Draft202012Validator, type_checker=finite)
    return cls(schema(kind))


def _inner(err):
    """For a mapping or list that fits no branch of a oneOf / anyOf, the error inside the branch of its own
    type (a per-class map missing a class is reported as that missing class, not as "fits no branch")."""
    from jsonschema.exceptions import best_match

    while err.validator in ("oneOf", "anyOf") and err.context and isinstance(err.instance, (dict, list)):
        same_type = [e for e in err.context if not (e.validator == "type" and not e.relative_path)]
        if not same_type:
            break
        err = best_match(same_type)
    return err


def _message(err, raw: dict, kind: str, source: str, flags: dict[str, str]) -> str:
    """One line: where, which key, what was expected, what was given."""
    path = [str(p) for p in err.absolute_path]
    key = ".".join(path)
    prefix = key + "." if key else ""
    if err.validator == "required":
        missing = next(r for r in err.validator_value if r not in err.instance)
        return f"{source}: missing key '{prefix}{missing}'"
    if err.validator == "additionalProperties":
        allowed = list(err.schema.get("properties", {}))
        extra = next(k for k in err.instance if k not in allowed)
        close = difflib.get_close_matches(str(extra), allowed, n=1)
        hint = f"; did you mean '{prefix}{close[0]}'?" if close else ""
        return (
            f"{source}: unknown key '{prefix}{extra}' (expected one of: {', '.join(prefix + a for a in allowed)}){hint}"
        )
    at = list(err.absolute_path)
    depth, expected = _described(schema(kind), at)
    if expected is None or (depth < len(at) and not any(isinstance(p, int) for p in at[depth:])):
        depth, expected = len(at), _expectation(err)  # described above only when inside a list: the list

    value = raw
    for part in list(err.absolute_path)[:depth]:
        value = value[part]
    key = ".".join(path[:depth])
    where = flags[key] if key in flags else f"{source}: '{key}'"
    return f"{where} must be {expected}, got {value!r}"


def _described(root: dict, path: list) -> tuple[int, str | None]:
    """(depth, description) of the deepest node along ``path`` whose schema has a ``description`` (an error
    inside a list whose items have none is stated for the whole list)."""

    def resolve(node: dict) -> dict:
        while isinstance(node, dict) and "$ref" in node:
            node = root["$defs"][node["$ref"].rsplit("/", 1)[1]]
        return node

    node, best = resolve(root), (0, None)
    for depth, part in enumerate(path, start=1):
        if isinstance(part, int):
            node = node.get("items", {})
        elif part in node.get("properties", {}):
            node = node["properties"][part]
        else:
            node = node.get("additionalProperties", {}) if isinstance(node.get("additionalProperties"), dict) else {}
        node = resolve(node)
        if "description" in node:
            best = (depth, node["description"])
    return best


def _expectation(err) -> str:
    """A readable expectation for a schema node without a description."""
    v = err.validator_value
    if err.validator == "enum":
        return "one of " + ", ".join(str(x) for x in v)
    if err.validator == "type":
        return expectation_of_type(v, "a mapping")
    bounds = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}
    if err.validator in bounds:
        return f"a number {bounds[err.validator]} {v}"
    if err.validator == "pattern":
        return f"text matching {v}"
    if err.validator in ("minItems", "minProperties", "minLength"):
        return f"at least {v} {'characters' if err.validator == 'minLength' else 'entries'}"
    if err.validator == "const":
        return repr(v)
    return err.message


def load_config(
    kind: str, name_or_path: str | Path, overrides: dict | None = None, flags: dict[str, str] | None = None
) -> tuple[dict, str]:
    """Read, merge ``overrides``, validate: the checked mapping and its source. ``flags``: see :func:`validate`
    (overrides given on the command line are checked alone first, so their error names the flag)."""
    raw, source = read_config(kind, name_or_path)
    if overrides:
        raw = merge(raw, overrides)
    validate(kind, raw, source, flags)
    return raw, source
