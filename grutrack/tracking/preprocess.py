"""Pre-processing of one frame's detections: per-class score filter, then NMS on BEV IoU."""

from __future__ import annotations

import numpy as np

from grutrack.data.scene import BoxSet
from grutrack.geometry import pairwise_bev_iou


def score_filter(dets: BoxSet, thresholds: np.ndarray) -> BoxSet:
    """Keep detections whose score is at least the threshold of their class.

    thresholds: (7,) float64 indexed by tracking-class label.
    """
    return dets.subset(dets.scores >= thresholds[dets.labels])


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
    over = pairwise_bev_iou(boxes, boxes) > threshold
    if class_aware:
        over &= labels[:, None] == labels[None, :]
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
