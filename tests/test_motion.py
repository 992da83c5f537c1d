"""Tests of grutrack.motion: state-space models, the batched Kalman filter and the per-class configuration."""

from __future__ import annotations

import numpy as np
import pytest

from grutrack.boxes import wrap_angle
from grutrack.classes import CLASS_INDEX, TRACKING_CLASSES
from grutrack.errors import ConfigError
from grutrack.motion import (
    CA,
    CTRA,
    CV,
    DEFAULT_CONFIG,
    BatchKalmanFilter,
    Bicycle,
    RobustUpdate,
    arc_moments,
    class_matrices,
    load_motion_config,
    make_model,
)

MODELS = [CTRA(), Bicycle(), Bicycle(wheelbase_ratio=0.7, front_ratio=0.3), CA(), CV()]
MODEL_IDS = ["CTRA", "Bicycle", "Bicycle-offset", "CA", "CV"]
DT = 0.5


def random_states(model, n: int = 40, seed: int = 0) -> np.ndarray:
    """Random plausible states plus singular rows (zero / tiny turn rate or steering, zero speed)."""
    rng = np.random.default_rng(seed)
    x = np.zeros((n, model.dim_x))
    x[:, 0:2] = rng.uniform(-50, 50, (n, 2))
    x[:, 2] = rng.uniform(-2, 2, n)
    x[:, 3:6] = rng.uniform(0.5, 10, (n, 3))
    x[:, model.yaw_index] = rng.uniform(-np.pi, np.pi, n)
    if isinstance(model, (CTRA, Bicycle)):
        x[:, 6] = rng.uniform(-5, 20, n)
        x[:, 7] = rng.uniform(-3, 3, n)
        x[:, 9] = rng.uniform(-1, 1, n) if isinstance(model, CTRA) else rng.uniform(-0.6, 0.6, n)
        # singular / near-singular turn rate (CTRA) or steering angle (Bicycle), either side of the series switch
        x[:6, 9] = [0.0, 1e-9, -1e-6, 0.2499 / DT, 0.2501 / DT, -0.25 / DT]
        x[6:9, 6] = 0.0  # standing still
        x[9, 6:8] = 0.0  # standing still, no acceleration, turning
    else:
        x[:, 6:8] = rng.uniform(-15, 15, (n, 2))
        if isinstance(model, CA):
            x[:, 8:10] = rng.uniform(-3, 3, (n, 2))
    return x


def numeric_jacobian(fun, x: np.ndarray) -> np.ndarray:
    """Central finite-difference Jacobian (N, m, d) of a batched function fun: (N, d) -> (N, m)."""
    n, d = x.shape
    cols = []
    for j in range(d):
        step = 1e-6 * np.maximum(1.0, np.abs(x[:, j]))
        xp, xm = x.copy(), x.copy()
        xp[:, j] += step
        xm[:, j] -= step
        cols.append((fun(xp) - fun(xm)) / (2 * step[:, None]))
    return np.stack(cols, axis=-1)


# ------------------------------------------------------------------------------------------------ models


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_F_matches_finite_differences(model):
    x = random_states(model)
    for dt in (DT, np.linspace(0.05, 1.0, x.shape[0])):
        analytic = model.F(x, dt)
        numeric = numeric_jacobian(lambda s: model.f(s, dt), x)
        assert analytic.shape == (x.shape[0], model.dim_x, model.dim_x)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_H_matches_finite_differences(model):
    x = random_states(model, seed=1)
    analytic = model.H(x)
    assert analytic.shape == (x.shape[0], 9, model.dim_x)
    np.testing.assert_allclose(analytic, numeric_jacobian(model.h, x), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("model", [CA(), CV()], ids=["CA", "CV"])
def test_linear_models_f_equals_F_x_and_h_equals_H_x(model):
    x = random_states(model, seed=2)
    np.testing.assert_allclose(model.f(x, DT), np.einsum("nij,nj->ni", model.F(x, DT), x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(model.h(x), np.einsum("nij,nj->ni", model.H(x), x), rtol=0, atol=1e-12)
    # and the transition is the textbook one
    xn = model.f(x, DT)
    acc = x[:, 8:10] if isinstance(model, CA) else 0.0
    np.testing.assert_allclose(xn[:, 0:2], x[:, 0:2] + x[:, 6:8] * DT + 0.5 * acc * DT**2, atol=1e-12)


def test_arc_moments_match_quadrature_on_both_sides_of_the_series_switch():
    phi = np.array([0.0, 1e-12, 1e-4, 0.1, 0.2499999, 0.2500001, 0.7, 2.0, -3.0])
    s = np.linspace(0.0, 1.0, 20001)
    w = np.full(s.size, 1.0)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0  # Simpson weights
    w *= (s[1] - s[0]) / 3.0
    for n, (re, im) in enumerate(arc_moments(phi, order=2)):
        ref = (s[None] ** n * np.exp(1j * phi[:, None] * s[None])) @ w
        np.testing.assert_allclose(re, ref.real, atol=1e-13)
        np.testing.assert_allclose(im, ref.imag, atol=1e-13)


def _rk4(deriv, y0: np.ndarray, t_end: float, steps: int = 2000) -> np.ndarray:
    h, y = t_end / steps, y0.copy()
    for k in range(steps):
        t = k * h
        k1 = deriv(t, y)
        k2 = deriv(t + h / 2, y + h / 2 * k1)
        k3 = deriv(t + h / 2, y + h / 2 * k2)
        k4 = deriv(t + h, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return y


def test_ctra_transition_integrates_the_ctra_ode():
    model = CTRA()
    x = random_states(model, n=12, seed=3)
    xn = model.f(x, DT)
    v, a, yaw, om = x[:, 6], x[:, 7], x[:, 8], x[:, 9]

    def deriv(t, p):  # p = (x, y) positions of all tracks
        speed, heading = v + a * t, yaw + om * t
        return np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)

    np.testing.assert_allclose(xn[:, 0:2], _rk4(deriv, x[:, 0:2], DT), atol=1e-9)
    np.testing.assert_allclose(xn[:, 6], v + a * DT, atol=1e-12)
    np.testing.assert_allclose(xn[:, 8], yaw + om * DT, atol=1e-12)


@pytest.mark.parametrize("model", [Bicycle(), Bicycle(wheelbase_ratio=0.7, front_ratio=0.3)], ids=["default", "offset"])
def test_bicycle_transition_integrates_the_kinematic_bicycle_ode(model):
    x = random_states(model, n=12, seed=4)
    xn = model.f(x, DT)
    v, a, delta, length = x[:, 6], x[:, 7], x[:, 9], x[:, 4]
    lr = length * model.wheelbase_ratio * (1 - model.front_ratio)
    beta = np.arctan((1 - model.front_ratio) * np.tan(delta))

    def deriv(t, p):  # p = (x, y, yaw)
        speed = v + a * t
        return np.stack([speed * np.cos(p[:, 2] + beta), speed * np.sin(p[:, 2] + beta), speed * np.sin(beta) / lr], 1)

    ref = _rk4(deriv, x[:, [0, 1, 8]], DT)
    np.testing.assert_allclose(xn[:, [0, 1, 8]], ref, atol=1e-9)
    np.testing.assert_allclose(xn[:, 6], v + a * DT, atol=1e-12)


def test_singular_limits_are_finite_and_continuous():
    ctra = CTRA()
    x = np.array([[1.0, 2.0, 0.0, 2.0, 4.5, 1.6, 8.0, 1.0, 0.3, 0.0]])
    straight = x[0, 0:2] + (8.0 * DT + 0.5 * DT**2) * np.array([np.cos(0.3), np.sin(0.3)])
    for om in (0.0, 1e-14, 1e-8, -1e-8):
        x[0, 9] = om
        out = ctra.f(x, DT)
        assert np.all(np.isfinite(out)) and np.all(np.isfinite(ctra.F(x, DT)))
        np.testing.assert_allclose(out[0, 0:2], straight, atol=1e-7)
    bic = Bicycle()
    xb = np.array(
        [
            [1.0, 2.0, 0.0, 0.7, 1.8, 1.4, 5.0, 0.0, -1.0, 0.0],
            [1.0, 2.0, 0.0, 0.7, 0.0, 1.4, 5.0, 0.0, -1.0, 0.3],  # zero length: curvature capped, finite
            [1.0, 2.0, 0.0, 0.7, 1.8, 1.4, 0.0, 0.0, -1.0, np.pi / 2],
        ]
    )  # steering at 90 degrees
    for fn in (bic.f(xb, DT), bic.F(xb, DT), bic.h(xb), bic.H(xb)):
        assert np.all(np.isfinite(fn))
    np.testing.assert_allclose(bic.f(xb, DT)[0, 0:2], [1 + 2.5 * np.cos(-1.0), 2 + 2.5 * np.sin(-1.0)], atol=1e-12)


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_init_state_round_trips_through_h_and_writes_global_velocity(model):
    rng = np.random.default_rng(5)
    n = 20
    z = np.zeros((n, 9))
    z[:, 0:3] = rng.uniform(-30, 30, (n, 3))
    z[:, 3:6] = rng.uniform(0.5, 8, (n, 3))
    z[:, 6] = rng.uniform(-np.pi, np.pi, n)
    speed = rng.uniform(0, 15, n)
    z[:, 7], z[:, 8] = speed * np.cos(z[:, 6]), speed * np.sin(z[:, 6])  # moving along the heading
    x = model.init_state(z)
    assert x.shape == (n, model.dim_x)
    boxes = model.to_boxes(x)
    np.testing.assert_allclose(boxes, z, atol=1e-12)
    # after a prediction the written velocity is still a global (vx, vy), never (v, a)
    pred = model.to_boxes(model.f(x, DT))
    np.testing.assert_allclose(np.hypot(pred[:, 7], pred[:, 8]), speed, atol=1e-9)
    assert np.all((pred[:, 6] >= -np.pi) & (pred[:, 6] < np.pi))


# ------------------------------------------------------------------------------------------------ filter


def simulate_arc(steps: int, speed: float = 10.0, omega: float = 0.3, seed: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth boxes (steps, 9) of a car on a constant-turn-rate circle and noisy detections of them."""
    t = np.arange(steps) * DT
    yaw = 0.2 + omega * t
    radius = speed / omega
    truth = np.zeros((steps, 9))
    truth[:, 0] = 10 + radius * (np.sin(yaw) - np.sin(0.2))
    truth[:, 1] = -5 - radius * (np.cos(yaw) - np.cos(0.2))
    truth[:, 3:6] = [1.9, 4.6, 1.7]
    truth[:, 6] = wrap_angle(yaw)
    truth[:, 7], truth[:, 8] = speed * np.cos(yaw), speed * np.sin(yaw)
    rng = np.random.default_rng(seed)
    noise = rng.normal(0, 1, truth.shape) * [0.1, 0.1, 0.05, 0.05, 0.05, 0.05, 0.02, 0.2, 0.2]
    return truth, truth + noise


def run_filter(kf, dets, P0, Q, R):
    """Filter one track through detections (steps, 9); the one-step-ahead predicted boxes (steps-1, 9)."""
    x, P = kf.initiate(dets[:1], P0)
    predicted = []
    for z in dets[1:]:
        x, P = kf.predict(x, P, Q, DT)
        predicted.append(kf.model.to_boxes(x)[0])
        x, P = kf.update(x, P, z[None], R)
    return np.array(predicted)


def test_ctra_tracks_a_turning_car_better_than_cv():
    truth, dets = simulate_arc(16)
    errors = {}
    for model in (CTRA(), CV()):
        d = model.dim_x
        q = np.full(d, 0.01)
        q[model.yaw_index] = 0.001
        R = np.diag([0.01, 0.01, 0.0025, 0.0025, 0.0025, 0.0025, 0.0004, 0.04, 0.04])
        pred = run_filter(BatchKalmanFilter(model), dets, np.eye(d), np.diag(q), R)
        errors[model.name] = np.linalg.norm(pred[4:, 0:2] - truth[5:, 0:2], axis=1).mean()
    # CV drifts outward by about v * omega * dt^2 / 2 per step; CTRA learns the turn rate
    assert errors["CTRA"] < 0.5 * errors["CV"], errors


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_joseph_covariance_stays_symmetric_positive_definite(model):
    cfg = load_motion_config()
    cls = {"CTRA": "car", "Bicycle": "bicycle", "CA": "trailer", "CV": "trailer"}[model.name]
    Q, R, P0 = cfg[cls]["Q"], cfg[cls]["R"], cfg[cls]["P0"]
    if model.name == "CV":
        Q, P0 = 100.0 * np.eye(9), 0.01 * np.eye(9)
    truth, dets = simulate_arc(101, speed=6.0, omega=0.15)
    kf = BatchKalmanFilter(model)
    x, P = kf.initiate(dets[:1], P0)
    for k, z in enumerate(dets[1:]):
        x, P = kf.predict(x, P, Q, DT)
        assert -np.pi <= x[0, model.yaw_index] < np.pi  # the heading goes round 7.5 rad: wrapped after predict
        if k % 7 != 3:  # a few missed frames
            x, P = kf.update(x, P, z[None], R)
        assert np.array_equal(P, np.swapaxes(P, 1, 2))
        assert np.linalg.eigvalsh(P).min() > 0.0
        assert np.all(np.isfinite(x))
    assert np.linalg.norm(model.to_boxes(x)[0, 0:2] - truth[-1, 0:2]) < 1.0


def _one_step_yaw(kf: BatchKalmanFilter, state_yaw: float, det_yaw: float) -> float:
    """Yaw after one update of a track at state_yaw with a detection at det_yaw (same position and velocity)."""
    model = kf.model
    z0 = np.array([[0.0, 0.0, 0.0, 2.0, 4.5, 1.6, state_yaw, 0.0, 0.0]])
    x, P = kf.initiate(z0, np.eye(model.dim_x))
    z = z0.copy()
    z[0, 6] = det_yaw
    x, _ = kf.update(x, P, z, np.eye(9))
    return float(x[0, model.yaw_index])


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
@pytest.mark.parametrize("yaw_flip", [True, False])
def test_yaw_residual_is_wrapped(model, yaw_flip):
    kf = BatchKalmanFilter(model, yaw_flip=yaw_flip)
    for start, det in ((-np.pi + 0.01, np.pi - 0.01), (-np.pi + 0.002, np.pi - 0.01)):
        new = _one_step_yaw(kf, start, det)  # 0.02 / 0.012 rad apart across the +-pi seam
        assert 0.0 < -wrap_angle(new - start) < abs(wrap_angle(det - start))  # a small step towards it, not ~2 pi
        assert -np.pi <= new < np.pi  # the state yaw is wrapped (the second case steps across the seam)
    assert _one_step_yaw(kf, -np.pi + 0.002, np.pi - 0.01) > 3.0


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_flipped_detection_heading(model):
    start = 0.5
    flipped = wrap_angle(start + np.pi - 0.1)  # the detector reversed the heading (and is 0.1 rad off)
    corrected = _one_step_yaw(BatchKalmanFilter(model, yaw_flip=True), start, flipped)
    raw = _one_step_yaw(BatchKalmanFilter(model, yaw_flip=False), start, flipped)
    # with the flip correction the heading moves by a fraction of -0.1 rad; without it (Poly-MOT) by K * (pi - 0.1)
    assert -0.1 < wrap_angle(corrected - start) < 0.0
    assert wrap_angle(raw - start) > 0.5


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_batch_equals_one_track_at_a_time(model):
    rng = np.random.default_rng(7)
    n = 12
    x0 = random_states(model, n=n, seed=8)
    boxes = model.to_boxes(x0)
    A = rng.normal(size=(n, model.dim_x, model.dim_x))
    P0 = A @ np.swapaxes(A, 1, 2) + np.eye(model.dim_x)  # a different SPD matrix per track
    Q = np.stack([np.diag(rng.uniform(0.01, 2.0, model.dim_x)) for _ in range(n)])
    R = np.stack([np.diag(rng.uniform(0.01, 2.0, 9)) for _ in range(n)])
    dets = [boxes + rng.normal(0, 0.3, boxes.shape) * (k + 1) for k in range(4)]
    kf = BatchKalmanFilter(model)

    xb, Pb = kf.initiate(boxes, P0)
    for z in dets:
        xb, Pb = kf.predict(xb, Pb, Q, DT)
        xb, Pb = kf.update(xb, Pb, z, R)
    for i in range(n):
        xi, Pi = kf.initiate(boxes[i : i + 1], P0[i : i + 1])
        for z in dets:
            xi, Pi = kf.predict(xi, Pi, Q[i : i + 1], DT)
            xi, Pi = kf.update(xi, Pi, z[i : i + 1], R[i : i + 1])
        np.testing.assert_allclose(xb[i], xi[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(Pb[i], Pi[0], rtol=1e-12, atol=1e-12)


def random_update(model, n: int, seed: int, noise: float):
    """An update of n random tracks: x (n, dim_x), a random SPD P per track, diagonal R (n, 9, 9) and z (n, 9)
    ``noise`` (standard deviation) off h(x)."""
    rng = np.random.default_rng(seed)
    x = random_states(model, n=n, seed=seed + 1)
    A = rng.normal(size=(n, model.dim_x, model.dim_x))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(model.dim_x)
    R = np.stack([np.diag(rng.uniform(0.05, 2.0, 9)) for _ in range(n)])
    return x, P, R, model.h(x) + rng.normal(0, noise, (n, 9))


@pytest.mark.parametrize("model", MODELS, ids=MODEL_IDS)
def test_update_matches_the_information_form(model):
    x, P, R, z = random_update(model, 12, 9, 0.2)
    kf = BatchKalmanFilter(model)
    xu, Pu = kf.update(x, P, z, R)
    H = model.H(x)
    Ht = np.swapaxes(H, 1, 2)
    P_info = np.linalg.inv(np.linalg.inv(P) + Ht @ np.linalg.inv(R) @ H)
    x_info = x + np.einsum("nij,nj->ni", P_info @ Ht @ np.linalg.inv(R), kf.residual(x, z))
    np.testing.assert_allclose(Pu, P_info, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(xu, model.wrap_state(x_info), rtol=1e-7, atol=1e-9)


def test_empty_batch():
    kf = BatchKalmanFilter(CTRA())
    x, P = kf.initiate(np.zeros((0, 9)), np.eye(10))
    x, P = kf.predict(x, P, np.eye(10), DT)
    x, P = kf.update(x, P, np.zeros((0, 9)), np.eye(9))
    assert x.shape == (0, 10) and P.shape == (0, 10, 10)


# ------------------------------------------------------------------------------------------------ configuration


def test_default_config_is_polymot_nuscenes():
    cfg = load_motion_config()
    assert set(cfg) == set(TRACKING_CLASSES)
    models = {c: cfg[c]["model"] for c in TRACKING_CLASSES}
    assert models == {
        "bicycle": "Bicycle",
        "bus": "CTRA",
        "car": "CTRA",
        "motorcycle": "Bicycle",
        "pedestrian": "CTRA",
        "trailer": "CA",
        "truck": "CTRA",
    }
    dims = {"CTRA": 10, "Bicycle": 10, "CA": 11, "CV": 9}
    for c in TRACKING_CLASSES:
        d = dims[cfg[c]["model"]]
        assert cfg[c]["Q"].shape == (d, d) and cfg[c]["P0"].shape == (d, d) and cfg[c]["R"].shape == (9, 9)
    np.testing.assert_array_equal(np.diag(cfg["car"]["P0"]), [4, 4, 4, 4, 4, 4, 1000, 4, 1, 0.1])
    np.testing.assert_array_equal(np.diag(cfg["bicycle"]["P0"]), [10] * 6 + [10000, 10, 10, 10])
    np.testing.assert_array_equal(np.diag(cfg["motorcycle"]["P0"]), [10] * 6 + [1000, 10, 10, 10])
    np.testing.assert_array_equal(cfg["truck"]["Q"], np.eye(10))
    np.testing.assert_array_equal(cfg["car"]["R"], np.eye(9))
    np.testing.assert_array_equal(cfg["trailer"]["Q"], 100 * np.eye(11))
    np.testing.assert_array_equal(cfg["trailer"]["R"], 0.001 * np.eye(9))
    np.testing.assert_array_equal(cfg["trailer"]["P0"], 0.01 * np.eye(11))
    assert cfg["bicycle"]["params"] == {"wheelbase_ratio": 0.8, "front_ratio": 0.5}


def test_model_override_takes_the_model_defaults():
    cfg = load_motion_config("polymot_nusc", model_override={"car": "bicycle", "trailer": "CTRA"})
    assert cfg["car"]["model"] == "Bicycle" and cfg["trailer"]["model"] == "CTRA"
    np.testing.assert_array_equal(np.diag(cfg["car"]["P0"]), [10] * 6 + [1000, 10, 10, 10])
    np.testing.assert_array_equal(np.diag(cfg["trailer"]["P0"]), [4, 4, 4, 4, 4, 4, 1000, 4, 1, 0.1])
    np.testing.assert_array_equal(np.diag(cfg["bicycle"]["P0"]), [10] * 6 + [10000, 10, 10, 10])  # own model kept
    allctra = load_motion_config(model_override="CTRA")
    assert {e["model"] for e in allctra.values()} == {"CTRA"}


def _write_variant(tmp_path, old: str, new: str):
    text = DEFAULT_CONFIG.read_text()
    assert old in text
    path = tmp_path / "motion.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


@pytest.mark.parametrize(
    ("old", "new", "key"),
    [
        (
            "  car:\n    # model {2: 'CTRA'}, filter ExtendKalmanFilter.\n    model: CTRA\n    P0",
            "  car:\n    # model {2: 'CTRA'}, filter ExtendKalmanFilter.\n    model: CTRA\n    PO",
            "classes.car.PO",
        ),
        ("  truck:\n", "  truk:\n", "classes.truk"),
        ("    # CTRA.getProcessNoiseQ: np.eye(10) * 1.\n    Q: 1.0\n", "", "models.CTRA.Q"),
        ("      wheelbase_ratio: 0.8", "      wheelbase_ration: 0.8", "models.Bicycle.params"),
        ("    model: CA\n", "    model: CAA\n", "classes.trailer.model"),
        (
            "P0: [10, 10, 10, 10, 10, 10, 10000, 10, 10, 10]",
            "P0: [10, 10, 10, 10000, 10, 10, 10]",
            "classes.bicycle.P0",
        ),
        ("    Q: 100.0\n    R: 0.001\n  truck:", "    Q: 100.0\n    R: -1\n  truck:", "classes.trailer.R"),
    ],
    ids=[
        "misspelt-class-key",
        "misspelt-class",
        "missing-model-key",
        "bad-param",
        "unknown-model",
        "wrong-size",
        "not-positive",
    ],
)
def test_config_errors_name_file_and_key(tmp_path, old, new, key):
    path = _write_variant(tmp_path, old, new)
    with pytest.raises(ConfigError) as info:
        load_motion_config(path)
    assert str(path) in str(info.value) and f"'{key}'" in str(info.value)


def test_missing_config_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="nope.yaml"):
        load_motion_config(tmp_path / "nope.yaml")


def test_class_matrices_gather_per_track_noise():
    cfg = load_motion_config()
    labels = np.array([CLASS_INDEX[c] for c in ("car", "pedestrian", "bus", "car")])
    P0 = class_matrices(cfg, labels, "P0")
    assert P0.shape == (4, 10, 10)
    np.testing.assert_array_equal(P0[1], cfg["pedestrian"]["P0"])
    with pytest.raises(ValueError):
        class_matrices(cfg, np.array([CLASS_INDEX["car"], CLASS_INDEX["trailer"]]), "Q")


# ------------------------------------------------------------------------------------------ compiled passes


def _ctra_numpy(x: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CTRA's f and F written with numpy arrays, operation for operation (the reference of the compiled pass)."""
    v, a, yaw, om = x[:, 6], x[:, 7], x[:, 8], x[:, 9]
    e0, e1, e2 = arc_moments(om * dt)
    ar = v * dt * e0[0] + a * dt * dt * e1[0]
    ai = v * dt * e0[1] + a * dt * dt * e1[1]
    c, s = np.cos(yaw), np.sin(yaw)
    dx, dy = c * ar - s * ai, s * ar + c * ai
    out = x.copy()
    out[:, 0] += dx
    out[:, 1] += dy
    out[:, 6] = v + a * dt
    out[:, 8] = yaw + om * dt
    J = np.repeat(np.eye(10)[None], len(x), axis=0)
    J[:, 0, 6], J[:, 1, 6] = dt * (c * e0[0] - s * e0[1]), dt * (s * e0[0] + c * e0[1])
    J[:, 0, 7], J[:, 1, 7] = dt * dt * (c * e1[0] - s * e1[1]), dt * dt * (s * e1[0] + c * e1[1])
    J[:, 0, 8], J[:, 1, 8] = -dy, dx
    br = v * dt**2 * e1[0] + a * dt**3 * e2[0]
    bi = v * dt**2 * e1[1] + a * dt**3 * e2[1]
    J[:, 0, 9], J[:, 1, 9] = -c * bi - s * br, -s * bi + c * br
    J[:, 6, 7] = J[:, 8, 9] = dt
    return out, J


def _same(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to rounding: the compiled passes repeat numpy's operations in order, so they agree bit for bit where
    numba's sin and cos are numpy's (libm on the machines measured; numpy may use other SIMD routines)."""
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13)


def test_compiled_ctra_transition_is_the_numpy_form():
    x = random_states(CTRA(), n=400, seed=21)
    x[:, 8] = np.random.default_rng(22).uniform(-4, 4, len(x))
    for dt in (DT, 0.45, 0.0):
        f, F = CTRA().transition(x, dt)
        f_ref, F_ref = _ctra_numpy(x, np.full(len(x), dt))
        _same(f, f_ref)
        _same(F, F_ref)
        np.testing.assert_array_equal(CTRA().f(x, dt), f)


@pytest.mark.parametrize(
    "model",
    [
        CTRA(),
        Bicycle(),
        Bicycle(wheelbase_ratio=0.7, front_ratio=0.3),
        make_model("Bicycle", "piecewise"),
        make_model("CTRA", "piecewise"),
        CA(),
        CV(),
    ],
    ids=["CTRA", "Bicycle", "Bicycle-offset", "Bicycle-piecewise", "CTRA-piecewise", "CA", "CV"],
)
def test_joint_passes_equal_the_separate_methods(model):
    """transition = (f, F), measurement = (h, H) and to_boxes = h with the yaw wrapped (the compiled measurement and
    box passes against the numpy h and H)."""
    x = random_states(model, n=300, seed=23)
    x[:, model.yaw_index] = np.random.default_rng(24).uniform(-4, 4, len(x))  # unwrapped yaw too
    f, F = model.transition(x, DT)
    _same(f, model.f(x, DT))  # numpy's SIMD tan / arctan may round with its operands' alignment: not bit for bit
    _same(F, model.F(x, DT))
    h, H = model.measurement(x)
    _same(h, model.h(x))
    _same(H, model.H(x))
    boxes = model.h(x)
    boxes[:, 6] = wrap_angle(boxes[:, 6])
    _same(model.to_boxes(x), boxes)


@pytest.mark.parametrize("yaw_flip", [True, False])
def test_correct_rows_in_place_equals_update_of_those_rows(yaw_flip):
    """The tracker's in-place correction of some rows with a per-class R table gives, row for row, what
    :meth:`BatchKalmanFilter.update` gives for those tracks; the other rows are untouched."""
    model = CTRA()
    rng = np.random.default_rng(25)
    n = 30
    x = random_states(model, n=n, seed=26)
    A = rng.normal(size=(n, 10, 10))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(10)
    R_table = np.stack([np.diag(rng.uniform(0.05, 2.0, 9)) for _ in range(7)])
    labels = rng.integers(0, 7, n)
    rows = np.array([3, 0, 17, 29, 8])
    z = model.h(x[rows]) + rng.normal(0, 0.3, (len(rows), 9))
    z[0, 6] += np.pi  # a flipped heading
    kf = BatchKalmanFilter(model, yaw_flip=yaw_flip)
    x_want, P_want = kf.update(x[rows], P[rows], z, R_table[labels[rows]])
    x_c, P_c = x.copy(), P.copy()
    kf.correct(x_c, P_c, rows, z, R_table, labels[rows])
    np.testing.assert_array_equal(x_c[rows], x_want)
    np.testing.assert_array_equal(P_c[rows], P_want)
    rest = np.setdiff1d(np.arange(n), rows)
    np.testing.assert_array_equal(x_c[rest], x[rest])
    np.testing.assert_array_equal(P_c[rest], P[rest])


@pytest.mark.parametrize("model", [CTRA(), CV()], ids=["CTRA", "CV"])
def test_nis_limit_scales_R_of_outlying_detections_only(model):
    """``nis_limit`` g: a detection whose position NIS d2 = r_xy^T S_xy^-1 r_xy exceeds g is the textbook update
    with R * d2 / g (computed here by hand); one within g is the plain update, bit for bit; g = 0 is off."""
    n = 16
    x, P, R, z = random_update(model, n, 31, 0.1)
    z[::2, :2] += np.random.default_rng(33).normal(0, 30.0, (n // 2, 2))  # far-off detections, every other track
    H = model.H(x)
    S = H[:, :2] @ P @ np.swapaxes(H[:, :2], 1, 2) + R[:, :2, :2]
    r = z[:, :2] - model.h(x)[:, :2]
    d2 = np.einsum("ni,nij,nj->n", r, np.linalg.inv(S), r)
    g = 3.0
    assert (d2[::2] > g).all() and (d2[1::2] < g).all()
    plain = BatchKalmanFilter(model)
    x_r, P_r = BatchKalmanFilter(model, robust=RobustUpdate(g)).update(x, P, z, R)
    x_p, P_p = plain.update(x, P, z, R)
    x_w, P_w = plain.update(x, P, z, R * np.maximum(1.0, d2 / g)[:, None, None])
    np.testing.assert_allclose(x_r, x_w, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P_r, P_w, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(x_r[1::2], x_p[1::2])
    # an outlier moves the track less than the plain update, and its NIS under the inflated S is smaller
    step_r = np.linalg.norm(x_r[::2, :2] - x[::2, :2], axis=1)
    step_p = np.linalg.norm(x_p[::2, :2] - x[::2, :2], axis=1)
    assert (step_r < step_p).all()
    S_in = H[::2, :2] @ P[::2] @ np.swapaxes(H[::2, :2], 1, 2) + (R[::2] * (d2[::2] / g)[:, None, None])[:, :2, :2]
    assert (np.einsum("ni,nij,nj->n", r[::2], np.linalg.inv(S_in), r[::2]) < d2[::2]).all()
    off = BatchKalmanFilter(model, robust=RobustUpdate(0.0)).update(x, P, z, R)
    np.testing.assert_array_equal(off[0], x_p)
    # min_hits: a track with fewer matched detections before the update (updates + 1) is not tested
    updates = np.arange(n) % 4  # 0-3 corrections before: 1-4 hits
    kf = BatchKalmanFilter(model, robust=RobustUpdate(g, min_hits=3))
    x_h, P_h = x.copy(), P.copy()
    kf.correct(x_h, P_h, np.arange(n), z, R, np.arange(n), updates)
    old = updates + 1 >= 3
    np.testing.assert_allclose(x_h[old], x_w[old], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(x_h[~old], x_p[~old])


@pytest.mark.parametrize("model", [CTRA(), CV()], ids=["CTRA", "CV"])
def test_score_exponent_takes_each_detection_with_R_over_its_score(model):
    """``score_exponent`` e: a detection scored c is the textbook update with R / max(c, 0.01)^e (computed here by
    hand); no scores, or e = 0,
    is the plain update bit for bit; with a ``nis_limit`` the outlier test reads the scaled R."""
    n = 16
    x, P, R, z = random_update(model, n, 41, 0.1)
    scores = np.linspace(0.0, 1.0, n)  # 0 floored at 0.01
    plain = BatchKalmanFilter(model)
    x_p, _ = plain.update(x, P, z, R)
    scaled = R / np.maximum(scores, 0.01)[:, None, None]
    x_w, P_w = plain.update(x, P, z, scaled)

    def corrected(robust, s):
        x_c, P_c = x.copy(), P.copy()
        BatchKalmanFilter(model, robust=robust).correct(x_c, P_c, np.arange(n), z, R, np.arange(n), None, s)
        return x_c, P_c

    x_s, P_s = corrected(RobustUpdate(0.0, score_exponent=1.0), scores)
    np.testing.assert_allclose(x_s, x_w, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P_s, P_w, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(x_s[-1], x_p[-1])  # score 1: R itself
    np.testing.assert_array_equal(corrected(RobustUpdate(0.0, score_exponent=1.0), None)[0], x_p)
    np.testing.assert_array_equal(corrected(RobustUpdate(0.0, score_exponent=0.0), scores)[0], x_p)
    x_sq, _ = corrected(RobustUpdate(0.0, score_exponent=2.0), scores)
    np.testing.assert_allclose(x_sq, plain.update(x, P, z, R / np.maximum(scores, 0.01)[:, None, None] ** 2)[0])
    # with the robust update: NIS under the scaled R, then R scaled by max(1, d2 / g)
    z_far = z.copy()
    z_far[::2, :2] += 30.0
    H = model.H(x)
    S = H[:, :2] @ P @ np.swapaxes(H[:, :2], 1, 2) + scaled[:, :2, :2]
    r = z_far[:, :2] - model.h(x)[:, :2]
    d2 = np.einsum("ni,nij,nj->n", r, np.linalg.inv(S), r)
    x_b, P_b = x.copy(), P.copy()
    robust = BatchKalmanFilter(model, robust=RobustUpdate(2.0, score_exponent=1.0))
    robust.correct(x_b, P_b, np.arange(n), z_far, R, np.arange(n), None, scores)
    want = plain.update(x, P, z_far, scaled * np.maximum(1.0, d2 / 2.0)[:, None, None])[0]
    np.testing.assert_allclose(x_b, want, rtol=1e-12, atol=1e-12)
