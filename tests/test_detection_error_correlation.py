"""scripts/detection_error_correlation.py: the lag-1 correlation of detection centre errors."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location(
    "detection_error_correlation", Path(__file__).parents[1] / "scripts/detection_error_correlation.py"
)
corr = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(corr)


def test_lag_one_correlation_is_zero_for_independent_and_one_for_kept_errors():
    rng = np.random.default_rng(0)
    e0, e1 = rng.normal(size=(5000, 2)) * 0.2, rng.normal(size=(5000, 2)) * 0.2
    assert abs(corr.lag_one_correlation(e0, e1)) < 0.03
    assert abs(corr.lag_one_correlation(e0, e0 + 1.0) - 1.0) < 1e-12  # each object keeps its error
    rho = 0.8  # an AR(1) step: e1 = rho e0 + sqrt(1 - rho^2) noise
    assert abs(corr.lag_one_correlation(e0, rho * e0 + np.sqrt(1 - rho**2) * e1) - rho) < 0.03
    assert np.isnan(corr.lag_one_correlation(e0[:2], e1[:2]))


def test_summary_pairs_the_same_object_in_consecutive_keyframes_only():
    errors = {
        ("s", "a", 0): (np.array([0.1, 0.0]), 0),
        ("s", "a", 1): (np.array([0.2, 0.0]), 0),
        ("s", "a", 3): (np.array([9.0, 9.0]), 0),  # no keyframe 2: not paired
        ("s", "b", 0): (np.array([-0.1, 0.1]), 0),
        ("s", "b", 1): (np.array([-0.2, 0.2]), 0),
        ("s", "c", 0): (np.array([0.0, -0.3]), 1),
        ("s", "c", 1): (np.array([0.0, -0.3]), 1),
        ("t", "c", 1): (np.array([5.0, 5.0]), 1),
    }  # another scene: not paired
    rows = {r[0]: r for r in corr.summary(errors, ("car", "pedestrian"))}
    assert rows["all"][1] == 3 and rows["car"][1] == 2 and rows["pedestrian"][1] == 1
    assert np.isnan(rows["car"][2])  # 2 pairs: too few
    assert rows["all"][2] > 0.9
    first = np.array([[0.1, 0.0], [-0.1, 0.1], [0.0, -0.3]])  # the first keyframe of each pair
    assert rows["all"][3] == pytest.approx(np.sqrt(np.mean(np.sum(first**2, axis=1))))
