"""The detector's velocity checked against a track's own motion (tracker preset ``motion.velocity_check_*``).

At an update at least ``window`` seconds after the track's last compared one, the displacement velocity
``v_disp = (z_xy - z_xy_prev) / t`` is the track's detected BEV centre minus the one of that update, over the seconds
``t`` between them; the detected velocity ``v_det`` disagrees with it when ``|v_det - v_disp| > max(difference,
ratio |v_disp|)`` (m/s). Updates sooner than ``window`` are not compared (they neither count nor reset the count), so
the test sees a displacement of about the same length at any frame rate: at nuScenes' 2 Hz every update is compared
(keyframes are 0.40-0.60 s apart), at 10 Hz (AV2's sweeps) every third. After ``updates`` disagreeing comparisons in
a row the track's velocity has failed: from then on, for the rest of its life, its updates take no velocity from the
detector. A detector whose velocity head fails on an object fails over its whole life (a moving bus reported
nearly static in every frame), and a filter that keeps measuring that velocity lags behind the object until the
association loses it (docs/results/default_tracker.md#velocity-check).

"Take no velocity" is done the same way by the EKF and the GRU-KF backends (:func:`without_velocity`): the
detection's velocity is replaced by the track's predicted one (zero innovation) and, for an EKF gain, its
variance by :data:`IGNORED_VELOCITY_VARIANCE`, the Kalman update without the velocity rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: measurement variance ((m/s)^2) of the detector's velocity for a track whose velocity failed the check
IGNORED_VELOCITY_VARIANCE = 1e6
#: columns of the velocity (vx, vy, m/s) in a canonical box / measurement (N, 9)
VELOCITY = slice(7, 9)


@dataclass
class CheckState:
    """The check's memory of N tracks: ``last_xy (N, 2)`` the detected BEV centre of each track's last compared
    update or birth (metres, global frame), ``elapsed (N,)`` the seconds since it, ``disagree (N,) int64`` its
    disagreeing comparisons in a row (frozen once it reaches the check's ``updates``: the velocity has failed)."""

    last_xy: np.ndarray
    elapsed: np.ndarray
    disagree: np.ndarray

    def predicted(self, dt: float) -> CheckState:
        """The same tracks ``dt`` seconds later."""
        return CheckState(self.last_xy, self.elapsed + dt, self.disagree)

    def select(self, index) -> CheckState:
        """Tracks ``index`` (mask or indices)."""
        return CheckState(self.last_xy[index], self.elapsed[index], self.disagree[index])

    @staticmethod
    def concat(a: CheckState | None, b: CheckState | None) -> CheckState | None:
        """Tracks of ``a`` then ``b`` (None without a check)."""
        if a is None:
            return None
        return CheckState(*(np.concatenate([u, v]) for u, v in zip(a.fields(), b.fields())))

    def fields(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(last_xy (N, 2), elapsed (N,), disagree (N,))."""
        return self.last_xy, self.elapsed, self.disagree


@dataclass(frozen=True)
class VelocityCheck:
    """The check's settings: ``updates`` disagreeing comparisons in a row make a velocity failed; ``difference``
    (m/s) and ``ratio`` (of ``|v_disp|``) the disagreement test; ``window`` (s) the least time between two compared
    updates of a track (see the module docstring)."""

    updates: int
    difference: float
    ratio: float
    window: float = 0.0

    def start(self, z: np.ndarray) -> CheckState:
        """The memory of new tracks born from detections ``z (N, 9)``."""
        n = len(z)
        return CheckState(np.array(z[:, :2], dtype=np.float64), np.zeros(n), np.zeros(n, dtype=np.int64))

    def disagree_with(self, z: np.ndarray, last_xy: np.ndarray, elapsed: np.ndarray) -> np.ndarray:
        """(K,) bool: whether the velocity of detections ``z (K, 9)`` disagrees with the displacement from
        ``last_xy (K, 2)`` (metres) over ``elapsed (K,)`` seconds."""
        v_disp = (z[:, :2] - last_xy) / np.maximum(elapsed, 1e-3)[:, None]
        diff = np.hypot(z[:, 7] - v_disp[:, 0], z[:, 8] - v_disp[:, 1])
        return diff > np.maximum(self.difference, self.ratio * np.hypot(v_disp[:, 0], v_disp[:, 1]))

    def observe(self, s: CheckState, rows: np.ndarray, z: np.ndarray) -> tuple[CheckState, np.ndarray]:
        """Tracks ``rows (K,)`` updated with detections ``z (K, 9)``: the new memory and ``failed (K,) bool``,
        whose velocity has failed (this update included) and is to be left out of this update. Only the rows at
        least ``window`` seconds after their last compared update are compared (and become the reference)."""
        count, since = s.disagree[rows], s.elapsed[rows]
        due = since >= self.window
        bad = self.disagree_with(z, s.last_xy[rows], since)
        disagree, last_xy, elapsed = s.disagree.copy(), s.last_xy.copy(), s.elapsed.copy()
        disagree[rows] = np.where((count >= self.updates) | ~due, count, np.where(bad, count + 1, 0))
        last_xy[rows] = np.where(due[:, None], z[:, :2], s.last_xy[rows])
        elapsed[rows] = np.where(due, 0.0, since)
        return CheckState(last_xy, elapsed, disagree), disagree[rows] >= self.updates

    def apply(self, s: CheckState, rows: np.ndarray, z, predicted, R: np.ndarray | None, R_index: np.ndarray | None):
        """One update of tracks ``rows (K,)`` with detections ``z (K, 9)`` through the check: :meth:`observe`, then
        :func:`without_velocity` for the failed tracks; ``predicted()`` gives their prior in measurement space
        (K, 9) (called only when a track failed). -> (z, R, R_index, the new memory)."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, 9)
        check, failed = self.observe(s, rows, z)
        if failed.any():
            z, R, R_index = without_velocity(z, predicted(), failed, R, R_index)
        return z, R, R_index, check


def without_velocity(
    z: np.ndarray, predicted: np.ndarray, failed: np.ndarray, R: np.ndarray | None, R_index: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Detections ``z (K, 9)`` and the noise table ``R (C, 9, 9)`` / index ``R_index (K,)`` of an update, with
    the tracks ``failed (K,) bool`` taking no velocity: their detected velocity replaced by their predicted one
    (``predicted (K, 9)``, the prior in measurement space) and their noise by a copy of their row of R whose
    velocity block is ``IGNORED_VELOCITY_VARIANCE * I`` (appended to the table, the index pointing at it; R None:
    no noise table, e.g. a GRU-KF without an EKF gain prior)."""
    if not failed.any():
        return z, R, R_index
    z = np.array(z, dtype=np.float64)
    z[failed, VELOCITY] = predicted[failed, VELOCITY]
    if R is None:
        return z, None, None
    extra = np.array(R[R_index[failed]], dtype=np.float64)
    extra[:, VELOCITY, :] = 0.0
    extra[:, :, VELOCITY] = 0.0
    extra[:, 7, 7] = extra[:, 8, 8] = IGNORED_VELOCITY_VARIANCE
    index = np.array(R_index, dtype=np.int64)
    index[failed] = len(R) + np.arange(int(failed.sum()))
    return z, np.ascontiguousarray(np.concatenate([R, extra])), index
