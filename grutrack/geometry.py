"""Rotated-box overlap measures (IoU / GIoU in bird's-eye view and 3D) between box sets, vectorised.

Boxes follow :mod:`grutrack.boxes`: rows ``[x, y, z, w, l, h, yaw, ...]`` (``(N, >=7)`` float, metres
and radians; ``w`` across the heading, ``l`` along it, ``z`` the box centre so the box spans
``z - h/2 .. z + h/2``). Extra columns (velocities) are ignored.

Four measures, ``bev_iou``, ``bev_giou``, ``iou_3d`` and ``giou_3d``, each in two forms:

* ``paired_*(a, b)`` with ``a`` and ``b`` both ``(K, >=7)``: the measure of each aligned pair
  ``(a[k], b[k])``, a ``(K,) float64`` array. Use it for a selected list of pairs.
* ``pairwise_*(a, b)`` with ``a`` ``(N, >=7)`` and ``b`` ``(M, >=7)``: all pairs, an ``(N, M) float64``
  array (``[i, j]`` = measure of ``(a[i], b[j])``, equal to the paired form on that pair).

Also :func:`bev_corners` ``(N, 4, 2)`` and :func:`pairwise_centre_distance` ``(N, M)`` in metres, and the same
measures of footprints given as convex quadrilaterals (:func:`footprint_similarities`), e.g. a tilted box's bottom
face on the ground (:func:`bottom_corners`, the nuScenes devkit's and Poly-MOT's footprint).

Definitions (those of Poly-MOT's GIoU): with ``I`` the BEV intersection area, ``U`` the BEV union area
and ``C`` the area of the convex hull of the 8 BEV corners of both boxes,

* BEV IoU = ``I / U``; BEV GIoU = ``IoU - (C - U) / C``;
* 3D IoU = ``I * dz / (V_a + V_b - I * dz)`` with ``dz = max(0, min(top) - max(bottom))``;
* 3D GIoU = ``IoU3d - (V_C - V_U) / V_C`` with ``V_C = C * (max(top) - min(bottom))`` and ``V_U`` the
  union volume.

IoU lies in [0, 1] and GIoU in [-1, 1].

Degenerate boxes (zero width, length or height: zero area or volume) never give NaN. They are
measured by the same formulas, with two conventions for vanishing denominators:

* IoU is 0 when the union (area or volume) is 0, e.g. two identical zero-size boxes;
* GIoU equals IoU (so 0) when the hull ``C`` (or ``V_C``) is 0, e.g. collinear segments (a hull area
  below :data:`HULL_EPS` times the squared extent counts as 0); otherwise the formula applies, so two
  zero-area boxes with a hull of positive area have GIoU -1 (union 0, penalty term 1).

A zero-area box has zero intersection with anything, so its IoU with any box is 0. Negative sizes and
non-finite values in columns 0-6 are rejected with ``ValueError``.

Method: the intersection of two rectangles is a convex polygon whose vertices are among 16
candidates (corners of either box inside the other, and where each edge of ``a`` enters and leaves
``b``); its area is the shoelace area of the valid candidates sorted by angle about their mean. The
convex hull's vertices are picked among the 8 corners with a support-function test (a corner of ``a``
is on the hull iff ``a`` reaches at least as far as ``b`` in some direction of that corner's normal
cone), then summed the same way. All work is done in the frame of box ``b`` (centre at the origin),
so large global coordinates cost no precision. Inside / on-edge tests have a slack of
:data:`TOL` metres; repeated or collinear boundary points add no area, so identical, nested and
touching boxes are exact to rounding. The per-pair polygon work (candidate points, angular sort,
shoelace sums) runs in numba-compiled kernels, one pair at a time with no temporaries; they are compiled
once and cached on disk beside this module.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from grutrack.boxes import rotation_matrices

TOL = 1e-10
"""Slack in metres of the inside / on-the-edge tests (points this close to a boundary count as on it).

It is far above the rounding of coordinates in the pair frame (~1e-13 m) and bounds the error it can
add to an area by ``TOL`` times the perimeter (under 1e-9 in the IoU of 0.3 m boxes)."""

HULL_EPS = 1e-12
"""Hull areas below ``HULL_EPS * D**2`` (``D`` bounding the pair's extent) are rounding noise of a
collinear point set and count as 0 (so, e.g., two collinear segments have GIoU 0, not -1)."""

CHUNK_PAIRS = 1 << 16
"""Pairs handled at once by the ``pairwise_*`` functions (bounds temporary memory)."""

# Corner order in the box frame (+x along l, +y along w): front-left, rear-left, rear-right,
# front-right, i.e. counter-clockwise. Edge k runs from corner k to corner k+1.
_SU = np.array([1.0, -1.0, -1.0, 1.0])
_SV = np.array([1.0, 1.0, -1.0, -1.0])
_SU_T, _SV_T = (1.0, -1.0, -1.0, 1.0), (1.0, 1.0, -1.0, -1.0)  # the same as tuples, for the kernels


def _check_boxes(boxes: np.ndarray, name: str, min_cols: int = 7) -> np.ndarray:
    """``boxes`` as a ``(N, >=min_cols) float64`` array.

    ``ValueError`` on a bad shape, a non-finite value in the first ``min_cols`` columns, or (boxes
    with sizes) a negative size.
    """
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < min_cols:
        raise ValueError(f"{name} must have shape (N, >={min_cols}), got {arr.shape}")
    if not np.isfinite(arr[:, :min_cols]).all():
        raise ValueError(f"{name} has non-finite values in its first {min_cols} columns")
    if min_cols >= 7 and np.any(arr[:, 3:6] < 0.0):
        raise ValueError(f"{name} has negative sizes (columns w, l, h)")
    return arr


def bev_corners(boxes: np.ndarray) -> np.ndarray:
    """Bird's-eye-view corners of ``boxes`` ``(N, >=7)``: ``(N, 4, 2) float64`` metres ``[x, y]``.

    Counter-clockwise: front-left, rear-left, rear-right, front-right ("front" is +l/2 along the
    heading, "left" is +w/2 to its left).
    """
    boxes = _check_boxes(boxes, "boxes")
    c, s = np.cos(boxes[:, 6]), np.sin(boxes[:, 6])
    du = 0.5 * boxes[:, 4, None] * _SU  # (N, 4) offset along the heading
    dv = 0.5 * boxes[:, 3, None] * _SV  # (N, 4) offset across it
    x = boxes[:, 0, None] + du * c[:, None] - dv * s[:, None]
    y = boxes[:, 1, None] + du * s[:, None] + dv * c[:, None]
    return np.stack([x, y], axis=-1)


#: rows of the per-box term array made by :func:`_box_terms`
_X, _Y, _C, _S, _HL, _HW, _LO, _HI, _AREA, _VOL, _RADIUS = range(11)


def _box_terms(boxes: np.ndarray) -> np.ndarray:
    """Per-box terms ``(11, N) float64`` of validated ``boxes (N, >=7)``: centre ``x, y`` (m); cosine and
    sine of the yaw; half length and half width (m); bottom and top (m); footprint area (m²); volume (m³);
    circumradius of the footprint (m). Rows are named by ``_X`` ... ``_RADIUS``."""
    t = np.empty((11, boxes.shape[0]))
    _box_terms_kernel(boxes, t)
    return t


@njit(cache=True)
def _box_terms_kernel(boxes, t) -> None:
    """:func:`_box_terms` of ``boxes (N, >=7)`` into ``t (11, N)``, box by box."""
    for n in range(boxes.shape[0]):
        t[_X, n], t[_Y, n] = boxes[n, 0], boxes[n, 1]
        t[_C, n], t[_S, n] = np.cos(boxes[n, 6]), np.sin(boxes[n, 6])
        t[_HL, n], t[_HW, n] = 0.5 * boxes[n, 4], 0.5 * boxes[n, 3]
        half_h = 0.5 * boxes[n, 5]
        t[_LO, n], t[_HI, n] = boxes[n, 2] - half_h, boxes[n, 2] + half_h
        t[_AREA, n] = boxes[n, 3] * boxes[n, 4]
        t[_VOL, n] = t[_AREA, n] * boxes[n, 5]
        t[_RADIUS, n] = np.hypot(t[_HL, n], t[_HW, n])


@njit(cache=True, inline="always")
def _pseudo_angle(dx: float, dy: float) -> float:
    """A key in [0, 4) increasing with the angle of ``(dx, dy)`` from +x, counter-clockwise; ``(0, 0)`` -> 1."""
    p = dx / (abs(dx) + abs(dy) + 1e-300)
    return 1.0 - p + (2.0 + 2.0 * p if dy < 0.0 else 0.0)


@njit(cache=True, inline="always")
def _ring_area(x: np.ndarray, y: np.ndarray, valid: np.ndarray, p: int, keys: np.ndarray) -> float:
    """Area (m²) of the convex polygon through the valid ones of the first ``p`` (<= 16) points
    ``x, y, valid``; ``keys (>=p,) int64`` is a work array.

    The valid points must lie on the boundary of the polygon and include its vertices; repeats and points
    along edges add nothing. They are sorted by angle about their mean (integer keys: the quantised angle
    with the point's index in the low 4 bits, insertion-sorted) and summed by the shoelace formula
    ``A = 1/2 sum_r (x_r y_{r+1} - y_r x_{r+1})``. No valid point gives area 0.
    """
    n = 0
    mx = 0.0
    my = 0.0
    for r in range(p):
        if valid[r]:
            n += 1
            mx += x[r]
            my += y[r]
    if n == 0:
        return 0.0
    mx /= n
    my /= n
    m = 0
    for r in range(p):
        if valid[r]:
            key = np.int64(_pseudo_angle(x[r] - mx, y[r] - my) * 2.0**44) * 16 + r
            q = m
            while q > 0 and keys[q - 1] > key:
                keys[q] = keys[q - 1]
                q -= 1
            keys[q] = key
            m += 1
    twice = 0.0
    first = keys[0] & 15
    x0, y0 = x[first] - mx, y[first] - my
    xp, yp = x0, y0
    for r in range(1, n):
        q = keys[r] & 15
        xq, yq = x[q] - mx, y[q] - my
        twice += xp * yq - yp * xq
        xp, yp = xq, yq
    twice += xp * y0 - yp * x0
    return 0.5 * twice


@njit(cache=True, inline="always")
def _intersection_area(cx, cy, c, s, al, aw, bl, bw, ax, ay, bx, by, px, py, valid, keys) -> float:
    """BEV intersection area (m²) of box ``a`` (centre ``cx, cy``, heading ``(c, s)``, half sizes ``al, aw``)
    given in the frame of box ``b`` (the box ``|x| <= bl, |y| <= bw``).

    The intersection polygon's vertices are among 16 candidates: corners of either box inside the other, and
    where each edge of ``a`` enters and leaves ``b``. ``ax .. by (4,)``, ``px, py (16,)`` float64 and
    ``valid (16,)`` bool and ``keys (16,) int64`` are work arrays.
    """
    for k in range(4):
        su, sv = _SU_T[k], _SV_T[k]
        ax[k] = cx + su * (al * c) - sv * (aw * s)
        ay[k] = cy + su * (al * s) + sv * (aw * c)
        bx[k] = su * bl
        by[k] = sv * bw
    for i in range(4):
        px[i], py[i] = ax[i], ay[i]
        valid[i] = abs(ax[i]) <= bl + TOL and abs(ay[i]) <= bw + TOL
        ex, ey = bx[i] - cx, by[i] - cy  # corner of b relative to a's centre
        px[4 + i], py[4 + i] = bx[i], by[i]
        valid[4 + i] = abs(ex * c + ey * s) <= al + TOL and abs(ey * c - ex * s) <= aw + TOL
    for i in range(4):
        nx = (i + 1) % 4
        dxe, dye = ax[nx] - ax[i], ay[nx] - ay[i]
        t_in, t_out = 2.0, -1.0
        for j in range(4):
            # signed distances outside b's edge line j (y = bw, x = -bl, y = -bw, x = bl) of the edge's ends
            if j == 0:
                e0, e1 = ay[i] - bw, ay[nx] - bw
            elif j == 1:
                e0, e1 = -ax[i] - bl, -ax[nx] - bl
            elif j == 2:
                e0, e1 = -ay[i] - bw, -ay[nx] - bw
            else:
                e0, e1 = ax[i] - bl, ax[nx] - bl
            if e0 == e1 or not ((e0 <= 0.0 and e1 >= 0.0) or (e0 >= 0.0 and e1 <= 0.0)):
                continue
            t = e0 / (e0 - e1)  # in [0, 1]: where the edge crosses the line
            along = abs(ax[i] + t * dxe) - bl if j % 2 == 0 else abs(ay[i] + t * dye) - bw
            if along <= TOL:  # the crossing falls within b's edge
                t_in = min(t_in, t)
                t_out = max(t_out, t)
        px[8 + i], py[8 + i] = ax[i] + t_in * dxe, ay[i] + t_in * dye
        valid[8 + i] = t_in <= 1.0
        px[12 + i], py[12 + i] = ax[i] + t_out * dxe, ay[i] + t_out * dye
        valid[12 + i] = t_out >= 0.0
    return _ring_area(px, py, valid, 16, keys)


@njit(cache=True, inline="always")
def _hull_area(cx, cy, c, s, al, aw, bl, bw, px, py, on, sup, keys) -> float:
    """Area (m²) of the convex hull of the 8 BEV corners of box ``a`` (as in :func:`_intersection_area`,
    in ``b``'s frame) and box ``b``.

    A corner of ``a`` is on the hull iff, for some direction ``m`` in its normal cone, ``a`` reaches at
    least as far as ``b`` along ``m`` (support functions ``h_a(m) >= h_b(m)``); checking ``a``'s two edge
    normals at the corner and ``b``'s edge normals inside the cone suffices (the support of ``b`` is linear
    between those). Likewise for the corners of ``b``. ``px, py (>=8,)``, ``on (>=8,)``, ``sup (6, 4)``
    and ``keys (>=8,) int64`` are work arrays.
    """
    nax, nay, ha_na, hb_na, ha_nb, hb_nb = sup[0], sup[1], sup[2], sup[3], sup[4], sup[5]
    # outward normals of a's edges (left, rear, right, front) in b's frame
    nax[0], nax[1], nax[2], nax[3] = -s, -c, s, c
    nay[0], nay[1], nay[2], nay[3] = c, -s, -c, s
    abs_s, abs_c = abs(s), abs(c)
    e_s = al * abs_s + aw * abs_c  # reach of a from its centre along b's y axis
    e_c = al * abs_c + aw * abs_s  # ... along b's x axis
    f_s = bl * abs_s + bw * abs_c  # reach of b from its centre along a's w axis
    f_c = bl * abs_c + bw * abs_s  # ... along a's l axis
    for i in range(4):
        ha_na[i] = nax[i] * cx + nay[i] * cy + (aw if i % 2 == 0 else al)  # supports along a's normals
        hb_na[i] = f_s if i % 2 == 0 else f_c
        hb_nb[i] = bw if i % 2 == 0 else bl  # supports along b's normals +y, -x, -y, +x
    ha_nb[0], ha_nb[1], ha_nb[2], ha_nb[3] = cy + e_s, e_c - cx, e_s - cy, cx + e_c
    for i in range(4):
        pi = (i + 3) % 4
        a_on = ha_na[pi] >= hb_na[pi] - TOL or ha_na[i] >= hb_na[i] - TOL
        b_on = hb_nb[pi] >= ha_nb[pi] - TOL or hb_nb[i] >= ha_nb[i] - TOL
        for j in range(4):
            # b's normal j in the cone of a's corner i, and a reaches as far as b along it
            if (
                not a_on
                and _dot_nonneg(nax[pi], nay[pi], j)
                and _dot_nonneg(nax[i], nay[i], j)
                and ha_nb[j] >= hb_nb[j] - TOL
            ):
                a_on = True
            # a's normal j in the cone of b's corner i, and b reaches as far as a along it
            if (
                not b_on
                and _dot_nonneg(nax[j], nay[j], pi)
                and _dot_nonneg(nax[j], nay[j], i)
                and hb_na[j] >= ha_na[j] - TOL
            ):
                b_on = True
        su, sv = _SU_T[i], _SV_T[i]
        px[i] = cx + su * (al * c) - sv * (aw * s)
        py[i] = cy + su * (al * s) + sv * (aw * c)
        on[i] = a_on
        px[4 + i], py[4 + i], on[4 + i] = su * bl, sv * bw, b_on
    return _ring_area(px, py, on, 8, keys)


@njit(cache=True, inline="always")
def _dot_nonneg(nx: float, ny: float, j: int) -> bool:
    """Whether the normal ``(nx, ny)`` has a non-negative dot product with b's edge normal ``j``
    (+y, -x, -y, +x)."""
    if j == 0:
        return ny >= 0.0
    if j == 1:
        return -nx >= 0.0
    if j == 2:
        return -ny >= 0.0
    return nx >= 0.0


@njit(cache=True, inline="always")
def _ratio(num: float, den: float) -> float:
    """``num / den``, 0 where ``den <= 0``."""
    return num / den if den > 0.0 else 0.0


@njit(cache=True, inline="always")
def _giou(iou: float, union: float, hull: float) -> float:
    """``iou - (hull - union) / hull`` clipped to [-1, 1]; ``iou`` where ``hull`` is 0."""
    hull = max(hull, union)
    return min(max(iou - _ratio(hull - union, hull), -1.0), 1.0)


#: measure indices: rows of the kernel's output
_IOU_BEV, _GIOU_BEV, _IOU_3D, _GIOU_3D = range(4)
SIMILARITIES = ("iou_bev", "giou_bev", "iou_3d", "giou_3d")


@njit(cache=True, inline="always")
def _pair_measures(ta, i, tb, j, want, out, k, work, flags, keys) -> None:
    """The measures flagged in ``want (4,) bool`` (order of :data:`SIMILARITIES`) of the pair
    ``(a[i], b[j])`` into ``out[:, k]`` (``out (4, K) float64``).

    ``ta (11, N)``, ``tb (11, M)``: terms from :func:`_box_terms`; ``work (12, 16) float64``,
    ``flags (16,) bool`` and ``keys (16,) int64`` are work arrays. Work is done in the frame of ``b``:

    * ``I`` BEV intersection (0 unless the circumscribed circles meet and both areas are positive), clipped
      to ``[0, min(A_a, A_b)]``; ``C`` hull area (below ``HULL_EPS (d + r_a + r_b)^2``: 0, or for boxes whose
      circumscribed circles are apart, ``d (r_a + r_b)`` with the inscribed radii, a lower bound of ``C``);
    * BEV IoU ``I / U``, ``U = A_a + A_b - I``; GIoU ``IoU - (C - U) / C``;
    * 3D IoU ``I dz / (V_a + V_b - I dz)``; GIoU with ``V_C = C * span``.
    """
    dx, dy = ta[_X, i] - tb[_X, j], ta[_Y, i] - tb[_Y, j]
    bc, bs, ac, as_ = tb[_C, j], tb[_S, j], ta[_C, i], ta[_S, i]
    cx, cy = dx * bc + dy * bs, dy * bc - dx * bs  # centre of a in b's frame
    c, s = ac * bc + as_ * bs, as_ * bc - ac * bs  # cosine and sine of yaw_a - yaw_b
    al, aw, bl, bw = ta[_HL, i], ta[_HW, i], tb[_HL, j], tb[_HW, j]
    area_a, area_b = ta[_AREA, i], tb[_AREA, j]
    dist, reach = np.hypot(dx, dy), ta[_RADIUS, i] + tb[_RADIUS, j]
    px, py = work[0], work[1]
    inter = 0.0
    if dist <= reach + TOL and area_a > 0.0 and area_b > 0.0:
        inter = _intersection_area(
            cx, cy, c, s, al, aw, bl, bw, work[2], work[3], work[4], work[5], px, py, flags, keys
        )
    inter = min(max(inter, 0.0), min(area_a, area_b))
    hull = 0.0
    if want[_GIOU_BEV] or want[_GIOU_3D]:
        hull = _hull_area(cx, cy, c, s, al, aw, bl, bw, px, py, flags, work[6:12, :4], keys)
        if hull <= HULL_EPS * (dist + reach) ** 2:
            # rounding noise: a collinear set (0), or corners lost in rounding at ~1e12 sizes apart; then the
            # hull holds the trapezoid of the boxes' inscribed discs, d (r_a + r_b), and GIoU tends to -1
            hull = dist * (min(al, aw) + min(bl, bw)) if dist > reach else 0.0
    if want[_IOU_BEV] or want[_GIOU_BEV]:
        union = area_a + area_b - inter
        iou = min(max(_ratio(inter, union), 0.0), 1.0)
        out[_IOU_BEV, k] = iou
        out[_GIOU_BEV, k] = _giou(iou, union, hull)
    if want[_IOU_3D] or want[_GIOU_3D]:
        overlap = max(0.0, min(ta[_HI, i], tb[_HI, j]) - max(ta[_LO, i], tb[_LO, j]))
        span = max(ta[_HI, i], tb[_HI, j]) - min(ta[_LO, i], tb[_LO, j])
        inter3 = inter * overlap
        union3 = ta[_VOL, i] + tb[_VOL, j] - inter3
        iou3 = min(max(_ratio(inter3, union3), 0.0), 1.0)
        out[_IOU_3D, k] = iou3
        out[_GIOU_3D, k] = _giou(iou3, union3, hull * span)


@njit(cache=True)
def _measures_kernel(ta, tb, outer, todo, want, out) -> None:
    """:func:`_pair_measures` of the K pairs with ``todo (K,) bool`` set into ``out (4, K) float64``
    (other pairs are left as they are). Pairs: ``(a[k], b[k])`` (K = N = M), or if ``outer`` all
    ``(a[i], b[j])`` in ``a``-major order (K = N * M)."""
    work, flags, keys = np.empty((12, 16)), np.empty(16, dtype=np.bool_), np.empty(16, dtype=np.int64)
    m = tb.shape[1]
    for k in range(out.shape[1]):
        if todo[k]:
            i, j = (k // m, k % m) if outer else (k, k)
            _pair_measures(ta, i, tb, j, want, out, k, work, flags, keys)


def _want(names) -> np.ndarray:
    """``(4,) bool`` flags of the named measures; ``ValueError`` on an unknown name."""
    names = set(names)
    unknown = names - set(SIMILARITIES)
    if unknown:
        raise ValueError(f"unknown similarity {sorted(unknown)}; expected {SIMILARITIES}")
    return np.array([n in names for n in SIMILARITIES])


def _paired_measures(a: np.ndarray, b: np.ndarray, names) -> np.ndarray:
    """Measures ``(4, K)`` (rows of :data:`SIMILARITIES`, only ``names`` filled) of aligned pairs of
    ``a, b (K, >=7)``."""
    want = _want(names)
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"paired boxes need equal counts, got {a.shape[0]} and {b.shape[0]}")
    out = np.zeros((4, a.shape[0]))
    if a.shape[0]:
        _measures_kernel(_box_terms(a), _box_terms(b), False, np.ones(a.shape[0], dtype=np.bool_), want, out)
    return out


def _pairwise_measures(a: np.ndarray, b: np.ndarray, names, where: np.ndarray | None = None) -> np.ndarray:
    """Measures ``(4, N, M)`` (rows of :data:`SIMILARITIES`, only ``names`` filled) of all pairs of
    ``a (N, >=7)`` x ``b (M, >=7)``; with ``where (N, M) bool`` only the selected pairs (others 0)."""
    want = _want(names)
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    n, m = a.shape[0], b.shape[0]
    out = np.zeros((4, n, m))
    if n == 0 or m == 0:
        return out
    if where is None:
        where = np.ones((n, m), dtype=np.bool_)
    elif where.shape != (n, m):
        raise ValueError(f"where must have shape {(n, m)}, got {where.shape}")
    ta, tb = _box_terms(a), _box_terms(b)
    rows = max(1, CHUNK_PAIRS // m)
    for start in range(0, n, rows):
        stop = min(n, start + rows)
        buf = np.zeros((4, (stop - start) * m))
        todo = np.ascontiguousarray(where[start:stop]).ravel()
        _measures_kernel(np.ascontiguousarray(ta[:, start:stop]), tb, True, todo, want, buf)
        out[:, start:stop] = buf.reshape(4, -1, m)
    return out


# --- Footprints given as convex quadrilaterals (a detection's bottom face turned by its whole rotation, pitch and
# roll included, and projected to the ground: the nuScenes devkit's ``Box.bottom_corners()``, Poly-MOT's footprint).


def bottom_corners(boxes: np.ndarray, quaternion: np.ndarray | None = None) -> np.ndarray:
    """Ground-plane footprint of ``boxes (N, >=7)``: ``(N, 4, 2) float64`` metres ``[x, y]``, counter-clockwise.

    Without ``quaternion``: the yaw-turned w x l rectangle (:func:`bev_corners`). With ``quaternion (N, 4)
    [w, x, y, z]`` (the box's own rotation): its bottom face ``c + R(q) [+-l/2, +-w/2, -h/2]`` projected to the
    ground, a parallelogram (the devkit's ``Box.bottom_corners()[:2]``); pitch and roll shrink it along their axes
    and shift it by ``h/2`` times their sine. Corners in :func:`bev_corners`'s order, reversed where the rotation
    turns the face over.
    """
    if quaternion is None:
        return bev_corners(boxes)
    b = _check_boxes(boxes, "boxes")
    R = rotation_matrices(quaternion)  # (N, 3, 3)
    local = np.stack(
        [
            _SU * (0.5 * b[:, 4])[:, None],
            _SV * (0.5 * b[:, 3])[:, None],
            np.broadcast_to((-0.5 * b[:, 5])[:, None], (len(b), 4)),
        ],
        axis=1,
    )  # (N, 3, 4) box frame: x along l, y along w, z up
    c = (np.einsum("nij,njk->nik", R[:, :2], local) + b[:, :2, None]).transpose(0, 2, 1)  # (N, 4, 2)
    x, y = c[..., 0], c[..., 1]
    twice_area = np.sum(x * np.roll(y, -1, axis=1) - y * np.roll(x, -1, axis=1), axis=1)
    return np.where((twice_area < 0.0)[:, None, None], c[:, ::-1], c)


@njit(cache=True, inline="always")
def _shoelace(x, y, n: int) -> float:
    """Signed area (m^2) of the polygon through the first ``n`` points ``x, y`` in order."""
    twice = 0.0
    for r in range(n):
        q = (r + 1) % n
        twice += x[r] * y[q] - y[r] * x[q]
    return 0.5 * twice


@njit(cache=True, inline="always")
def _clip_area(ax, ay, bx, by, px, py, qx, qy) -> float:
    """Intersection area (m^2) of the convex counter-clockwise quadrilaterals ``a`` and ``b`` (``(4,)`` each).

    Sutherland-Hodgman: ``a`` is clipped by the half-plane left of each edge of ``b`` in turn (a convex polygon
    gains at most one vertex per edge, so at most 8); ``px .. qy (16,)`` are work arrays."""
    n = 4
    for r in range(4):
        px[r], py[r] = ax[r], ay[r]
    for e in range(4):
        x0, y0 = bx[e], by[e]
        ex, ey = bx[(e + 1) % 4] - x0, by[(e + 1) % 4] - y0
        m = 0
        for r in range(n):
            sx, sy, tx, ty = px[r], py[r], px[(r + 1) % n], py[(r + 1) % n]
            ds, dt = ex * (sy - y0) - ey * (sx - x0), ex * (ty - y0) - ey * (tx - x0)  # > 0: inside
            if ds >= 0.0:
                qx[m], qy[m] = sx, sy
                m += 1
            if (ds >= 0.0) != (dt >= 0.0):
                t = ds / (ds - dt)
                qx[m], qy[m] = sx + t * (tx - sx), sy + t * (ty - sy)
                m += 1
        if m < 3:
            return 0.0
        n = m
        for r in range(n):
            px[r], py[r] = qx[r], qy[r]
    return max(_shoelace(px, py, n), 0.0)


@njit(cache=True, inline="always")
def _turn(x0, y0, x1, y1, x2, y2) -> float:
    """Cross product ``(p1 - p0) x (p2 - p0)``: > 0 where ``p0, p1, p2`` turn counter-clockwise."""
    return (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)


@njit(cache=True, inline="always")
def _hull8_area(x, y, order, hx, hy) -> float:
    """Area (m^2) of the convex hull of the 8 points ``x, y (8,)`` (Andrew's monotone chain); ``order (8,) int64``,
    ``hx, hy (>=17,)`` are work arrays."""
    for r in range(8):
        q = r
        while q > 0 and (x[order[q - 1]] > x[r] or (x[order[q - 1]] == x[r] and y[order[q - 1]] > y[r])):
            order[q] = order[q - 1]
            q -= 1
        order[q] = r
    m = 0
    for t in range(8):  # lower chain, left to right
        r = order[t]
        while m >= 2 and _turn(hx[m - 2], hy[m - 2], hx[m - 1], hy[m - 1], x[r], y[r]) <= 0.0:
            m -= 1
        hx[m], hy[m] = x[r], y[r]
        m += 1
    floor = m + 1
    for t in range(6, -1, -1):  # upper chain, right to left
        r = order[t]
        while m >= floor and _turn(hx[m - 2], hy[m - 2], hx[m - 1], hy[m - 1], x[r], y[r]) <= 0.0:
            m -= 1
        hx[m], hy[m] = x[r], y[r]
        m += 1
    m -= 1  # the first point closes the ring
    return _shoelace(hx, hy, m) if m >= 3 else 0.0


@njit(cache=True, inline="always")
def _footprint_pair(ca, i, ta, cb, j, tb, want, out, k, w, order) -> None:
    """The measures flagged in ``want (4,) bool`` of the pair ``(a[i], b[j])`` into ``out[:, k]``.

    ``ca (N, 4, 2)``, ``cb (M, 4, 2)``: counter-clockwise footprints; ``ta (11, N)``, ``tb (11, M)``: terms of
    :func:`_box_terms` (areas ``w l``, volumes, vertical extents); ``w (10, 17) float64`` and ``order (8,) int64``
    are work arrays. Work is done relative to ``b``'s centre. With ``I`` the footprints' intersection, ``C`` their
    convex hull and the areas ``A = w l`` (so the union ``U = A_a + A_b - I``, as Poly-MOT's):
    IoU ``I / U``, GIoU ``IoU - (C - U) / C`` (``IoU`` where ``C`` is 0), not clipped: a tilted box's footprint
    is smaller than ``w l``, so two nearly equal tilted boxes can score just above 1, as in Poly-MOT; 3D as
    :func:`_pair_measures`.
    """
    ox, oy = tb[_X, j], tb[_Y, j]
    ax, ay, bx, by, hxs, hys = w[0, :4], w[1, :4], w[2, :4], w[3, :4], w[4, :8], w[5, :8]
    for r in range(4):
        ax[r], ay[r] = ca[i, r, 0] - ox, ca[i, r, 1] - oy
        bx[r], by[r] = cb[j, r, 0] - ox, cb[j, r, 1] - oy
        hxs[r], hys[r], hxs[4 + r], hys[4 + r] = ax[r], ay[r], bx[r], by[r]
    inter = 0.0
    if _shoelace(ax, ay, 4) > 0.0 and _shoelace(bx, by, 4) > 0.0:
        inter = _clip_area(ax, ay, bx, by, w[6, :16], w[7, :16], w[8, :16], w[9, :16])
    hull = _hull8_area(hxs, hys, order, w[6], w[7]) if want[_GIOU_BEV] or want[_GIOU_3D] else 0.0
    union = ta[_AREA, i] + tb[_AREA, j] - inter
    iou = _ratio(inter, union)
    out[_IOU_BEV, k] = iou
    out[_GIOU_BEV, k] = iou - _ratio(hull - union, hull)
    if want[_IOU_3D] or want[_GIOU_3D]:
        overlap = max(0.0, min(ta[_HI, i], tb[_HI, j]) - max(ta[_LO, i], tb[_LO, j]))
        span = max(ta[_HI, i], tb[_HI, j]) - min(ta[_LO, i], tb[_LO, j])
        inter3 = inter * overlap
        union3 = ta[_VOL, i] + tb[_VOL, j] - inter3
        iou3 = _ratio(inter3, union3)
        out[_IOU_3D, k] = iou3
        out[_GIOU_3D, k] = iou3 - _ratio(hull * span - union3, hull * span)


@njit(cache=True)
def _footprint_kernel(ca, ta, cb, tb, outer, todo, want, out) -> None:
    """:func:`_footprint_pair` of the K pairs with ``todo (K,) bool`` set into ``out (4, K)``; pairs as
    :func:`_measures_kernel`."""
    w, order = np.empty((10, 17)), np.empty(8, dtype=np.int64)
    m = tb.shape[1]
    for k in range(out.shape[1]):
        if todo[k]:
            i, j = (k // m, k % m) if outer else (k, k)
            _footprint_pair(ca, i, ta, cb, j, tb, want, out, k, w, order)


def _check_corners(corners: np.ndarray, n: int, name: str) -> np.ndarray:
    """``corners`` as a C-contiguous ``(n, 4, 2) float64`` array; ``ValueError`` on another shape."""
    c = np.ascontiguousarray(corners, dtype=np.float64)
    if c.shape != (n, 4, 2):
        raise ValueError(f"{name} must have shape {(n, 4, 2)}, got {c.shape}")
    return c


def footprint_similarities(
    a: np.ndarray,
    corners_a: np.ndarray,
    b: np.ndarray,
    corners_b: np.ndarray,
    names,
    pairwise: bool = True,
    where: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The measures ``names`` (of :data:`SIMILARITIES`) of boxes whose footprints are the given quadrilaterals.

    a (N, >=7), corners_a (N, 4, 2), b (M, >=7), corners_b (M, 4, 2): boxes and their counter-clockwise
    footprints (metres, e.g. :func:`bottom_corners`); the boxes give the areas ``w l``, volumes and vertical
    extents. ``pairwise``: ``{name: (N, M) float64}`` over all pairs (with ``where (N, M) bool`` only the
    selected ones, others 0); otherwise aligned pairs (N = M), ``{name: (N,) float64}``. Definitions:
    :func:`_footprint_pair` (equal to the ``pairwise_*`` functions, to rounding, when the footprints are the
    :func:`bev_corners` rectangles).
    """
    want = _want(names)
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    ca, cb = _check_corners(corners_a, len(a), "corners_a"), _check_corners(corners_b, len(b), "corners_b")
    if not pairwise and len(a) != len(b):
        raise ValueError(f"paired boxes need equal counts, got {len(a)} and {len(b)}")
    k = len(a) * len(b) if pairwise else len(a)
    out = np.zeros((4, k))
    if k:
        todo = np.ones(k, dtype=np.bool_) if where is None else np.ascontiguousarray(where, dtype=np.bool_).ravel()
        if todo.shape != (k,):
            raise ValueError(f"where must have shape {(len(a), len(b))}, got {np.shape(where)}")
        _footprint_kernel(ca, _box_terms(a), cb, _box_terms(b), pairwise, todo, want, out)
    shape = (len(a), len(b)) if pairwise else (len(a),)
    return {n: out[SIMILARITIES.index(n)].reshape(shape) for n in SIMILARITIES if n in set(names)}


def _pairwise_measure(name: str, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The measure ``name`` of all pairs of ``a (N, >=7)`` x ``b (M, >=7)`` -> ``(N, M) float64``."""
    return _pairwise_measures(a, b, [name])[SIMILARITIES.index(name)]


def paired_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    return _paired_measures(a, b, ["iou_bev"])[_IOU_BEV]


def paired_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing region is the convex hull of the 8 BEV corners.
    """
    return _paired_measures(a, b, ["giou_bev"])[_GIOU_BEV]


def paired_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    return _paired_measures(a, b, ["iou_3d"])[_IOU_3D]


def paired_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing volume is the convex hull of the 8 BEV corners times the vertical span of both.
    """
    return _paired_measures(a, b, ["giou_3d"])[_GIOU_3D]


def paired_similarities(a: np.ndarray, b: np.ndarray, names) -> dict[str, np.ndarray]:
    """Several measures of aligned pairs ``a[k], b[k]`` (both ``(K, >=7)``) from one geometry pass.

    names: any of :data:`SIMILARITIES`. Returns ``{name: (K,) float64}``, each equal to the matching
    ``paired_*`` function; the intersection and the hull are computed once for all of them.
    """
    out = _paired_measures(a, b, names)
    return {n: out[SIMILARITIES.index(n)] for n in SIMILARITIES if n in set(names)}


def pairwise_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise_measure("iou_bev", a, b)


def pairwise_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise_measure("giou_bev", a, b)


def pairwise_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise_measure("iou_3d", a, b)


def pairwise_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise_measure("giou_3d", a, b)


def pairwise_centre_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV centre distance ``(N, M) float64`` in metres between ``a (N, >=2)`` and ``b (M, >=2)``."""
    a, b = _check_boxes(a, "a", min_cols=2), _check_boxes(b, "b", min_cols=2)
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
