"""Box layout shared by every stage.

A box set is a ``(N, 9) float64`` array in the global (nuScenes) or city (AV2) frame, columns
``[x, y, z, w, l, h, yaw, vx, vy]``: centre in metres, size in metres (``w`` across the heading,
``l`` along it, ``h`` up), ``yaw`` in radians about +z measured from +x (range [-pi, pi)), and the
ground-plane velocity in metres per second. Scores are a separate ``(N,) float64`` array and class
labels a separate ``(N,) int64`` array of indices into :data:`grutrack.classes.TRACKING_CLASSES`.
"""

from __future__ import annotations

import numpy as np

X, Y, Z, W, L, H, YAW, VX, VY = range(9)
BOX_DIM = 9
BOX_FIELDS = ("x", "y", "z", "w", "l", "h", "yaw", "vx", "vy")


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap angles (any shape, radians) to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def empty_boxes() -> np.ndarray:
    """An empty ``(0, 9) float64`` box set."""
    return np.zeros((0, BOX_DIM), dtype=np.float64)


def yaw_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Yaw about +z of unit quaternions ``(N, 4) [w, x, y, z]`` -> ``(N,)`` radians in [-pi, pi)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return wrap_angle(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def quaternion_from_yaw(yaw: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(N, 4) [w, x, y, z]`` of rotations by ``yaw (N,)`` radians about +z."""
    yaw = np.asarray(yaw, dtype=np.float64).reshape(-1)
    q = np.zeros((yaw.shape[0], 4))
    q[:, 0] = np.cos(yaw / 2.0)
    q[:, 3] = np.sin(yaw / 2.0)
    return q
