"""The EKF / linear-KF motion backend: one batched filter per state-space model, per-class Q, R, P0."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grutrack.motion.kalman import BatchKalmanFilter, Correction
from grutrack.motion.models import MotionModel


@dataclass
class KFState:
    """Filter state of N tracks: x (N, dim_x), P (N, dim_x, dim_x), labels (N,) class indices; after an update,
    ``corrected``: what it computed for the tracks it corrected (innovation, its covariance and the gain, rows in
    the order of the update's ``rows``; :class:`~grutrack.motion.kalman.Correction`), else None."""

    x: np.ndarray
    P: np.ndarray
    labels: np.ndarray
    corrected: Correction | None = None


class KalmanBackend:
    """Batched (E)KF over the tracks of one state-space model.

    Q, R, P0: per-class tables (7, d, d) indexed by label; classes this backend never sees may be zeros.
    """

    def __init__(self, model: MotionModel, Q: np.ndarray, R: np.ndarray, P0: np.ndarray, yaw_flip: bool = True):
        self.model = model
        self.kf = BatchKalmanFilter(model, yaw_flip=yaw_flip)
        self.Q, self.R, self.P0 = Q, R, P0

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> KFState:
        """State of new tracks from detections z (N, 9)."""
        x, P = self.kf.initiate(z, self.P0[labels])
        return KFState(x, P, labels.copy())

    def predict(self, s: KFState, dt: float) -> KFState:
        """Predict every track dt seconds ahead."""
        x, P = self.kf.predict(s.x, s.P, self.Q[s.labels], dt)
        return KFState(x, P, s.labels)

    def update(self, s: KFState, rows: np.ndarray, z: np.ndarray) -> KFState:
        """Correct tracks ``rows`` with measurements z (K, 9)."""
        x, P = s.x.copy(), s.P.copy()
        corrected = self.kf.correct(x, P, rows, z, self.R, s.labels[rows])
        return KFState(x, P, s.labels, corrected)

    def boxes(self, s: KFState) -> np.ndarray:
        """Canonical boxes (N, 9) of the current state."""
        return self.model.to_boxes(s.x)

    def select(self, s: KFState, index: np.ndarray) -> KFState:
        """Subset of the tracks."""
        return KFState(s.x[index], s.P[index], s.labels[index])

    def concat(self, a: KFState, b: KFState) -> KFState:
        """Tracks of a then b."""
        return KFState(np.concatenate([a.x, b.x]), np.concatenate([a.P, b.P]), np.concatenate([a.labels, b.labels]))
