"""Track-to-ground-truth association for training: same class, BEV centre distance below a gate, Hungarian,
sticky once matched.

A track keeps its GT instance for the rest of the scene; in a frame where that instance is absent the track
has no GT (its pseudo-label is used). Free tracks are matched only to instances that no track holds. Indices
always refer to the current frame's arrays (the authors' code reads ids from the wrong list once some GT is
taken; here the free-GT subset is indexed explicitly).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment


class StickyGTAssociation:
    """Per-scene state: which GT instance each track holds."""

    def __init__(self, max_distance: float = 2.0):
        self.max_distance = max_distance
        self.held: dict[int, str] = {}  # track id -> GT instance id

    def held_rows(self, track_ids: np.ndarray, gt_ids: np.ndarray) -> np.ndarray:
        """GT row per track (K,) int64 of the instance each track already holds, -1 where it holds none or
        its instance is absent from this frame (no new matching)."""
        return self._held_rows(track_ids, {g: i for i, g in enumerate(gt_ids)})

    def _held_rows(self, track_ids: np.ndarray, row_of: dict) -> np.ndarray:
        """Row (via ``row_of``: instance id -> row of this frame's GT) of the instance each track (K,) holds, -1
        where it holds none or its instance is absent (dictionary lookups: a few tens of tracks per frame)."""
        held = self.held
        return np.fromiter(
            (row_of.get(held.get(t), -1) for t in track_ids.tolist()), dtype=np.int64, count=len(track_ids)
        )

    def match(
        self,
        track_ids: np.ndarray,
        track_xy: np.ndarray,
        track_labels: np.ndarray,
        gt_ids: np.ndarray,
        gt_xy: np.ndarray,
        gt_labels: np.ndarray,
    ) -> np.ndarray:
        """GT row per track (K,) int64, -1 where the track has no GT this frame.

        track_ids (K,), track_xy (K, 2) metres, track_labels (K,); gt_ids (G,) instance ids, gt_xy (G, 2),
        gt_labels (G,).
        """
        # rows of the current GT list holding each track's instance (sticky tracks whose instance is present)
        row_of = {g: i for i, g in enumerate(gt_ids)}
        out = self._held_rows(track_ids, row_of)
        held_set = set(self.held.values())
        taken = np.fromiter((g in held_set for g in gt_ids), dtype=bool, count=len(gt_ids))
        free = np.fromiter((int(t) not in self.held for t in track_ids.tolist()), dtype=bool, count=len(track_ids))
        ft = np.flatnonzero(free)
        free_gt = np.flatnonzero(~taken)
        if len(ft) == 0 or len(free_gt) == 0:
            return out
        d = np.linalg.norm(track_xy[ft][:, None, :] - gt_xy[free_gt][None, :, :], axis=2)
        ok = (d < self.max_distance) & (track_labels[ft][:, None] == gt_labels[free_gt][None, :])
        cost = np.where(ok, d, 1e6)
        r, c = linear_sum_assignment(cost)
        keep = ok[r, c]
        for k, gi in zip(ft[r[keep]], free_gt[c[keep]]):
            out[k] = gi
            self.held[int(track_ids[k])] = gt_ids[gi]
        return out
