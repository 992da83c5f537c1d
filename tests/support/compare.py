"""Entry-by-entry comparison of two metrics summaries (evaluator parity checks: the fast evaluator against the
devkit's ``metrics_summary.json``), shared by the parity tests and the evaluation benchmark."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: top-level entries that legitimately differ between two evaluations of the same input
IGNORED = ("eval_time",)


def flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    """Nested dicts as one dict with dotted keys (``label_metrics.amota.car``)."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        if isinstance(value, dict):
            out.update(flatten(value, prefix + str(key) + "."))
        else:
            out[prefix + str(key)] = value
    return out


def value_difference(a: Any, b: Any) -> float:
    """Absolute difference of two numbers (0 for NaN/NaN, inf for NaN/number); 0 or inf by ``==`` otherwise
    (strings, booleans, lists)."""
    if isinstance(a, (int, float, np.number)) and isinstance(b, (int, float, np.number)) \
            and not isinstance(a, bool) and not isinstance(b, bool):
        a, b = float(a), float(b)
        if math.isnan(a) or math.isnan(b):
            return 0.0 if math.isnan(a) and math.isnan(b) else math.inf
        return abs(a - b)
    return 0.0 if a == b else math.inf


def entry_differences(ref: dict, ours: dict) -> dict[str, float]:
    """Difference per flattened entry of two summaries with the same keys (``IGNORED`` entries left out).

    Raises ValueError naming the entries present in only one of them.
    """
    fr, fo = flatten(ref), flatten(ours)
    if set(fr) != set(fo):
        raise ValueError("different entries: %s" % sorted(set(fr) ^ set(fo)))
    return {k: value_difference(fr[k], fo[k]) for k in sorted(fr) if k not in IGNORED}
