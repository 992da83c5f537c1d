"""Two-stage track-detection association with the Hungarian algorithm (scipy's, compiled: :mod:`grutrack.lsap`).

Stage 1 scores every same-class (detection, track) pair with its class's similarity (3D or BEV GIoU/IoU),
cost = 1 - similarity, and accepts assignments whose cost is below the class threshold. Stage 2 repeats
this with one similarity (BEV GIoU by default) on what stage 1 left unmatched. Different classes never match,
nor, in either stage, a pair farther apart than its class's distance gate (``association.distance_gate``) or
whose footprint areas differ by more than its class's size gate (``association.size_gate``, :func:`size_consistent`).

Two assignment rules (tracker preset key ``association.assignment``), both over the admissible pairs
(cost < threshold):

* ``most_pairs`` (:func:`hungarian`): the most admissible pairs, and among those the least total cost.
* ``threshold_margin`` (:func:`threshold_margin`): the matching that maximises the total margin
  ``sum (threshold - cost)`` over its pairs; a cheap pair is kept even when it leaves two others unmatched.
  This is what ``lap.lapjv(cost, extend_cost=True, cost_limit=threshold)`` solves (Poly-MOT, Fast-Poly): lap
  pads the matrix so that leaving a detection and a track unmatched costs ``threshold / 2`` each.

Fast-Poly's association (Li et al., "Fast-Poly", RA-L 2024; preset ``fastpoly``), on dense cost matrices
(:func:`gated_association`, :func:`gated_costs`): the alignment GIoU (A-GIoU, :func:`aligned_extents`,
:func:`pairwise_a_giou`: every box is replaced by the axis-aligned rectangle enclosing its, optionally scaled,
BEV footprint, so no polygon clipping is needed; the 3D variant extrudes the rectangles by the box heights) and
the "voxel" distance gate (:func:`distance_mask`: a 3D centre distance below a per-class radius; pairs outside
it are never scored). Scale NMS (:func:`grutrack.tracking.preprocess.scale_nms_keep`) uses the same measures.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from grutrack import geometry
from grutrack.lsap import scipy_lsa_compiled as linear_sum_assignment

_INVALID = 1e6  # cost of a forbidden pair; far above any threshold (costs live in [0, 2])


@dataclass
class Matches:
    """Result of association: matched (det, track) index pairs and the unmatched indices of each side."""

    dets: np.ndarray  # (K,) int64 detection indices
    tracks: np.ndarray  # (K,) int64 track indices, aligned with ``dets``
    unmatched_dets: np.ndarray
    unmatched_tracks: np.ndarray


#: slack of the pruning test: a pair is scored unless its similarity bound is this far below what the
#: threshold needs (covers the rounding of the bound and of the polygon areas, ~TOL * perimeter)
_BOUND_SLACK = 1e-9


@njit(cache=True, inline="always")
def _similarity_bound(ta, i, tb, j, d: float, code: int) -> float:
    """Upper bound of similarity ``code`` (index into ``geometry.SIMILARITIES``) of boxes ``i`` and ``j`` of the
    term arrays ``ta (11, N)``, ``tb (11, M)`` (:func:`geometry._box_terms`) at BEV centre distance ``d`` (m).

    When d exceeds the sum of circumradii the footprints are disjoint (IoU = 0, union ``A_a + A_b``) and the
    convex hull contains both boxes, and also the trapezoid between their chords across the centre line
    (each at least ``2 rho``, ``rho = min(w, l) / 2``) plus the two outer halves of the boxes, so
    ``C >= max(A_a + A_b, d (rho_a + rho_b) + (A_a + A_b) / 2)``; then GIoU_bev <= (A_a + A_b) / C - 1. In 3D
    the enclosing volume is at least C times the vertical span of the pair, so GIoU_3d <= (V_a + V_b) / (C span)
    - 1. Elsewhere, and for boxes of zero area or volume, the bound is the trivial 1.
    """
    if d <= ta[geometry._RADIUS, i] + tb[geometry._RADIUS, j]:
        return 1.0
    if code == geometry._IOU_BEV or code == geometry._IOU_3D:
        return 0.0
    area = ta[geometry._AREA, i] + tb[geometry._AREA, j]
    rho = min(ta[geometry._HL, i], ta[geometry._HW, i]) + min(tb[geometry._HL, j], tb[geometry._HW, j])
    hull = max(area, d * rho + 0.5 * area)
    if code == geometry._GIOU_3D:
        span = max(ta[geometry._HI, i], tb[geometry._HI, j]) - min(ta[geometry._LO, i], tb[geometry._LO, j])
        volume = ta[geometry._VOL, i] + tb[geometry._VOL, j]
        return min(volume / (hull * span) - 1.0, 1.0) if volume > 0.0 else 1.0
    return min(area / hull - 1.0, 1.0) if area > 0.0 else 1.0


@njit(cache=True, inline="always")
def _centre_distance(ta, i, tb, j) -> float:
    """BEV distance (m) between the centres of box ``i`` of ``ta`` and box ``j`` of ``tb`` (term arrays)."""
    dx, dy = ta[geometry._X, i] - tb[geometry._X, j], ta[geometry._Y, i] - tb[geometry._Y, j]
    return np.sqrt(dx * dx + dy * dy)


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
def _cost_kernel(det_labels, trk_labels, ta, tb, ca, cb, fa, fb, codes, thresholds, costs) -> None:
    """Fill ``costs (S, D, T)`` (pre-set to ``_INVALID``) with ``1 - similarity`` of every candidate pair.

    ta (11, D), tb (11, T): :func:`geometry._box_terms` of the detections and the tracks; labels (D,), (T,);
    codes (S, C) int: the similarity (index into ``geometry.SIMILARITIES``) of each stage and class;
    thresholds (S, C): cost thresholds. A pair is a candidate of stage s when its labels agree and the bound of
    :func:`_similarity_bound` can beat ``thresholds[s, label]``. With footprints, ``ca (D, 4, 2)`` and
    ``cb (T, 4, 2)`` (parallelograms, metres) and their terms ``fa (5, D)``, ``fb (5, T)``
    (:func:`_parallelogram_terms`), pairs are measured by :func:`geometry._footprint_pair` and bounded by
    :func:`_footprint_bound`; without, ``ca`` is ``(0, 4, 2)``.
    """
    n_stages, footprints = codes.shape[0], ca.shape[0] > 0
    out, work, flags = np.zeros((4, 1)), np.empty((12, 16)), np.empty(16, dtype=np.bool_)
    keys, fwork, order = np.empty(16, dtype=np.int64), np.empty((10, 17)), np.empty(8, dtype=np.int64)
    want, need = np.zeros(4, dtype=np.bool_), np.zeros(n_stages, dtype=np.bool_)
    for i in range(det_labels.shape[0]):
        lab = det_labels[i]
        for j in range(trk_labels.shape[0]):
            if trk_labels[j] != lab:
                continue
            d = 0.0 if footprints else _centre_distance(ta, i, tb, j)
            want[:] = False
            any_need = False
            for st in range(n_stages):
                code = codes[st, lab]
                if footprints:
                    bound = _footprint_bound(ta, fa, i, tb, fb, j, code)
                else:
                    bound = _similarity_bound(ta, i, tb, j, d, code)
                need[st] = bound > 1.0 - thresholds[st, lab] - _BOUND_SLACK
                if need[st]:
                    want[code] = True
                    any_need = True
            if not any_need:
                continue
            if footprints:
                geometry._footprint_pair(ca, i, ta, cb, j, tb, want, out, 0, fwork, order)
            else:
                geometry._pair_measures(ta, i, tb, j, want, out, 0, work, flags, keys)
            for st in range(n_stages):
                if need[st]:
                    costs[st, i, j] = 1.0 - out[codes[st, lab], 0]


@functools.lru_cache(maxsize=64)
def _similarity_codes(metrics: tuple[tuple[str, ...], ...]) -> np.ndarray:
    """(S, C) int64 similarity index (into ``geometry.SIMILARITIES``) of each stage's metric per class."""
    codes = np.array([[geometry.SIMILARITIES.index(m) for m in metric] for metric in metrics], dtype=np.int64)
    codes.setflags(write=False)
    return codes


def _candidate_costs(
    det_boxes: np.ndarray,
    det_labels: np.ndarray,
    trk_boxes: np.ndarray,
    trk_labels: np.ndarray,
    stages: list[tuple[tuple[str, ...], np.ndarray]],
    det_corners: np.ndarray | None = None,
) -> list[np.ndarray]:
    """(D, T) cost matrices, one per stage, from ONE compiled geometry pass over the candidate pairs.

    stages: per stage, (metric name per class, cost threshold per class (C,)). A pair is a candidate of a
    stage when its classes agree and the similarity bound (:func:`_similarity_bound`) can beat that
    stage's threshold; everything else costs ``_INVALID`` (the bound never prunes a pair that could pass).
    det_corners (D, 4, 2): the detections' own footprints (:func:`grutrack.geometry.bottom_corners`), measured
    against the tracks' yaw rectangles (:func:`grutrack.geometry.footprint_similarities`).
    """
    D, T = len(det_boxes), len(trk_boxes)
    costs = np.full((len(stages), D, T), _INVALID)
    if D and T:
        det = geometry._check_boxes(det_boxes, "detection boxes")
        trk = geometry._check_boxes(trk_boxes, "track boxes")
        if det_corners is None:
            ca = cb = np.zeros((0, 4, 2))
            fa = fb = np.zeros((5, 0))
        else:
            ca, cb = np.ascontiguousarray(det_corners, dtype=np.float64), geometry.bev_corners(trk)
            fa, fb = _parallelogram_terms(ca), _parallelogram_terms(cb)
        _cost_kernel(
            det_labels.astype(np.int64, copy=False),
            trk_labels.astype(np.int64, copy=False),
            geometry._box_terms(det),
            geometry._box_terms(trk),
            ca,
            cb,
            fa,
            fb,
            _similarity_codes(tuple(metric for metric, _ in stages)),
            np.array([thr for _, thr in stages], dtype=np.float64),
            costs,
        )
    return list(costs)


#: rows of :func:`_parallelogram_terms`
_PX, _PY, _PR, _PIN, _PAREA = range(5)


def _parallelogram_terms(c: np.ndarray) -> np.ndarray:
    """(5, N) terms of parallelograms ``c (N, 4, 2)`` (metres, counter-clockwise): centre x, y; circumradius about
    the centre; inradius (half the least width: the area over the longer side, halved); area (m^2)."""
    centre = c.mean(axis=1)
    radius = np.linalg.norm(c - centre[:, None], axis=2).max(axis=1)
    e0, e1 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 1]
    area = np.abs(e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0])
    longest = np.maximum(np.linalg.norm(e0, axis=1), np.linalg.norm(e1, axis=1))
    inradius = np.where(longest > 0.0, 0.5 * area / np.where(longest > 0.0, longest, 1.0), 0.0)
    return np.ascontiguousarray(np.stack([centre[:, 0], centre[:, 1], radius, inradius, area]))


@njit(cache=True, inline="always")
def _footprint_bound(ta, fa, i, tb, fb, j, code: int) -> float:
    """Upper bound of similarity ``code`` of footprint ``i`` of ``fa`` and ``j`` of ``fb`` (terms of
    :func:`_parallelogram_terms`; ``ta``, ``tb``: :func:`geometry._box_terms` of the boxes), as
    :func:`_similarity_bound` for parallelograms.

    1 where the footprints' discs meet. Apart: IoU 0; the convex hull holds both footprints (areas P) and the
    trapezoid between their chords through the centres across the centre line, each at least twice the
    footprint's inradius r (a parallelogram is symmetric about its centre), so
    ``C >= max(P_a + P_b, d (r_a + r_b) + (P_a + P_b) / 2)``; then GIoU_bev <= (A_a + A_b) / C - 1 and
    GIoU_3d <= (V_a + V_b) / (C span) - 1, with A = w l and V = w l h the union's terms
    (:func:`grutrack.geometry.footprint_similarities`); the trivial 1 where that bound of C is 0.
    """
    dx, dy = fa[_PX, i] - fb[_PX, j], fa[_PY, i] - fb[_PY, j]
    d = np.sqrt(dx * dx + dy * dy)
    if d <= fa[_PR, i] + fb[_PR, j]:
        return 1.0
    if code == geometry._IOU_BEV or code == geometry._IOU_3D:
        return 0.0
    area = fa[_PAREA, i] + fb[_PAREA, j]
    hull = max(area, d * (fa[_PIN, i] + fb[_PIN, j]) + 0.5 * area)
    if hull <= 0.0:
        return 1.0
    if code == geometry._GIOU_3D:
        span = max(ta[geometry._HI, i], tb[geometry._HI, j]) - min(ta[geometry._LO, i], tb[geometry._LO, j])
        volume = ta[geometry._VOL, i] + tb[geometry._VOL, j]
        return min(volume / (hull * span) - 1.0, 1.0) if span > 0.0 else 1.0
    return min((ta[geometry._AREA, i] + tb[geometry._AREA, j]) / hull - 1.0, 1.0)


def associate(
    det_boxes: np.ndarray,
    det_labels: np.ndarray,
    trk_boxes: np.ndarray,
    trk_labels: np.ndarray,
    first_metric: tuple[str, ...],
    first_threshold: np.ndarray,
    two_stage: bool,
    second_metric: str,
    second_threshold: np.ndarray,
    assignment: str = "most_pairs",
    distance_gate: np.ndarray | None = None,
    first_override: tuple[np.ndarray, np.ndarray] | None = None,
    crowded: tuple[np.ndarray, Callable[[np.ndarray, np.ndarray], np.ndarray]] | None = None,
    track_penalty: np.ndarray | None = None,
    crowded_skip: np.ndarray | None = None,
    det_corners: np.ndarray | None = None,
    gate_scale: np.ndarray | None = None,
    size_gate: np.ndarray | None = None,
) -> Matches:
    """Two-stage association of D detections with T (predicted) tracks.

    det_boxes (D, 9), trk_boxes (T, 9): canonical boxes; labels (D,), (T,) class indices;
    first_metric: similarity name per class; thresholds: cost thresholds per class;
    assignment: the rule of both stages, a key of :data:`ASSIGNMENT`; distance_gate (C,) metres, 0 = none: a pair
    is scored, in either stage, only when its 3D centre distance is below its class's gate (a long box such as a
    trailer's still overlaps a track some metres off, so an ungated stage 2 would match it);
    first_override: (classes (C,) bool, costs (D, T)): stage 1 takes these costs for the detections of those
    classes instead of their ``first_metric``'s (a similarity the compiled kernel does not hold, e.g. Ro_GDIoU);
    crowded: (limit (C,), strict costs ``(rows (R,), cols (K,)) -> (R, K)``): for a class with limit > 0, a stage-1
    row or column with more than one pair below ``first_threshold`` takes the strict costs, admitted below ``limit``
    (:func:`crowded_stage_one`); track_penalty (T,): added to the stage-1 cost of each track's admissible pairs, up to
    just below the threshold (:func:`penalized`); crowded_skip (T,) bool: tracks that neither make a row crowded nor
    take the strict cost there (``skip`` of :func:`crowded_stage_one`); det_corners (D, 4, 2): the detections' own
    footprints for the IoU / GIoU measures (``preprocessing.footprint: bottom_face``; None: their yaw rectangles);
    gate_scale (T,): each track's gate is its class's ``distance_gate`` times this (None: 1), grown with the time
    since its last detection (:func:`grutrack.tracking.tracker.gate_scale`); size_gate (C,) in [0, 1], 0 = none:
    a pair is scored, in either stage, only when its footprint areas agree within its class's ratio
    (:func:`size_consistent`).
    """
    solve = ASSIGNMENT[assignment]
    stages = [(tuple(first_metric), first_threshold)]
    if two_stage:
        stages.append(((second_metric,) * len(first_metric), second_threshold))
    costs = _candidate_costs(det_boxes, det_labels, trk_boxes, trk_labels, stages, det_corners)
    if first_override is not None and costs[0].size:
        classes, override = first_override
        costs[0] = np.where(classes[det_labels][:, None], override, costs[0])
    if distance_gate is not None and np.any(distance_gate > 0) and costs[0].size:
        radii = np.where(distance_gate > 0, distance_gate, np.inf)[det_labels][:, None]  # (D, 1) metres
        if gate_scale is not None:
            radii = radii * gate_scale[None, :]  # (D, T)
        inside = np.linalg.norm(det_boxes[:, None, :3] - trk_boxes[None, :, :3], axis=2) < radii  # (D, T)
        costs = [np.where(inside, c, _INVALID) for c in costs]
    if size_gate is not None and np.any(size_gate > 0) and costs[0].size:
        alike = size_consistent(det_boxes, trk_boxes, size_gate[trk_labels])  # (D, T)
        costs = [np.where(alike, c, _INVALID) for c in costs]
    if crowded is not None and costs[0].size:
        costs[0] = crowded_stage_one(costs[0], det_labels, first_threshold, *crowded, skip=crowded_skip)
    if track_penalty is not None and costs[0].size and np.any(track_penalty > 0):
        costs[0] = penalized(costs[0], first_threshold[det_labels], track_penalty)
    return _solve_stages(solve, costs, det_labels, first_threshold, second_threshold)


def size_consistent(det_boxes: np.ndarray, trk_boxes: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """(D, T) bool: the pairs whose BEV footprint areas agree, ``min(a_d, a_t) >= ratio * max(a_d, a_t)``.

    det_boxes (D, 9), trk_boxes (T, 9): canonical boxes, a = w l in square metres (the track's filtered size);
    ratio (T,) in [0, 1], each track's class's ``association.size_gate`` (0: every pair agrees). A box of another
    object's size near a track (a neighbour's box given this class, a fragment) is refused however close it lies,
    while an object's own detections, whose size errors are a few tens of per cent, pass."""
    a_d = det_boxes[:, 3] * det_boxes[:, 4]  # (D,) m^2
    a_t = trk_boxes[:, 3] * trk_boxes[:, 4]  # (T,) m^2
    small = np.minimum(a_d[:, None], a_t[None, :])
    large = np.maximum(a_d[:, None], a_t[None, :])
    return small >= ratio[None, :] * large


def penalized(cost: np.ndarray, threshold: np.ndarray, penalty: np.ndarray) -> np.ndarray:
    """Stage-1 costs (D, T) with ``penalty`` (T,) added to each admissible pair (``cost < threshold``, the row's
    threshold (D,)), capped at the largest value below the threshold: the pair's margin shrinks, so it loses a near
    tie, but it is never refused for the penalty alone."""
    thr = threshold[:, None]
    cap = np.nextafter(thr, -np.inf)
    return np.where(cost < thr, np.minimum(cost + penalty[None, :], cap), cost)


def crowded_stage_one(
    cost: np.ndarray,
    det_labels: np.ndarray,
    threshold: np.ndarray,
    limit: np.ndarray,
    strict: Callable[[np.ndarray, np.ndarray], np.ndarray],
    skip: np.ndarray | None = None,
) -> np.ndarray:
    """Stage-1 costs (D, T) with a stricter measure where the first one is ambiguous.

    A detection of a class with ``limit > 0`` (per class, (C,)) that has more than one track below its class's
    ``threshold`` (C,) in ``cost``, or a track with more than one such detection, is crowded: every admissible
    pair (cost below the forbidden value) of that row or column takes its strict cost instead, shifted by
    ``threshold - limit`` so that it is admitted exactly when ``strict < limit``, with margin ``limit - strict``
    (:func:`threshold_margin`). Elsewhere ``cost`` is kept: a lone pair is judged by the looser first measure.
    ``det_labels`` (D,) int64; ``strict(rows (R,), cols (K,), need (R, K) bool) -> (R, K)``: the strict costs of
    those detections against those tracks, asked once, for the rows and columns that hold a crowded pair (not at
    all when none does: the strict measure costs more than the first); only the ``need`` pairs are read.
    ``skip`` (T,) bool, optional: tracks left out of the test, as if absent: they make no row crowded and their
    pairs keep ``cost`` (the tracker's lost newborns, ``association.crowded_skips_lost_newborns``)."""
    on = np.flatnonzero((limit > 0)[det_labels])  # the rows of those classes
    if not len(on):
        return cost
    sub = cost[on]
    counted = np.ones(cost.shape[1], dtype=bool) if skip is None else ~skip  # (T,)
    near = (sub < threshold[det_labels[on]][:, None]) & counted[None, :]
    busy = ((near.sum(axis=1) > 1)[:, None] | (near.sum(axis=0) > 1)[None, :]) & (sub < _INVALID) & counted[None, :]
    if not busy.any():
        return cost
    keep_rows, cols = np.flatnonzero(busy.any(axis=1)), np.flatnonzero(busy.any(axis=0))
    rows = on[keep_rows]
    block = np.ix_(rows, cols)
    need = busy[np.ix_(keep_rows, cols)]
    shifted = strict(rows, cols, need) + (threshold - limit)[det_labels[rows]][:, None]
    out = cost.copy()
    out[block] = np.where(need, shifted, cost[block])
    return out


def _solve_stages(
    solve, costs: list[np.ndarray], det_labels: np.ndarray, first_threshold: np.ndarray, second_threshold: np.ndarray
) -> Matches:
    """Assign on ``costs[0] (D, T)`` with the per-class ``first_threshold``, then (when a second cost
    matrix is given) on ``costs[1]`` restricted to what stage 1 left, with ``second_threshold``."""
    n_det, n_trk = costs[0].shape
    md, mt = solve(costs[0], first_threshold[det_labels][:, None])
    if len(costs) > 1:
        ud, ut = _unmatched(n_det, md), _unmatched(n_trk, mt)
        if len(ud) and len(ut):
            r, c = solve(costs[1][np.ix_(ud, ut)], second_threshold[det_labels[ud]][:, None])
            md, mt = np.concatenate([md, ud[r]]), np.concatenate([mt, ut[c]])
    return Matches(md, mt, _unmatched(n_det, md), _unmatched(n_trk, mt))


# --- Fast-Poly's association (preset ``fastpoly``; Li et al., "Fast-Poly", RA-L 2024, behaviour read from its
# public code at 694dec3): alignment GIoU (A-GIoU) similarities and a 3D centre-distance gate, on dense costs.


def aligned_extents(
    boxes: np.ndarray, scale: np.ndarray | float = 1.0, quaternion: np.ndarray | None = None
) -> np.ndarray:
    """Axis-aligned BEV extents of boxes whose size is scaled by ``scale`` about its centre.

    boxes (N, >=7); scale scalar or (N,) -> (N, 4) float64 ``[x_min, y_min, x_max, y_max]`` metres.
    Without ``quaternion`` the footprint is the yaw-rotated w x l rectangle. With ``quaternion`` (N, 4)
    ``[w, x, y, z]`` (a detection's own rotation, pitch and roll included) it is, as Fast-Poly's, the ground-plane
    projection of the box's bottom face: ``c + R(q) [+-l/2, +-w/2, -h/2]`` with w, l, h scaled.
    """
    b = np.array(boxes, dtype=np.float64, ndmin=2)[:, :7]
    k = np.broadcast_to(np.asarray(scale, dtype=np.float64), (len(b),))
    b[:, 3:6] *= k[:, None]  # w, l, h
    c = geometry.bottom_corners(b, quaternion)  # (N, 4, 2)
    return np.concatenate([c.min(axis=1), c.max(axis=1)], axis=1)


def _rect_area(e: np.ndarray) -> np.ndarray:
    """Areas (m^2) of extents ``e (..., 4)``."""
    return (e[..., 2] - e[..., 0]) * (e[..., 3] - e[..., 1])


def pairwise_a_giou(
    ext_a: np.ndarray, ext_b: np.ndarray, z_h_a: np.ndarray | None = None, z_h_b: np.ndarray | None = None
) -> np.ndarray:
    """A-GIoU between every pair of axis-aligned extents: (Na, 4), (Nb, 4) -> (Na, Nb) in (-1, 1].

    BEV (``z_h_*`` None): ``A-GIoU = I / U - (C - U) / C`` with I, U the intersection and union areas of the
    two rectangles and C the area of the smallest axis-aligned rectangle enclosing both.
    3D (``z_h_a (Na, 2)``, ``z_h_b (Nb, 2)`` = centre height z and box height h, metres): the same formula on
    volumes, ``I3 = I * h_o``, ``U3 = A_a h_a + A_b h_b - I3``, ``C3 = C * h_u`` with h_o the overlap and h_u the
    span of the two vertical intervals [z - h/2, z + h/2].
    """
    a, b = ext_a[:, None, :], ext_b[None, :, :]
    iw = np.maximum(0.0, np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]))
    ih = np.maximum(0.0, np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]))
    inter = iw * ih
    area_a, area_b = _rect_area(a), _rect_area(b)
    hull = (np.maximum(a[..., 2], b[..., 2]) - np.minimum(a[..., 0], b[..., 0])) * (
        np.maximum(a[..., 3], b[..., 3]) - np.minimum(a[..., 1], b[..., 1])
    )
    if z_h_a is None:
        union = area_a + area_b - inter
        return inter / union - (hull - union) / hull
    za, ha = z_h_a[:, None, 0], z_h_a[:, None, 1]
    zb, hb = z_h_b[None, :, 0], z_h_b[None, :, 1]
    top_a, bot_a, top_b, bot_b = za + ha / 2, za - ha / 2, zb + hb / 2, zb - hb / 2
    h_over = np.maximum(0.0, np.minimum(top_a, top_b) - np.maximum(bot_a, bot_b))
    h_span = np.maximum(top_a, top_b) - np.minimum(bot_b, bot_a)
    inter3 = inter * h_over
    union3 = area_a * ha + area_b * hb - inter3
    hull3 = hull * h_span
    return inter3 / union3 - (hull3 - union3) / hull3


def a_giou_bev(a: np.ndarray, b: np.ndarray, qa: np.ndarray | None = None) -> np.ndarray:
    """BEV A-GIoU between boxes a (Na, 9) and b (Nb, 9) -> (Na, Nb); ``qa`` (Na, 4): a's own quaternions."""
    return pairwise_a_giou(aligned_extents(a, quaternion=qa), aligned_extents(b))


def a_giou_3d(a: np.ndarray, b: np.ndarray, qa: np.ndarray | None = None) -> np.ndarray:
    """3D A-GIoU between boxes a (Na, 9) and b (Nb, 9) -> (Na, Nb); ``qa`` (Na, 4): a's own quaternions."""
    return pairwise_a_giou(aligned_extents(a, quaternion=qa), aligned_extents(b), a[:, [2, 5]], b[:, [2, 5]])


def distance_mask(a: np.ndarray, b: np.ndarray, radius: np.ndarray | float) -> np.ndarray:
    """(Na, Nb) bool: 3D centre distance ``||c_a - c_b||_2 < radius`` (metres).

    a (Na, >=3), b (Nb, >=3); radius scalar, (Na, 1) or (Na, Nb) (e.g. per class of ``a``).
    """
    d = np.linalg.norm(a[:, None, :3] - b[None, :, :3], axis=2)
    return d < radius


#: similarities :func:`gated_costs` can compute densely
DENSE_METRICS = ("a_giou_3d", "a_giou_bev", "giou_3d", "giou_bev", "iou_3d", "iou_bev")


def _dense_similarity(
    name: str, a: np.ndarray, b: np.ndarray, qa: np.ndarray | None = None, ca: np.ndarray | None = None
) -> np.ndarray:
    """(Na, Nb) similarity ``name`` between boxes a (Na, 9) and b (Nb, 9); ``qa`` (Na, 4) a's own quaternions
    (A-GIoU footprints); ``ca`` (Na, 4, 2) a's own footprints for IoU / GIoU (None: yaw rectangles)."""
    if name == "a_giou_3d":
        return a_giou_3d(a, b, qa)
    if name == "a_giou_bev":
        return a_giou_bev(a, b, qa)
    if ca is not None:
        return geometry.footprint_similarities(a, ca, b, geometry.bev_corners(b), [name])[name]
    fn = {
        "giou_3d": geometry.pairwise_giou_3d,
        "giou_bev": geometry.pairwise_bev_giou,
        "iou_3d": geometry.pairwise_iou_3d,
        "iou_bev": geometry.pairwise_bev_iou,
    }[name]
    return fn(a, b)


def _dense_bound(name: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(Na, Nb) upper bound of similarity ``name`` between boxes a (Na, 9) and b (Nb, 9): the bound of
    :func:`_similarity_bound` (1 where the footprints may overlap) for every pair at once; for IoU and GIoU only
    (Fast-Poly's A-GIoU can exceed it: trivial bound 1)."""
    ta = geometry._box_terms(geometry._check_boxes(a, "detection boxes"))
    tb = geometry._box_terms(geometry._check_boxes(b, "track boxes"))
    col, row = (lambda k: ta[k][:, None]), (lambda k: tb[k][None, :])
    d = np.hypot(col(geometry._X) - row(geometry._X), col(geometry._Y) - row(geometry._Y))
    disjoint = d > col(geometry._RADIUS) + row(geometry._RADIUS)
    if name.startswith("a_"):
        return np.ones_like(d)
    if name in ("iou_bev", "iou_3d"):
        return np.where(disjoint, 0.0, 1.0)
    area = col(geometry._AREA) + row(geometry._AREA)
    rho = np.minimum(col(geometry._HL), col(geometry._HW)) + np.minimum(row(geometry._HL), row(geometry._HW))
    hull = np.maximum(area, d * rho + 0.5 * area)  # C >= max(A_a + A_b, d (rho_a + rho_b) + (A_a + A_b) / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        if name == "giou_3d":
            span = np.maximum(col(geometry._HI), row(geometry._HI)) - np.minimum(col(geometry._LO), row(geometry._LO))
            volume = col(geometry._VOL) + row(geometry._VOL)
            bound = np.where(volume > 0.0, np.minimum(volume / (hull * span) - 1.0, 1.0), 1.0)
        else:
            bound = np.where(area > 0.0, np.minimum(area / hull - 1.0, 1.0), 1.0)
    return np.where(disjoint, bound, 1.0)


def gated_costs(
    det_boxes: np.ndarray,
    det_labels: np.ndarray,
    trk_boxes: np.ndarray,
    trk_labels: np.ndarray,
    first_metric: tuple[str, ...],
    second_metric: str,
    gate: np.ndarray,
    invalid: float = np.inf,
    det_quaternion: np.ndarray | None = None,
    det_corners: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Stage-1 and stage-2 cost matrices (D, T) with Fast-Poly's distance gate; cost = 1 - similarity.

    Stage 1: a pair is scored when its classes agree and its 3D centre distance is below ``gate[class]``
    metres (``gate`` (C,), 0 = no gate for that class); other pairs cost ``invalid``.
    Stage 2 with a gate on every class: as Fast-Poly, the gate only selects rows and columns: every same-class
    pair between a detection and a track that each have a same-class partner closer than the largest gate radius
    is scored with ``second_metric``, even when that pair itself lies outside the gate (Fast-Poly's rows and
    columns come from the union of its per-class distance masks). With some classes ungated: the stage-1 pairs,
    as :func:`associate`. ``det_quaternion`` (D, 4): the detections' own rotations, for their A-GIoU footprints
    (tracks are yaw-only boxes); ``det_corners`` (D, 4, 2): their footprints for IoU / GIoU (None: yaw rectangles).
    """
    D, T = len(det_boxes), len(trk_boxes)
    c1, c2 = np.full((D, T), invalid), np.full((D, T), invalid)
    same = det_labels[:, None] == trk_labels[None, :]
    radii = np.where(gate > 0, gate, np.inf)
    dist = np.linalg.norm(det_boxes[:, None, :3] - trk_boxes[None, :, :3], axis=2)
    valid = same & (dist < radii[det_labels][:, None])  # stage-1 pairs
    near = same & (dist < radii.max())  # Fast-Poly's union of the class masks (every pair when a class is ungated)
    second = same if np.isfinite(radii.max()) else valid  # stage-2 pairs within the rows and columns
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if len(rows) == 0:
        return c1, c2
    a, b = det_boxes[rows], trk_boxes[cols]
    sub = np.ix_(rows, cols)
    names = {first_metric[c] for c in np.unique(det_labels[rows])} | {second_metric}
    qa = None if det_quaternion is None else det_quaternion[rows]
    ca = None if det_corners is None else det_corners[rows]
    # each similarity at most its bound: far apart (a diverged track kilometres away) the dense geometry loses
    # its digits, and the bound, exact there, keeps such a pair from passing a threshold (the yaw rectangles' bound;
    # the footprints' measures are taken relative to the track's centre)
    sims = {
        n: _dense_similarity(n, a, b, qa, ca)
        if ca is not None and not n.startswith("a_")
        else np.minimum(_dense_similarity(n, a, b, qa), _dense_bound(n, a, b))
        for n in sorted(names)
    }
    first = np.full((len(rows), len(cols)), -np.inf)
    for c in np.unique(det_labels[rows]):
        r = det_labels[rows] == c
        first[r] = sims[first_metric[c]][r]
    c1[sub] = np.where(valid[sub], 1.0 - first, invalid)
    c2[sub] = np.where(second[sub], 1.0 - sims[second_metric], invalid)
    return c1, c2


def gated_association_needed(cfg) -> bool:
    """Whether a preset needs :func:`gated_association`: alignment-GIoU metrics, or a distance gate on every class
    (then Fast-Poly's stage 2 takes only the rows and columns within the largest gate). A gate on some classes
    only gates each pair of both stages, which :func:`associate` applies."""
    metrics = set(cfg.first_metric) | {cfg.second_metric}
    return bool(np.all(cfg.distance_gate > 0)) or any(m.startswith("a_") for m in metrics)


def gated_association(cfg):
    """Two-stage association on dense costs with Fast-Poly's distance gate and A-GIoU metrics
    (:func:`gated_costs`); thresholds and assignment rule as :func:`associate`."""
    solve = ASSIGNMENT[cfg.assignment]

    def run(dets, trk_boxes: np.ndarray, trk_labels: np.ndarray, dt: float) -> Matches:
        c1, c2 = gated_costs(
            dets.boxes,
            dets.labels,
            trk_boxes,
            trk_labels,
            cfg.first_metric,
            cfg.second_metric,
            cfg.distance_gate,
            invalid=_INVALID,
            det_quaternion=dets.extra.get("quaternion"),
            det_corners=dets.extra.get("footprint"),
        )
        return _solve_stages(
            solve, [c1, c2] if cfg.two_stage else [c1], dets.labels, cfg.first_threshold, cfg.second_threshold
        )

    return run
