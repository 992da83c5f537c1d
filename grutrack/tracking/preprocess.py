"""Pre-processing of one frame's detections: per-class score filter, then NMS on BEV IoU."""

from __future__ import annotations

import numpy as np

from grutrack.data.scene import BoxSet
from grutrack.geometry import paired_bev_iou
from grutrack.tracking.fastpoly import scale_nms_keep


def score_filter(dets: BoxSet, thresholds: np.ndarray, strict: bool = False) -> BoxSet:
    """Keep detections whose score is at least (``strict``: above) the threshold of their class.

    thresholds: (7,) float64 indexed by tracking-class label.
    """
    thr = thresholds[dets.labels]
    return dets.subset(dets.scores > thr if strict else dets.scores >= thr)


def overlap_matrix(boxes: np.ndarray, labels: np.ndarray | None, threshold: float) -> np.ndarray:
    """(N, N) bool: BEV IoU of boxes i, j above ``threshold`` (and same label when ``labels`` is given).

    Only pairs whose circumscribed circles intersect can overlap, so IoU is computed for those alone.
    """
    n = len(boxes)
    i, j = np.triu_indices(n, k=1)
    radius = 0.5 * np.hypot(boxes[:, 3], boxes[:, 4])
    near = np.hypot(boxes[i, 0] - boxes[j, 0], boxes[i, 1] - boxes[j, 1]) < radius[i] + radius[j]
    if labels is not None:
        near &= labels[i] == labels[j]
    i, j = i[near], j[near]
    over = np.zeros((n, n), dtype=bool)
    hit = paired_bev_iou(boxes[i], boxes[j]) > threshold
    over[i[hit], j[hit]] = True
    over[j[hit], i[hit]] = True
    return over


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
    over = overlap_matrix(boxes, labels if class_aware else None, threshold)
    order = np.argsort(-scores, kind="stable")
    removed = np.zeros(n, dtype=bool)
    keep = []
    for i in order:
        if removed[i]:
            continue
        keep.append(i)
        removed |= over[i]
    return np.sort(np.asarray(keep, dtype=np.int64))


def preprocess(dets: BoxSet, score_threshold: np.ndarray, nms_threshold: float,
               nms_class_aware: bool = True) -> BoxSet:
    """Score filter followed by NMS; returns the surviving detections in their original order."""
    dets = score_filter(dets, score_threshold)
    return dets.subset(nms_keep(dets.boxes, dets.scores, dets.labels, nms_threshold, nms_class_aware))


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
