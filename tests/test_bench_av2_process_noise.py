"""benchmarks/bench_av2_process_noise.py: inside its block every Kalman prediction adds the scaled Q, and the
filter is restored after it (docs/results/process_noise.md quotes its figures)."""

import importlib.util
from pathlib import Path

import numpy as np

from grutrack.motion.kalman import BatchKalmanFilter
from grutrack.motion.models import make_model

_SPEC = importlib.util.spec_from_file_location(
    "bench_av2_process_noise", Path(__file__).parents[1] / "benchmarks/bench_av2_process_noise.py"
)
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


def test_the_scaled_prediction_adds_factor_times_q_and_is_undone_after():
    kf = BatchKalmanFilter(make_model("CV"))
    x, P = kf.initiate(np.array([[1.0, 2.0, 0.5, 2.0, 4.5, 1.6, 0.3, 3.0, -1.0]]), np.eye(kf.model.dim_x))
    Q = np.eye(kf.model.dim_x)
    _, plain = kf.predict(x, P, Q, 0.5)
    with bench.process_noise_scaled(0.2):
        _, scaled = kf.predict(x, P, Q, 0.5)
    _, after = kf.predict(x, P, Q, 0.5)
    assert np.allclose(plain - scaled, 0.8 * Q) and np.array_equal(after, plain)
