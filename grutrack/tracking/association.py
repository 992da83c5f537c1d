"""Two-stage track-detection association with the Hungarian algorithm (scipy).

Stage 1 scores every same-class (detection, track) pair with its class's similarity (3D or BEV GIoU/IoU),
cost = 1 - similarity, and accepts assignments whose cost is below the class threshold. Stage 2 repeats
this with one similarity (BEV GIoU by default) on what stage 1 left unmatched. Different classes never match.

Two assignment rules (tracker preset key ``association.assignment``), both over the admissible pairs
(cost < threshold):

* ``most_pairs`` (:func:`hungarian`): the most admissible pairs, and among those the least total cost.
* ``threshold_margin`` (:func:`threshold_margin`): the matching that maximises the total margin
  ``sum (threshold - cost)`` over its pairs; a cheap pair is kept even when it leaves two others unmatched.
  This is what ``lap.lapjv(cost, extend_cost=True, cost_limit=threshold)`` solves (Poly-MOT, Fast-Poly): lap
  pads the matrix so that leaving a detection and a track unmatched costs ``threshold / 2`` each.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.optimize import linear_sum_assignment

from grutrack import geometry

_INVALID = 1e6  # cost of a forbidden pair; far above any threshold (costs live in [0, 2])


@dataclass
class Matches:
    """Result of association: matched (det, track) index pairs and the unmatched indices of each side."""

    dets: np.ndarray        # (K,) int64 detection indices
    tracks: np.ndarray      # (K,) int64 track indices, aligned with ``dets``
    unmatched_dets: np.ndarray
    unmatched_tracks: np.ndarray


def similarity_upper_bounds(a: np.ndarray, b: np.ndarray, names) -> dict[str, np.ndarray]:
    """Cheap upper bounds of the named similarities between aligned pairs of boxes a, b (..., 9) (any
    broadcastable shapes, e.g. (K, 9) and (K, 9), or (D, 1, 9) and (1, T, 9)) -> {name: (...)}.

    When the BEV centre distance d exceeds the sum of circumradii the footprints are disjoint (IoU = 0) and
    the convex hull contains the trapezoid spanned by the inscribed discs, of area >= d (rho_a + rho_b), so
    GIoU_bev <= (area_a + area_b) / (d (rho_a + rho_b)) - 1; in 3D the enclosing volume is at least that area
    times max(h_a, h_b). Elsewhere the bound is the trivial 1. Pairs whose bound cannot beat a threshold are
    skipped without computing the polygon geometry; the result is identical.
    """
    d = np.hypot(a[..., 0] - b[..., 0], a[..., 1] - b[..., 1])
    disjoint = d > 0.5 * (np.hypot(a[..., 3], a[..., 4]) + np.hypot(b[..., 3], b[..., 4]))
    hull = np.maximum(d * 0.5 * (np.minimum(a[..., 3], a[..., 4]) + np.minimum(b[..., 3], b[..., 4])), 1e-12)
    out = {}
    for name in names:
        if name.startswith("iou"):
            out[name] = np.where(disjoint, 0.0, 1.0)
        elif name == "giou_3d":
            vol = a[..., 3] * a[..., 4] * a[..., 5] + b[..., 3] * b[..., 4] * b[..., 5]
            out[name] = np.where(disjoint, np.minimum(vol / (hull * np.maximum(a[..., 5], b[..., 5])) - 1.0, 1.0), 1.0)
        else:
            area = a[..., 3] * a[..., 4] + b[..., 3] * b[..., 4]
            out[name] = np.where(disjoint, np.minimum(area / hull - 1.0, 1.0), 1.0)
    return out


def similarity_upper_bound(a: np.ndarray, b: np.ndarray, metric: str) -> np.ndarray:
    """:func:`similarity_upper_bounds` for one metric -> (K,)."""
    return similarity_upper_bounds(a, b, [metric])[metric]


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


def threshold_margin(cost: np.ndarray, threshold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Matching of maximum total margin ``sum (threshold - cost)`` among the pairs with ``cost < threshold``.

    cost (D, T); threshold (D, T) or broadcastable -> (rows, cols). With ``G = min(cost - threshold, 0)``
    (0 for inadmissible pairs) a full rectangular assignment minimising ``sum G`` restricted to its admissible
    pairs is an optimal partial matching: any partial matching extends to a full assignment at no cost (the
    added pairs are worth 0 or less), so both optima are equal. Same result as lap.lapjv with ``cost_limit``.
    """
    if cost.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    thr = np.broadcast_to(threshold, cost.shape)
    allowed = cost < thr
    rows, cols = linear_sum_assignment(np.where(allowed, cost - thr, 0.0))
    ok = allowed[rows, cols]
    return rows[ok].astype(np.int64), cols[ok].astype(np.int64)


#: assignment rules by preset name (``association.assignment``)
ASSIGNMENT = {"most_pairs": hungarian, "threshold_margin": threshold_margin}


def _unmatched(n: int, matched: np.ndarray) -> np.ndarray:
    """Sorted ``(n - K,) int64`` indices in ``0 .. n-1`` that are not in ``matched (K,)``."""
    free = np.ones(n, dtype=bool)
    free[matched] = False
    return np.flatnonzero(free).astype(np.int64)


@njit(cache=True)
def _cost_kernel(det, det_labels, trk, trk_labels, ta, tb, codes, thresholds, costs) -> None:
    """Fill ``costs (S, D, T)`` (pre-set to ``_INVALID``) with ``1 - similarity`` of every candidate pair.

    det (D, >=7), trk (T, >=7): boxes; ta, tb: their :func:`geometry._box_terms`; codes (S, C) int: the
    similarity (index into ``geometry.SIMILARITIES``) of each stage and class; thresholds (S, C): cost
    thresholds. A pair is a candidate of stage s when its labels agree and the bound of
    :func:`similarity_upper_bounds` can beat ``thresholds[s, label]``.
    """
    n_stages = codes.shape[0]
    out, work, flags = np.zeros((4, 1)), np.empty((12, 16)), np.empty(16, dtype=np.bool_)
    keys = np.empty(16, dtype=np.int64)
    want, need = np.zeros(4, dtype=np.bool_), np.zeros(n_stages, dtype=np.bool_)
    for i in range(det.shape[0]):
        lab = det_labels[i]
        ra = np.hypot(det[i, 3], det[i, 4])
        for j in range(trk.shape[0]):
            if trk_labels[j] != lab:
                continue
            d = np.hypot(det[i, 0] - trk[j, 0], det[i, 1] - trk[j, 1])
            disjoint = d > 0.5 * (ra + np.hypot(trk[j, 3], trk[j, 4]))
            hull = max(d * 0.5 * (min(det[i, 3], det[i, 4]) + min(trk[j, 3], trk[j, 4])), 1e-12)
            want[:] = False
            any_need = False
            for st in range(n_stages):
                code = codes[st, lab]
                bound = 1.0
                if disjoint:
                    if code == geometry._IOU_BEV or code == geometry._IOU_3D:
                        bound = 0.0
                    elif code == geometry._GIOU_3D:
                        vol = det[i, 3] * det[i, 4] * det[i, 5] + trk[j, 3] * trk[j, 4] * trk[j, 5]
                        bound = min(vol / (hull * max(det[i, 5], trk[j, 5])) - 1.0, 1.0)
                    else:
                        area = det[i, 3] * det[i, 4] + trk[j, 3] * trk[j, 4]
                        bound = min(area / hull - 1.0, 1.0)
                need[st] = bound > 1.0 - thresholds[st, lab]
                if need[st]:
                    want[code] = True
                    any_need = True
            if not any_need:
                continue
            geometry._pair_measures(ta, i, tb, j, want, out, 0, work, flags, keys)
            for st in range(n_stages):
                if need[st]:
                    costs[st, i, j] = 1.0 - out[codes[st, lab], 0]


def _candidate_costs(det_boxes: np.ndarray, det_labels: np.ndarray, trk_boxes: np.ndarray,
                     trk_labels: np.ndarray, stages: list[tuple[tuple[str, ...], np.ndarray]]) -> list[np.ndarray]:
    """(D, T) cost matrices, one per stage, from ONE compiled geometry pass over the candidate pairs.

    stages: per stage, (metric name per class, cost threshold per class (C,)). A pair is a candidate of a
    stage when its classes agree and the similarity bound (:func:`similarity_upper_bounds`) can beat that
    stage's threshold; everything else costs ``_INVALID`` (the bound never prunes a pair that could pass).
    """
    D, T = len(det_boxes), len(trk_boxes)
    costs = np.full((len(stages), D, T), _INVALID)
    if D and T:
        codes = np.array([[geometry.SIMILARITIES.index(m) for m in metric] for metric, _ in stages], dtype=np.int64)
        thresholds = np.array([thr for _, thr in stages], dtype=np.float64)
        det = geometry._check_boxes(det_boxes, "detection boxes")
        trk = geometry._check_boxes(trk_boxes, "track boxes")
        _cost_kernel(det, det_labels.astype(np.int64), trk, trk_labels.astype(np.int64), geometry._box_terms(det),
                     geometry._box_terms(trk), codes, thresholds, costs)
    return list(costs)


def associate(det_boxes: np.ndarray, det_labels: np.ndarray, trk_boxes: np.ndarray, trk_labels: np.ndarray,
              first_metric: tuple[str, ...], first_threshold: np.ndarray, two_stage: bool,
              second_metric: str, second_threshold: np.ndarray, assignment: str = "most_pairs") -> Matches:
    """Two-stage association of D detections with T (predicted) tracks.

    det_boxes (D, 9), trk_boxes (T, 9): canonical boxes; labels (D,), (T,) class indices;
    first_metric: similarity name per class; thresholds: cost thresholds per class;
    assignment: the rule of both stages, a key of :data:`ASSIGNMENT`.
    """
    solve = ASSIGNMENT[assignment]
    stages = [(tuple(first_metric), first_threshold)]
    if two_stage:
        stages.append(((second_metric,) * len(first_metric), second_threshold))
    costs = _candidate_costs(det_boxes, det_labels, trk_boxes, trk_labels, stages)
    md, mt = solve(costs[0], first_threshold[det_labels][:, None])
    if two_stage:
        ud, ut = _unmatched(len(det_boxes), md), _unmatched(len(trk_boxes), mt)
        if len(ud) and len(ut):
            r, c = solve(costs[1][np.ix_(ud, ut)], second_threshold[det_labels[ud]][:, None])
            md, mt = np.concatenate([md, ud[r]]), np.concatenate([mt, ut[c]])
    return Matches(md, mt, _unmatched(len(det_boxes), md), _unmatched(len(trk_boxes), mt))
