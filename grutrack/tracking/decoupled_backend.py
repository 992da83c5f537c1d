"""MCTrack's decoupled filters (preset ``mctrack``; ``motion.filter: decoupled_cv``), batched over tracks.

Instead of one Kalman filter over the whole box, a track carries

* a position filter: constant velocity on ``[x, y, vx, vy]`` that measures the detection's centre AND its velocity
  (``z = [x, y, vx, vy]``, H = I), per-class diagonal P0, Q, R (``motion.position_noise``);
* a size filter: constant rate on ``[l, w, dl, dw]`` measuring ``[l, w]`` (``motion.size_noise``), stepped
  (predicted and corrected) only in the frames where the track is matched (``motion.size_steps: per_update``;
  ``per_frame``, the textbook choice, predicts it every frame);
* the last detection's z, h, yaw and velocity, which no filter estimates.

A matched track's box: the position filter's x, y, the detection's z, h and yaw, the size filter's l, w, and the
detection's own velocity (``motion.written_velocity: detection``; ``filter`` writes the filter's vx, vy).
The box a track is compared at (:meth:`DecoupledCVBackend.boxes` after :meth:`~DecoupledCVBackend.predict`) has the
predicted x, y and the size of the last detection (``motion.compared_size: detection``; after a miss the size
filter's one-step prediction; ``filter``: always the size filter's estimate); its last-update box
(:meth:`~DecoupledCVBackend.last_boxes`) has the x, y before this frame's prediction.

A missed track (:meth:`~DecoupledCVBackend.miss`) keeps the predicted state; with ``motion.missed_update:
zero_innovation`` (MCTrack) its position covariance is also corrected as if the prediction had been measured
(``P = (I - K) P-``, the state unchanged: the innovation is zero), so a coasting track's covariance does not grow;
``predict`` (the textbook choice) leaves ``P-``. Its box is written as it was compared in this frame (the
predicted position, the compared size, the last z, h, yaw and velocity).

Every step is a few array operations over all tracks; the time step is the tracker's (MCTrack: a fixed 0.5 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: columns of ``DecoupledState.geo``: the compared geometry
_Z, _L, _W, _H, _YAW = range(5)


@dataclass
class DecoupledState:
    """N tracks: position ``x (N, 4)``, ``P (N, 4, 4)``; the position before this frame's prediction ``x_last``;
    size ``s (N, 4)``, ``Ps (N, 4, 4)``; compared geometry ``geo (N, 5)`` [z, l, w, h, yaw]; last detection
    velocity ``vel (N, 2)``; ``box (N, 9)`` the current canonical box; ``labels (N,)``."""

    x: np.ndarray
    P: np.ndarray
    x_last: np.ndarray
    s: np.ndarray
    Ps: np.ndarray
    geo: np.ndarray
    vel: np.ndarray
    box: np.ndarray
    labels: np.ndarray

    def take(self, index) -> DecoupledState:
        return DecoupledState(*(getattr(self, f)[index] for f in _FIELDS))


_FIELDS = ("x", "P", "x_last", "s", "Ps", "geo", "vel", "box", "labels")


def _cv(dt: float) -> np.ndarray:
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


class DecoupledCVBackend:
    """The filters of the module docstring over the tracks of one group. ``pos`` / ``size``: per-label tables
    ``{"P0", "Q", "R"}`` of shapes (n_labels, 4, 4) and R (n_labels, 4, 4) / (n_labels, 2, 2)."""

    def __init__(
        self,
        pos: dict[str, np.ndarray],
        size: dict[str, np.ndarray],
        dt: float = 0.5,
        missed_update: str = "zero_innovation",
        size_steps: str = "per_update",
        compared_size: str = "detection",
        written_velocity: str = "detection",
    ):
        self.pos, self.size = pos, size
        self.dt = dt
        self.zero_innovation = missed_update == "zero_innovation"
        self.size_per_update = size_steps == "per_update"
        self.compared_detection_size = compared_size == "detection"
        self.filter_velocity = written_velocity == "filter"

    # --- protocol of grutrack.tracking.tracker.MotionBackend

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> DecoupledState:
        z = np.asarray(z, dtype=np.float64).reshape(-1, 9)
        n = len(z)
        x = np.column_stack([z[:, 0], z[:, 1], z[:, 7], z[:, 8]])
        s = np.column_stack([z[:, 4], z[:, 3], np.zeros(n), np.zeros(n)])
        geo = np.column_stack([z[:, 2], z[:, 4], z[:, 3], z[:, 5], z[:, 6]])
        return DecoupledState(
            x,
            self.pos["P0"][labels].copy(),
            x.copy(),
            s,
            self.size["P0"][labels].copy(),
            geo,
            z[:, 7:9].copy(),
            z.copy(),
            labels.copy(),
        )

    def predict(self, st: DecoupledState, dt: float) -> DecoupledState:
        """Position: ``x- = F x``, ``P- = F P F^T + Q``; size: predicted too unless stepped per update."""
        F = _cv(self.dt if dt is None else dt)
        x = st.x @ F.T
        P = F @ st.P @ F.T + self.pos["Q"][st.labels]
        s, Ps = st.s, st.Ps
        if not self.size_per_update:
            s = st.s @ F.T
            Ps = F @ st.Ps @ F.T + self.size["Q"][st.labels]
        geo = st.geo.copy()
        if not self.compared_detection_size:
            geo[:, _L], geo[:, _W] = s[:, 0], s[:, 1]
        out = DecoupledState(x, P, st.x.copy(), s, Ps, geo, st.vel, st.box.copy(), st.labels)
        out.box = self._compared(out, out.x)
        self._F = F
        return out

    def update(
        self, st: DecoupledState, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None
    ) -> DecoupledState:
        """Correct tracks ``rows`` with detections ``z (K, 9)`` (MCTrack's filters do not read ``scores``)."""
        st = DecoupledState(*(getattr(st, f).copy() for f in _FIELDS))
        lab = st.labels[rows]
        P = st.P[rows]
        K = P @ np.linalg.inv(P + self.pos["R"][lab])
        meas = np.column_stack([z[:, 0], z[:, 1], z[:, 7], z[:, 8]])
        x = st.x[rows]
        st.x[rows] = x + np.einsum("kij,kj->ki", K, meas - x)
        st.P[rows] = (np.eye(4) - K) @ P
        s, Ps = st.s[rows], st.Ps[rows]
        if self.size_per_update:
            F = self._F
            s = s @ F.T
            Ps = F @ Ps @ F.T + self.size["Q"][lab]
        Hs = np.eye(2, 4)
        Ks = Ps @ Hs.T @ np.linalg.inv(Hs @ Ps @ Hs.T + self.size["R"][lab])
        st.s[rows] = s + np.einsum("kij,kj->ki", Ks, np.column_stack([z[:, 4], z[:, 3]]) - s[:, :2])
        st.Ps[rows] = (np.eye(4) - Ks @ Hs) @ Ps
        st.geo[rows] = np.column_stack([z[:, 2], z[:, 4], z[:, 3], z[:, 5], z[:, 6]])
        st.vel[rows] = z[:, 7:9]
        box = np.column_stack(
            [st.x[rows, :2], z[:, 2], st.s[rows, 1], st.s[rows, 0], z[:, 5], z[:, 6], self._velocity(st, rows)]
        )
        st.box[rows] = box
        return st

    def miss(self, st: DecoupledState, rows: np.ndarray) -> DecoupledState:
        """Tracks ``rows`` went unmatched this frame: written as compared; covariance as ``missed_update``."""
        if len(rows) == 0:
            return st
        st = DecoupledState(*(getattr(st, f).copy() for f in _FIELDS))
        if self.zero_innovation:
            P = st.P[rows]
            K = P @ np.linalg.inv(P + self.pos["R"][st.labels[rows]])
            st.P[rows] = (np.eye(4) - K) @ P
        st.box[rows, 7:9] = self._velocity(st, rows)
        if self.compared_detection_size and self.size_per_update:
            # the size the track is compared at from now on: the size filter's one-step prediction
            pred = st.s[rows] @ self._F.T
            st.geo[rows, _L], st.geo[rows, _W] = pred[:, 0], pred[:, 1]
        return st

    def boxes(self, st: DecoupledState) -> np.ndarray:
        return st.box.copy()

    def last_boxes(self, st: DecoupledState) -> np.ndarray:
        """The boxes at the position before this frame's prediction (the last posterior), compared geometry."""
        return self._compared(st, st.x_last)

    def select(self, st: DecoupledState, index: np.ndarray) -> DecoupledState:
        return st.take(index)

    def concat(self, a: DecoupledState, b: DecoupledState) -> DecoupledState:
        return DecoupledState(*(np.concatenate([getattr(a, f), getattr(b, f)]) for f in _FIELDS))

    # ---

    def _velocity(self, st: DecoupledState, rows) -> np.ndarray:
        return st.x[rows, 2:4] if self.filter_velocity else st.vel[rows]

    def _compared(self, st: DecoupledState, xy: np.ndarray) -> np.ndarray:
        g = st.geo
        vel = st.x[:, 2:4] if self.filter_velocity else st.vel
        return np.column_stack([xy[:, :2], g[:, _Z], g[:, _W], g[:, _L], g[:, _H], g[:, _YAW], vel])
