"""Tracker preset keys ``motion.coast_yaw_rate`` and ``motion.coast_acceleration``: with ``zero`` an (E)KF track
predicted again without an update (coasting) has its turn rate (CTRA omega, Bicycle delta) and acceleration (CTRA
and Bicycle a, CA ax / ay) held at 0, so it goes straight on at constant speed; the first prediction after an update
and every track under ``keep`` (Poly-MOT's) are the motion model's."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from grutrack.classes import TRACKING_CLASSES
from grutrack.data.scene import BoxSet
from grutrack.errors import ConfigError
from grutrack.motion.models import make_model
from grutrack.tracking.config import PRESET_DIR, config_from_dict
from grutrack.tracking.ekf_backend import KalmanBackend
from grutrack.tracking.factory import coast_held

DT = 0.5


def _cfg(turn: str = "keep", accel: str = "keep", preset: str = "polymot", **per_class):
    """A preset with every class's coasting keys ``turn`` / ``accel``, and ``per_class`` {key: {class: value}}."""
    raw = yaml.safe_load((PRESET_DIR / f"{preset}.yaml").read_text())
    for key, value in (("coast_yaw_rate", turn), ("coast_acceleration", accel)):
        raw["motion"][key] = {**dict.fromkeys(TRACKING_CLASSES, value), **per_class.get(key, {})}
    return config_from_dict(raw, "test")


def _backend(model: str, turn: str, accel: str) -> KalmanBackend:
    m = make_model(model)
    d = m.dim_x
    R = np.tile(np.eye(9), (7, 1, 1))
    b = KalmanBackend(m, np.tile(np.eye(d) * 0.1, (7, 1, 1)), R, np.tile(np.eye(d), (7, 1, 1)))
    b.coast_held = coast_held(m, _cfg(turn, accel))
    return b


def _turning(b: KalmanBackend):
    """Two car tracks at the origin heading along x at 5 m/s, turning at 0.4 (rad/s or rad) and accelerating at
    1 m/s^2, as right after an update."""
    s = b.initiate(np.tile([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 5.0, 0.0]], (2, 1)), np.array([2, 2]))
    names = b.model.state_names
    turn = "omega" if "omega" in names else "delta"
    s.x[:, names.index(turn)] = 0.4
    s.x[:, names.index("a")] = 1.0
    return s


def _held(model, cfg) -> list[list[str]]:
    """The slot names each label holds."""
    return [[n for n, h in zip(model.state_names, row) if h] for row in coast_held(model, cfg)]


def test_coast_held_names_the_turn_rate_and_the_acceleration_per_class():
    ctra, bic, ca, cv = (make_model(n) for n in ("CTRA", "Bicycle", "CA", "CV"))
    both = _cfg("zero", "zero")
    assert _held(ctra, both) == [["a", "omega"]] * 7  # state order: x y z w l h v a yaw omega
    assert _held(bic, both) == [["a", "delta"]] * 7
    assert _held(ca, both) == [["ax", "ay"]] * 7
    assert coast_held(cv, both) is None and coast_held(ctra, _cfg()) is None
    assert _held(ctra, _cfg("zero")) == [["omega"]] * 7
    bus = TRACKING_CLASSES.index("bus")
    mixed = _cfg("zero", "zero", coast_yaw_rate={"bus": "keep"}, coast_acceleration={"bus": "keep"})
    assert _held(ctra, mixed)[bus] == [] and _held(ctra, mixed)[bus + 1] == ["a", "omega"]


def test_a_class_that_keeps_is_predicted_by_its_model_while_another_coasts():
    """One group, two labels: the bus keeps its turn rate, the car holds it."""
    m = make_model("CTRA")
    b = KalmanBackend(
        m, np.tile(np.eye(10) * 0.1, (7, 1, 1)), np.tile(np.eye(9), (7, 1, 1)), np.tile(np.eye(10), (7, 1, 1))
    )
    b.coast_held = coast_held(
        m, _cfg("zero", "zero", coast_yaw_rate={"bus": "keep"}, coast_acceleration={"bus": "keep"})
    )
    s = b.initiate(np.tile([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 5.0, 0.0]], (2, 1)), np.array([1, 2]))  # bus, car
    s.x[:, 9], s.x[:, 7] = 0.4, 1.0
    s1 = b.predict(s, DT, np.ones(2, dtype=bool))
    assert s1.x[0, 8] > 0.0 and s1.x[0, 6] > 5.0  # the bus turned and sped up
    assert s1.x[1, 8] == 0.0 and s1.x[1, 6] == 5.0  # the car went straight on at its speed


@pytest.mark.parametrize("model", ["CTRA", "Bicycle"])
def test_zero_drives_a_coasting_track_straight_at_constant_speed(model):
    keep, zero = _backend(model, "keep", "keep"), _backend(model, "zero", "zero")
    names = keep.model.state_names
    yaw, v = names.index("yaw"), names.index("v")
    coasting = np.array([True, False])  # the second track was just updated: predicted as the model says
    k1 = keep.predict(_turning(keep), DT)
    z1 = zero.predict(_turning(zero), DT, np.zeros(2, dtype=bool))  # the first prediction after the update
    np.testing.assert_array_equal(k1.x, z1.x)
    k2, z2 = keep.predict(k1, DT, coasting), zero.predict(z1, DT, coasting)
    k3, z3 = keep.predict(k2, DT, coasting), zero.predict(z2, DT, coasting)
    assert k3.x[0, yaw] > k2.x[0, yaw] > k1.x[0, yaw] and k3.x[0, v] > k2.x[0, v]  # keep turns and speeds up
    assert z3.x[0, yaw] == pytest.approx(z1.x[0, yaw], abs=1e-12)  # zero holds the heading it had ...
    assert z3.x[0, v] == pytest.approx(z1.x[0, v], abs=1e-12)  # ... and the speed
    step, heading = z3.x[0, :2] - z2.x[0, :2], z1.x[0, yaw]
    assert np.cross(step, [np.cos(heading), np.sin(heading)]) == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_array_equal(z3.x[1], k3.x[1])  # a track not coasting is predicted as under keep
    assert not np.array_equal(z3.P[0], k3.P[0])  # F is taken at the held state


def test_a_tracker_with_zero_coasts_a_lost_turning_car_straight(tmp_path):
    """End to end: a car driving a circle, then no detections; under ``zero`` the boxes written for the missed
    frames (punish_num) lie on the straight line of the heading the track had, under ``keep`` they turn on."""
    from grutrack.tracking.factory import build_tracker

    r, w = 20.0, 0.5  # a circle of 20 m at 0.5 rad/s: 10 m/s
    frames = []
    for k in range(8):
        a = w * DT * k
        box = [r * np.sin(a), r * (1 - np.cos(a)), 0.0, 1.9, 4.6, 1.7, a, r * w * np.cos(a), r * w * np.sin(a)]
        frames.append(BoxSet(np.array([box]), np.array([0.9]), np.array([2])))
    frames += [BoxSet(np.zeros((0, 9)), np.zeros(0), np.zeros(0, dtype=np.int64))] * 2
    written = {}
    for mode in ("keep", "zero"):
        raw = yaml.safe_load((PRESET_DIR / "polymot.yaml").read_text())
        raw["motion"].update(coast_yaw_rate=dict.fromkeys(TRACKING_CLASSES, mode))
        raw["motion"].update(coast_acceleration=dict.fromkeys(TRACKING_CLASSES, mode))
        raw["lifecycle"]["punish_num"] = 2
        raw["motion"]["time_step"] = "timestamps"
        path = tmp_path / f"coast_{mode}.yaml"
        path.write_text(yaml.safe_dump(raw))
        tracker = build_tracker("ekf", path)
        out = [tracker.step(f, int(k * DT * 1e6)) for k, f in enumerate(frames)]
        written[mode] = np.array([o.boxes[0] for o in out[-2:]])  # the two coasted frames
    keep, zero = written["keep"], written["zero"]
    assert zero[1, 6] == pytest.approx(zero[0, 6], abs=1e-9)  # the heading held from the first coasted frame
    assert abs(keep[1, 6] - keep[0, 6]) > 0.1  # keep turns on (0.5 rad/s x 0.5 s)
    step = zero[1, :2] - zero[0, :2]
    assert np.cross(step, [np.cos(zero[0, 6]), np.sin(zero[0, 6])]) == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(zero[0], keep[0])  # the first coasted frame: the model's prediction under both


def test_the_geometry_filter_passes_coasting_on():
    """Fast-Poly's geometry window wraps the EKF: coasting reaches the wrapped filter."""
    from grutrack.tracking.factory import ekf_groups

    groups = ekf_groups(_cfg("zero", "zero", preset="fastpoly"))
    ctra = next(g for g in groups if getattr(g.backend, "inner", None) and g.backend.inner.model.name == "CTRA")
    assert ctra.backend.coast_held is ctra.backend.inner.coast_held is not None
    s = ctra.backend.initiate(np.array([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 5.0, 0.0]]), np.array([2]))
    names = ctra.backend.inner.model.state_names
    s.motion.x[0, names.index("omega")] = 0.4
    held = ctra.backend.predict(s, DT, np.array([True]))
    assert held.motion.x[0, names.index("omega")] == 0.0


@pytest.mark.parametrize("key", ["coast_yaw_rate", "coast_acceleration"])
def test_bad_coast_values_are_refused(key):
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["motion"][key] = {**dict.fromkeys(TRACKING_CLASSES, "keep"), "car": "hold"}
    with pytest.raises(ConfigError, match=f"'motion.{key}.car' must be one of keep, zero"):
        config_from_dict(copy.deepcopy(raw), "test")
    mct = yaml.safe_load((PRESET_DIR / "mctrack.yaml").read_text())
    mct["motion"][key] = {**dict.fromkeys(TRACKING_CLASSES, "keep"), "car": "zero"}
    with pytest.raises(ConfigError, match=f"'motion.{key}' must be keep with 'motion.filter: decoupled_cv'"):
        config_from_dict(mct, "test")
