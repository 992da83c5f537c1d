"""scripts/grukf_suite.py's many-seed summary: paired differences to the ekf row with standard errors."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location("grukf_suite", Path(__file__).parents[1] / "scripts/grukf_suite.py")
suite = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(suite)


def test_paired_difference_is_the_mean_and_standard_error_of_the_set_by_set_differences():
    m, se = suite.paired_difference([0.40, 0.38, 0.41, 0.37], [0.42, 0.41, 0.42, 0.40])
    d = np.array([-0.02, -0.03, -0.01, -0.03])
    assert m == pytest.approx(d.mean())
    assert se == pytest.approx(d.std(ddof=1) / 2.0)
    assert suite.paired_difference([0.5], [0.4]) == (pytest.approx(0.1), 0.0)


def test_difference_table_pairs_every_model_with_the_ekf_row_set_by_set():
    sets = ["centerpoint_s21", "centerpoint_s22"]
    rows = [
        {
            "model": "ekf",
            "centerpoint_s21_amota": 0.90,
            "centerpoint_s21_amotp": 0.40,
            "centerpoint_s22_amota": 0.80,
            "centerpoint_s22_amotp": 0.50,
        },
        {
            "model": "grukf",
            "centerpoint_s21_amota": 0.91,
            "centerpoint_s21_amotp": 0.37,
            "centerpoint_s22_amota": 0.80,
            "centerpoint_s22_amotp": 0.49,
        },
    ]
    classes = {
        ("ekf", sets[0]): {"car": 0.30, "bus": 0.5},
        ("ekf", sets[1]): {"car": 0.32},
        ("grukf", sets[0]): {"car": 0.28, "bus": 0.4},
        ("grukf", sets[1]): {"car": 0.31},
    }
    lines = suite._difference_table(rows, classes, sets)
    assert "2 CenterPoint-like sets" in lines[0] and "SYNTHETIC" in lines[0]
    assert lines[2] == "| model | AMOTA | AMOTP (m) | bus AMOTP | car AMOTP |"
    ekf, grukf = lines[4], lines[5]
    assert ekf == "| ekf | +0.0000 +- 0.0000 | +0.0000 +- 0.0000 | +0.000 | +0.000 |"
    # AMOTA: +0.01, 0 -> mean 0.005, s.e. 0.005; AMOTP: -0.03, -0.01 -> -0.02 +- 0.01; bus only where both have it
    assert grukf == "| grukf | +0.0050 +- 0.0050 | -0.0200 +- 0.0100 | -0.100 | -0.015 |"
    drift = suite._difference_table(rows, classes, sets, "drift (time-correlated centre error)")
    assert "2 drift (time-correlated centre error) sets" in drift[0] and drift[2:] == lines[2:]


def test_drift_sets_use_the_evaluation_profile_of_the_results():
    """--drift-seeds simulates with docs/results/grukf_eval/drift.yaml, a profile with a drifting centre."""
    from grutrack.data.detection_sim import load_profile

    assert Path(suite.DRIFT_PROFILE).is_file()
    assert load_profile(suite.DRIFT_PROFILE).classes["car"].pos_drift_sigma_m > 0


def test_seed_list_takes_seeds_and_inclusive_ranges_each_once():
    """--cp-seed-list 2-11,21-30 is the twenty draws of issue 14's bars (docs/results/pretrained.md#twenty-draws)."""
    assert suite.seed_list("2-11,21-30") == [*range(2, 12), *range(21, 31)]
    assert suite.seed_list("5, 3-4,4") == [5, 3, 4]
    for bad in ("", "a", "4-2", "-3", "2-", "1.5"):
        with pytest.raises(ValueError, match="expected seeds and ranges"):
            suite.seed_list(bad)


def test_profile_sets_name_each_set_and_refuse_a_bad_spec():
    sets = suite.profile_sets(["pointpillars:2-3", "centerpoint_velfail:5"])
    assert sets == {
        "pointpillars_s2": ("pointpillars", 2),
        "pointpillars_s3": ("pointpillars", 3),
        "centerpoint_velfail_s5": ("centerpoint_velfail", 5),
    }
    for bad, why in (
        ("pointpillars", "expected PROFILE:SEEDS"),
        ("centerpoint:2", "other than centerpoint"),
        ("nosuch:2", "unknown detector profile 'nosuch'"),
        ("pointpillars:4-2", "expected seeds and ranges"),
    ):
        with pytest.raises(ValueError, match=why):
            suite.profile_sets([bad])
