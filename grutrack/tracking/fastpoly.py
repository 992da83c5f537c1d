"""Fast-Poly's tracking components (Li et al., "Fast-Poly: A Fast Polyhedral Framework For 3D Multi-Object
Tracking", RA-L 2024; behaviour read from its public code at 694dec3, default nuScenes configuration).

Each function is one of Fast-Poly's additions to the Poly-MOT pipeline, batched over boxes or tracks:

* :func:`aligned_extents`, :func:`pairwise_a_giou`: the alignment GIoU (A-GIoU). Every box is replaced by the
  axis-aligned rectangle that encloses its (optionally scaled) BEV footprint; IoU, union and enclosing box are
  those of the rectangles, so no polygon clipping is needed. The 3D variant extrudes them by the box heights.
* :func:`distance_mask`: the "voxel" gate, a 3D centre distance below a per-class radius; pairs outside it are
  never scored (association) or never suppress each other (NMS).
* :func:`scale_nms_keep`: scale NMS, class by class, on footprints enlarged by a per-class factor, with a
  per-class similarity (A-GIoU BEV or rotated BEV IoU) and threshold.
* :class:`GeometryWindow`: the decoupled geometry, i.e. ``[z, w, l, h]`` of a track is the median (or mean) of
  its last ``W`` matched detections instead of a Kalman state.
* The tracklet score (decayed while unmatched, fused with the detection score when matched) and the
  average-score termination rule run in the tracker's compiled lifecycle pass
  (:func:`grutrack.tracking.lifecycle.lifecycle_kernel`, ``score_update: multiply``, ``termination: average_score``).

Box arrays follow :mod:`grutrack.boxes`: ``(N, 9) float64 [x, y, z, w, l, h, yaw, vx, vy]``, metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grutrack.geometry import bev_corners, paired_bev_iou

#: per-class NMS similarities scale_nms_keep accepts
NMS_METRICS = ("a_giou_bev", "iou_bev")


def aligned_extents(boxes: np.ndarray, scale: np.ndarray | float = 1.0,
                    quaternion: np.ndarray | None = None) -> np.ndarray:
    """Axis-aligned BEV extents of boxes whose size is scaled by ``scale`` about its centre.

    boxes (N, >=7); scale scalar or (N,) -> (N, 4) float64 ``[x_min, y_min, x_max, y_max]`` metres.
    Without ``quaternion`` the footprint is the yaw-rotated w x l rectangle. With ``quaternion`` (N, 4)
    ``[w, x, y, z]`` (a detection's own rotation, pitch and roll included) it is, as Fast-Poly's, the ground-plane
    projection of the box's bottom face: ``c + R(q) [+-l/2, +-w/2, -h/2]`` with w, l, h scaled.
    """
    b = np.array(boxes, dtype=np.float64, ndmin=2)[:, :7]
    k = np.broadcast_to(np.asarray(scale, dtype=np.float64), (len(b),))
    if quaternion is None:
        b[:, 3:5] *= k[:, None]
        c = bev_corners(b)                                         # (N, 4, 2)
    else:
        R = rotation_matrices(quaternion)                          # (N, 3, 3)
        local = np.stack([np.array([1, 1, -1, -1]) * (0.5 * k * b[:, 4])[:, None],
                          np.array([-1, 1, 1, -1]) * (0.5 * k * b[:, 3])[:, None],
                          np.broadcast_to((-0.5 * k * b[:, 5])[:, None], (len(b), 4))], axis=1)   # (N, 3, 4)
        c = (np.einsum("nij,njk->nik", R[:, :2], local) + b[:, :2, None]).transpose(0, 2, 1)
    return np.concatenate([c.min(axis=1), c.max(axis=1)], axis=1)


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of quaternions ``q (N, 4) [w, x, y, z]`` (normalised first)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], axis=1)


def _rect_area(e: np.ndarray) -> np.ndarray:
    """Areas (m^2) of extents ``e (..., 4)``."""
    return (e[..., 2] - e[..., 0]) * (e[..., 3] - e[..., 1])


def pairwise_a_giou(ext_a: np.ndarray, ext_b: np.ndarray, z_h_a: np.ndarray | None = None,
                    z_h_b: np.ndarray | None = None) -> np.ndarray:
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
    hull = ((np.maximum(a[..., 2], b[..., 2]) - np.minimum(a[..., 0], b[..., 0]))
            * (np.maximum(a[..., 3], b[..., 3]) - np.minimum(a[..., 1], b[..., 1])))
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


def scale_nms_keep(boxes: np.ndarray, scores: np.ndarray, labels: np.ndarray, metric: tuple[str, ...],
                   threshold: np.ndarray, scale: np.ndarray, radius: np.ndarray,
                   quaternion: np.ndarray | None = None) -> np.ndarray:
    """Fast-Poly's scale NMS; returns the kept indices (K,) int64, class by class (label 0 first), each class in
    descending score order.

    Within one class c, boxes are visited by descending score (numpy's default, non-stable argsort of
    ``-score``, as Fast-Poly); a visited box that is still present is kept and removes every later box of
    its class whose centre lies within ``radius[c]`` metres (3D) and whose similarity ``metric[c]`` with it,
    computed on both footprints enlarged by ``scale[c]`` (w and l times the factor), exceeds
    ``threshold[c]``. Metrics: ``a_giou_bev`` (alignment GIoU of the enlarged footprints' enclosing
    rectangles) or ``iou_bev`` (rotated BEV IoU of the enlarged footprints). Boxes of different classes never
    suppress each other.

    boxes (N, 9), scores (N,), labels (N,) int; metric: name per class (7,); threshold, scale, radius (7,);
    quaternion: optional (N, 4) own rotations of the boxes, for the A-GIoU footprints (:func:`aligned_extents`;
    the rotated IoU always uses the yaw-only footprint).
    """
    keep = []
    for c in range(len(metric)):
        idx = np.flatnonzero(labels == c)
        if len(idx) == 0:
            continue
        order = idx[np.argsort(-scores[idx])]
        b = boxes[order]
        q = None if quaternion is None else quaternion[order]
        over = _suppression_matrix(b, metric[c], threshold[c], scale[c], radius[c], q)
        removed = np.zeros(len(order), dtype=bool)
        for i in range(len(order)):
            if removed[i]:
                continue
            keep.append(order[i])
            removed[i + 1:] |= over[i, i + 1:]
    return np.asarray(keep, dtype=np.int64)


def _suppression_matrix(b: np.ndarray, metric: str, threshold: float, scale: float, radius: float,
                        quaternion: np.ndarray | None = None) -> np.ndarray:
    """(N, N) bool: box i would suppress box j (centres within ``radius``, similarity above ``threshold``)."""
    near = distance_mask(b, b, radius)
    if metric == "a_giou_bev":
        e = aligned_extents(b, scale, quaternion)
        return near & (pairwise_a_giou(e, e) > threshold)
    if metric == "iou_bev":
        i, j = np.nonzero(np.triu(near, k=1))
        big = b.copy()
        big[:, 3:6] *= scale
        over = np.zeros(near.shape, dtype=bool)
        hit = paired_bev_iou(big[i], big[j]) > threshold
        over[i[hit], j[hit]] = over[j[hit], i[hit]] = True
        return over
    raise ValueError(f"unknown NMS metric {metric!r} (expected one of {', '.join(NMS_METRICS)})")


@dataclass
class GeometryWindow:
    """Decoupled track geometry: the last ``W`` matched ``[z, w, l, h]`` of every track.

    hist (N, W, 4) float64 metres, oldest first, NaN where the window is not yet full; mean (N,) bool: the
    track's estimate is the mean of its window (else the median).
    """

    hist: np.ndarray
    mean: np.ndarray

    @classmethod
    def start(cls, zwlh: np.ndarray, window: np.ndarray, mean: np.ndarray) -> "GeometryWindow":
        """Windows holding one measurement each. zwlh (N, 4); window (N,) int >= 1; mean (N,) bool.

        The array width is the largest window; a track with a smaller window W_i keeps its last W_i entries
        (the entries before are NaN).
        """
        width = int(np.max(window)) if len(window) else 1
        hist = np.full((len(zwlh), width, 4), np.nan)
        hist[:, -1] = zwlh
        return cls(hist, np.asarray(mean, dtype=bool))

    def push(self, rows: np.ndarray, zwlh: np.ndarray, window: np.ndarray) -> None:
        """Append ``zwlh (K, 4)`` to the windows of tracks ``rows (K,)``; the oldest entry falls out once a
        window holds ``window[rows]`` (K,) entries."""
        h = self.hist[rows]
        h[:, :-1] = h[:, 1:]
        h[:, -1] = zwlh
        width = h.shape[1]
        stale = np.arange(width)[None, :] < (width - window)[:, None]   # (K, width) beyond the window
        h[stale] = np.nan
        self.hist[rows] = h

    def estimate(self) -> np.ndarray:
        """(N, 4) ``[z, w, l, h]``: per track the median (or mean) over its window, ignoring empty slots."""
        if len(self.hist) == 0:
            return np.zeros((0, 4))
        filled = ~np.isnan(self.hist[:, :, 0])
        n = filled.sum(axis=1)                                            # (N,) entries per window
        rows = np.arange(len(self.hist))
        s = np.sort(self.hist, axis=1)                                    # NaN sort last
        # median: the middle entry (odd n) or the mean of the two middle ones (even n), as numpy's median
        out = 0.5 * (s[rows, (n - 1) // 2] + s[rows, n // 2])
        if self.mean.any():
            total = np.where(filled[:, :, None], self.hist, 0.0).sum(axis=1)
            out[self.mean] = (total / n[:, None])[self.mean]
        return out

    def select(self, index: np.ndarray) -> "GeometryWindow":
        """The tracks picked by a boolean mask or index array."""
        return GeometryWindow(self.hist[index], self.mean[index])

    @staticmethod
    def concat(a: "GeometryWindow", b: "GeometryWindow") -> "GeometryWindow":
        """Tracks of ``a`` followed by those of ``b`` (windows padded to the wider one)."""
        w = max(a.hist.shape[1], b.hist.shape[1])
        pad = [np.concatenate([np.full((len(g.hist), w - g.hist.shape[1], 4), np.nan), g.hist], axis=1)
               for g in (a, b)]
        return GeometryWindow(np.concatenate(pad), np.concatenate([a.mean, b.mean]))


@dataclass
class GeometryState:
    """State of a :class:`GeometryFilterBackend`: the wrapped backend's state and the geometry windows."""

    motion: object
    geometry: GeometryWindow
    labels: np.ndarray


class GeometryFilterBackend:
    """A motion backend whose boxes take ``[z, w, l, h]`` from a window filter (Fast-Poly's decoupled geometry).

    The wrapped backend still filters every state (in grutrack's models z, w, l, h form an independent block,
    so the other states are unaffected); :meth:`boxes` replaces columns z, w, l, h by the median (or mean) of
    the track's last ``window[label]`` matched detections. ``window`` (C,) int >= 1 and ``mean`` (C,) bool per
    class label; a class with ``window`` 0 is passed through unchanged (geometry from the motion filter).
    """

    def __init__(self, inner, window: np.ndarray, mean: np.ndarray):
        self.inner = inner
        self.window = np.asarray(window, dtype=np.int64)
        self.mean = np.asarray(mean, dtype=bool)

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> GeometryState:
        """New tracks from detections z (N, 9)."""
        win = np.maximum(self.window[labels], 1)
        return GeometryState(self.inner.initiate(z, labels),
                             GeometryWindow.start(z[:, 2:6], win, self.mean[labels]), labels.copy())

    def predict(self, s: GeometryState, dt: float) -> GeometryState:
        """Motion predicted ``dt`` seconds ahead; the geometry is constant."""
        return GeometryState(self.inner.predict(s.motion, dt), s.geometry, s.labels)

    def update(self, s: GeometryState, rows: np.ndarray, z: np.ndarray) -> GeometryState:
        """Tracks ``rows (K,)`` corrected by z (K, 9); their windows take ``z[:, 2:6]``."""
        g = GeometryWindow(s.geometry.hist.copy(), s.geometry.mean)
        g.push(rows, z[:, 2:6], np.maximum(self.window[s.labels[rows]], 1))
        return GeometryState(self.inner.update(s.motion, rows, z), g, s.labels)

    def boxes(self, s: GeometryState) -> np.ndarray:
        """(N, 9) boxes: the motion filter's, with z, w, l, h from the windows where the class uses them."""
        out = self.inner.boxes(s.motion)
        use = self.window[s.labels] > 0
        out[use, 2:6] = s.geometry.estimate()[use]
        return out

    def select(self, s: GeometryState, index: np.ndarray) -> GeometryState:
        return GeometryState(self.inner.select(s.motion, index), s.geometry.select(index), s.labels[index])

    def concat(self, a: GeometryState, b: GeometryState) -> GeometryState:
        return GeometryState(self.inner.concat(a.motion, b.motion), GeometryWindow.concat(a.geometry, b.geometry),
                             np.concatenate([a.labels, b.labels]))


#: similarities :func:`gated_costs` can compute densely
DENSE_METRICS = ("a_giou_3d", "a_giou_bev", "giou_3d", "giou_bev", "iou_3d", "iou_bev")


def _similarity(name: str, a: np.ndarray, b: np.ndarray, qa: np.ndarray | None = None) -> np.ndarray:
    """(Na, Nb) similarity ``name`` between boxes a (Na, 9) and b (Nb, 9); ``qa`` (Na, 4) a's own quaternions
    (A-GIoU footprints only)."""
    from grutrack import geometry

    if name == "a_giou_3d":
        return a_giou_3d(a, b, qa)
    if name == "a_giou_bev":
        return a_giou_bev(a, b, qa)
    fn = {"giou_3d": geometry.pairwise_giou_3d, "giou_bev": geometry.pairwise_bev_giou,
          "iou_3d": geometry.pairwise_iou_3d, "iou_bev": geometry.pairwise_bev_iou}[name]
    return fn(a, b)


def gated_costs(det_boxes: np.ndarray, det_labels: np.ndarray, trk_boxes: np.ndarray, trk_labels: np.ndarray,
                first_metric: tuple[str, ...], second_metric: str, gate: np.ndarray,
                invalid: float = np.inf, det_quaternion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Stage-1 and stage-2 cost matrices (D, T) with Fast-Poly's distance gate; cost = 1 - similarity.

    Stage 1: a pair is scored when its classes agree and its 3D centre distance is below ``gate[class]``
    metres (``gate`` (C,), 0 = no gate for that class); other pairs cost ``invalid``.
    Stage 2: as Fast-Poly, the gate only selects rows and columns: every same-class pair between a detection
    and a track that each have a same-class partner closer than the largest gate radius is scored with
    ``second_metric``, even when that pair itself lies outside the gate (Fast-Poly's rows and columns come
    from the union of its per-class distance masks). ``det_quaternion`` (D, 4): the detections' own rotations, for their A-GIoU
    footprints (tracks are yaw-only boxes).
    """
    D, T = len(det_boxes), len(trk_boxes)
    c1, c2 = np.full((D, T), invalid), np.full((D, T), invalid)
    same = det_labels[:, None] == trk_labels[None, :]
    radii = np.where(gate > 0, gate, np.inf)
    dist = np.linalg.norm(det_boxes[:, None, :3] - trk_boxes[None, :, :3], axis=2)
    valid = same & (dist < radii[det_labels][:, None])                 # stage-1 pairs
    near = same & (dist < radii.max())                                 # Fast-Poly's union of the class masks
    rows, cols = np.flatnonzero(near.any(axis=1)), np.flatnonzero(near.any(axis=0))
    if len(rows) == 0:
        return c1, c2
    a, b = det_boxes[rows], trk_boxes[cols]
    sub = np.ix_(rows, cols)
    names = {first_metric[c] for c in np.unique(det_labels[rows])} | {second_metric}
    qa = None if det_quaternion is None else det_quaternion[rows]
    sims = {n: _similarity(n, a, b, qa) for n in sorted(names)}
    first = np.full((len(rows), len(cols)), -np.inf)
    for c in np.unique(det_labels[rows]):
        r = det_labels[rows] == c
        first[r] = sims[first_metric[c]][r]
    c1[sub] = np.where(valid[sub], 1.0 - first, invalid)
    c2[sub] = np.where(same[sub], 1.0 - sims[second_metric], invalid)
    return c1, c2
