"""One description per input format, and one checker that names the first failing field.

Each file format grutrack reads is described once, as a JSON Schema under ``grutrack/configs/schemas/formats/``
(:data:`FORMATS`); the paper's numbers are a configuration kind of :mod:`grutrack.config_loader` with their
schema beside the other configuration schemas. Every reader checks a file against its description before using
it, and a file that does not fit raises :class:`~grutrack.errors.InputFormatError` with one line naming the file,
the field path and what was expected (the ``description`` of the schema node that failed)::

    d.json: field 'results['3e87…'][2].rotation' must be a unit quaternion [w, x, y, z] (...), got [2.0, 0, 0, 0]

Field paths: object properties the schema names are joined with dots (``meta.use_camera``), other keys
(sample tokens, log ids) are subscripts in quotes (``results['3e87…']``), list items are indices (``[2]``); the keys
of an object marked ``dottedKeys`` (metric and class names) are joined with dots too (``per_class.car.amota``). A table
(feather, CSV, a pickled DataFrame) is described by its row: its errors name the row and the column.

Keywords beyond JSON Schema (what a number array of a pickle or a quaternion needs):

- ``unitNorm: tol`` on an array of numbers: its Euclidean norm is 1 within ``tol``;
- ``unitNormOf: {keys: [...], tolerance: tol}`` on an object (a table row): the numbers at those keys have norm 1;
- ``ndarray: {dtype: number|integer|string, shape: [null | int, ...], exclusiveMinimum: x, enum: [...],
  unique: true}`` on a value of a pickle: a numpy array of that kind and shape (``null``: any length; number arrays
  are finite), its values above ``x``, among ``enum``, each once;
- ``sameLength: [key, ...]`` on an object: the values at those keys have the same first dimension;
- ``rowContext: [column, ...]`` on a table: the columns that name a row in messages; ``dottedKeys`` (see above).

A number is finite and not a boolean (JSON's true / false, and NaN / Infinity, which Python's JSON reader
accepts, are not numbers here); the type ``nan`` is NaN, which a metric may be where it is not defined. The schema
files are JSON text (YAML too), read without a YAML parser.

Large documents (a detection file of a million boxes) are checked at the level of arrays first
(:class:`RecordPlan`, derived from the same schema); only when that finds something does this schema run on the
part that failed, to name the field. Both read the same description, so they accept the same files.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from functools import cache
from pathlib import Path
from typing import Any

from grutrack.errors import InputFormatError

SCHEMA_DIR = Path(__file__).resolve().parent / "configs" / "schemas" / "formats"

#: format name -> what a user calls such a file (the schema is ``<name>.schema.yaml`` in :data:`SCHEMA_DIR`)
FORMATS: dict[str, str] = {
    "nusc_detections": "nuScenes detection submission JSON",
    "nusc_tracking": "nuScenes tracking submission JSON",
    "metrics": "metrics JSON of grutrack evaluate",
    "lt3d_detections": "LT3D detection table (Argoverse 2)",
    "av2_tracks": "AV2 tracking pickle",
    "av2_annotations": "AV2 annotations table",
    "av2_poses": "AV2 ego-pose table",
}

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_REPR_LIMIT = 120


@cache
def schema(name: str) -> dict:
    """The JSON Schema of a format (read once). The files are JSON text (which is YAML too, as the other schemas
    beside them are): reading them needs no YAML parser, which the fast evaluator's command never imports."""
    import json

    if name not in FORMATS:
        raise KeyError(f"unknown format {name!r} (known: {', '.join(FORMATS)})")
    return json.loads((SCHEMA_DIR / f"{name}.schema.yaml").read_text())


def node(name: str, path: Sequence[str | int]) -> dict:
    """The schema node that describes the value at ``path`` of a document of the format."""
    return _walk(schema(name), path)[-1]


def _walk(root: dict, path: Sequence[str | int]) -> list[dict]:
    """The schema nodes along ``path`` (the root first; ``{}`` where the schema says nothing)."""
    nodes = [root]
    cur = root
    for part in path:
        if isinstance(part, int):
            cur = cur.get("items", {}) if isinstance(cur.get("items"), dict) else {}
        elif part in cur.get("properties", {}):
            cur = cur["properties"][part]
        elif isinstance(cur.get("additionalProperties"), dict):
            cur = cur["additionalProperties"]
        else:
            cur = {}
        nodes.append(cur)
    return nodes


# ---------------------------------------------------------------------------------------------------------------
# the validator: Draft 2020-12, finite numbers, the keywords above
# ---------------------------------------------------------------------------------------------------------------


def is_number(x: Any) -> bool:
    """A finite real number, booleans excluded (numpy scalars included)."""
    import numbers

    return isinstance(x, numbers.Real) and not isinstance(x, bool) and _finite(x)


def _finite(x) -> bool:
    try:
        return math.isfinite(x)
    except (TypeError, ValueError, OverflowError):
        return False


def _is_integer(x: Any) -> bool:
    """An integer (bool excluded), or a finite number with no fractional part (JSON Schema's integer)."""
    import numbers

    if isinstance(x, bool):
        return False
    return isinstance(x, numbers.Integral) or (isinstance(x, numbers.Real) and _finite(x) and float(x).is_integer())


def _is_nan(x: Any) -> bool:
    """NaN (the type ``nan`` of a schema: a value written as NaN that means "not defined")."""
    return isinstance(x, float) and math.isnan(x)


def _unit_norm(validator, tol, instance, schema):
    from jsonschema.exceptions import ValidationError

    if isinstance(instance, list) and instance and all(is_number(x) for x in instance):
        norm = math.sqrt(sum(float(x) ** 2 for x in instance))
        if abs(norm - 1.0) > tol:
            yield ValidationError(f"has norm {norm:.4f}")


def _unit_norm_of(validator, spec, instance, schema):
    from jsonschema.exceptions import ValidationError

    if not isinstance(instance, dict):
        return
    vals = [instance.get(k) for k in spec["keys"]]
    if all(is_number(v) for v in vals):
        norm = math.sqrt(sum(float(v) ** 2 for v in vals))
        if abs(norm - 1.0) > spec["tolerance"]:
            yield ValidationError(
                f"{'/'.join(spec['keys'])} has norm {norm:.4f}", validator_value={**spec, "norm": norm}
            )


_DTYPE_KINDS = {"number": "fiu", "integer": "iu", "string": "UO"}


def _ndarray(validator, spec, instance, schema):
    import numpy as np
    from jsonschema.exceptions import ValidationError

    if not isinstance(instance, np.ndarray):
        yield ValidationError(f"is a {type(instance).__name__}, not a numpy array")
        return
    shape = spec.get("shape", [])
    if instance.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, instance.shape)):
        yield ValidationError(f"has shape {instance.shape}")
        return
    kind = spec.get("dtype")
    if kind and instance.dtype.kind not in _DTYPE_KINDS[kind]:
        yield ValidationError(f"has dtype {instance.dtype}")
        return
    if kind == "string" and instance.dtype.kind == "O" and not all(isinstance(x, str) for x in instance.ravel()):
        yield ValidationError("holds a value that is not a string")
        return
    if kind == "number" and not np.isfinite(instance).all():
        yield ValidationError("holds a value that is not finite")
        return
    if "exclusiveMinimum" in spec and instance.size and not (instance > spec["exclusiveMinimum"]).all():
        yield ValidationError(f"holds a value <= {spec['exclusiveMinimum']}")
        return
    if "enum" in spec:
        bad = sorted({str(x) for x in instance.ravel()} - set(spec["enum"]))
        if bad:
            yield ValidationError(f"holds {bad[:3]}")
            return
    if spec.get("unique") and len(set(instance.tolist())) != len(instance):
        yield ValidationError("holds a value twice")


def _same_length(validator, keys, instance, schema):
    from jsonschema.exceptions import ValidationError

    if not isinstance(instance, dict):
        return
    lengths = {}
    for k in keys:
        v = instance.get(k)
        shape = getattr(v, "shape", None)
        if shape:
            lengths[k] = shape[0]
    if len(set(lengths.values())) > 1:
        first = next(iter(lengths))
        other = next(k for k in lengths if lengths[k] != lengths[first])
        yield ValidationError(
            f"'{other}' has {lengths[other]} rows and '{first}' {lengths[first]}",
            validator_value={"key": other, "rows": lengths[other], "against": first, "expected": lengths[first]},
        )


@cache
def _validator_class():
    from jsonschema import Draft202012Validator, validators

    checker = Draft202012Validator.TYPE_CHECKER.redefine_many(
        {"number": lambda _, x: is_number(x), "integer": lambda _, x: _is_integer(x), "nan": lambda _, x: _is_nan(x)}
    )
    return validators.extend(
        Draft202012Validator,
        validators={
            "unitNorm": _unit_norm,
            "unitNormOf": _unit_norm_of,
            "ndarray": _ndarray,
            "sameLength": _same_length,
        },
        type_checker=checker,
    )


@cache
def _validator(name: str, key: tuple):
    """A validator of the schema node at ``key`` (see :func:`_schema_key`)."""
    return _validator_class()(node(name, key))


def _schema_key(name: str, at: Sequence[str | int]) -> tuple:
    """A hashable key of a path for the validator cache: keys the schema does not name become ``'\\0'`` (every
    sample token walks to the same node), indices ``0``."""
    out: list[str | int] = []
    for part, parent in zip(at, _walk(schema(name), at)):
        if isinstance(part, int):
            out.append(0)
        else:
            out.append(part if part in parent.get("properties", {}) else "\0")
    return tuple(out)


def first_error(name: str, instance: Any, at: Sequence[str | int] = ()):
    """The first error of ``instance`` (the value at path ``at`` of a document) against the format's
    description, in the order the schema lists its keywords and properties; None when it fits."""
    return next(_validator(name, _schema_key(name, at)).iter_errors(instance), None)


def check(name: str, instance: Any, source: str | Path, at: Sequence[str | int] = ()) -> None:
    """Raise :class:`InputFormatError` naming ``source`` and the first failing field when ``instance`` (the value at
    path ``at`` of a document of the format) does not fit its description."""
    err = first_error(name, instance, at)
    if err is not None:
        raise InputFormatError(message(name, err, source, instance, at))


def field_path(name: str, path: Sequence[str | int]) -> str:
    """``results['tok'][2].rotation``: names the schema knows joined by dots, other keys quoted, indices."""
    out = ""
    nodes = _walk(schema(name), path)
    for part, parent in zip(path, nodes):
        if isinstance(part, int):
            out += f"[{part}]"
        elif _IDENTIFIER.match(part) and (part in parent.get("properties", {}) or parent.get("dottedKeys")):
            out += f".{part}" if out else part
        else:
            out += f"[{part!r}]"
    return out


def short_repr(value: Any, limit: int = _REPR_LIMIT) -> str:
    """``repr(value)`` cut to ``limit`` characters (``...`` marks the cut); a numpy array by its shape and a long
    list by its length and first items (never the repr of a whole document)."""
    if type(value).__name__ == "ndarray":
        return f"an array of shape {value.shape}, dtype {value.dtype}"
    if isinstance(value, (list, dict)) and len(value) > 8:
        head = list(value)[:2] if isinstance(value, list) else list(value.items())[:2]
        what = "list" if isinstance(value, list) else "object"
        text = f"a {what} of {len(value)} items ({repr(head)[: limit // 2]}...)"
        return text
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def require_type(name: str, value: Any, source: str | Path, at: Sequence[str | int]) -> None:
    """Check only the JSON type of the value at path ``at`` (a document's top level before its parts are read
    one by one); raises :class:`InputFormatError` naming the field and its description."""
    spec = node(name, at)
    kinds = spec.get("type", [])
    kinds = [kinds] if isinstance(kinds, str) else kinds
    checker = _validator_class()({})
    if kinds and not any(checker.is_type(value, k) for k in kinds):
        where = f"field '{field_path(name, at)}'" if at else "the document"
        expected = spec.get("description") or expectation_of_type(spec["type"])
        raise InputFormatError(f"{source}: {where} must be {expected}, got {short_repr(value)}")


def require_key(name: str, doc: dict, key: str, source: str | Path, at: Sequence[str | int] = ()) -> None:
    """Raise :class:`InputFormatError` naming the field when ``key`` is missing from the object ``doc`` at ``at``."""
    if key not in doc:
        described = node(name, [*at, key]).get("description")
        expected = f"; expected {described}" if described else ""
        raise InputFormatError(f"{source}: field '{field_path(name, [*at, key])}' is missing{expected}")


_TYPE_NAMES = {
    "object": "an object",
    "array": "a list",
    "boolean": "true or false",
    "integer": "an integer",
    "number": "a finite number",
    "string": "a string",
    "null": "null",
    "nan": "NaN",
}


def expectation_of_type(kind: str | list[str], object_word: str = "an object") -> str:
    """``a finite number or null`` for the JSON-schema type ``[number, "null"]``; an object is ``object_word`` (a
    config file says "a mapping")."""
    names = {**_TYPE_NAMES, "object": object_word}
    return " or ".join(names.get(t, t) for t in ([kind] if isinstance(kind, str) else kind))


def message(
    name: str, err, source: str | Path, instance: Any, at: Sequence[str | int] = (), where: str | None = None
) -> str:
    """One line: the file, the field path, what was expected (the failing node's description), what was given.

    ``instance``: the value validated (at path ``at`` of the document); ``where``: how to name the place of a
    table row instead of its field path (``row 5 (log …)``), the field then being the column."""
    rel = list(err.absolute_path)
    path = list(at) + rel
    nodes = _walk(schema(name), path)
    if err.validator == "required":
        missing = next(r for r in err.validator_value if r not in err.instance)
        described = nodes[-1].get("properties", {}).get(missing, {}).get("description")
        field = _name(name, [*path, missing], len(at), where)
        return f"{source}: {field} is missing" + (f"; expected {described}" if described else "")
    if err.validator == "additionalProperties":
        allowed = list(nodes[-1].get("properties", {}))
        extra = next(k for k in err.instance if k not in allowed)
        return (
            f"{source}: {_name(name, path, len(at), where)} has the unknown field {extra!r}; expected "
            f"{nodes[-1].get('description') or 'only ' + ', '.join(allowed)}"
        )
    if err.validator == "sameLength":
        v = err.validator_value
        return (
            f"{source}: {_name(name, [*path, v['key']], len(at), where)} must have as many rows as "
            f"'{v['against']}' ({v['expected']}), got {v['rows']}"
        )
    if err.validator == "unitNormOf":
        v = err.validator_value
        return (
            f"{source}: {_name(name, [*path, '/'.join(v['keys'])], len(at), where)} must be a unit quaternion "
            f"(norm 1 within {v['tolerance']}), got norm {v['norm']:.4f}"
        )
    # the deepest node along the path with a description says what was expected; an error inside a list whose
    # items have none is stated for the whole list (``size`` for ``size[1]``)
    depth = max(i for i, n in enumerate(nodes) if "description" in n or i == 0)
    if not all(isinstance(p, int) for p in path[depth:]):
        depth = len(path)
    expected = nodes[depth].get("description") or _expectation(err)
    value = instance
    for part in rel[: max(depth - len(at), 0)]:
        value = value[part]
    if depth < len(at):
        value = err.instance
    detail = f" ({err.message})" if err.validator in ("ndarray", "unitNorm") else ""
    if err.validator == "type" and "number" in err.validator_value and _numeric_text(err.instance):
        detail = " (a number written as a string)"
    return f"{source}: {_name(name, path[:depth], len(at), where)} must be {expected}, got {short_repr(value)}{detail}"


def _numeric_text(value: Any) -> bool:
    """Whether ``value`` is a string that reads as a number (``"1.5"``)."""
    if not isinstance(value, str):
        return False
    try:
        float(value)
    except ValueError:
        return False
    return True


def _name(name: str, path: Sequence[str | int], start: int, where: str | None) -> str:
    """``field '<path>'``; for a table row, ``<where>: field '<column>'``."""
    if where is not None:
        col = ".".join(str(p) for p in path[start:])
        return f"{where}: field '{col}'" if col else where
    return f"field '{field_path(name, path)}'" if path else "the document"


def _expectation(err) -> str:
    """A readable expectation for a schema node without a description."""
    v = err.validator_value
    if err.validator == "enum":
        return "one of " + ", ".join(str(x) for x in v)
    if err.validator == "type":
        return expectation_of_type(v)
    bounds = {"minimum": ">=", "exclusiveMinimum": ">", "maximum": "<=", "exclusiveMaximum": "<"}
    if err.validator in bounds:
        return f"a number {bounds[err.validator]} {v}"
    if err.validator in ("minItems", "maxItems"):
        return f"a list of {'at least' if err.validator == 'minItems' else 'at most'} {v} items"
    return err.message


# ---------------------------------------------------------------------------------------------------------------
# array-level check of a list of records (the boxes of a sample), derived from the same description
# ---------------------------------------------------------------------------------------------------------------


class RecordPlan:
    """The array-level check of a list of records (a sample's boxes) against the schema node of its items.

    Derived from the node: fixed-length arrays of numbers (``minItems == maxItems``, item bounds, ``unitNorm``),
    numbers (bounds), enums, strings, required keys and ``additionalProperties: false``. :meth:`arrays` returns
    the numeric fields as arrays when every record fits, else None; the caller then runs the schema on the list
    to name the first failing field (:func:`check`). The two accept the same records: each record's numbers are
    gathered into one row (the arrays one after the other) with a last column that encodes the lengths of the
    arrays (digits in base ``width + 1``, so a list one item short beside one an item long shows), and a boolean
    (a number to numpy) is looked for, value by value, in every column holding an exact 0 or 1.
    """

    def __init__(self, name: str, at: Sequence[str | int]):
        import numpy as np

        self.name, self.at = name, tuple(at)
        items = node(name, [*at, 0])
        props = items["properties"]
        self.required = tuple(items.get("required", ()))
        self.strings: list[str] = []
        self.enums: dict[str, frozenset] = {}
        self.exact = len(props) if items.get("additionalProperties") is False else None
        if self.exact is not None and set(self.required) != set(props):
            raise ValueError(f"{name}: a closed record must require all its properties")
        self.max_items = node(name, at).get("maxItems")
        vectors, scalars = [], []
        self.columns: dict[str, slice | int] = {}
        lower, lower_open, upper, norms = [], [], [], []
        for key, spec in props.items():
            if key not in self.required:
                raise ValueError(f"{name}: the array check reads required fields only ({key} is optional)")
            kind = spec.get("type")
            if kind == "array" and spec.get("items", {}).get("type") == "number":
                n = spec["minItems"]
                if spec.get("maxItems") != n:
                    raise ValueError(f"{name}: array field {key} needs minItems == maxItems")
                vectors.append((key, n, spec))
            elif kind == "number":
                scalars.append((key, spec))
            elif "enum" in spec:
                self.enums[key] = frozenset(spec["enum"])
            elif kind == "string":
                self.strings.append(key)
            else:
                raise ValueError(f"{name}: field {key} has no array-level check")
        col = 0
        for key, n, spec in vectors:
            self.columns[key] = slice(col, col + n)
            lower += [spec["items"].get("minimum", -np.inf)] * n
            lower_open += [spec["items"].get("exclusiveMinimum", -np.inf)] * n
            upper += [spec["items"].get("maximum", np.inf)] * n
            if "unitNorm" in spec:
                norms.append((self.columns[key], spec["unitNorm"]))
            col += n
        for key, spec in scalars:
            self.columns[key] = col
            lower.append(spec.get("minimum", -np.inf))
            lower_open.append(spec.get("exclusiveMinimum", -np.inf))
            upper.append(spec.get("maximum", np.inf))
            col += 1
        self.width = col
        base = col + 1
        bounded = [i for i in range(col) if np.isfinite([lower[i], lower_open[i], upper[i]]).any()]
        self.bounded = np.asarray(bounded, dtype=np.intp)  # the columns with a range: compared alone
        self.lower, self.lower_open, self.upper = (
            np.asarray(v, dtype=np.float64)[self.bounded] for v in (lower, lower_open, upper)
        )
        self.norms = norms
        terms = [f"*b[{k!r}]" for k, _, _ in vectors] + [f"b[{k!r}]" for k, _ in scalars]
        # the last array's length follows from the others' and the row's width
        self.length_code = float(sum(n * base**i for i, (_, n, _) in enumerate(vectors[:-1])))
        terms.append(" + ".join(f"{base**i} * len(b[{k!r}])" for i, (k, _, _) in enumerate(vectors[:-1])) or "0")
        # one list per record, its numbers in schema order and the length code: a comprehension compiled from the
        # schema's field names (not the file's) is the fastest way to gather them from a list of dicts
        self._rows = eval("lambda boxes: [[" + ", ".join(terms) + "] for b in boxes]")  # noqa: S307

    #: records checked in one pass by :meth:`iter_arrays`
    CHUNK = 300

    def iter_arrays(
        self, lists: list, key: str | None = None, values: list | None = None
    ) -> Iterator[tuple[int, int, dict[str, Any] | None]]:
        """:meth:`arrays` of many lists (the samples of a document) in chunks of about :data:`CHUNK` records:
        ``(i, j, arrays of the records of lists[i:j] one after the other)``, the arrays None when a list or record
        of the chunk does not fit. ``key``, ``values``: every record of ``lists[i]`` must have ``values[i]`` at the
        string field ``key`` (a box's ``sample_token``: the sample it is listed under); that field is then not
        returned. Chunks: few numpy calls per record however small the lists, and each chunk's records are read
        while they are in the processor's cache (measured: one pass over a whole document is slower)."""
        from itertools import chain
        from operator import itemgetter

        limit = self.max_items if self.max_items is not None else float("inf")
        get = itemgetter(key) if key is not None else None
        start, size = 0, 0
        for i, x in enumerate(lists):
            size += len(x) if type(x) is list else 0
            if size < self.CHUNK and i < len(lists) - 1:
                continue
            part = lists[start : i + 1]
            cols = None
            if all(type(x) is list and len(x) <= limit for x in part):
                try:
                    same = get is None or all(
                        list(map(get, x)).count(v) == len(x) for x, v in zip(part, values[start : i + 1])
                    )
                except (KeyError, TypeError):
                    same = False
                if same:
                    cols = self.arrays(list(chain.from_iterable(part)), whole=False, skip=key)
            yield start, i + 1, cols
            start, size = i + 1, 0

    def arrays(self, boxes: Any, whole: bool = True, skip: str | None = None) -> dict[str, Any] | None:
        """``{field: (N, n) or (N,) float64 array}`` for the numeric fields and ``{field: list}`` for the enums and
        strings of a list of records, when every record fits the description; None otherwise (including a
        record of another type, a missing or unknown key, a value of another type, length or range).
        ``whole``: the list is one the schema describes (its ``maxItems`` applies); ``skip``: a string field
        checked already (not returned)."""
        if type(boxes) is not list or (whole and self.max_items is not None and len(boxes) > self.max_items):
            return None
        part = self._checked(boxes, skip)
        if part is None:
            return None
        arr, out = part
        return {**out, **{key: arr[:, cols] for key, cols in self.columns.items()}}

    def _checked(self, boxes: list, skip: str | None = None) -> tuple[Any, dict[str, list]] | None:
        """(the (N, width) numbers, ``{field: list}`` of the enums and strings) of a list of records that all fit the
        description, else None (``skip``: a string field checked already)."""
        import numpy as np

        try:
            rows = self._rows(boxes)  # gathered first: a missing key or a non-record stops here
            if self.exact is not None and any(len(b) != self.exact for b in boxes):
                return None
            out: dict[str, Any] = {k: [b[k] for b in boxes] for k in (*self.enums, *self.strings) if k != skip}
        except (KeyError, TypeError, IndexError):
            return None
        for key in self.strings:
            if key != skip and boxes and set(map(type, out[key])) != {str}:
                return None
        try:
            for key, allowed in self.enums.items():
                if not allowed.issuperset(out[key]):
                    return None
        except TypeError:  # an unhashable value (a list where a name belongs)
            return None
        if not boxes:
            return np.zeros((0, self.width)), out
        try:
            full = np.array(rows)
        except (ValueError, TypeError, OverflowError):  # ragged, or an integer beyond a float's range
            return None
        del rows
        if full.ndim != 2 or full.shape[1] != self.width + 1 or full.dtype.kind not in "fiu":
            return None
        if not (full[:, -1] == self.length_code).all():
            return None
        arr = full[:, :-1].astype(np.float64, copy=False)
        if not np.isfinite(arr).all():
            return None
        ranged = arr[:, self.bounded]
        if (ranged < self.lower).any() or (ranged <= self.lower_open).any() or (ranged > self.upper).any():
            return None
        for cols, tol in self.norms:
            if (np.abs(np.linalg.norm(arr[:, cols], axis=1) - 1.0) > tol).any():
                return None
        if self._has_bool(boxes, arr):
            return None
        return arr, out

    def _has_bool(self, boxes: list, arr) -> bool:
        """Whether a JSON true / false stands where a number belongs (numpy made it 1.0 / 0.0): the fields with a
        column holding an exact 0 or 1 are looked at, value by value."""
        from itertools import chain
        from operator import itemgetter

        suspect = ((arr == 0) | (arr == 1)).any(axis=0)
        for key, cols in self.columns.items():
            if not suspect[cols].any():
                continue
            values = map(itemgetter(key), boxes)
            if bool in map(type, chain.from_iterable(values) if isinstance(cols, slice) else values):
                return True
        return False


@cache
def record_plan(name: str, at: tuple) -> RecordPlan:
    """The :class:`RecordPlan` of the list at path ``at`` of a format (built once)."""
    return RecordPlan(name, at)


# ---------------------------------------------------------------------------------------------------------------
# tables: a row description checked column by column
# ---------------------------------------------------------------------------------------------------------------


def check_table(name: str, df, source: str | Path) -> None:
    """Check a pandas DataFrame against a table format (its schema describes one row): the required columns,
    then every described column array by array (type, finiteness, range, enum; ``unitNormOf`` over its columns).
    The first failing row is checked against the row's schema to name the column; raises
    :class:`InputFormatError` with ``<file>: row <i> (<rowContext>): field '<column>' must be …``."""
    import numpy as np

    root = schema(name)
    row = root["items"]
    missing = [c for c in row.get("required", ()) if c not in df.columns]
    if missing:
        raise InputFormatError(f"{source}: missing column(s) {missing}; expected {row['description']}")
    if len(df) == 0:
        return
    bad = np.zeros(len(df), dtype=bool)
    for col, spec in row.get("properties", {}).items():
        if col in df.columns:
            bad |= _bad_rows(df[col], spec)
    norm = row.get("unitNormOf")
    if norm and not bad.any():
        q = df[list(norm["keys"])].to_numpy(dtype=np.float64)
        bad |= np.abs(np.linalg.norm(q, axis=1) - 1.0) > norm["tolerance"]
    if not bad.any():
        return
    i = int(np.argmax(bad))
    record = {c: _plain(df[c].iat[i]) for c in df.columns if c in row.get("properties", {})}
    err = first_error(name, record, (i,))
    if err is None:  # the array check and the schema disagree: a programming error
        raise AssertionError(f"{source}: row {i} fails the array check of {name} but fits its schema")
    context = ", ".join(f"{c} {df[c].iat[i]}" for c in root.get("rowContext", ()) if c in df.columns)
    where = f"row {i}" + (f" ({context})" if context else "")
    raise InputFormatError(message(name, err, source, record, (i,), where=where))


def _plain(v):
    """A table cell as the Python value the schema checks (numpy scalars to Python numbers)."""
    return v.item() if hasattr(v, "item") and type(v).__module__ == "numpy" else v


def _in(value, allowed: set) -> bool:
    try:
        return value in allowed
    except TypeError:
        return False


def _bad_rows(series, spec: dict):
    """(N,) bool: the rows whose value in this column does not fit ``spec`` (type, finite, range, enum)."""
    import numpy as np
    import pandas as pd

    kind = spec.get("type")
    values = series.to_numpy()
    if "enum" in spec:
        try:
            return ~series.isin(spec["enum"]).to_numpy()
        except TypeError:  # an unhashable value (a list in a cell): value by value
            allowed = set(spec["enum"])
            return ~np.fromiter((_in(v, allowed) for v in values), dtype=bool, count=len(values))
    if kind == "string":
        if pd.api.types.infer_dtype(series, skipna=False) == "string":
            return np.zeros(len(values), dtype=bool)
        return ~np.fromiter((isinstance(v, str) for v in values), dtype=bool, count=len(values))
    if kind in ("number", "integer"):
        if values.dtype.kind in "iu":
            num = values.astype(np.float64)
            bad = np.zeros(len(values), dtype=bool)
        elif values.dtype.kind == "f":
            num = values.astype(np.float64)
            bad = ~np.isfinite(num)
        else:  # object, bool, strings: only real numbers pass
            ok = np.fromiter((is_number(v) for v in values), dtype=bool, count=len(values))
            num = np.where(ok, pd.to_numeric(pd.Series(np.where(ok, values, 0)), errors="coerce"), 0.0)
            bad = ~ok
        if kind == "integer":
            bad |= num != np.round(num)
        if "minimum" in spec:
            bad |= num < spec["minimum"]
        if "exclusiveMinimum" in spec:
            bad |= num <= spec["exclusiveMinimum"]
        if "maximum" in spec:
            bad |= num > spec["maximum"]
        return bad
    return np.zeros(len(values), dtype=bool)
