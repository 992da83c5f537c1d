"""Box-for-box comparison of two nuScenes tracking submissions (a reproduced tracker against the original code's
own output): boxes paired per sample and class, box counts per sample, scores, yaw, and the track partition.

Conventions that differ without touching any metric are not compared: the ``velocity`` field (Poly-MOT writes
[v, a] for CTRA and Bicycle tracks), pitch and roll of the quaternion (Poly-MOT writes a new track's tilted
detection quaternion; the yaw compared is the quaternion's rotation angle about +z, the same for both), the ids
themselves (only the partition of boxes into tracks is compared; ids may restart per scene), and ``meta``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from grutrack.boxes import rotation_angle_about_z, wrap_angle


@dataclass
class TrackParity:
    """Outcome of :func:`compare_tracks`. Counts are over the reference's boxes unless named otherwise."""

    samples: int = 0
    ref_boxes: int = 0
    our_boxes: int = 0
    paired: int = 0  # reference boxes with a box of ours of the same class within tolerance
    count_mismatch: list[str] = field(default_factory=list)  # samples whose box counts differ
    score_mismatch: int = 0  # paired boxes whose scores differ by more than score_tolerance
    yaw_mismatch: int = 0  # paired boxes whose yaws differ by more than the tolerance (radians)
    partition_breaks: int = 0  # reference tracks split across, or merged with, tracks of ours
    max_distance: float = 0.0  # largest centre / size difference of a paired box (m)
    first_divergence: str | None = None  # first sample (in the order given) where anything differs

    @property
    def paired_fraction(self) -> float:
        """Share of the reference's boxes paired (1.0 for an empty reference)."""
        return self.paired / self.ref_boxes if self.ref_boxes else 1.0

    @property
    def identical(self) -> bool:
        """Every box paired, same counts, scores and yaws, same track partition."""
        return (
            self.paired == self.ref_boxes == self.our_boxes
            and not self.count_mismatch
            and self.score_mismatch == 0
            and self.yaw_mismatch == 0
            and self.partition_breaks == 0
        )

    def summary(self) -> str:
        """One line of figures."""
        return (
            f"{self.paired}/{self.ref_boxes} reference boxes paired ({100 * self.paired_fraction:.3f} %), "
            f"{self.our_boxes} boxes of ours, {len(self.count_mismatch)} of {self.samples} samples with other "
            f"box counts, {self.score_mismatch} score and {self.yaw_mismatch} yaw mismatches, "
            f"{self.partition_breaks} track partition breaks, largest paired difference "
            f"{self.max_distance:.2e} m, first divergence: {self.first_divergence or 'none'}"
        )


def _sample_arrays(boxes: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(N, 6) [x, y, z, w, l, h], (N,) yaw (rotation angle about +z), (N,) score, names as class|id strings."""
    if not boxes:
        return np.zeros((0, 6)), np.zeros(0), np.zeros(0), []
    geo = np.array([[*b["translation"], *b["size"]] for b in boxes], dtype=np.float64)
    yaw = rotation_angle_about_z(np.array([b["rotation"] for b in boxes], dtype=np.float64))
    score = np.array([b["tracking_score"] for b in boxes], dtype=np.float64)
    return geo, yaw, score, [b["tracking_name"] for b in boxes]


def _pair(ref: np.ndarray, ours: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (i, j) of boxes (n, 6), (m, 6) of one class whose largest coordinate difference is within
    ``tolerance``; one-to-one by least total difference. -> rows, cols, differences."""
    if len(ref) == 0 or len(ours) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
    diff = np.abs(ref[:, None, :] - ours[None, :, :]).max(axis=2)
    r, c = linear_sum_assignment(np.where(diff <= tolerance, diff, 1e9))
    ok = diff[r, c] <= tolerance
    return r[ok], c[ok], diff[r[ok], c[ok]]


def compare_tracks(
    reference: dict, ours: dict, sample_scene: dict[str, str], tolerance: float = 1e-6, score_tolerance: float = 1e-9
) -> TrackParity:
    """Compare the ``results`` of two tracking submissions sample by sample.

    ``sample_scene``: sample token -> scene token, in the order to report the first divergence; only these samples
    are compared. Tracks are keyed by (scene, tracking_id) on both sides, so ids may restart per scene.
    """
    out = TrackParity()
    ref_res, our_res = reference["results"], ours["results"]
    ref_to_ours: dict[tuple, set] = {}
    ours_to_ref: dict[tuple, set] = {}
    for token, scene in sample_scene.items():
        rb, ob = ref_res.get(token, []), our_res.get(token, [])
        out.samples += 1
        out.ref_boxes += len(rb)
        out.our_boxes += len(ob)
        differs = len(rb) != len(ob)
        if differs:
            out.count_mismatch.append(token)
        rg, ry, rs, rn = _sample_arrays(rb)
        og, oy, os_, on = _sample_arrays(ob)
        rn_arr, on_arr = np.array(rn, dtype=object), np.array(on, dtype=object)
        for name in sorted(set(rn) | set(on)):
            ri, oi = np.flatnonzero(rn_arr == name), np.flatnonzero(on_arr == name)
            r, c, d = _pair(rg[ri], og[oi], tolerance)
            r, c = ri[r], oi[c]
            out.paired += len(r)
            differs |= len(r) != len(ri) or len(r) != len(oi)
            if len(d):
                out.max_distance = max(out.max_distance, float(d.max()))
            bad_score = int(np.sum(np.abs(rs[r] - os_[c]) > score_tolerance))
            bad_yaw = int(np.sum(np.abs(wrap_angle(ry[r] - oy[c])) > tolerance))
            out.score_mismatch += bad_score
            out.yaw_mismatch += bad_yaw
            differs |= bad_score > 0 or bad_yaw > 0
            for i, j in zip(r, c):
                a, b = (scene, str(rb[i]["tracking_id"])), (scene, str(ob[j]["tracking_id"]))
                ref_to_ours.setdefault(a, set()).add(b)
                ours_to_ref.setdefault(b, set()).add(a)
        if differs and out.first_divergence is None:
            out.first_divergence = token
    out.partition_breaks = sum(len(v) - 1 for v in ref_to_ours.values()) + sum(len(v) - 1 for v in ours_to_ref.values())
    return out
