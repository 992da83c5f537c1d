"""Entry-by-entry comparison of metrics summaries (used by the evaluator parity tests and benchmark)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support.compare import entry_differences, flatten, value_difference


def test_flatten_uses_dotted_keys():
    assert flatten({"a": 1, "b": {"c": 2, "d": {"e": "x"}}}) == {"a": 1, "b.c": 2, "b.d.e": "x"}


@pytest.mark.parametrize(
    "a, b, want",
    [
        (0.5, 0.25, 0.25),
        (np.float64(1.0), 1, 0.0),
        (np.int64(3), 5, 2.0),
        (math.nan, math.nan, 0.0),
        (math.nan, 1.0, math.inf),
        ("car", "car", 0.0),
        ("car", "bus", math.inf),
        (True, True, 0.0),
        (True, False, math.inf),
        ([1, 2], [1, 2], 0.0),
    ],
)
def test_value_difference(a, b, want):
    assert value_difference(a, b) == want


def test_entry_differences_ignores_eval_time_and_names_missing_entries():
    ref = {"amota": 0.5, "eval_time": 3.0, "label_metrics": {"amota": {"car": 0.4}}}
    ours = {"amota": 0.5 + 1e-12, "eval_time": 9.0, "label_metrics": {"amota": {"car": math.nan}}}
    d = entry_differences(ref, ours)
    assert set(d) == {"amota", "label_metrics.amota.car"}
    assert d["amota"] == pytest.approx(1e-12) and d["label_metrics.amota.car"] == math.inf
    with pytest.raises(ValueError, match="label_metrics.amota.bus"):
        entry_differences(ref, {**ours, "label_metrics": {"amota": {"car": 0.4, "bus": 0.1}}})
