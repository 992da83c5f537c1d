"""Pre-processing of one frame's detections: per-class score filter, then NMS: blend NMS on BEV IoU
(:func:`nms_keep`, Poly-MOT) or Fast-Poly's scale NMS (:func:`scale_nms_keep`: class by class, on footprints
enlarged by a per-class factor, with a per-class similarity, A-GIoU BEV or rotated BEV IoU, threshold and
distance gate; its A-GIoU and gate come from :mod:`grutrack.tracking.association`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from grutrack import geometry
from grutrack.data.scene import BoxSet
from grutrack.tracking.association import aligned_extents, distance_mask, pairwise_a_giou


def score_filter(dets: BoxSet, thresholds: np.ndarray, strict: bool = False) -> BoxSet:
    """Keep detections whose score is at least (``strict``: above) the threshold of their class.

    thresholds: (n_labels,) float64 indexed by label (sized by the dataset's vocabulary).
    """
    thr = thresholds[dets.labels]
    return dets.subset(dets.scores > thr if strict else dets.scores >= thr)


@njit(cache=True)
def _nms_kernel(terms, corners, centre, radius, labels, order, threshold, class_aware, keep, visited) -> None:
    """Greedy NMS over ``order (N,)`` (descending score): set ``keep[i]`` for each box that no kept box
    overlaps with BEV IoU > ``threshold[labels[kept]]`` (``threshold (n_labels,)``). terms:
    :func:`geometry._box_terms` of the boxes; corners (N, 4, 2) their own footprints, or (0, 4, 2) for the yaw
    rectangles; centre (N, 2), radius (N,): a disc holding each footprint; labels (N,). ``visited (N,)``: the kept
    boxes in the order they were kept (-1 after the last).

    Only pairs whose discs meet can overlap; IoU is computed for those alone, always with the lower index first
    so that it equals :func:`geometry.paired_bev_iou` (or :func:`geometry.footprint_similarities`) of that pair.
    """
    n = terms.shape[1]
    removed = np.zeros(n, dtype=np.bool_)
    want = np.zeros(4, dtype=np.bool_)
    want[geometry._IOU_BEV] = True
    out, work, flags = np.zeros((4, 1)), np.empty((12, 16)), np.empty(16, dtype=np.bool_)
    keys = np.empty(16, dtype=np.int64)
    fwork, forder = np.empty((10, 17)), np.empty(8, dtype=np.int64)
    nk = 0
    for i in order:
        if removed[i]:
            continue
        keep[i] = True
        visited[nk] = i
        nk += 1
        for j in range(n):
            if removed[j] or keep[j] or (class_aware and labels[j] != labels[i]):
                continue
            lo, hi = min(i, j), max(i, j)
            if np.hypot(centre[lo, 0] - centre[hi, 0], centre[lo, 1] - centre[hi, 1]) >= radius[lo] + radius[hi]:
                continue
            if corners.shape[0]:
                geometry._footprint_pair(corners, lo, terms, corners, hi, terms, want, out, 0, fwork, forder)
            else:
                geometry._pair_measures(terms, lo, terms, hi, want, out, 0, work, flags, keys)
            if out[geometry._IOU_BEV, 0] > threshold[labels[i]]:
                removed[j] = True


def nms_keep(
    boxes: np.ndarray,
    scores: np.ndarray,
    labels: np.ndarray,
    threshold: float | np.ndarray,
    class_aware: bool = True,
    order: str = "input",
    corners: np.ndarray | None = None,
) -> np.ndarray:
    """Greedy "blend" NMS: visit boxes of all classes in one descending-score order; each kept box
    removes the not-yet-visited boxes whose BEV IoU with it exceeds ``threshold`` (one value, or (n_labels,) by
    the kept box's label; only boxes of its own class when ``class_aware``).

    boxes (N, 9), scores (N,), labels (N,) -> (K,) int64 indices of the kept boxes: sorted (``order: input``,
    visiting boxes of equal score in input order), or in the order they were kept (``score``: descending score,
    ties as numpy's default sort leaves them, MCTrack's order). corners (N, 4, 2): the boxes' own footprints
    (:func:`geometry.bottom_corners`, ``preprocessing.footprint: bottom_face``); None: their yaw rectangles.
    """
    n = len(boxes)
    if n <= 1:
        return np.arange(n, dtype=np.int64)
    boxes = geometry._check_boxes(boxes, "boxes")
    labels = np.asarray(labels, dtype=np.int64)
    thr = np.asarray(threshold, dtype=np.float64)
    thr = np.full(int(labels.max()) + 1, float(thr)) if thr.ndim == 0 else np.ascontiguousarray(thr)
    keep = np.zeros(n, dtype=np.bool_)
    visited = np.full(n, -1, dtype=np.int64)
    if corners is None:
        corners, centre, radius = np.zeros((0, 4, 2)), boxes[:, :2], 0.5 * np.hypot(boxes[:, 3], boxes[:, 4])
    else:
        corners = np.ascontiguousarray(corners, dtype=np.float64)
        centre = corners.mean(axis=1)  # (N, 2)
        radius = np.linalg.norm(corners - centre[:, None], axis=2).max(axis=1)
    _nms_kernel(
        geometry._box_terms(boxes),
        corners,
        np.ascontiguousarray(centre),
        radius,
        labels,
        np.argsort(-scores, kind="stable") if order == "input" else np.argsort(-scores),
        thr,
        bool(class_aware),
        keep,
        visited,
    )
    if order == "input":
        return np.flatnonzero(keep).astype(np.int64)
    return visited[: int(keep.sum())]


#: per-class NMS similarities scale_nms_keep accepts
NMS_METRICS = ("a_giou_bev", "iou_bev")


def scale_nms_keep(
    boxes: np.ndarray,
    scores: np.ndarray,
    labels: np.ndarray,
    metric: tuple[str, ...],
    threshold: np.ndarray,
    scale: np.ndarray,
    radius: np.ndarray,
    quaternion: np.ndarray | None = None,
    footprint: bool = False,
) -> np.ndarray:
    """Fast-Poly's scale NMS; returns the kept indices (K,) int64, class by class (label 0 first), each class in
    descending score order.

    Within one class c, boxes are visited by descending score (numpy's default, non-stable argsort of
    ``-score``, as Fast-Poly); a visited box that is still present is kept and removes every later box of
    its class whose centre lies within ``radius[c]`` metres (3D) and whose similarity ``metric[c]`` with it,
    computed on both footprints enlarged by ``scale[c]`` (w and l times the factor), exceeds
    ``threshold[c]``. Metrics: ``a_giou_bev`` (alignment GIoU of the enlarged footprints' enclosing
    rectangles) or ``iou_bev`` (rotated BEV IoU of the enlarged footprints). Boxes of different classes never
    suppress each other.

    boxes (N, 9), scores (N,), labels (N,) int; metric: name per label (n_labels,); threshold, scale, radius
    (n_labels,) (per-label arrays sized by the dataset's vocabulary);
    quaternion: optional (N, 4) own rotations of the boxes, for the A-GIoU footprints (:func:`aligned_extents`);
    the rotated IoU uses the yaw rectangles (Fast-Poly), or with ``footprint`` the bottom faces
    (:func:`geometry.bottom_corners`, ``preprocessing.footprint: bottom_face``).
    """
    keep = []
    for c in range(len(metric)):
        idx = np.flatnonzero(labels == c)
        if len(idx) == 0:
            continue
        order = idx[np.argsort(-scores[idx])]
        b = boxes[order]
        q = None if quaternion is None else quaternion[order]
        over = _suppression_matrix(b, metric[c], threshold[c], scale[c], radius[c], q, footprint)
        removed = np.zeros(len(order), dtype=bool)
        for i in range(len(order)):
            if removed[i]:
                continue
            keep.append(order[i])
            removed[i + 1 :] |= over[i, i + 1 :]
    return np.asarray(keep, dtype=np.int64)


def _suppression_matrix(
    b: np.ndarray,
    metric: str,
    threshold: float,
    scale: float,
    radius: float,
    quaternion: np.ndarray | None = None,
    footprint: bool = False,
) -> np.ndarray:
    """(N, N) bool: box i would suppress box j (centres within ``radius``, similarity above ``threshold``); the
    rotated IoU on the yaw rectangles, or with ``footprint`` on the bottom faces of ``quaternion``."""
    near = distance_mask(b, b, radius)
    if metric == "a_giou_bev":
        e = aligned_extents(b, scale, quaternion)
        return near & (pairwise_a_giou(e, e) > threshold)
    if metric == "iou_bev":
        i, j = np.nonzero(np.triu(near, k=1))
        big = b.copy()
        big[:, 3:6] *= scale
        over = np.zeros(near.shape, dtype=bool)
        if footprint:
            c = geometry.bottom_corners(big, quaternion)
            iou = geometry.footprint_similarities(big[i], c[i], big[j], c[j], ["iou_bev"], pairwise=False)["iou_bev"]
        else:
            iou = geometry.paired_bev_iou(big[i], big[j])
        hit = iou > threshold
        over[i[hit], j[hit]] = over[j[hit], i[hit]] = True
        return over
    raise ValueError(f"unknown NMS metric {metric!r} (expected one of {', '.join(NMS_METRICS)})")


def preprocess_frame(dets: BoxSet, cfg) -> BoxSet:
    """Pre-processing of one frame as a tracker preset (:class:`TrackerConfig`) asks: score filter (score at
    least or above the class threshold, ``preprocessing.score_filter``), then blend
    NMS (:func:`nms_keep`, original order kept) or Fast-Poly's scale NMS (:func:`scale_nms_keep`; the
    survivors come class by class, each class by descending score, as Fast-Poly orders them).

    With ``preprocessing.footprint: bottom_face`` the kept detections carry ``extra["footprint"] (N, 4, 2)``, their
    bottom faces on the ground (:func:`geometry.bottom_corners` of their own quaternion), which NMS and the
    association's IoU / GIoU measure. A frame whose boxes all turn about +z only (quaternion x = y = 0), or carry no
    quaternion (AV2, LT3D tables), keeps the rectangle measures: their bottom faces are those rectangles."""
    dets = score_filter(dets, cfg.score_threshold, strict=cfg.score_filter == "above")
    corners = None
    q = dets.extra.get("quaternion")
    if cfg.footprint == "bottom_face" and q is not None and np.any(q[:, 1:3] != 0.0):  # some box pitched or rolled
        corners = geometry.bottom_corners(dets.boxes, q)
        dets = BoxSet(dets.boxes, dets.scores, dets.labels, dets.ids, {**dets.extra, "footprint": corners})
    if cfg.nms_method == "blend":
        return dets.subset(
            nms_keep(
                dets.boxes, dets.scores, dets.labels, cfg.nms_threshold, cfg.nms_class_aware, cfg.nms_order, corners
            )
        )
    thr = np.broadcast_to(np.asarray(cfg.nms_threshold, dtype=np.float64), cfg.score_threshold.shape)
    gate = np.where(cfg.nms_distance_gate > 0, cfg.nms_distance_gate, np.inf)
    return dets.subset(
        scale_nms_keep(
            dets.boxes,
            dets.scores,
            dets.labels,
            cfg.nms_metric,
            thr,
            cfg.nms_scale,
            gate,
            dets.extra.get("quaternion"),
            footprint=corners is not None,
        )
    )
