"""GRU-KF option ``coast_yaw_rate``: "zero" holds a coasting track's turn rate at 0 from its second frame without a
detection on (CTRA omega, Bicycle steering angle), so it keeps its heading through a gap; "keep" (the paper, and
every checkpoint written before the key) predicts with the SS model as it stands."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from grutrack.errors import ConfigError
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig
from grutrack.tracking.grukf_backend import GRUKFBackend, GRUState

DT = 0.5


def _backend(coast: str, ss_model: str = "CTRA") -> GRUKFBackend:
    net = GRUKalmanNet(GRUKFConfig(ss_model=ss_model, coast_yaw_rate=coast), generator=torch.Generator())
    return GRUKFBackend(net, device="cpu")


def _turning_track(b: GRUKFBackend, turn: float = 0.4) -> GRUState:
    """One car track at the origin heading along x at 5 m/s with turn-rate slot ``turn`` (CTRA omega rad/s,
    Bicycle steering angle rad), as right after an update (since 0)."""
    z = np.array([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 5.0, 0.0]])
    s = b.initiate(z, np.array([0]))
    x = s.x.clone()
    x[0, b.ss.turn_index] = turn
    return GRUState(torch.cat([x, s.rows[:, s.m :]], dim=1), s.hid, s.labels, s.n_updates, np.zeros(1, np.int64), s.P)


@pytest.mark.parametrize("ss_model", ["CTRA", "Bicycle"])
def test_zero_holds_the_turn_rate_from_the_second_coasted_frame_on(ss_model):
    keep, zero = _backend("keep", ss_model), _backend("zero", ss_model)
    sk, sz = _turning_track(keep), _turning_track(zero)
    yi, ti = keep.ss.yaw_index, keep.ss.turn_index
    sk1, sz1 = keep.predict(sk, DT), zero.predict(sz, DT)
    # the first prediction after an update is the SS model's under both (the frame may still bring a detection)
    assert torch.equal(sk1.x, sz1.x)
    assert float(sz1.x[0, yi]) != 0.0 and float(sz1.x[0, ti]) == pytest.approx(0.4)
    sk2, sz2 = keep.predict(sk1, DT), zero.predict(sz1, DT)
    sk3, sz3 = keep.predict(sk2, DT), zero.predict(sz2, DT)
    # coasting on: "keep" goes on turning, "zero" holds the heading it had and drives straight along it
    assert float(sk3.x[0, yi]) > float(sk2.x[0, yi]) > float(sk1.x[0, yi])
    assert float(sz3.x[0, ti]) == 0.0 and float(sz3.x[0, yi]) == pytest.approx(float(sz1.x[0, yi]), abs=1e-12)
    step = (sz3.x[0, :2] - sz2.x[0, :2]).numpy()
    heading = float(sz1.x[0, yi])
    assert np.cross(step, [np.cos(heading), np.sin(heading)]) == pytest.approx(0.0, abs=1e-9)


def test_keep_is_the_ss_model_and_zero_changes_only_coasting_tracks():
    keep, zero = _backend("keep"), _backend("zero")
    s = _turning_track(keep)
    np.testing.assert_array_equal(keep.predict(s, DT).x.numpy(), keep.ss.f(s.x, DT).numpy())
    # a track just updated (since 0) is predicted identically under both
    np.testing.assert_array_equal(zero.predict(s, DT).x.numpy(), keep.predict(s, DT).x.numpy())


def test_the_ekf_gain_prior_covariance_follows_the_zeroed_state():
    # with gain_prior ekf the prior EKF's P^- is predicted at the same (zeroed) state as the network's prior
    net = GRUKalmanNet(GRUKFConfig(gain_prior="ekf", coast_yaw_rate="zero"), generator=torch.Generator())
    eye = torch.eye(10, dtype=torch.float64).repeat(7, 1, 1)
    net.set_ekf_noise(0.1 * eye, torch.eye(9, dtype=torch.float64).repeat(7, 1, 1), eye)
    b = GRUKFBackend(net, device="cpu")
    s1 = b.predict(_turning_track(b), DT)
    s2 = b.predict(s1, DT)
    x0 = s1.x.numpy().copy()
    x0[0, b.ss.turn_index] = 0.0
    _, P_want = b.kf.predict(x0, s1.P, b.Q[b._classes(s1.labels)], DT)
    _, P_unzeroed = b.kf.predict(s1.x.numpy(), s1.P, b.Q[b._classes(s1.labels)], DT)
    np.testing.assert_allclose(s2.P, P_want, rtol=0, atol=1e-12)
    assert not np.allclose(s2.P, P_unzeroed)


def test_the_option_is_checked_stored_and_absent_means_keep(tmp_path):
    from grutrack.motion.checkpoint import load_network, save_checkpoint
    from grutrack.training.config import load_train_config

    with pytest.raises(ValueError, match="coast_yaw_rate must be one of keep, zero, got 'hold'"):
        GRUKalmanNet(GRUKFConfig(coast_yaw_rate="hold"))
    with pytest.raises(ConfigError, match="'network.coast_yaw_rate' must be 'keep' or 'zero', got 'hold'"):
        load_train_config("grukf", {"coast_yaw_rate": "hold"})
    assert load_train_config("grukf").network["coast_yaw_rate"] == "zero"  # the default recipe's
    assert load_train_config("paper").network["coast_yaw_rate"] == "keep"  # the paper's
    net = GRUKalmanNet(GRUKFConfig(coast_yaw_rate="zero"), generator=torch.Generator())
    save_checkpoint(tmp_path / "z.pt", net)
    assert load_network(tmp_path / "z.pt").cfg.coast_yaw_rate == "zero"
    ck = torch.load(tmp_path / "z.pt", weights_only=False)
    del ck["arch"]["coast_yaw_rate"]  # a checkpoint written before the key
    torch.save(ck, tmp_path / "old.pt")
    assert load_network(tmp_path / "old.pt").cfg.coast_yaw_rate == "keep"


def test_the_trainer_builds_the_network_with_the_training_configs_value():
    from grutrack.training.config import load_train_config
    from grutrack.training.network import network_config as _arch

    assert _arch(load_train_config("grukf", {"coast_yaw_rate": "keep"})).coast_yaw_rate == "keep"
    assert _arch(load_train_config("grukf")).coast_yaw_rate == "zero"


# ``coast_acceleration``: "zero" holds a coasting track's acceleration at 0 from its second frame without a detection
# on, so that it coasts at the speed it had; "keep" (the paper, and every checkpoint written before the key)
# extrapolates the acceleration, which can turn the speed's sign over a long gap.


def _accelerating_track(b: GRUKFBackend, accel: float = -2.0) -> GRUState:
    """One car track at the origin heading along x at 5 m/s with acceleration ``accel`` m/s^2, as right after an
    update (since 0)."""
    z = np.array([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, 0.0, 5.0, 0.0]])
    s = b.initiate(z, np.array([0]))
    x = s.x.clone()
    x[0, b.ss.accel_index] = accel
    return GRUState(torch.cat([x, s.rows[:, s.m :]], dim=1), s.hid, s.labels, s.n_updates, np.zeros(1, np.int64), s.P)


def _accel_backend(coast: str, ss_model: str = "CTRA", yaw: str = "keep") -> GRUKFBackend:
    net = GRUKalmanNet(
        GRUKFConfig(ss_model=ss_model, coast_acceleration=coast, coast_yaw_rate=yaw), generator=torch.Generator()
    )
    return GRUKFBackend(net, device="cpu")


@pytest.mark.parametrize("ss_model", ["CTRA", "Bicycle"])
def test_zero_acceleration_coasts_at_the_speed_of_the_first_prediction(ss_model):
    keep, zero = _accel_backend("keep", ss_model), _accel_backend("zero", ss_model)
    ai, vi = keep.ss.accel_index, 6
    sk1, sz1 = keep.predict(_accelerating_track(keep), DT), zero.predict(_accelerating_track(zero), DT)
    # the first prediction after an update is the SS model's under both: 5 - 2 * 0.5 = 4 m/s
    assert torch.equal(sk1.x, sz1.x) and float(sz1.x[0, vi]) == pytest.approx(4.0)
    sk, sz = sk1, sz1
    for _ in range(5):  # 3 s of coasting in all
        sk, sz = keep.predict(sk, DT), zero.predict(sz, DT)
    # "keep" brakes through zero and drives backwards (5 - 2 * 3 = -1 m/s); "zero" holds 4 m/s
    assert float(sk.x[0, vi]) == pytest.approx(-1.0)
    assert float(sz.x[0, vi]) == pytest.approx(4.0) and float(sz.x[0, ai]) == 0.0
    # and moves 4 m/s * 0.5 s = 2 m along its heading (x) per frame
    step = zero.predict(sz, DT).x[0, :2] - sz.x[0, :2]
    np.testing.assert_allclose(step.numpy(), [2.0, 0.0], atol=1e-9)


def test_both_options_hold_both_slots_and_nothing_else():
    both = _accel_backend("zero", yaw="zero")
    s = _accelerating_track(both)
    x = s.x.clone()
    x[0, both.ss.turn_index] = 0.3
    s = GRUState(torch.cat([x, s.rows[:, s.m :]], dim=1), s.hid, s.labels, s.n_updates, np.ones(1, np.int64), s.P)
    held = both._coasted(s)  # since 1: coasting
    want = x.clone()
    want[0, both.ss.turn_index] = want[0, both.ss.accel_index] = 0.0
    assert torch.equal(held, want)
    assert both._coast_slots() == [both.ss.turn_index, both.ss.accel_index]
    assert _accel_backend("keep")._coast_slots() == []


def test_coast_acceleration_is_checked_stored_and_absent_means_keep(tmp_path):
    from grutrack.motion.checkpoint import load_network, save_checkpoint
    from grutrack.training.config import load_train_config
    from grutrack.training.network import network_config as _arch

    with pytest.raises(ValueError, match="coast_acceleration must be one of keep, zero, got 'hold'"):
        GRUKalmanNet(GRUKFConfig(coast_acceleration="hold"))
    with pytest.raises(ConfigError, match="'network.coast_acceleration' must be 'keep' or 'zero', got 'hold'"):
        load_train_config("grukf", {"coast_acceleration": "hold"})
    assert load_train_config("grukf").network["coast_acceleration"] == "zero"  # the default recipe's
    assert load_train_config("paper").network["coast_acceleration"] == "keep"  # the paper's
    assert _arch(load_train_config("grukf", {"coast_acceleration": "zero"})).coast_acceleration == "zero"
    assert _arch(load_train_config("grukf", {"coast_acceleration": "keep"})).coast_acceleration == "keep"
    net = GRUKalmanNet(GRUKFConfig(coast_acceleration="zero"), generator=torch.Generator())
    save_checkpoint(tmp_path / "z.pt", net)
    assert load_network(tmp_path / "z.pt").cfg.coast_acceleration == "zero"
    ck = torch.load(tmp_path / "z.pt", weights_only=False)
    del ck["arch"]["coast_acceleration"]  # a checkpoint written before the key
    torch.save(ck, tmp_path / "old.pt")
    assert load_network(tmp_path / "old.pt").cfg.coast_acceleration == "keep"
