"""The preset options behind Poly-MOT's behaviours, one by one: the threshold-margin assignment, the fixed time
step, the piecewise CTRA and Bicycle forms, the rotation-angle measured yaw, the strict score filter, NMS's order
on tied scores, the new schema keys; and the
tracking-submission comparison used by the parity tests."""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest
import yaml

from grutrack.boxes import quaternion_from_yaw, rotation_angle_about_z, yaw_from_quaternion
from grutrack.classes import CLASS_INDEX
from grutrack.data.scene import BoxSet
from grutrack.errors import ConfigError
from grutrack.evaluation.track_parity import compare_tracks
from grutrack.motion.models import CTRA, PIECEWISE_SWITCH, Bicycle, BicyclePiecewise, CTRAPiecewise, make_model
from grutrack.tracking.association import hungarian, threshold_margin
from grutrack.tracking.config import config_from_dict, preset_path
from grutrack.tracking.factory import ekf_groups
from grutrack.tracking.preprocess import preprocess_frame
from grutrack.tracking.tracker import Tracker

# ----------------------------------------------------------------------------------------------------------------
# assignment
# ----------------------------------------------------------------------------------------------------------------


def _best_margin(cost: np.ndarray, thr: float) -> float:
    """Largest sum(thr - cost) over all partial matchings of admissible pairs, by enumeration."""
    D, T = cost.shape
    best = 0.0
    for k in range(1, min(D, T) + 1):
        for rows in itertools.combinations(range(D), k):
            for cols in itertools.permutations(range(T), k):
                c = cost[list(rows), list(cols)]
                if np.all(c < thr):
                    best = max(best, float(np.sum(thr - c)))
    return best


def test_threshold_margin_is_the_optimal_partial_matching():
    rng = np.random.default_rng(3)
    for _ in range(60):
        D, T = rng.integers(1, 5, size=2)
        cost = rng.uniform(0.0, 2.0, (D, T))
        cost[rng.random((D, T)) < 0.2] = 1e6  # forbidden pairs (other class, or skipped by the bound)
        thr = float(rng.uniform(0.8, 1.6))
        r, c = threshold_margin(cost, np.full((D, 1), thr))
        assert len(set(r)) == len(r) and len(set(c)) == len(c)
        assert np.all(cost[r, c] < thr)
        assert np.sum(thr - cost[r, c]) == pytest.approx(_best_margin(cost, thr), abs=1e-12)


def test_threshold_margin_keeps_a_cheap_pair_that_most_pairs_gives_up():
    # det 0 fits track 0 very well; det 1 only fits track 0, det 0 also fits track 1 (poorly)
    cost = np.array([[0.1, 1.1], [1.15, 1e6]])
    thr = np.full((2, 1), 1.2)
    r, c = hungarian(cost, thr)  # two pairs: 1.1 + 1.15
    assert sorted(zip(r.tolist(), c.tolist())) == [(0, 1), (1, 0)]
    r, c = threshold_margin(cost, thr)  # margin 1.1 beats 0.1 + 0.05
    assert list(zip(r.tolist(), c.tolist())) == [(0, 0)]


# ----------------------------------------------------------------------------------------------------------------
# measured yaw
# ----------------------------------------------------------------------------------------------------------------


def test_rotation_angle_matches_pyquaternion_radians_with_axis_up():
    from pyquaternion import Quaternion

    rng = np.random.default_rng(0)
    q = rng.normal(size=(200, 4)) * np.array([1, 0.05, 0.05, 1])  # mostly yaw, some pitch and roll
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    expected = []
    for row in q:
        p = Quaternion(row)
        p = -p if p.axis[-1] < 0 else p
        expected.append(p.radians)
    got = rotation_angle_about_z(q)
    assert np.max(np.abs(np.angle(np.exp(1j * (got - np.array(expected)))))) < 1e-12
    # a pure yaw rotation: both definitions agree; a tilted one: they differ
    yaw = rng.uniform(-np.pi, np.pi, 50)
    np.testing.assert_allclose(rotation_angle_about_z(quaternion_from_yaw(yaw)), yaw, atol=1e-12)
    assert np.max(np.abs(rotation_angle_about_z(q) - yaw_from_quaternion(q))) > 1e-3


# ----------------------------------------------------------------------------------------------------------------
# piecewise model forms
# ----------------------------------------------------------------------------------------------------------------


def _numeric_jacobian(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central differences of f (N, d) -> (N, d) at x: (N, d, d)."""
    J = np.zeros(x.shape + (x.shape[1],))
    for j in range(x.shape[1]):
        e = np.zeros(x.shape[1])
        e[j] = eps
        J[:, :, j] = (f(x + e) - f(x - e)) / (2 * eps)
    return J


def _states(n: int, rng, last: np.ndarray) -> np.ndarray:
    x = np.zeros((n, 10))
    x[:, 0:3] = rng.normal(0, 20, (n, 3))
    x[:, 3:6] = rng.uniform(0.5, 5, (n, 3))
    x[:, 6] = rng.uniform(-3, 12, n)
    x[:, 7] = rng.normal(0, 1, n)
    x[:, 8] = rng.uniform(-3, 3, n)
    x[:, 9] = last
    return x


def test_ctra_piecewise_is_ctra_above_the_switch_and_straight_below():
    rng = np.random.default_rng(1)
    arc, pw = CTRA(), CTRAPiecewise()
    big = _states(40, rng, rng.choice([-1, 1], 40) * rng.uniform(2 * PIECEWISE_SWITCH, 0.8, 40))
    np.testing.assert_array_equal(pw.f(big, 0.5), arc.f(big, 0.5))
    np.testing.assert_array_equal(pw.F(big, 0.5), arc.F(big, 0.5))
    small = _states(40, rng, rng.uniform(-0.5, 0.5, 40) * PIECEWISE_SWITCH)
    out = pw.f(small, 0.5)
    ds = small[:, 6] * 0.5 + 0.5 * small[:, 7] * 0.25
    np.testing.assert_allclose(out[:, 0] - small[:, 0], ds * np.cos(small[:, 8]), atol=1e-12)
    np.testing.assert_allclose(out[:, 8], small[:, 8] + small[:, 9] * 0.5, atol=1e-15)
    assert np.max(np.abs(out[:, :2] - arc.f(small, 0.5)[:, :2])) > 1e-6  # the arc turns, the line does not
    # F is the exact Jacobian of the straight-line branch: d(x, y)/d omega = 0
    F = pw.F(small, 0.5)
    np.testing.assert_allclose(F, _numeric_jacobian(lambda s: pw.f(s, 0.5), small, 1e-7), atol=1e-6)
    assert np.all(F[:, 0:2, 9] == 0.0)


def test_bicycle_piecewise_branches_and_jacobians():
    rng = np.random.default_rng(2)
    arc, pw = Bicycle(), BicyclePiecewise()
    turning = _states(40, rng, rng.choice([-1, 1], 40) * rng.uniform(0.01, 0.6, 40))
    out = pw.f(turning, 0.5)
    np.testing.assert_array_equal(out[:, 6], turning[:, 6])  # v kept
    np.testing.assert_array_equal(out[:, 7], 0.0)  # a reset
    np.testing.assert_allclose(pw.h(turning), arc.h(turning), atol=1e-12)  # same beta below |delta| < pi/2
    no_accel = turning.copy()
    no_accel[:, 7] = 0.0
    np.testing.assert_allclose(out[:, [0, 1, 8]], arc.f(no_accel, 0.5)[:, [0, 1, 8]], atol=1e-9)
    # F: the Jacobian of f except the columns Poly-MOT leaves out (l, delta), which are zero off the diagonal
    F = pw.F(turning, 0.5)
    num = _numeric_jacobian(lambda s: pw.f(s, 0.5), turning, 1e-7)
    keep = [0, 1, 2, 3, 5, 6, 7, 8]
    np.testing.assert_allclose(F[:, :, keep], num[:, :, keep], atol=2e-6)
    np.testing.assert_array_equal(F[:, [0, 1, 8], 4], 0.0)
    np.testing.assert_array_equal(F[:, [0, 1, 8], 9], 0.0)
    H = pw.H(turning)
    assert np.all(H[:, 7:9, 9] == 0.0) and np.any(arc.H(turning)[:, 7:9, 9] != 0.0)

    straight = _states(40, rng, rng.uniform(-0.5, 0.5, 40) * PIECEWISE_SWITCH)
    out = pw.f(straight, 0.5)
    np.testing.assert_array_equal(out[:, 8], straight[:, 8])  # yaw fixed
    np.testing.assert_allclose(out[:, 6], straight[:, 6] + 0.5 * straight[:, 7], atol=1e-15)
    F = pw.F(straight, 0.5)
    np.testing.assert_allclose(F, _numeric_jacobian(lambda s: pw.f(s, 0.5), straight, 1e-7), atol=1e-6)


def test_make_model_forms():
    assert type(make_model("ctra", "piecewise")) is CTRAPiecewise
    assert type(make_model("Bicycle", "piecewise", wheelbase_ratio=0.8, front_ratio=0.5)) is BicyclePiecewise
    assert type(make_model("CTRA")) is CTRA
    assert make_model("CA", "piecewise").name == "CA"  # the linear models have one form
    with pytest.raises(ValueError, match="form"):
        make_model("CTRA", "curvy")


# ----------------------------------------------------------------------------------------------------------------
# schema and tracker
# ----------------------------------------------------------------------------------------------------------------


def _raw(name: str = "polymot") -> dict:
    return yaml.safe_load(preset_path(name).read_text())


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        ("association", "assignment", "lapjv", "'association.assignment' must be one of most_pairs, threshold_margin"),
        ("motion", "time_step", 0, "'motion.time_step' must be 'timestamps' or a positive number of seconds"),
        ("motion", "time_step", "0.5s", "'motion.time_step' must be 'timestamps'"),
        ("motion", "ctra_form", "exact", "'motion.ctra_form' must be one of arc, piecewise"),
        ("motion", "bicycle_form", None, "'motion.bicycle_form' must be one of arc, piecewise"),
        (
            "preprocessing",
            "measured_yaw",
            "euler",
            "'preprocessing.measured_yaw' must be one of euler_z, rotation_angle",
        ),
        (
            "preprocessing",
            "footprint",
            "polygon",
            "'preprocessing.footprint' must be one of yaw_rectangle, bottom_face",
        ),
    ],
)
def test_new_keys_are_validated(section, key, value, message):
    raw = _raw()
    raw[section][key] = value
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        config_from_dict(raw, "p.yaml")
    del raw[section][key]  # left out: the schema's default, the tracker's behaviour without the key
    default = {
        "assignment": "most_pairs",
        "time_step": None,
        "ctra_form": "arc",
        "bicycle_form": "arc",
        "measured_yaw": "euler_z",
        "footprint": "yaw_rectangle",
    }[key]
    assert getattr(config_from_dict(raw, "p.yaml"), key) == default


def test_polymot_preset_values():
    cfg = config_from_dict(_raw())
    assert (cfg.assignment, cfg.time_step, cfg.ctra_form, cfg.bicycle_form, cfg.measured_yaw, cfg.footprint) == (
        "threshold_margin",
        0.5,
        "piecewise",
        "piecewise",
        "rotation_angle",
        "bottom_face",
    )
    assert cfg.first_threshold[1] == 1.34 and cfg.first_threshold[4] == 1.69  # bus, pedestrian (HEAD)


def _car(x: float) -> list[float]:
    return [x, 0.0, 1.0, 1.8, 4.5, 1.6, 0.0, 0.0, 0.0]


def test_polymot_drops_a_score_equal_to_its_threshold():
    # Poly-MOT's nusc_loader keeps det score > SF_thre; a file with scores at 2 decimals has many on a threshold
    cfg = config_from_dict(_raw())
    car, ped = CLASS_INDEX["car"], CLASS_INDEX["pedestrian"]
    thr = cfg.score_threshold
    dets = BoxSet(
        [_car(0.0), _car(10.0), _car(20.0), _car(30.0)],
        [thr[car], np.nextafter(thr[car], 1.0), thr[ped], 0.9],
        [car, car, ped, ped],
    )
    kept = preprocess_frame(dets, cfg)
    assert sorted(kept.scores.tolist()) == [np.nextafter(thr[car], 1.0), 0.9]
    at_least = preprocess_frame(
        dets, config_from_dict({**_raw(), "preprocessing": {**_raw()["preprocessing"], "score_filter": "at_least"}})
    )
    assert len(at_least.scores) == 4


def test_polymot_nms_visits_tied_scores_as_numpys_default_sort():
    # Poly-MOT's blend_nms: np.argsort(-score) (not stable). 100 cars of one score, far apart, but for one
    # overlapping pair (i, j), i < j, that the default sort visits j first: Poly-MOT keeps j, file order keeps i.
    n = 100
    scores = np.full(n, 0.5)
    order = np.argsort(-scores)
    rank = np.empty(n, dtype=np.int64)
    rank[order] = np.arange(n)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if rank[j] < rank[i]]
    assert pairs, "numpy's default sort left 100 equal scores in input order: no tie to test on"
    i, j = pairs[0]
    boxes = np.array([_car(50.0 * k) for k in range(n)])
    boxes[j, 0] = boxes[i, 0] + 0.5  # IoU well above 0.08
    labels = np.full(n, CLASS_INDEX["car"])
    cfg = config_from_dict(_raw())
    kept = preprocess_frame(BoxSet(boxes, scores, labels), cfg)
    xs = set(kept.boxes[:, 0].tolist())
    assert len(xs) == n - 1 and boxes[j, 0] in xs and boxes[i, 0] not in xs
    assert kept.boxes[:, 0].tolist() == boxes[[k for k in order if k != i], 0].tolist()  # in the order kept
    raw = _raw()
    raw["preprocessing"]["nms_order"] = "input"
    by_file = preprocess_frame(BoxSet(boxes, scores, labels), config_from_dict(raw))
    assert boxes[i, 0] in by_file.boxes[:, 0] and boxes[j, 0] not in by_file.boxes[:, 0]


@pytest.mark.parametrize("time_step, expected", [("timestamps", 0.4), (0.5, 0.5)])
def test_time_step(time_step, expected):
    raw = _raw()
    raw["motion"]["time_step"] = time_step
    cfg = config_from_dict(raw)
    tracker = Tracker(cfg, ekf_groups(cfg))
    car = np.array([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 10.0, 0.0]])
    tracker.step(BoxSet(car, np.array([0.9]), np.array([2])), 0)
    out = tracker.step(BoxSet(np.zeros((0, 9)), np.zeros(0), np.zeros(0, dtype=np.int64)), 400_000)
    assert out.boxes[0, 0] == pytest.approx(10.0 * expected, abs=1e-9)  # coasting car predicted dt ahead


# ----------------------------------------------------------------------------------------------------------------
# submission comparison
# ----------------------------------------------------------------------------------------------------------------


def _box(x: float, tid: str, name: str = "car", score: float = 0.5, yaw: float = 0.3) -> dict:
    return {
        "translation": [x, 1.0, 0.5],
        "size": [2.0, 4.0, 1.5],
        "rotation": quaternion_from_yaw(yaw)[0].tolist(),
        "velocity": [0.0, 0.0],
        "tracking_id": tid,
        "tracking_name": name,
        "tracking_score": score,
    }


def test_compare_tracks():
    ref = {"results": {"a": [_box(0, "0"), _box(10, "1", "pedestrian")], "b": [_box(1, "0"), _box(11, "1")]}}
    scene = {"a": "s", "b": "s"}
    renamed = copy.deepcopy(ref)
    for boxes in renamed["results"].values():
        for b in boxes:
            b["tracking_id"] = "x" + b["tracking_id"]
            b["velocity"] = [7.0, 0.1]  # Poly-MOT's [v, a]: not compared
    assert compare_tracks(ref, renamed, scene).identical
    split = copy.deepcopy(ref)
    split["results"]["b"][0]["tracking_id"] = "9"
    assert compare_tracks(ref, split, scene).partition_breaks == 1
    moved = copy.deepcopy(ref)
    moved["results"]["b"][1]["translation"][0] += 2e-6
    p = compare_tracks(ref, moved, scene)
    assert (p.paired, p.ref_boxes, p.first_divergence, p.identical) == (3, 4, "b", False)
    rescored = copy.deepcopy(ref)
    rescored["results"]["a"][0]["tracking_score"] = 0.6
    assert compare_tracks(ref, rescored, scene).score_mismatch == 1
    fewer = copy.deepcopy(ref)
    fewer["results"]["a"].pop()
    p = compare_tracks(ref, fewer, scene)
    assert p.count_mismatch == ["a"] and p.paired_fraction == 0.75


def test_report_poly_mot_rows_run_the_polymot_preset():
    """Table III's Poly-MOT row and Table IV's EKF / KF rows (Poly-MOT's motion models) track with the polymot
    preset (Table IV's with the model of bicycle and car replaced)."""
    from pathlib import Path

    cfg = yaml.safe_load((Path(__file__).resolve().parents[1] / "workflow/config/config.yaml").read_text())
    report = cfg["reports"]["nusc_val"]
    runs = cfg["experiments"][report["experiment"]]["runs"]
    rows = [report["tables"]["III"]["Poly-MOT"]] + [
        report["tables"]["IV"][r] for r in ("Bicycle+EKF", "CTRA+EKF", "CA+KF")
    ]
    for run in rows:
        assert runs[run]["tracker"] == "ekf"
        assert cfg["tracker_presets"][runs[run]["preset"]]["base"] == "polymot", run
    assert cfg["tracker_presets"][runs["ekf_ctra"]["preset"]]["overrides"] == {
        "motion": {"model_override": {"bicycle": "CTRA", "car": "CTRA"}}
    }
