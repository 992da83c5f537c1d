"""The EKF / linear-KF motion backend: one batched filter per state-space model, per-class Q, R, P0."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grutrack.motion.kalman import BatchKalmanFilter, Correction, RobustUpdate
from grutrack.motion.models import MotionModel
from grutrack.tracking.velocity_check import CheckState, VelocityCheck


@dataclass
class KFState:
    """Filter state of N tracks: x (N, dim_x), P (N, dim_x, dim_x), labels (N,) class indices; after an update,
    ``corrected``: what it computed for the tracks it corrected (innovation, its covariance and the gain, rows in
    the order of the update's ``rows``; :class:`~grutrack.motion.kalman.Correction`), else None; ``check``: the
    velocity check's memory of the tracks (:class:`~grutrack.tracking.velocity_check.CheckState`; None without a
    check); ``updates`` (N,) int64 the corrections each track has had (None: all 0)."""

    x: np.ndarray
    P: np.ndarray
    labels: np.ndarray
    corrected: Correction | None = None
    check: CheckState | None = None
    updates: np.ndarray | None = None

    def counts(self) -> np.ndarray:
        """(N,) int64 the corrections each track has had."""
        return np.zeros(len(self.x), dtype=np.int64) if self.updates is None else self.updates


class KalmanBackend:
    """Batched (E)KF over the tracks of one state-space model.

    Q, R, P0: per-class tables (7, d, d) indexed by label; classes this backend never sees may be zeros.
    velocity_check: the check of the detector's velocity (:mod:`grutrack.tracking.velocity_check`), or None
    (every update takes the detector's velocity with R).
    robust: the robust update and confidence-weighted noise (:class:`~grutrack.motion.kalman.RobustUpdate`), or None.
    """

    def __init__(
        self,
        model: MotionModel,
        Q: np.ndarray,
        R: np.ndarray,
        P0: np.ndarray,
        yaw_flip: bool = True,
        velocity_check: VelocityCheck | None = None,
        robust: RobustUpdate | None = None,
    ):
        self.model = model
        self.kf = BatchKalmanFilter(model, yaw_flip=yaw_flip, robust=robust)
        self.Q, self.R, self.P0 = Q, R, P0
        self.velocity_check = velocity_check

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> KFState:
        """State of new tracks from detections z (N, 9)."""
        x, P = self.kf.initiate(z, self.P0[labels])
        check = None if self.velocity_check is None else self.velocity_check.start(np.asarray(z).reshape(-1, 9))
        return KFState(x, P, labels.copy(), None, check, np.zeros(len(x), dtype=np.int64))

    #: (n_labels, dim_x) bool: the state slots (turn rate, acceleration) a coasting track of each label holds
    #: at 0 (tracker preset ``motion.coast_*``); None: none
    coast_held: np.ndarray | None = None

    def predict(self, s: KFState, dt: float, coasting: np.ndarray | None = None) -> KFState:
        """Predict every track dt seconds ahead: x <- f(x, dt), P <- F P F^T + Q. The tracks ``coasting`` (N,)
        bool (already predicted once since their last update) have the slots :attr:`coast_held` names for their
        label set to 0 first, so that a track seen no more goes straight on at constant speed (F is taken at that
        state)."""
        x0 = s.x
        if coasting is not None and self.coast_held is not None and coasting.any():
            x0 = np.where(coasting[:, None] & self.coast_held[s.labels], 0.0, s.x)
        x, P = self.kf.predict(x0, s.P, self.Q[s.labels], dt)
        return KFState(x, P, s.labels, None, None if s.check is None else s.check.predicted(dt), s.updates)

    def update(self, s: KFState, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None) -> KFState:
        """Correct tracks ``rows`` with measurements z (K, 9) scored ``scores`` (K,) (confidence-weighted noise;
        None: R as given); with a velocity check, the tracks whose velocity failed take none from z
        (:func:`~grutrack.tracking.velocity_check.without_velocity`)."""
        x, P = s.x.copy(), s.P.copy()
        R, R_index, check = self.R, s.labels[rows], None
        if self.velocity_check is not None:
            prior = self.model.measurement
            z, R, R_index, check = self.velocity_check.apply(s.check, rows, z, lambda: prior(x[rows])[0], R, R_index)
        counts = s.counts()
        corrected = self.kf.correct(x, P, rows, z, R, R_index, counts[rows], scores)
        updates = counts.copy()
        updates[rows] += 1
        return KFState(x, P, s.labels, corrected, check, updates)

    def boxes(self, s: KFState) -> np.ndarray:
        """Canonical boxes (N, 9) of the current state."""
        return self.model.to_boxes(s.x)

    def select(self, s: KFState, index: np.ndarray) -> KFState:
        """Subset of the tracks."""
        check = None if s.check is None else s.check.select(index)
        return KFState(s.x[index], s.P[index], s.labels[index], None, check, s.counts()[index])

    def concat(self, a: KFState, b: KFState) -> KFState:
        """Tracks of a then b."""
        return KFState(
            np.concatenate([a.x, b.x]),
            np.concatenate([a.P, b.P]),
            np.concatenate([a.labels, b.labels]),
            None,
            CheckState.concat(a.check, b.check),
            np.concatenate([a.counts(), b.counts()]),
        )
