"""benchmarks/bench_default_tracker.py: every candidate is a valid preset, every edited profile a valid profile, and
the groups the decisions were measured on keep their sets (docs/results/default_tracker.md quotes them)."""

import importlib.util
from pathlib import Path

from grutrack.data.detection_sim import load_profile
from grutrack.tracking.config import load_tracker_config

_SPEC = importlib.util.spec_from_file_location(
    "bench_default_tracker", Path(__file__).parents[1] / "benchmarks/bench_default_tracker.py"
)
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def test_every_candidate_writes_a_preset_that_loads_and_differs_from_the_preset():
    preset = load_tracker_config("ekf")
    for name in bench.CANDIDATES:
        cfg = load_tracker_config(bench.candidate_path(name))
        if name != "ekf":
            assert cfg != preset, name


def test_every_edited_profile_is_a_valid_profile_with_its_changed_noise(tmp_path):
    for name, (base, _) in bench.PROFILE_VARIANTS.items():
        prof, shipped = load_profile(bench.profile_arg(name, tmp_path)), load_profile(base)
        assert prof.name == name and prof.classes != shipped.classes, name
    strong, cp = load_profile(bench.profile_arg("cp_strong", tmp_path)), load_profile("centerpoint")
    for cls in ("car", "pedestrian", "bus"):  # the defaults and a class override (bus) halved alike
        assert strong.classes[cls].pos_sigma_m == 0.5 * cp.classes[cls].pos_sigma_m, cls


def test_the_groups_keep_their_sets():
    sets = bench.generated(*bench.GROUPS["variants"])
    assert len(sets) == 3 * 2 * 4 and {p for _, p, _ in sets.values()} == set(bench.VARIANTS)
    assert len(bench.generated(*bench.GROUPS["fresh4"])) == 200
    strong = bench.generated(*bench.GROUPS["strong"])
    assert len(strong) == 50 and {p for _, p, _ in strong.values()} == {"cp_strong"}
    val = bench.generated(*bench.GROUPS["variants_val"])
    assert len(val) == 100 and {s for s, _, _ in val.values()} == {"mini_val"}
    train = bench.generated(*bench.GROUPS["variants_train"])
    assert len(train) == 40 and {p for _, p, _ in train.values()} == set(bench.VARIANTS)


def test_the_deciding_class_is_the_largest_class_loss_against_the_sets_best_tracker():
    nan = float("nan")
    row = {
        "polymot": {"all": 0.70, "bicycle": 0.60, "bus": 0.90, "car": 0.60, "truck": nan},
        "fastpoly": {"all": 0.60, "bicycle": 0.20, "bus": 1.00, "car": 0.60, "truck": nan},
        "mctrack": {"all": 0.65, "bicycle": 0.50, "bus": 0.85, "car": 0.60, "truck": nan},
        "ekf": {"all": 0.68, "bicycle": 0.55, "bus": 0.84, "car": 0.64, "truck": nan},
    }
    # against Poly-MOT, the best overall (not Fast-Poly, whose bus is best): bicycle -0.05, bus -0.06, car +0.04;
    # the set has no truck
    assert bench.deciding_class(row, "ekf") == "bus"
    row["ekf"]["all"] = 0.70  # at the best of the three: not below, nothing decides
    assert bench.deciding_class(row, "ekf") is None


def test_an_unknown_group_or_candidate_exits_2_with_one_line_naming_it(capsys):
    assert bench.main(["--groups", "fresh,fresh9", "--candidates", "ekf"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "fresh9" in err and "--groups" in err and "variants_val" in err
    assert bench.main(["--groups", "fresh", "--candidates", "ekf,+nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "+nope" in err
