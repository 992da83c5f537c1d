"""The Table I baselines on the shared tracker loop: Greedy and AB3DMOT.

Greedy (the AV2 tracking baseline, a port of CenterPoint's greedy tracker, run on LT3D detections): a track is
its last matched detection, carried forward at that detection's velocity while unmatched
(:class:`DetectionBackend`). Association (:func:`greedy_association`): every detection's centre is moved back
by its own velocity times the frame interval and compared with each track's centre at the previous frame
(BEV distance, metres); detections are visited in decreasing score order and each takes the nearest free track
of its label within the label's ``max_distance``. Lifecycle and output come from the preset (greedy.yaml).

AB3DMOT (Weng et al., IROS 2020): 3D IoU + Hungarian + a linear constant-velocity Kalman filter whose
detections carry no velocity (:class:`NoVelocityKalmanBackend`: tracks start at velocity 0, and the motion
config ``ab3dmot`` gives the velocity measurement a variance so large that it carries no information).
"""

from __future__ import annotations

import numpy as np

from grutrack.data.scene import BoxSet
from grutrack.tracking.association import Matches
from grutrack.tracking.ekf_backend import KalmanBackend, KFState


class DetectionBackend:
    """Track state = a box (N, 9) ``[x, y, z, w, l, h, yaw, vx, vy]``, city/global frame: the last matched
    detection, moved at its own velocity (m/s) while no detection is matched."""

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """New tracks: the detections ``z (N, 9)`` themselves."""
        return np.array(z, dtype=np.float64, copy=True).reshape(-1, 9)

    def predict(self, state: np.ndarray, dt: float) -> np.ndarray:
        """Boxes moved ``dt`` seconds along their velocity."""
        out = state.copy()
        out[:, 0:2] += dt * state[:, 7:9]
        return out

    def update(
        self, state: np.ndarray, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None
    ) -> np.ndarray:
        """Tracks ``rows (K,)`` replaced by their matched detections ``z (K, 9)`` (``scores`` unused)."""
        out = state.copy()
        out[rows] = z
        return out

    def boxes(self, state: np.ndarray) -> np.ndarray:
        """The boxes (N, 9)."""
        return state.copy()

    def select(self, state: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Subset of the tracks."""
        return state[index]

    def concat(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Tracks of a then b."""
        return np.concatenate([a, b])


class NoVelocityKalmanBackend(KalmanBackend):
    """A :class:`KalmanBackend` whose tracks start with zero velocity whatever the detector says (AB3DMOT
    initialises its velocity state to 0 and estimates it from successive positions only)."""

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> KFState:
        """State of new tracks from detections ``z (N, 9)`` with their velocity set to 0."""
        z = np.array(z, dtype=np.float64, copy=True).reshape(-1, 9)
        z[:, 7:9] = 0.0
        return super().initiate(z, labels)


def _no_matches(d: int, t: int) -> Matches:
    e = np.zeros(0, dtype=np.int64)
    return Matches(e, e, np.arange(d, dtype=np.int64), np.arange(t, dtype=np.int64))


def greedy_pairs(cost: np.ndarray, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Greedy assignment: rows in ``order`` each take their cheapest free column with a finite cost.

    cost (D, T) float with ``inf`` for forbidden pairs; order (D,) row visiting order -> (rows, cols) int64.
    The visit is inherently sequential (each choice removes a column); only rows with a candidate are visited.
    """
    cost = cost.copy()
    rows, cols = [], []
    for r in order[np.isfinite(cost[order]).any(axis=1)]:
        c = int(np.argmin(cost[r]))
        if np.isfinite(cost[r, c]):
            rows.append(r)
            cols.append(c)
            cost[:, c] = np.inf
    return np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)


def greedy_association(max_distance: np.ndarray):
    """The Greedy baseline's association; ``max_distance`` (n_labels,) metres per label.

    Returns an association function ``(dets, trk_boxes (T, 9), trk_labels (T,), dt) -> Matches`` for
    :class:`grutrack.tracking.tracker.Tracker`. Track boxes arrive predicted to this frame; moving them back by
    their velocity gives their previous-frame centre (exact for :class:`DetectionBackend`).
    """
    max_distance = np.asarray(max_distance, dtype=np.float64)

    def run(dets: BoxSet, trk_boxes: np.ndarray, trk_labels: np.ndarray, dt: float) -> Matches:
        d, t = len(dets), len(trk_boxes)
        if d == 0 or t == 0:
            return _no_matches(d, t)
        det_prev = dets.boxes[:, 0:2] - dt * dets.boxes[:, 7:9]
        trk_prev = trk_boxes[:, 0:2] - dt * trk_boxes[:, 7:9]
        dist = np.linalg.norm(det_prev[:, None, :] - trk_prev[None, :, :], axis=2)
        ok = (dets.labels[:, None] == trk_labels[None, :]) & (dist <= max_distance[dets.labels][:, None])
        md, mt = greedy_pairs(np.where(ok, dist, np.inf), np.argsort(-dets.scores, kind="stable"))
        return Matches(md, mt, np.setdiff1d(np.arange(d), md), np.setdiff1d(np.arange(t), mt))

    return run
