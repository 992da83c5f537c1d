"""Batched extended / linear Kalman filter over N tracks that share one motion model.

Every track carries its own state ``x (N, dim_x)``, covariance ``P (N, dim_x, dim_x)`` and noise
``Q (N, dim_x, dim_x)``, ``R (N, 9, 9)``, so tracks of different classes that use the same model (car, bus, truck
and pedestrian all use CTRA) are filtered in one array operation with their own class noise. ``Q``, ``R`` and
``P0`` may also be given as one ``(d, d)`` matrix for all tracks. With a linear model the same code is the
ordinary Kalman filter (its F and H are exact).

* predict: ``F = F(x)`` at the prior state, ``x = f(x, dt)``, ``P = F P F^T + Q``; yaw state wrapped.
* update: residual ``r = z - h(x)`` with the yaw component wrapped to [-pi, pi) (and, with ``yaw_flip``, turned
  by pi when it exceeds pi/2, see below), ``S = H P H^T + R``, ``K = P H^T S^-1`` (by ``np.linalg.solve``),
  ``x = x + K r`` with the yaw wrapped again, and Joseph form ``P = (I-KH) P (I-KH)^T + K R K^T``, symmetrised.

Heading ambiguity (``yaw_flip``, default True): a box's footprint is the same under a 180 degree turn and
detectors often return the reversed heading. When the wrapped yaw residual exceeds pi/2 in magnitude the
detection's yaw is taken to be flipped and the residual is replaced by ``wrap(r + pi)`` (the measured yaw turned
by pi); position, size and the detector's velocity are used unchanged. A real heading change of more than 90
degrees between two frames (0.5 s on nuScenes) is not physically plausible for the tracked classes. Poly-MOT
does NOT do this: it only wraps the yaw residual to [-pi, pi) (``warpResYawToPi``), so a flipped detection pulls
the heading by up to K * pi; ``yaw_flip=False`` reproduces that.
"""

from __future__ import annotations

import numpy as np

from grutrack.boxes import BOX_DIM, wrap_angle
from grutrack.motion.models import MotionModel

YAW_Z = 6  # yaw column of the canonical measurement / box


def _batch(M: np.ndarray, n: int, d: int, name: str) -> np.ndarray:
    """``M`` as an ``(n, d, d)`` float64 array (a single ``(d, d)`` matrix is broadcast)."""
    M = np.asarray(M, dtype=np.float64)
    if n == 0:
        return np.zeros((0, d, d))
    if M.shape == (d, d):
        return np.broadcast_to(M, (n, d, d))
    if M.shape != (n, d, d):
        raise ValueError(f"{name} must have shape ({n}, {d}, {d}) or ({d}, {d}), got {M.shape}")
    return M


def _symmetrise(P: np.ndarray) -> np.ndarray:
    """``(P + P^T) / 2`` over the last two axes."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def wrap_yaw_residual(r_yaw: np.ndarray, yaw_flip: bool) -> np.ndarray:
    """Yaw residuals ``(N,)`` wrapped to [-pi, pi); with ``yaw_flip`` those beyond pi/2 are turned by pi."""
    r = wrap_angle(r_yaw)
    if yaw_flip:
        r = np.where(np.abs(r) > 0.5 * np.pi, wrap_angle(r + np.pi), r)
    return r


class BatchKalmanFilter:
    """EKF (non-linear model) or KF (linear model) over a batch of tracks; see the module docstring."""

    def __init__(self, model: MotionModel, yaw_flip: bool = True) -> None:
        self.model = model
        self.yaw_flip = bool(yaw_flip)

    def __repr__(self) -> str:
        return f"BatchKalmanFilter({self.model!r}, yaw_flip={self.yaw_flip})"

    def initiate(self, z: np.ndarray, P0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Start tracks from detections ``z (N, 9)`` -> ``x (N, dim_x)``, ``P (N, dim_x, dim_x)`` (a copy of P0)."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        n, d = z.shape[0], self.model.dim_x
        x = self.model.init_state(z)
        P = np.array(_batch(P0, n, d, "P0"), dtype=np.float64, copy=True)
        return x, P

    def predict(self, x: np.ndarray, P: np.ndarray, Q: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """Predict ``dt`` seconds (scalar or ``(N,)``) ahead -> ``(x (N, dim_x), P (N, dim_x, dim_x))``."""
        x = np.asarray(x, dtype=np.float64)
        n, d = x.shape[0], self.model.dim_x
        F = self.model.F(x, dt)
        x_new = self.model.wrap_state(self.model.f(x, dt))
        P_new = F @ _batch(P, n, d, "P") @ np.swapaxes(F, -1, -2) + _batch(Q, n, d, "Q")
        return x_new, _symmetrise(P_new)

    def residual(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Innovation ``z - h(x)`` ``(N, 9)`` with the yaw component wrapped (and flip-corrected if enabled)."""
        r = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM) - self.model.h(x)
        r[:, YAW_Z] = wrap_yaw_residual(r[:, YAW_Z], self.yaw_flip)
        return r

    def project(self, x: np.ndarray, P: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Measurement-space prediction: ``h(x) (N, 9)``, ``H (N, 9, dim_x)``, ``S = H P H^T + R (N, 9, 9)``."""
        x = np.asarray(x, dtype=np.float64)
        n, d = x.shape[0], self.model.dim_x
        H = self.model.H(x)
        S = H @ _batch(P, n, d, "P") @ np.swapaxes(H, -1, -2) + _batch(R, n, BOX_DIM, "R")
        return self.model.h(x), H, _symmetrise(S)

    def update(self, x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Correct with measurements ``z (N, 9)`` (row i for track i) -> ``(x, P)``, Joseph form."""
        x = np.asarray(x, dtype=np.float64)
        n, d = x.shape[0], self.model.dim_x
        if n == 0:
            return x.copy(), np.zeros((0, d, d))
        P = _batch(P, n, d, "P")
        R = _batch(R, n, BOX_DIM, "R")
        _, H, S = self.project(x, P, R)
        r = self.residual(x, z)
        HP = H @ P  # (N, 9, d) = (P H^T)^T since P is symmetric
        K = np.swapaxes(np.linalg.solve(S, HP), -1, -2)  # P H^T S^-1, (N, d, 9)
        x_new = self.model.wrap_state(x + np.einsum("nij,nj->ni", K, r))
        I_KH = np.eye(d) - K @ H
        P_new = I_KH @ P @ np.swapaxes(I_KH, -1, -2) + K @ R @ np.swapaxes(K, -1, -2)
        return x_new, _symmetrise(P_new)
