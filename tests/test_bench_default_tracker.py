"""benchmarks/bench_default_tracker.py: every candidate is a valid preset, every edited profile a valid profile, and
the groups the decisions were measured on keep their sets (docs/results/default_tracker.md quotes them)."""

import importlib.util
import json
from pathlib import Path

import pytest
import yaml

from grutrack.data.detection_sim import load_profile
from grutrack.tracking.config import load_tracker_config, preset_path

_SPEC = importlib.util.spec_from_file_location(
    "bench_default_tracker", Path(__file__).parents[1] / "benchmarks/bench_default_tracker.py"
)
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def test_every_candidate_writes_a_preset_that_loads_and_differs_from_the_preset():
    preset = yaml.safe_load(preset_path("ekf").read_text())
    for name in bench.CANDIDATES:
        path = bench.candidate_path(name)
        load_tracker_config(path)
        # every setting, as written (a config's source path alone would always differ)
        assert (yaml.safe_load(path.read_text()) == preset) == (name == "ekf" or name in bench.ADOPTED), name


def test_two_candidates_cannot_share_a_motion_file_name():
    """A name written twice with other contents is refused: the later candidate would otherwise change the motion
    file the earlier one's preset points to (as ekf_prev13 and -truck_heading once did)."""

    def write(r_yaw: float) -> None:
        bench._class_motion("truck", "shared_name_test", R=bench._heading_r(r_yaw))(
            {"motion": {"config": "grutrack_nusc"}}
        )

    write(1.0)
    write(1.0)  # the same contents again: the same file
    with pytest.raises(ValueError, match="'shared_name_test' is used by two candidates"):
        write(0.5)


def test_the_preset_before_decision_13_measures_the_long_vehicles_heading_as_poly_mot():
    before = yaml.safe_load(Path(load_tracker_config(bench.candidate_path("ekf_prev13")).motion_config).read_text())
    now = yaml.safe_load(Path(bench._motion_file("grutrack_nusc")).read_text())
    for cls in ("bus", "truck"):
        assert before["classes"][cls]["R"][6] == 1.0 and now["classes"][cls]["R"][6] == 0.1, cls
    assert before["classes"]["car"] == now["classes"]["car"]


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
    assert len(bench.generated(*bench.GROUPS["fresh6"])) == 200
    strong = bench.generated(*bench.GROUPS["strong"])
    assert len(strong) == 50 and {p for _, p, _ in strong.values()} == {"cp_strong"}
    val = bench.generated(*bench.GROUPS["variants_val"])
    assert len(val) == 100 and {s for s, _, _ in val.values()} == {"mini_val"}
    train = bench.generated(*bench.GROUPS["variants_train"])
    assert len(train) == 40 and {p for _, p, _ in train.values()} == set(bench.VARIANTS)
    made = {}
    for group, count in (("dense", 40), ("dense_variants", 25), ("dense_train", 20)):  # Decisions 14, 15's dense sets
        # dense2 to dense6 were held out after Decisions 15 to 19, dense7 after Decision 19 too
        dense = ("dense", "dense2", "dense3", "dense4", "dense5", "dense6", "dense7")
        names = [n for n in (group.replace("dense", d) for d in dense) if n in bench.DENSE]  # dense5: no variants
        for name in names:
            base, start, n = bench.DENSE[name]
            first, *rest = bench.GROUPS[base]
            made[name] = set(bench.generated(first[start : start + n], *rest).values())
            three = name in ("dense6_train", "dense7_train")  # 3 seeds each
            assert len(made[name]) == (12 if three else count), name
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                assert not made[a] & made[b], (a, b)  # no set in two groups


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


def _row(ekf: float, best: float, **classes) -> dict:
    """A set's row: Poly-MOT at ``best`` (Fast-Poly and MCTrack below it), the candidate ``ekf`` at ``ekf``; the
    classes' AMOTA as given, the three's best in class 0.5."""
    three = {t: {"all": best - 0.01 * i, "car": 0.5, "bus": float("nan")} for i, t in enumerate(bench.THREE)}
    return {**three, "ekf": {"all": ekf, "car": classes.get("car", 0.5), "bus": float("nan")}}


def test_the_spread_per_kind_of_set_counts_margins_and_the_uniform_gain_that_closes_them():
    classes = {f"mini_val centerpoint s{i}": _row(0.80 + 0.01 * (i - 2), 0.80, car=0.6) for i in range(200)}
    classes["worlds s1 pointpillars"] = _row(0.50, 0.52)
    out = bench.spread(classes, "ekf")
    assert set(out) == {"mini_val centerpoint", "worlds pointpillars"}
    cp = out["mini_val centerpoint"]
    # margins -0.02, -0.01, 0.00, ... 1.97: two below; 1 % of 200 sets may stay below, so the gain lifts the third
    # lowest (0.00) to 0 and needs nothing; none below needs +0.02
    assert cp["n"] == 200 and cp["below"] == 2 and cp["gain_1pct"] == 0.0
    assert abs(cp["gain_none"] - 0.02) < 1e-12 and abs(cp["mean"] - 0.975) < 1e-9
    assert abs(cp["per_class"]["car"] - 0.1) < 1e-12 and "bus" not in cp["per_class"]  # a class no set has
    one = out["worlds pointpillars"]
    assert one["below"] == 1 and one["sd"] == 0.0 and abs(one["gain_1pct"] - 0.02) < 1e-12


def test_the_summary_reports_saved_runs_and_refuses_a_file_that_is_not_one(tmp_path, capsys):
    classes = {"mini_val centerpoint s1": _row(0.79, 0.80), "mini_val centerpoint s2": _row(0.85, 0.80)}
    saved = tmp_path / "run.json"
    saved.write_text(json.dumps({"table": {}, "per_class": classes}))
    assert bench.main(["--summary", str(saved)]) == 0
    out = capsys.readouterr().out
    assert "below on 1/2" in out and "mini_val centerpoint" in out and "1/2" in out
    bad = tmp_path / "bad.json"
    bad.write_text('{"table": {}}')
    assert bench.main(["--summary", str(saved), "--summary", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and str(bad) in err and "--json" in err
