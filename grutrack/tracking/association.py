"""Two-stage track-detection association with the Hungarian algorithm (scipy).

Stage 1 scores every same-class (detection, track) pair with its class's similarity (3D or BEV GIoU/IoU),
cost = 1 - similarity, and accepts assignments whose cost is below the class threshold. Stage 2 repeats
this with one similarity (BEV GIoU by default) on what stage 1 left unmatched. Different classes never match.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from grutrack import geometry

_PAIRED = {"giou_3d": geometry.paired_giou_3d, "giou_bev": geometry.paired_bev_giou,
           "iou_3d": geometry.paired_iou_3d, "iou_bev": geometry.paired_bev_iou}
_INVALID = 1e6  # cost of a forbidden pair; far above any threshold (costs live in [0, 2])


@dataclass
class Matches:
    """Result of association: matched (det, track) index pairs and the unmatched indices of each side."""

    dets: np.ndarray        # (K,) int64 detection indices
    tracks: np.ndarray      # (K,) int64 track indices, aligned with ``dets``
    unmatched_dets: np.ndarray
    unmatched_tracks: np.ndarray


def pair_costs(det_boxes: np.ndarray, trk_boxes: np.ndarray, di: np.ndarray, ti: np.ndarray,
               metric_of_pair: np.ndarray, metrics: tuple[str, ...]) -> np.ndarray:
    """Cost ``1 - similarity`` of the listed pairs, each scored with its own metric.

    det_boxes (D, 9), trk_boxes (T, 9); di, ti (K,) pair indices; metric_of_pair (K,) int index into
    ``metrics`` -> (K,) float64.
    """
    cost = np.empty(len(di))
    for m, name in enumerate(metrics):
        sel = metric_of_pair == m
        if sel.any():
            cost[sel] = 1.0 - _PAIRED[name](det_boxes[di[sel]], trk_boxes[ti[sel]])
    return cost


def similarity_upper_bound(a: np.ndarray, b: np.ndarray, metric: str) -> np.ndarray:
    """A cheap upper bound of ``metric`` between aligned pairs of boxes a, b (K, 9) -> (K,).

    When the BEV centre distance d exceeds the sum of circumradii the footprints are disjoint (IoU = 0) and
    the convex hull contains the trapezoid spanned by the inscribed discs, of area >= d (rho_a + rho_b), so
    GIoU_bev <= (area_a + area_b) / (d (rho_a + rho_b)) - 1; in 3D the enclosing volume is at least that area
    times max(h_a, h_b). Elsewhere the bound is the trivial 1. Pairs whose bound cannot beat a threshold are
    skipped without computing the polygon geometry; the result is identical.
    """
    d = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1])
    circum = 0.5 * (np.hypot(a[:, 3], a[:, 4]) + np.hypot(b[:, 3], b[:, 4]))
    rho = 0.5 * (np.minimum(a[:, 3], a[:, 4]) + np.minimum(b[:, 3], b[:, 4]))
    disjoint = d > circum
    if metric.startswith("iou"):
        return np.where(disjoint, 0.0, 1.0)
    area = a[:, 3] * a[:, 4] + b[:, 3] * b[:, 4]
    hull = np.maximum(d * rho, 1e-12)
    if metric == "giou_3d":
        vol = a[:, 3] * a[:, 4] * a[:, 5] + b[:, 3] * b[:, 4] * b[:, 5]
        bound = vol / (hull * np.maximum(a[:, 5], b[:, 5])) - 1.0
    else:
        bound = area / hull - 1.0
    return np.where(disjoint, np.minimum(bound, 1.0), 1.0)


def hungarian(cost: np.ndarray, threshold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Minimum-cost assignment among the pairs with ``cost < threshold`` (elementwise).

    cost (D, T) with forbidden pairs at a large value; threshold (D, T) or broadcastable -> (rows, cols).
    """
    if cost.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    allowed = cost < np.broadcast_to(threshold, cost.shape)
    # forbid pairs above threshold before solving, so they cannot displace an acceptable assignment
    rows, cols = linear_sum_assignment(np.where(allowed, cost, _INVALID))
    ok = allowed[rows, cols]
    return rows[ok].astype(np.int64), cols[ok].astype(np.int64)


def _stage(det_boxes, det_labels, trk_boxes, trk_labels, dets, trks, metric_names, metric_of_class,
           threshold_of_class) -> tuple[np.ndarray, np.ndarray]:
    """One Hungarian stage over the candidate subsets ``dets`` / ``trks``; returns matched global indices."""
    if len(dets) == 0 or len(trks) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    same = det_labels[dets][:, None] == trk_labels[trks][None, :]
    li, lj = np.nonzero(same)
    cost = np.full(same.shape, _INVALID)
    thr = threshold_of_class[det_labels[dets]][:, None]
    if len(li):
        di, ti = dets[li], trks[lj]
        metric = metric_of_class[det_labels[di]]
        # skip pairs whose similarity bound cannot reach the threshold (cost < t  <=>  similarity > 1 - t)
        need = np.zeros(len(li), dtype=bool)
        for m, name in enumerate(metric_names):
            sel = metric == m
            if sel.any():
                ub = similarity_upper_bound(det_boxes[di[sel]], trk_boxes[ti[sel]], name)
                need[sel] = ub > 1.0 - thr[li[sel], 0]
        li, lj, di, ti, metric = li[need], lj[need], di[need], ti[need], metric[need]
        cost[li, lj] = pair_costs(det_boxes, trk_boxes, di, ti, metric, metric_names)
    r, c = hungarian(cost, thr)
    return dets[r], trks[c]


def associate(det_boxes: np.ndarray, det_labels: np.ndarray, trk_boxes: np.ndarray, trk_labels: np.ndarray,
              first_metric: tuple[str, ...], first_threshold: np.ndarray, two_stage: bool,
              second_metric: str, second_threshold: np.ndarray) -> Matches:
    """Two-stage association of D detections with T (predicted) tracks.

    det_boxes (D, 9), trk_boxes (T, 9): canonical boxes; labels (D,), (T,) class indices;
    first_metric: similarity name per class (7,); thresholds (7,) cost thresholds per class.
    """
    d_all = np.arange(len(det_boxes), dtype=np.int64)
    t_all = np.arange(len(trk_boxes), dtype=np.int64)
    names = tuple(sorted(set(first_metric)))
    metric_of_class = np.array([names.index(m) for m in first_metric])
    md, mt = _stage(det_boxes, det_labels, trk_boxes, trk_labels, d_all, t_all, names, metric_of_class,
                    first_threshold)
    if two_stage:
        ud, ut = np.setdiff1d(d_all, md), np.setdiff1d(t_all, mt)
        md2, mt2 = _stage(det_boxes, det_labels, trk_boxes, trk_labels, ud, ut, (second_metric,),
                          np.zeros(len(first_metric), dtype=np.int64), second_threshold)
        md, mt = np.concatenate([md, md2]), np.concatenate([mt, mt2])
    return Matches(md, mt, np.setdiff1d(d_all, md), np.setdiff1d(t_all, mt))
