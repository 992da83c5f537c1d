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


def rotation_angle_about_z(q: np.ndarray) -> np.ndarray:
    """Signed rotation angle of unit quaternions ``(N, 4) [w, x, y, z]`` about their axis turned to +z -> ``(N,)``
    radians in [-pi, pi).

    A quaternion ``(w, v)`` is a rotation by ``2 atan2(|v|, w)`` about ``v / |v|``; with the axis flipped into the
    upper half-space (``q -> -q`` when ``v_z < 0``) the angle is read as a turn about +z. For a pure yaw rotation
    this equals :func:`yaw_from_quaternion`; with pitch and roll it also counts their share of the rotation
    (differences of ~1e-2 rad on real detections). Poly-MOT's measured yaw (pyquaternion ``.radians`` after
    ``-q if q.axis[-1] < 0``).
    """
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w = np.where(q[:, 3] < 0, -q[:, 0], q[:, 0])
    return wrap_angle(2.0 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), w))


#: measured-yaw definitions by name (tracker preset key ``preprocessing.measured_yaw``)
MEASURED_YAW = {"euler_z": yaw_from_quaternion, "rotation_angle": rotation_angle_about_z}


def quaternion_from_yaw(yaw: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(N, 4) [w, x, y, z]`` of rotations by ``yaw (N,)`` radians about +z."""
    yaw = np.asarray(yaw, dtype=np.float64).reshape(-1)
    q = np.zeros((yaw.shape[0], 4))
    q[:, 0] = np.cos(yaw / 2.0)
    q[:, 3] = np.sin(yaw / 2.0)
    return q


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of quaternions ``q (N, 4) [w, x, y, z]`` (normalised first)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )
