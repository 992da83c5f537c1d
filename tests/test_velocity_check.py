"""The check of the detector's velocity against a track's displacement (tracker preset ``motion.velocity_check_*``,
``grutrack/tracking/velocity_check.py``): a track whose detected velocity keeps disagreeing with the
motion of its detections stops taking it; a track whose velocity agrees is filtered exactly as without the check."""

from __future__ import annotations

import numpy as np
import pytest

from grutrack.motion.models import make_model
from grutrack.tracking.ekf_backend import KalmanBackend
from grutrack.tracking.velocity_check import IGNORED_VELOCITY_VARIANCE, VelocityCheck

DT = 0.5
CHECK = VelocityCheck(updates=5, difference=2.0, ratio=0.5)


def _backend(model: str, check: VelocityCheck | None) -> KalmanBackend:
    m = make_model(model)
    d = m.dim_x
    R = np.tile(np.diag([1.0, 1, 1, 1, 1, 1, 1, 2, 2]), (7, 1, 1))
    return KalmanBackend(m, np.tile(np.eye(d), (7, 1, 1)), R, np.tile(np.eye(d) * 4.0, (7, 1, 1)), velocity_check=check)


def _detections(speed: float, reported: float, frames: int) -> np.ndarray:
    """(frames, 1, 9) detections of a bus driving along x at ``speed`` m/s whose detector reports ``reported``
    times its velocity."""
    z = np.zeros((frames, 1, 9))
    z[:, 0, 0] = speed * DT * np.arange(frames)
    z[:, 0, 3:6] = (2.9, 11.0, 3.5)
    z[:, 0, 7] = reported * speed
    return z


def _run(backend: KalmanBackend, z: np.ndarray):
    s = backend.initiate(z[0], np.array([1]))
    for frame in z[1:]:
        s = backend.update(backend.predict(s, DT), np.array([0]), frame)
    return s


def test_disagreement_is_against_the_displacement_velocity():
    z = np.zeros((4, 9))
    z[:, 0] = [2.5, 2.5, 0.5, 20.0]  # 2.5 m in 0.5 s = 5 m/s, except row 2 (1 m/s) and row 3 (40 m/s)
    z[:, 7] = [0.5, 4.0, -0.9, 30.0]
    got = CHECK.disagree_with(z, np.zeros((4, 2)), np.array([0.5, 0.5, 0.5, 0.5]))
    # 4.5 m/s off at 5 m/s: disagrees; 1 m/s off: agrees; 1.9 m/s off at 1 m/s: under 2 m/s; 10 m/s off at 40 m/s:
    # within 50 %
    assert got.tolist() == [True, False, False, False]


@pytest.mark.parametrize("model", ["CTRA", "CV"])
def test_a_failed_velocity_is_ignored_after_the_set_number_of_updates(model):
    """A bus at 8 m/s detected at 0.8 m/s: with the check the filter's speed reaches the true one, without it the
    detected velocity holds it back."""
    z = _detections(8.0, 0.1, 16)
    checked, plain = _run(_backend(model, CHECK), z), _run(_backend(model, None), z)
    assert checked.check.disagree[0] == CHECK.updates  # frozen there: failed for the rest of the track's life
    v_checked = np.hypot(*_backend(model, None).boxes(checked)[0, 7:9])
    v_plain = np.hypot(*_backend(model, None).boxes(plain)[0, 7:9])
    assert abs(v_checked - 8.0) < 1.0 < abs(v_plain - 8.0)


def test_the_failed_track_takes_the_ignored_variance_only_after_the_count():
    backend = _backend("CTRA", CHECK)
    z = _detections(8.0, 0.1, 8)
    s = backend.initiate(z[0], np.array([1]))
    counts = []
    for frame in z[1:]:
        s = backend.update(backend.predict(s, DT), np.array([0]), frame)
        counts.append(int(s.check.disagree[0]))
        S_vv = s.corrected.S[0, 7, 7]
        assert (S_vv > IGNORED_VELOCITY_VARIANCE) == (counts[-1] >= CHECK.updates)
    assert counts == [1, 2, 3, 4, 5, 5, 5]


def test_an_agreeing_update_resets_the_count():
    backend = _backend("CV", CHECK)
    z = _detections(8.0, 0.1, 8)
    z[4, 0, 7] = 8.0  # one frame with the right velocity
    s = backend.initiate(z[0], np.array([1]))
    counts = []
    for frame in z[1:]:
        s = backend.update(backend.predict(s, DT), np.array([0]), frame)
        counts.append(int(s.check.disagree[0]))
    assert counts == [1, 2, 3, 0, 1, 2, 3]


@pytest.mark.parametrize("model", ["CTRA", "CV", "Bicycle"])
def test_agreeing_velocities_are_filtered_exactly_as_without_the_check(model):
    z = _detections(8.0, 1.0, 12)
    z[:, 0, 0] += np.random.default_rng(0).normal(0, 0.2, 12)
    checked, plain = _run(_backend(model, CHECK), z), _run(_backend(model, None), z)
    assert np.array_equal(checked.x, plain.x) and np.array_equal(checked.P, plain.P)
    assert checked.check.disagree[0] < CHECK.updates


def _counts(check: VelocityCheck, z: np.ndarray, dts: np.ndarray) -> list[int]:
    """The disagreement count of one track after each update with detections ``z (F, 9)``, ``dts (F - 1,)`` s apart."""
    s, counts = check.start(z[:1]), []
    for frame, dt in zip(z[1:], dts):
        s, _ = check.observe(s.predicted(dt), np.array([0]), frame[None])
        counts.append(int(s.disagree[0]))
    return counts


def _bus(speed: float, reported: float, times: np.ndarray, noise: float, seed: int = 0) -> np.ndarray:
    """(F, 9) detections at ``times`` (s) of a vehicle along x at ``speed`` m/s, centres with ``noise`` m (sigma) of
    noise, its velocity reported at ``reported`` times the true one."""
    z = np.zeros((len(times), 9))
    z[:, :2] = np.random.default_rng(seed).normal(0.0, noise, (len(times), 2))
    z[:, 0] += speed * times
    z[:, 7] = reported * speed
    return z


def test_the_window_compares_updates_at_least_that_far_apart():
    """At 10 Hz with a 0.25 s window, a failed velocity is compared at every third update (0.3 s of displacement)."""
    t = np.arange(16) * 0.1
    counts = _counts(VelocityCheck(5, 2.0, 0.5, window=0.25), _bus(8.0, 0.1, t, 0.0), np.diff(t))
    assert counts == [0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3, 4, 4, 4, 5]


def test_the_window_keeps_noisy_centres_at_10_hz_from_failing_a_right_velocity():
    """A car at 3 m/s whose centres carry 0.2 m of noise, 0.1 s apart, makes a displacement velocity some 2.8 m/s off
    the true one: compared at every update, a right velocity fails on nearly every draw; over 0.3 s (the preset's
    window of 0.25 s at 10 Hz) on none."""
    t = np.arange(40) * 0.1
    failed_every, failed_window = 0, 0
    for seed in range(10):
        z = _bus(3.0, 1.0, t, 0.2, seed)
        failed_every += max(_counts(VelocityCheck(5, 2.0, 0.5), z, np.diff(t))) == 5
        failed_window += max(_counts(VelocityCheck(5, 2.0, 0.5, window=0.25), z, np.diff(t))) == 5
    assert failed_every >= 8 and failed_window == 0


def test_the_window_changes_nothing_at_nuscenes_keyframe_intervals():
    rng = np.random.default_rng(1)
    dts = rng.uniform(0.40, 0.60, 30)  # nuScenes keyframes are 0.40-0.60 s apart
    t = np.concatenate([[0.0], np.cumsum(dts)])
    for reported in (0.1, 1.0):
        z = _bus(8.0, reported, t, 0.3, seed=2)
        assert _counts(VelocityCheck(5, 2.0, 0.5, window=0.25), z, dts) == _counts(CHECK, z, dts)


def test_select_and_concat_carry_the_check_state():
    backend = _backend("CV", CHECK)
    z = np.concatenate([_detections(8.0, 0.1, 7), _detections(3.0, 1.0, 7)], axis=1)
    s = backend.initiate(z[0], np.array([1, 2]))
    for frame in z[1:]:
        s = backend.update(backend.predict(s, DT), np.array([0, 1]), frame)
    both = backend.concat(backend.select(s, np.array([1])), backend.select(s, np.array([0])))
    assert both.check.disagree.tolist() == [0, 5]
    np.testing.assert_array_equal(both.check.last_xy, s.check.last_xy[::-1])
    np.testing.assert_array_equal(both.check.elapsed, s.check.elapsed[::-1])


def test_the_preset_keys_build_the_check():
    from grutrack.config_loader import read_config
    from grutrack.errors import ConfigError
    from grutrack.tracking.config import config_from_dict, load_tracker_config, preset_path
    from grutrack.tracking.factory import velocity_check

    assert velocity_check(load_tracker_config("polymot")) is None  # off unless a preset asks for it
    raw, _ = read_config("tracker", preset_path("polymot"))
    raw["motion"].update(velocity_check_updates=3, velocity_check_difference=1.5, velocity_check_ratio=0.25)
    assert velocity_check(config_from_dict(raw, "test")) == VelocityCheck(3, 1.5, 0.25, 0.25)
    raw["motion"]["velocity_check_updates"] = -1
    with pytest.raises(ConfigError, match="velocity_check_updates"):
        config_from_dict(raw, "test")


def _gru_run(backend, z: np.ndarray, replace_from: int | None = None):
    """Track the bus of ``z`` with a GRU-KF backend; with ``replace_from`` the detected velocity of every update from
    that one on (0-based) is replaced by the track's predicted one, by hand."""
    s = backend.initiate(z[0], np.array([1]))
    for k, frame in enumerate(z[1:]):
        s = backend.predict(s, DT)
        if replace_from is not None and k >= replace_from:
            frame = frame.copy()
            frame[0, 7:9] = backend.measure(s).detach().numpy()[0, 7:9]
        s = backend.update(s, np.array([0]), frame)
    return s


def test_the_gru_kf_takes_the_predicted_velocity_once_the_velocity_failed():
    """Without an EKF gain prior the check changes only z: the checked run equals, bit for bit, an unchecked run
    fed the track's predicted velocity from the update where the count reaches 5 on."""
    import torch

    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig
    from grutrack.tracking.grukf_backend import GRUKFBackend

    net = GRUKalmanNet(GRUKFConfig(), generator=torch.Generator().manual_seed(0)).eval()
    g = torch.Generator().manual_seed(1)
    with torch.no_grad():  # a gain that is not 0 (the initial network's output layer is)
        for p in net.parameters():
            p.copy_(0.1 * torch.randn(p.shape, generator=g, dtype=p.dtype))
    z = _detections(8.0, 0.1, 10)
    checked = _gru_run(GRUKFBackend(net, "cpu", velocity_check=CHECK), z)
    by_hand = _gru_run(GRUKFBackend(net, "cpu"), z, replace_from=CHECK.updates - 1)
    unchecked = _gru_run(GRUKFBackend(net, "cpu"), z)
    assert checked.check.disagree.tolist() == [CHECK.updates]
    assert torch.equal(checked.rows, by_hand.rows)
    assert not torch.equal(checked.rows, unchecked.rows)


def test_the_shipped_gru_kf_follows_a_failed_velocity_less_with_the_check():
    """The pretrained network (EKF gain prior, whose noise then leaves the velocity out) on a bus at 8 m/s
    detected at 0.8 m/s: its speed is nearer the true one with the check."""
    from grutrack.motion.checkpoint import load_network
    from grutrack.tracking.grukf_backend import GRUKFBackend
    from grutrack.training.pretrained import pretrained_dir

    net = load_network(pretrained_dir("grukf_default") / "model.pt")
    z = _detections(8.0, 0.1, 16)
    speed = {}
    for name, check in (("checked", CHECK), ("plain", None)):
        backend = GRUKFBackend(net, "cpu", velocity_check=check)
        speed[name] = float(np.hypot(*backend.boxes(_gru_run(backend, z))[0, 7:9]))
    assert abs(speed["checked"] - 8.0) < abs(speed["plain"] - 8.0) - 1.0, speed


def test_the_gru_kf_prior_tests_a_track_only_after_min_hits():
    """The GRU-KF's EKF gain prior reads each track's update count for the robust update (``nis_min_hits``): a bus
    whose last detection jumps 6 m sideways (5 hits before it) is filtered as without the robust update when
    min_hits is above its hits, and differently when it is not."""
    import torch

    from grutrack.motion.checkpoint import load_network
    from grutrack.motion.kalman import RobustUpdate
    from grutrack.tracking.grukf_backend import GRUKFBackend
    from grutrack.training.pretrained import pretrained_dir

    net = load_network(pretrained_dir("grukf_default") / "model.pt")
    z = _detections(8.0, 1.0, 6)
    z[5, 0, 1] += 6.0  # 5 hits before it (birth and 4 updates)
    rows = {
        name: _gru_run(GRUKFBackend(net, "cpu", robust=robust), z).rows
        for name, robust in (("plain", None), ("late", RobustUpdate(2.0, 6)), ("early", RobustUpdate(2.0, 5)))
    }
    assert torch.equal(rows["late"], rows["plain"])
    assert not torch.equal(rows["early"], rows["plain"])
