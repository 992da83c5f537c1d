"""Pre-processing of one frame's detections: per-class score filter, then NMS on BEV IoU."""

from __future__ import annotations

import numpy as np
from numba import njit

from grutrack import geometry
from grutrack.data.scene import BoxSet
from grutrack.tracking.fastpoly import scale_nms_keep


def score_filter(dets: BoxSet, thresholds: np.ndarray, strict: bool = False) -> BoxSet:
    """Keep detections whose score is at least (``strict``: above) the threshold of their class.

    thresholds: (7,) float64 indexed by tracking-class label.
    """
    thr = thresholds[dets.labels]
    return dets.subset(dets.scores > thr if strict else dets.scores >= thr)


@njit(cache=True)
def _nms_kernel(boxes, terms, labels, order, threshold, class_aware, keep) -> None:
    """Greedy NMS over ``order (N,)`` (descending score): set ``keep[i]`` for each box that no kept box
    overlaps with BEV IoU > ``threshold``. boxes (N, >=7), terms: :func:`geometry._box_terms`, labels (N,).

    Only pairs whose circumscribed circles meet can overlap; IoU is computed for those alone, always with the
    lower index first so that it equals :func:`geometry.paired_bev_iou` of that pair.
    """
    n = boxes.shape[0]
    radius = np.empty(n)
    for i in range(n):
        radius[i] = 0.5 * np.hypot(boxes[i, 3], boxes[i, 4])
    removed = np.zeros(n, dtype=np.bool_)
    want = np.zeros(4, dtype=np.bool_)
    want[geometry._IOU_BEV] = True
    out, work, flags = np.zeros((4, 1)), np.empty((12, 16)), np.empty(16, dtype=np.bool_)
    keys = np.empty(16, dtype=np.int64)
    for i in order:
        if removed[i]:
            continue
        keep[i] = True
        for j in range(n):
            if removed[j] or keep[j] or (class_aware and labels[j] != labels[i]):
                continue
            lo, hi = min(i, j), max(i, j)
            if np.hypot(boxes[lo, 0] - boxes[hi, 0], boxes[lo, 1] - boxes[hi, 1]) >= radius[lo] + radius[hi]:
                continue
            geometry._pair_measures(terms, lo, terms, hi, want, out, 0, work, flags, keys)
            if out[geometry._IOU_BEV, 0] > threshold:
                removed[j] = True


def nms_keep(boxes: np.ndarray, scores: np.ndarray, labels: np.ndarray, threshold: float,
             class_aware: bool = True) -> np.ndarray:
    """Greedy "blend" NMS: visit boxes of all classes in one descending-score order; each kept box
    removes the not-yet-visited boxes whose BEV IoU with it exceeds ``threshold`` (only boxes of its own
    class when ``class_aware``).

    boxes (N, 9), scores (N,), labels (N,) -> sorted (K,) int64 indices of the kept boxes.
    """
    n = len(boxes)
    if n <= 1:
        return np.arange(n, dtype=np.int64)
    boxes = geometry._check_boxes(boxes, "boxes")
    keep = np.zeros(n, dtype=np.bool_)
    _nms_kernel(boxes, geometry._box_terms(boxes), np.asarray(labels, dtype=np.int64),
                np.argsort(-scores, kind="stable"), float(threshold), bool(class_aware), keep)
    return np.flatnonzero(keep).astype(np.int64)


def preprocess_frame(dets: BoxSet, cfg) -> BoxSet:
    """Pre-processing of one frame as a tracker preset (:class:`TrackerConfig`) asks: score filter (score at
    least or above the class threshold, ``preprocessing.score_filter``), then blend
    NMS (:func:`nms_keep`, original order kept) or Fast-Poly's scale NMS (:func:`scale_nms_keep`; the
    survivors come class by class, each class by descending score, as Fast-Poly orders them)."""
    dets = score_filter(dets, cfg.score_threshold, strict=cfg.score_filter == "above")
    if cfg.nms_method == "blend":
        return dets.subset(nms_keep(dets.boxes, dets.scores, dets.labels, cfg.nms_threshold, cfg.nms_class_aware))
    thr = np.full(len(cfg.score_threshold), cfg.nms_threshold)
    gate = np.where(cfg.nms_distance_gate > 0, cfg.nms_distance_gate, np.inf)
    return dets.subset(scale_nms_keep(dets.boxes, dets.scores, dets.labels, cfg.nms_metric, thr, cfg.nms_scale,
                                      gate, dets.extra.get("quaternion")))
