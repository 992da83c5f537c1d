"""MCTrack's association similarity, Ro_GDIoU (Wang et al., "MCTrack: A Unified 3D Multi-Object Tracking Framework
for Autonomous Driving", 2024; preset ``mctrack``), and the choice of the pose a track is compared at.

For a track box A and a detection box B (bird's-eye view):

    Ro_GDIoU = IoU(A, B) - w1 * (C - U) / C - w2 * d^2 / c^2

with U the union area of the two rotated footprints, C the area and c the diagonal of the smallest rotated
rectangle enclosing both footprints (not the axis-aligned hull of GIoU / DIoU), d the distance between the box
centres, and w1, w2 per-class weights (the track's class). The cost is ``1 - Ro_GDIoU``, in [0, 1 + w1 + w2).

Geometry precision (preset key ``association.geometry_precision``): ``float64`` computes the overlap and the
enclosing rectangle in double precision (the textbook choice); ``float32`` computes them as MCTrack's OpenCV calls
do, on single-precision corners (``cv2.rotatedRectangleIntersection`` and ``cv2.minAreaRect`` on float32 points
relative to the track's centre), which moves the similarity by ~1e-7 and can flip a pair lying that close to its
class's threshold. The centre distance and the box areas stay in double precision in both.

Track pose (``association.track_pose`` per class, :data:`POSES`): ``predicted`` compares the track's predicted
box with the detection; ``last_update`` compares the track's box before this frame's prediction (its last
posterior) with the detection moved back by its own velocity over one time step (MCTrack's "BackPredict");
``blend`` averages the two similarities, ``r * predicted + (1 - r) * last_update`` with the class's ratio r
(``association.track_pose_blend``). Which class's pose applies (``association.track_pose_rule``):
``own_class`` (each pair by its track's class, the textbook choice) or ``oldest_track`` (one pose for every pair
of a frame, the class of the live track with the smallest id: MCTrack reads it from the first track of its
id-sorted list).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grutrack.tracking.association import Matches, _solve_stages

#: track poses by preset name -> code
POSES = {"predicted": 0, "last_update": 1, "blend": 2}


@njit(cache=True, inline="always")
def _f(v: float, f32: bool) -> float:
    """``v`` rounded to single precision when ``f32``."""
    return float(np.float32(v)) if f32 else v


@njit(cache=True)
def _corners(cx, cy, length, width, yaw, f32, out, ccw=True) -> None:
    """Footprint corners (4, 2), counter-clockwise, of a ``length`` (along ``yaw``) x ``width`` rectangle.

    ``f32``: as OpenCV's ``RotatedRect::points`` (centre, size and angle in degrees held as float32, the
    half-extent factors ``cos`` and ``sin`` of the double angle rounded to float32, products in float32)."""
    if f32:
        ang = np.float32(yaw * 180.0 / np.pi)
        rad = float(ang) * np.pi / 180.0
        b = np.float32(np.float32(math.cos(rad)) * np.float32(0.5))
        a = np.float32(np.float32(math.sin(rad)) * np.float32(0.5))
        x, y = np.float32(cx), np.float32(cy)
        w, h = np.float32(length), np.float32(width)
        # OpenCV order: p0 = c - a h - b w (x), c + b h - a w (y); p1 = c + a h - b w, c - b h - a w; p2 = 2c - p0;
        # p3 = 2c - p1
        p0x = np.float32(np.float32(x - np.float32(a * h)) - np.float32(b * w))
        p0y = np.float32(np.float32(y + np.float32(b * h)) - np.float32(a * w))
        p1x = np.float32(np.float32(x + np.float32(a * h)) - np.float32(b * w))
        p1y = np.float32(np.float32(y - np.float32(b * h)) - np.float32(a * w))
        p2x = np.float32(np.float32(np.float32(2.0) * x) - p0x)
        p2y = np.float32(np.float32(np.float32(2.0) * y) - p0y)
        p3x = np.float32(np.float32(np.float32(2.0) * x) - p1x)
        p3y = np.float32(np.float32(np.float32(2.0) * y) - p1y)
        out[0, 0], out[0, 1] = float(p0x), float(p0y)
        out[1, 0], out[1, 1] = float(p1x), float(p1y)
        out[2, 0], out[2, 1] = float(p2x), float(p2y)
        out[3, 0], out[3, 1] = float(p3x), float(p3y)
    else:
        c, s = math.cos(yaw), math.sin(yaw)
        hl, hw = 0.5 * length, 0.5 * width
        for k, (u, v) in enumerate(((-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw))):
            out[k, 0] = cx + c * u - s * v
            out[k, 1] = cy + s * u + c * v
    if not ccw:
        return
    # counter-clockwise order (OpenCV's points run clockwise for a positive size)
    area2 = 0.0
    for k in range(4):
        j = (k + 1) % 4
        area2 += out[k, 0] * out[j, 1] - out[j, 0] * out[k, 1]
    if area2 < 0.0:
        for d in range(2):
            out[1, d], out[3, d] = out[3, d], out[1, d]


@njit(cache=True)
def _clip(poly, n, ax, ay, bx, by, out) -> int:
    """Sutherland-Hodgman: the part of the convex polygon ``poly[:n]`` left of the directed edge a -> b."""
    m = 0
    for k in range(n):
        px, py = poly[k, 0], poly[k, 1]
        qx, qy = poly[(k + 1) % n, 0], poly[(k + 1) % n, 1]
        sp = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        sq = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
        if sp >= 0.0:
            out[m, 0], out[m, 1] = px, py
            m += 1
        if (sp >= 0.0) != (sq >= 0.0):
            t = sp / (sp - sq)
            out[m, 0], out[m, 1] = px + t * (qx - px), py + t * (qy - py)
            m += 1
    return m


@njit(cache=True)
def _polygon_area(poly, n) -> float:
    area2 = 0.0
    for k in range(n):
        j = (k + 1) % n
        area2 += poly[k, 0] * poly[j, 1] - poly[j, 0] * poly[k, 1]
    return 0.5 * abs(area2)


@njit(cache=True)
def _intersection_area(ca, cb, work_a, work_b) -> float:
    """Area of the intersection of two convex quadrilaterals (4, 2) (counter-clockwise)."""
    n = 4
    for k in range(4):
        work_a[k, 0], work_a[k, 1] = ca[k, 0], ca[k, 1]
    for e in range(4):
        ax, ay = cb[e, 0], cb[e, 1]
        bx, by = cb[(e + 1) % 4, 0], cb[(e + 1) % 4, 1]
        n = _clip(work_a, n, ax, ay, bx, by, work_b)
        for k in range(n):
            work_a[k, 0], work_a[k, 1] = work_b[k, 0], work_b[k, 1]
        if n < 3:
            return 0.0
    return _polygon_area(work_a, n)


@njit(cache=True)
def _on_positive_side(vx, vy, lx, ly, px, py) -> bool:
    """float32 side test of point p against the line through l along v (OpenCV's form)."""
    return np.float32(vy * np.float32(lx - px)) >= np.float32(vx * np.float32(ly - py))


@njit(cache=True)
def _f32_intersection_area(cx2, cy2, l1, w1, yaw1, l2, w2, yaw2, work) -> float:
    """Area of the overlap of two rotated rectangles as OpenCV 4's ``rotatedRectangleIntersection`` finds its
    vertices in float32 (the first centred at the origin, the second at (cx2, cy2)): both moved by their mean
    centre, edge-edge crossings and contained corners collected, points closer than its tolerance merged; the
    area is that of the vertices' convex hull in double precision (``contourArea`` of ``convexHull``)."""
    f = np.float32
    if f(l1) <= 0 or f(w1) <= 0 or f(l2) <= 0 or f(w2) <= 0:
        return 0.0
    mx = f(f(f(0.0) + f(cx2)) / f(2.0))
    my = f(f(f(0.0) + f(cy2)) / f(2.0))
    p1, p2 = work[0:4], work[4:8]
    _corners(float(f(f(0.0) - mx)), float(f(f(0.0) - my)), l1, w1, yaw1, True, p1, False)
    _corners(float(f(f(cx2) - mx)), float(f(f(cy2) - my)), l2, w2, yaw2, True, p2, False)
    eps = f(f(1e-6) * max(f(f(l1) * f(w1)), f(f(l2) * f(w2))))
    same = True
    for i in range(4):
        if abs(f(p1[i, 0]) - f(p2[i, 0])) > eps or abs(f(p1[i, 1]) - f(p2[i, 1])) > eps:
            same = False
            break
    pts = work[8:40]
    n = 0
    if same:
        for i in range(4):
            pts[n, 0], pts[n, 1] = p1[i, 0], p1[i, 1]
            n += 1
    else:
        v1, v2 = np.empty((4, 2), dtype=np.float32), np.empty((4, 2), dtype=np.float32)
        for i in range(4):
            for d in range(2):
                v1[i, d] = f(f(p1[(i + 1) % 4, d]) - f(p1[i, d]))
                v2[i, d] = f(f(p2[(i + 1) % 4, d]) - f(p2[i, d]))
        for i in range(4):
            eps = min(eps, f(math.sqrt(f(f(v1[i, 0] * v1[i, 0]) + f(v1[i, 1] * v1[i, 1])))))
            eps = min(eps, f(math.sqrt(f(f(v2[i, 0] * v2[i, 0]) + f(v2[i, 1] * v2[i, 1])))))
        eps = max(f(1e-16), eps)
        for i in range(4):
            for j in range(4):
                x21 = f(f(p2[j, 0]) - f(p1[i, 0]))
                y21 = f(f(p2[j, 1]) - f(p1[i, 1]))
                vx1, vy1, vx2, vy2 = v1[i, 0], v1[i, 1], v2[j, 0], v2[j, 1]
                det = f(f(vx2 * vy1) - f(vx1 * vy2))
                if abs(float(det)) < 1e-12:
                    continue
                inv = f(f(1.0) / det)
                t1 = f(f(f(vx2 * y21) - f(vy2 * x21)) * inv)
                t2 = f(f(f(vx1 * y21) - f(vy1 * x21)) * inv)
                if not (np.isfinite(t1) and np.isfinite(t2)):
                    continue
                if t1 >= 0 and t1 <= 1 and t2 >= 0 and t2 <= 1:
                    pts[n, 0] = f(f(p1[i, 0]) + f(vx1 * t1))
                    pts[n, 1] = f(f(p1[i, 1]) + f(vy1 * t1))
                    n += 1
        for a_, b_, vb in ((p1, p2, v2), (p2, p1, v1)):
            for i in range(4):
                pos = 0
                for j in range(4):
                    if _on_positive_side(vb[j, 0], vb[j, 1], f(b_[j, 0]), f(b_[j, 1]), f(a_[i, 0]), f(a_[i, 1])):
                        pos += 1
                if pos == 4 or pos == 0:
                    pts[n, 0], pts[n, 1] = a_[i, 0], a_[i, 1]
                    n += 1
        if n == 0:
            return 0.0
        i = 0
        while i < n:  # merge points closer than the tolerance (squared distance against eps, as OpenCV)
            j = i + 1
            while j < n:
                dx, dy = f(f(pts[j, 0]) - f(pts[i, 0])), f(f(pts[j, 1]) - f(pts[i, 1]))
                if f(f(dx * dx) + f(dy * dy)) <= eps:
                    if j < n - 1:
                        pts[j, 0], pts[j, 1] = pts[n - 1, 0], pts[n - 1, 1]
                    n -= 1
                    continue
                j += 1
            i += 1
    for i in range(n):
        pts[i, 0] = float(f(f(pts[i, 0]) + mx))
        pts[i, 1] = float(f(f(pts[i, 1]) + my))
    if n < 3:
        return 0.0
    hull = np.empty((2 * n + 1, 2))
    m = _hull(pts, n, hull)
    area2 = 0.0
    px, py = hull[m - 1, 0], hull[m - 1, 1]
    for k in range(m):
        area2 += px * hull[k, 1] - py * hull[k, 0]
        px, py = hull[k, 0], hull[k, 1]
    return 0.5 * abs(area2)


@njit(cache=True, inline="always")
def _turn(hull, m, srt, k) -> float:
    """Cross product (hull[m-1] - hull[m-2]) x (srt[k] - hull[m-2]): > 0 when srt[k] turns left of the hull's last
    edge (m^2)."""
    return (hull[m - 1, 0] - hull[m - 2, 0]) * (srt[k, 1] - hull[m - 2, 1]) - (hull[m - 1, 1] - hull[m - 2, 1]) * (
        srt[k, 0] - hull[m - 2, 0]
    )


@njit(cache=True)
def _hull(pts, n, hull) -> int:
    """Convex hull (monotone chain, counter-clockwise, collinear points dropped) of ``pts[:n]`` -> its size."""
    srt = np.empty((n, 2))
    for k in range(n):
        srt[k] = pts[k]
    for i in range(1, n):  # lexicographic (x, then y) insertion sort
        j = i
        while j > 0 and (srt[j - 1, 0] > srt[j, 0] or (srt[j - 1, 0] == srt[j, 0] and srt[j - 1, 1] > srt[j, 1])):
            tx, ty = srt[j - 1, 0], srt[j - 1, 1]
            srt[j - 1, 0], srt[j - 1, 1] = srt[j, 0], srt[j, 1]
            srt[j, 0], srt[j, 1] = tx, ty
            j -= 1
    m = 0
    for k in range(n):
        while m >= 2 and _turn(hull, m, srt, k) <= 0.0:
            m -= 1
        hull[m] = srt[k]
        m += 1
    low = m + 1
    for k in range(n - 2, -1, -1):
        while m >= low and _turn(hull, m, srt, k) <= 0.0:
            m -= 1
        hull[m] = srt[k]
        m += 1
    return max(m - 1, 1)  # the last point repeats the first


@njit(cache=True)
def _min_area_rect(pts, n, hull, f32) -> tuple[float, float]:
    """Sides (a, b) of the minimum-area rectangle enclosing the points ``pts[:n]`` (rotating calipers over the
    edges of their convex hull); ``f32``: the projections in float32, as OpenCV's ``minAreaRect``."""
    m = _hull(pts, n, hull)
    best, ba, bb = np.inf, 0.0, 0.0
    for e in range(m):
        dx, dy = hull[(e + 1) % m, 0] - hull[e, 0], hull[(e + 1) % m, 1] - hull[e, 1]
        norm = math.sqrt(dx * dx + dy * dy)
        if norm == 0.0:
            continue
        ux, uy = dx / norm, dy / norm
        lo_u, hi_u, lo_v, hi_v = np.inf, -np.inf, np.inf, -np.inf
        for k in range(m):
            px, py = hull[k, 0] - hull[e, 0], hull[k, 1] - hull[e, 1]
            pu = _f(px * ux + py * uy, f32)
            pv = _f(-px * uy + py * ux, f32)
            lo_u, hi_u = min(lo_u, pu), max(hi_u, pu)
            lo_v, hi_v = min(lo_v, pv), max(hi_v, pv)
        a, b = _f(hi_u - lo_u, f32), _f(hi_v - lo_v, f32)
        area = a * b
        if area < best:
            best, ba, bb = area, a, b
    return ba, bb


@njit(cache=True)
def footprints_apart(pa, pb) -> bool:
    """Whether the BEV footprints of boxes ``pa`` and ``pb`` (x, y, z, w, l, ...) cannot overlap: their
    circumscribed circles lie apart by more than a rounding margin (0.1 % of the radii and 1e-6 m^2)."""
    reach = 0.5 * (math.sqrt(pa[3] * pa[3] + pa[4] * pa[4]) + math.sqrt(pb[3] * pb[3] + pb[4] * pb[4]))
    return (pb[0] - pa[0]) ** 2 + (pb[1] - pa[1]) ** 2 > (1.001 * reach) ** 2 + 1e-6


#: rows of :func:`ro_gdiou_pair`'s scratch ``work (WORK_ROWS, 2)``: the footprints' intersection (40), the eight
#: corners (8) and their hull (17)
WORK_ROWS = 65


@njit(cache=True)
def ro_gdiou_pair(pa, pb, w1, w2, f32, work) -> float:
    """Ro_GDIoU of the track pose ``pa`` and the detection pose ``pb`` (canonical boxes, >= 7 values: x, y, z, w,
    l, h, yaw); ``work``: scratch (WORK_ROWS, 2)."""
    # both footprints relative to the track's centre; footprints apart intersect in 0, without clipping
    if footprints_apart(pa, pb):
        inter = 0.0
    elif f32:
        inter = _f32_intersection_area(pb[0] - pa[0], pb[1] - pa[1], pa[4], pa[3], pa[6], pb[4], pb[3], pb[6], work)
    else:
        ca, cb = work[0:4], work[4:8]
        _corners(0.0, 0.0, pa[4], pa[3], pa[6], False, ca)
        _corners(pb[0] - pa[0], pb[1] - pa[1], pb[4], pb[3], pb[6], False, cb)
        inter = _intersection_area(ca, cb, work[8:24], work[24:40])
    area_a, area_b = pa[4] * pa[3], pb[4] * pb[3]
    iou = inter / (area_a + area_b - inter)
    pts = work[40:48]
    ha, hb = math.cos(pa[6]), math.sin(pa[6])
    ga, gb = math.cos(pb[6]), math.sin(pb[6])
    k = 0
    for sx, sy in ((1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0)):
        # as MCTrack: corners rotated about the box centre, moved to it, then taken relative to the track's centre
        u, v = sx * 0.5 * pa[4], sy * 0.5 * pa[3]
        pts[k, 0] = _f((ha * u - hb * v + pa[0]) - pa[0], f32)
        pts[k, 1] = _f((hb * u + ha * v + pa[1]) - pa[1], f32)
        u, v = sx * 0.5 * pb[4], sy * 0.5 * pb[3]
        pts[k + 4, 0] = _f((ga * u - gb * v + pb[0]) - pa[0], f32)
        pts[k + 4, 1] = _f((gb * u + ga * v + pb[1]) - pa[1], f32)
        k += 1
    ra, rb = _min_area_rect(pts, 8, work[48:65], f32)
    universe = ra * rb
    extra = universe - (area_a + area_b - inter)
    dist2 = (pa[0] - pb[0]) ** 2 + (pa[1] - pb[1]) ** 2
    diag = math.sqrt(ra * ra + rb * rb)
    return iou - w1 * extra / universe - w2 * dist2 / (diag * diag)


@njit(cache=True)
def _ro_cost_kernel(det_p, det_b, det_labels, trk_p, trk_b, trk_labels, modes, ratio, w1, w2, f32, costs) -> None:
    """``costs (D, T)`` (pre-set to invalid) = 1 - Ro_GDIoU of every same-class pair; ``modes (T,)``,
    ``ratio (T,)``: each track's pose code and blend ratio; ``w1, w2 (n_labels,)`` by the track's class;
    ``det_p / det_b``, ``trk_p / trk_b``: the detections' and tracks' boxes for the predicted and the
    last-update comparisons."""
    work = np.empty((WORK_ROWS, 2))
    for j in range(trk_labels.shape[0]):
        lab = trk_labels[j]
        for i in range(det_labels.shape[0]):
            if det_labels[i] != lab:
                continue
            mode = modes[j]
            if mode == 0:
                sim = ro_gdiou_pair(trk_p[j], det_p[i], w1[lab], w2[lab], f32, work)
            elif mode == 1:
                sim = ro_gdiou_pair(trk_b[j], det_b[i], w1[lab], w2[lab], f32, work)
            else:
                p = ro_gdiou_pair(trk_p[j], det_p[i], w1[lab], w2[lab], f32, work)
                b = ro_gdiou_pair(trk_b[j], det_b[i], w1[lab], w2[lab], f32, work)
                sim = ratio[j] * p + (1.0 - ratio[j]) * b
            costs[i, j] = 1.0 - sim


@njit(cache=True)
def _ro_pair_kernel(det, trk, labels, rows, cols, w1, w2, f32, costs) -> None:
    """``costs[rows[k], cols[k]] = 1 - Ro_GDIoU`` of detection ``rows[k]`` against track ``cols[k]`` (boxes at
    the track's predicted pose, ``labels[rows[k]]`` the pair's class for the weights ``w1, w2 (n_labels,)``)."""
    work = np.empty((WORK_ROWS, 2))
    for k in range(rows.shape[0]):
        i, j = rows[k], cols[k]
        lab = labels[i]
        costs[i, j] = 1.0 - ro_gdiou_pair(trk[j], det[i], w1[lab], w2[lab], f32, work)


def ro_gdiou_costs(
    det_boxes: np.ndarray,
    det_labels: np.ndarray,
    trk_boxes: np.ndarray,
    trk_last: np.ndarray,
    trk_labels: np.ndarray,
    trk_ids: np.ndarray,
    cfg,
    back_step: float,
    invalid: float = 1e6,
) -> np.ndarray:
    """(D, T) cost ``1 - Ro_GDIoU`` of every same-class pair (others ``invalid``), each pair at the pose the preset
    asks for (module docstring). ``trk_boxes``: predicted track boxes; ``trk_last``: the tracks' boxes before
    this frame's prediction; ``back_step``: seconds the detections are moved back for ``last_update``."""
    D, T = len(det_boxes), len(trk_boxes)
    costs = np.full((D, T), invalid)
    if D == 0 or T == 0:
        return costs
    pose = np.array([POSES[p] for p in cfg.track_pose], dtype=np.int64)
    ratio = np.asarray(cfg.track_pose_blend, dtype=np.float64)
    if cfg.track_pose_rule == "oldest_track":
        oldest = trk_labels[int(np.argmin(trk_ids))]
        modes, ratios = np.full(T, pose[oldest]), np.full(T, ratio[oldest])
    else:
        modes, ratios = pose[trk_labels], ratio[trk_labels]
    det_b = np.array(det_boxes, dtype=np.float64)
    det_b[:, 0:2] -= det_boxes[:, 7:9] * back_step
    _ro_cost_kernel(
        np.ascontiguousarray(det_boxes, dtype=np.float64),
        det_b,
        det_labels.astype(np.int64),
        np.ascontiguousarray(trk_boxes, dtype=np.float64),
        np.ascontiguousarray(trk_last, dtype=np.float64),
        trk_labels.astype(np.int64),
        modes.astype(np.int64),
        ratios.astype(np.float64),
        np.ascontiguousarray(cfg.ro_gdiou_weights[:, 0], dtype=np.float64),
        np.ascontiguousarray(cfg.ro_gdiou_weights[:, 1], dtype=np.float64),
        cfg.geometry_precision == "float32",
        costs,
    )
    return costs


def ro_gdiou_association(cfg):
    """One-stage association on Ro_GDIoU costs (:func:`ro_gdiou_costs`) with the preset's per-class thresholds
    and assignment rule. The tracker passes the tracks' ids and last-update boxes (``wants_tracks``)."""
    from grutrack.tracking.association import ASSIGNMENT

    solve = ASSIGNMENT[cfg.assignment]

    def run(dets, trk_boxes: np.ndarray, trk_labels: np.ndarray, dt: float, tracks=None) -> Matches:
        back = cfg.time_step if cfg.time_step is not None else dt
        costs = ro_gdiou_costs(dets.boxes, dets.labels, trk_boxes, tracks.last_boxes, trk_labels, tracks.ids, cfg, back)
        return _solve_stages(solve, [costs], dets.labels, cfg.first_threshold, cfg.second_threshold)

    run.wants_tracks = True
    return run


def ro_gdiou_first_stage(cfg):
    """Stage 1 of the two-stage association (:func:`grutrack.tracking.tracker.two_stage_association`) scored by
    Ro_GDIoU for the classes whose ``first_metric`` is ``ro_gdiou_bev`` (their weights, the track's predicted box
    against the detection); a preset with Ro_GDIoU for every class runs :func:`ro_gdiou_association` (MCTrack's
    one stage) instead. -> (``first_metric`` with ``giou_bev`` standing in for those classes, a function
    ``(dets, trk_boxes (T, 9), trk_labels (T,)) -> (classes (C,) bool, costs (D, T))`` giving
    :func:`~grutrack.tracking.association.associate` its ``first_override``)."""
    classes = np.array([m == "ro_gdiou_bev" for m in cfg.first_metric])
    placeholder = tuple("giou_bev" if ro else m for ro, m in zip(classes, cfg.first_metric))
    costs = predicted_pose_costs(classes, cfg)
    return placeholder, lambda dets, trk_boxes, trk_labels: (
        classes,
        costs(dets.boxes, dets.labels, trk_boxes, trk_labels),
    )


def predicted_pose_costs(classes: np.ndarray, cfg):
    """A function ``(det_boxes (D, 9), det_labels (D,), trk_boxes (T, 9), trk_labels (T,)) -> (D, T)``: 1 - Ro_GDIoU
    of each detection of the ``classes`` ((C,) bool) against each track of its class at the track's predicted box
    (the preset's ``ro_gdiou_weights`` and ``geometry_precision``); 1e6 for the other pairs. Stage 1 of some
    classes (:func:`ro_gdiou_first_stage`) and the crowded pairs of ``association.crowded_threshold``, for which
    an optional fifth argument ``need (D, T) bool`` restricts the scored pairs to those (the others 1e6)."""
    w1 = np.ascontiguousarray(cfg.ro_gdiou_weights[:, 0], dtype=np.float64)
    w2 = np.ascontiguousarray(cfg.ro_gdiou_weights[:, 1], dtype=np.float64)

    def costs(
        det_boxes: np.ndarray,
        det_labels: np.ndarray,
        trk_boxes: np.ndarray,
        trk_labels: np.ndarray,
        need: np.ndarray | None = None,
    ):
        D, T = len(det_boxes), len(trk_boxes)
        out = np.full((D, T), 1e6)
        if D and T:
            boxes = np.ascontiguousarray(det_boxes, dtype=np.float64)
            trk = np.ascontiguousarray(trk_boxes, dtype=np.float64)
            if need is not None:  # only these pairs (D, T) bool, of the classes' same-class pairs
                rows, cols = np.nonzero(need & classes[det_labels][:, None] & (det_labels[:, None] == trk_labels))
                f32 = cfg.geometry_precision == "float32"
                _ro_pair_kernel(boxes, trk, det_labels.astype(np.int64), rows, cols, w1, w2, f32, out)
                return out
            _ro_cost_kernel(
                boxes,
                boxes,
                np.where(classes[det_labels], det_labels, -1).astype(np.int64),  # only these classes' rows
                trk,
                trk,
                trk_labels.astype(np.int64),
                np.zeros(T, dtype=np.int64),  # pose code 0: predicted
                np.ones(T),
                w1,
                w2,
                cfg.geometry_precision == "float32",
                out,
            )
        return out

    return costs
