"""Rotated-box overlap measures (IoU / GIoU in bird's-eye view and 3D) between box sets, vectorised.

Boxes follow :mod:`grutrack.boxes`: rows ``[x, y, z, w, l, h, yaw, ...]`` (``(N, >=7)`` float, metres
and radians; ``w`` across the heading, ``l`` along it, ``z`` the box centre so the box spans
``z - h/2 .. z + h/2``). Extra columns (velocities) are ignored.

Four measures, ``bev_iou``, ``bev_giou``, ``iou_3d`` and ``giou_3d``, each in two forms:

* ``paired_*(a, b)`` with ``a`` and ``b`` both ``(K, >=7)``: the measure of each aligned pair
  ``(a[k], b[k])``, a ``(K,) float64`` array. Use it for a selected list of pairs.
* ``pairwise_*(a, b)`` with ``a`` ``(N, >=7)`` and ``b`` ``(M, >=7)``: all pairs, an ``(N, M) float64``
  array (``[i, j]`` = measure of ``(a[i], b[j])``, equal to the paired form on that pair).

Also :func:`bev_corners` ``(N, 4, 2)`` and :func:`pairwise_centre_distance` ``(N, M)`` in metres.

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

from typing import NamedTuple

import numpy as np
from numba import njit

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


class _PairFrame(NamedTuple):
    """Box ``a`` of each pair expressed in the frame of box ``b`` (all ``(K,) float64``).

    ``cx, cy``: centre of ``a`` in metres; ``c, s``: cosine and sine of ``yaw_a - yaw_b``;
    ``al, aw`` / ``bl, bw``: half length and half width of ``a`` / ``b`` in metres.
    """

    cx: np.ndarray
    cy: np.ndarray
    c: np.ndarray
    s: np.ndarray
    al: np.ndarray
    aw: np.ndarray
    bl: np.ndarray
    bw: np.ndarray


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


class _Boxes(NamedTuple):
    """Per-box terms, all ``(N,) float64``: centre ``x, y`` (m); ``c, s`` cosine and sine of the yaw;
    half length ``hl`` and half width ``hw`` (m); bottom ``lo`` and top ``hi`` (m); footprint ``area``
    (m²); volume ``vol`` (m³); circumradius ``radius`` of the footprint (m)."""

    x: np.ndarray
    y: np.ndarray
    c: np.ndarray
    s: np.ndarray
    hl: np.ndarray
    hw: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    area: np.ndarray
    vol: np.ndarray
    radius: np.ndarray


def _box_terms(boxes: np.ndarray) -> _Boxes:
    """Per-box terms of validated ``boxes (N, >=7)``."""
    hl, hw, half_h = 0.5 * boxes[:, 4], 0.5 * boxes[:, 3], 0.5 * boxes[:, 5]
    area = boxes[:, 3] * boxes[:, 4]
    return _Boxes(x=boxes[:, 0].copy(), y=boxes[:, 1].copy(), c=np.cos(boxes[:, 6]),
                  s=np.sin(boxes[:, 6]), hl=hl, hw=hw, lo=boxes[:, 2] - half_h,
                  hi=boxes[:, 2] + half_h, area=area, vol=area * boxes[:, 5], radius=np.hypot(hl, hw))


def _take(boxes: _Boxes, start: int, stop: int) -> _Boxes:
    """Boxes ``start:stop`` of ``boxes``."""
    return _Boxes(*(v[start:stop] for v in boxes))


class _Pairs(NamedTuple):
    """K pairs of boxes: ``frame`` (box ``a`` in the frame of box ``b``) and ``(K,) float64`` terms:
    centre distance ``dist`` and sum of circumradii ``reach`` (m), footprint areas (m²), volumes
    (m³), vertical ``overlap`` and ``span`` (m) of the two boxes."""

    frame: _PairFrame
    dist: np.ndarray
    reach: np.ndarray
    area_a: np.ndarray
    area_b: np.ndarray
    vol_a: np.ndarray
    vol_b: np.ndarray
    overlap: np.ndarray
    span: np.ndarray


def _pairs(a: _Boxes, b: _Boxes, outer: bool) -> _Pairs:
    """Aligned pairs ``(a[k], b[k])`` or, if ``outer``, all ``N * M`` pairs (``a``-major order)."""
    if outer:
        shape = (a.x.shape[0], b.x.shape[0])
        a, b = _Boxes(*(v[:, None] for v in a)), _Boxes(*(v[None, :] for v in b))
    else:
        shape = a.x.shape

    def flat(v: np.ndarray) -> np.ndarray:
        """The per-pair term ``v`` broadcast to all pairs, as a contiguous ``(K,)`` array."""
        return np.ascontiguousarray(np.broadcast_to(v, shape)).ravel()

    dx, dy = a.x - b.x, a.y - b.y
    # Centre of a rotated into b's frame; cosine and sine of yaw_a - yaw_b.
    frame = _PairFrame(cx=flat(dx * b.c + dy * b.s), cy=flat(dy * b.c - dx * b.s),
                       c=flat(a.c * b.c + a.s * b.s), s=flat(a.s * b.c - a.c * b.s),
                       al=flat(a.hl), aw=flat(a.hw), bl=flat(b.hl), bw=flat(b.hw))
    overlap = np.maximum(0.0, np.minimum(a.hi, b.hi) - np.maximum(a.lo, b.lo))
    span = np.maximum(a.hi, b.hi) - np.minimum(a.lo, b.lo)
    return _Pairs(frame=frame, dist=flat(np.hypot(dx, dy)), reach=flat(a.radius + b.radius),
                  area_a=flat(a.area), area_b=flat(b.area), vol_a=flat(a.vol), vol_b=flat(b.vol),
                  overlap=flat(overlap), span=flat(span))


_SU_T = (1.0, -1.0, -1.0, 1.0)
_SV_T = (1.0, 1.0, -1.0, -1.0)


@njit(cache=True, inline="always")
def _pseudo_angle(dx: float, dy: float) -> float:
    """A key in [0, 4) increasing with the angle of ``(dx, dy)`` from +x, counter-clockwise; ``(0, 0)`` -> 1."""
    p = dx / (abs(dx) + abs(dy) + 1e-300)
    return 1.0 - p + (2.0 + 2.0 * p if dy < 0.0 else 0.0)


@njit(cache=True)
def _ring_area(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> float:
    """Area (m²) of the convex polygon through the valid points ``x, y, valid (P,)`` (P <= 16).

    The valid points must lie on the boundary of the polygon and include its vertices; repeats and points
    along edges add nothing. They are sorted by angle about their mean and summed by the shoelace formula:
    ``A = 1/2 sum_r (x_r y_{r+1} - y_r x_{r+1})``. No valid point gives area 0.
    """
    p = x.shape[0]
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
    # Integer keys: quantised angle, invalid points last, the point's index in the low 4 bits.
    keys = np.empty(p, dtype=np.int64)
    for r in range(p):
        dx, dy = x[r] - mx, y[r] - my
        key = _pseudo_angle(dx, dy) if valid[r] else 9.0
        keys[r] = np.int64(key * 2.0**44) * 16 + r
    keys.sort()
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


@njit(cache=True)
def _pair_corners(cx, cy, c, s, al, aw, bl, bw, ax, ay, bx, by) -> None:
    """Fill the corners of ``a`` in ``b``'s frame ``ax, ay (4,)`` and of ``b`` ``bx, by (4,)``, metres, CCW."""
    for k in range(4):
        su, sv = _SU_T[k], _SV_T[k]
        ax[k] = cx + su * (al * c) - sv * (aw * s)
        ay[k] = cy + su * (al * s) + sv * (aw * c)
        bx[k] = su * bl
        by[k] = sv * bw


@njit(cache=True)
def _intersection_kernel(cx, cy, c, s, al, aw, bl, bw, todo, out) -> None:
    """BEV intersection area ``out (K,)`` m² of the pairs with ``todo (K,)`` set (frame from ``_pairs``).

    The intersection polygon's vertices are among 16 candidates: corners of either box inside the other, and
    where each edge of ``a`` enters and leaves ``b`` (the box ``|x| <= bl, |y| <= bw``).
    """
    ax = np.empty(4)
    ay = np.empty(4)
    bx = np.empty(4)
    by = np.empty(4)
    px = np.empty(16)
    py = np.empty(16)
    valid = np.empty(16, dtype=np.bool_)
    s0 = np.empty(4)
    for k in range(cx.shape[0]):
        if not todo[k]:
            out[k] = 0.0
            continue
        ck, sk, alk, awk, blk, bwk = c[k], s[k], al[k], aw[k], bl[k], bw[k]
        _pair_corners(cx[k], cy[k], ck, sk, alk, awk, blk, bwk, ax, ay, bx, by)
        for i in range(4):
            px[i], py[i] = ax[i], ay[i]
            valid[i] = abs(ax[i]) <= blk + TOL and abs(ay[i]) <= bwk + TOL
            ex, ey = bx[i] - cx[k], by[i] - cy[k]  # corner of b relative to a's centre
            px[4 + i], py[4 + i] = bx[i], by[i]
            valid[4 + i] = abs(ex * ck + ey * sk) <= alk + TOL and abs(ey * ck - ex * sk) <= awk + TOL
        for i in range(4):
            nx = (i + 1) % 4
            dxe, dye = ax[nx] - ax[i], ay[nx] - ay[i]
            # signed distance outside b's edge lines y = bw, x = -bl, y = -bw, x = bl of a's edge start / end
            s0[0], s0[1], s0[2], s0[3] = ay[i] - bwk, -ax[i] - blk, -ay[i] - bwk, ax[i] - blk
            t_in, t_out = 2.0, -1.0
            for j in range(4):
                if j == 0:
                    e1 = ay[nx] - bwk
                elif j == 1:
                    e1 = -ax[nx] - blk
                elif j == 2:
                    e1 = -ay[nx] - bwk
                else:
                    e1 = ax[nx] - blk
                e0 = s0[j]
                if e0 == e1 or not ((e0 <= 0.0 and e1 >= 0.0) or (e0 >= 0.0 and e1 <= 0.0)):
                    continue
                t = e0 / (e0 - e1)  # in [0, 1]: where the edge crosses the line
                along = abs(ax[i] + t * dxe) - blk if j % 2 == 0 else abs(ay[i] + t * dye) - bwk
                if along <= TOL:  # the crossing falls within b's edge
                    t_in = min(t_in, t)
                    t_out = max(t_out, t)
            px[8 + i], py[8 + i] = ax[i] + t_in * dxe, ay[i] + t_in * dye
            valid[8 + i] = t_in <= 1.0
            px[12 + i], py[12 + i] = ax[i] + t_out * dxe, ay[i] + t_out * dye
            valid[12 + i] = t_out >= 0.0
        out[k] = _ring_area(px, py, valid)


@njit(cache=True)
def _hull_kernel(cx, cy, c, s, al, aw, bl, bw, out) -> None:
    """Area ``out (K,)`` m² of the convex hull of the 8 BEV corners of each pair (frame from ``_pairs``).

    A corner of ``a`` is on the hull iff, for some direction ``m`` in its normal cone, ``a`` reaches at
    least as far as ``b`` along ``m`` (support functions ``h_a(m) >= h_b(m)``); checking ``a``'s two edge
    normals at the corner and ``b``'s edge normals inside the cone suffices. Likewise for ``b``.
    """
    ax = np.empty(4)
    ay = np.empty(4)
    bx = np.empty(4)
    by = np.empty(4)
    nax = np.empty(4)
    nay = np.empty(4)
    ha_na = np.empty(4)
    hb_na = np.empty(4)
    ha_nb = np.empty(4)
    hb_nb = np.empty(4)
    pos = np.empty((4, 4), dtype=np.bool_)
    px = np.empty(8)
    py = np.empty(8)
    on = np.empty(8, dtype=np.bool_)
    for k in range(cx.shape[0]):
        ck, sk, alk, awk, blk, bwk, cxk, cyk = c[k], s[k], al[k], aw[k], bl[k], bw[k], cx[k], cy[k]
        # outward normals of a's edges (left, rear, right, front) in b's frame
        nax[0], nax[1], nax[2], nax[3] = -sk, -ck, sk, ck
        nay[0], nay[1], nay[2], nay[3] = ck, -sk, -ck, sk
        abs_s, abs_c = abs(sk), abs(ck)
        e_s = alk * abs_s + awk * abs_c  # reach of a from its centre along b's y axis
        e_c = alk * abs_c + awk * abs_s  # ... along b's x axis
        f_s = blk * abs_s + bwk * abs_c  # reach of b from its centre along a's w axis
        f_c = blk * abs_c + bwk * abs_s  # ... along a's l axis
        for i in range(4):
            ha_na[i] = nax[i] * cxk + nay[i] * cyk + (awk if i % 2 == 0 else alk)
            hb_na[i] = f_s if i % 2 == 0 else f_c
            hb_nb[i] = bwk if i % 2 == 0 else blk
        ha_nb[0], ha_nb[1], ha_nb[2], ha_nb[3] = cyk + e_s, e_c - cxk, e_s - cyk, cxk + e_c
        for i in range(4):  # pos[i, j]: (a's normal i) . (b's normal j: +y, -x, -y, +x) >= 0
            pos[i, 0] = nay[i] >= 0.0
            pos[i, 1] = -nax[i] >= 0.0
            pos[i, 2] = -nay[i] >= 0.0
            pos[i, 3] = nax[i] >= 0.0
        _pair_corners(cxk, cyk, ck, sk, alk, awk, blk, bwk, ax, ay, bx, by)
        for i in range(4):
            pi = (i + 3) % 4
            a_on = ha_na[pi] >= hb_na[pi] - TOL or ha_na[i] >= hb_na[i] - TOL
            b_on = hb_nb[pi] >= ha_nb[pi] - TOL or hb_nb[i] >= ha_nb[i] - TOL
            for j in range(4):
                # b's normal j in the cone of a's corner i and a reaches as far as b along it
                if not a_on and pos[pi, j] and pos[i, j] and ha_nb[j] >= hb_nb[j] - TOL:
                    a_on = True
                # a's normal j in the cone of b's corner i and b reaches as far as a along it
                if not b_on and pos[j, pi] and pos[j, i] and hb_na[j] >= ha_na[j] - TOL:
                    b_on = True
            px[i], py[i], on[i] = ax[i], ay[i], a_on
            px[4 + i], py[4 + i], on[4 + i] = bx[i], by[i], b_on
        out[k] = _ring_area(px, py, on)


def _intersection(p: _Pairs) -> np.ndarray:
    """BEV intersection areas ``(K,) float64`` m² (0 for a zero-area box or far-apart boxes)."""
    inter = np.empty(p.dist.shape[0])
    near = (p.dist <= p.reach + TOL) & (p.area_a > 0.0) & (p.area_b > 0.0)
    _intersection_kernel(*p.frame, near, inter)
    return np.clip(inter, 0.0, np.minimum(p.area_a, p.area_b))


def _hull(p: _Pairs) -> np.ndarray:
    """Areas ``(K,) float64`` m² of the convex hulls of the 8 BEV corners of the pairs."""
    hull = np.empty(p.dist.shape[0])
    _hull_kernel(*p.frame, hull)
    hull[hull <= HULL_EPS * (p.dist + p.reach) ** 2] = 0.0
    return hull


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den`` elementwise, 0 where ``den <= 0``."""
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0.0)


def _giou(iou: np.ndarray, union: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """``iou - (hull - union) / hull`` clipped to [-1, 1]; ``iou`` where ``hull`` is 0."""
    hull = np.maximum(hull, union)
    return np.clip(iou - _ratio(hull - union, hull), -1.0, 1.0)


def _bev_iou_union(p: _Pairs) -> tuple[np.ndarray, np.ndarray]:
    """BEV IoU ``(K,)`` and union area ``(K,)`` m²."""
    inter = _intersection(p)
    union = p.area_a + p.area_b - inter
    return np.clip(_ratio(inter, union), 0.0, 1.0), union


def _iou_3d_union(p: _Pairs) -> tuple[np.ndarray, np.ndarray]:
    """3D IoU ``(K,)`` and union volume ``(K,)`` m³."""
    inter = _intersection(p) * p.overlap
    union = p.vol_a + p.vol_b - inter
    return np.clip(_ratio(inter, union), 0.0, 1.0), union


def _bev_iou(p: _Pairs) -> np.ndarray:
    """BEV IoU ``(K,)`` of pairs."""
    return _bev_iou_union(p)[0]


def _bev_giou(p: _Pairs) -> np.ndarray:
    """BEV GIoU ``(K,)`` of pairs."""
    iou, union = _bev_iou_union(p)
    return _giou(iou, union, _hull(p))


def _iou_3d(p: _Pairs) -> np.ndarray:
    """3D IoU ``(K,)`` of pairs."""
    return _iou_3d_union(p)[0]


def _giou_3d(p: _Pairs) -> np.ndarray:
    """3D GIoU ``(K,)`` of pairs."""
    iou, union = _iou_3d_union(p)
    return _giou(iou, union, _hull(p) * p.span)


def _paired(fn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Apply the pair measure ``fn`` to aligned pairs of ``a, b (K, >=7)`` -> ``(K,)``."""
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"paired boxes need equal counts, got {a.shape[0]} and {b.shape[0]}")
    return fn(_pairs(_box_terms(a), _box_terms(b), outer=False))


def _pairwise(fn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Apply the pair measure ``fn`` to all pairs of ``a (N, >=7)`` x ``b (M, >=7)`` -> ``(N, M)``."""
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    n, m = a.shape[0], b.shape[0]
    out = np.zeros((n, m))
    if n == 0 or m == 0:
        return out
    terms_a, terms_b = _box_terms(a), _box_terms(b)
    rows = max(1, CHUNK_PAIRS // m)
    for start in range(0, n, rows):
        stop = min(n, start + rows)
        out[start:stop] = fn(_pairs(_take(terms_a, start, stop), terms_b, outer=True)).reshape(-1, m)
    return out


def paired_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    return _paired(_bev_iou, a, b)


def paired_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing region is the convex hull of the 8 BEV corners.
    """
    return _paired(_bev_giou, a, b)


def paired_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    return _paired(_iou_3d, a, b)


def paired_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing volume is the convex hull of the 8 BEV corners times the vertical span of both.
    """
    return _paired(_giou_3d, a, b)


SIMILARITIES = ("iou_bev", "giou_bev", "iou_3d", "giou_3d")


def paired_similarities(a: np.ndarray, b: np.ndarray, names) -> dict[str, np.ndarray]:
    """Several measures of aligned pairs ``a[k], b[k]`` (both ``(K, >=7)``) from one geometry pass.

    names: any of :data:`SIMILARITIES`. Returns ``{name: (K,) float64}``, each equal to the matching
    ``paired_*`` function; the intersection and the hull are computed once for all of them.
    """
    names = set(names)
    unknown = names - set(SIMILARITIES)
    if unknown:
        raise ValueError(f"unknown similarity {sorted(unknown)}; expected {SIMILARITIES}")
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"paired boxes need equal counts, got {a.shape[0]} and {b.shape[0]}")
    p = _pairs(_box_terms(a), _box_terms(b), outer=False)
    inter = _intersection(p)
    hull = _hull(p) if names & {"giou_bev", "giou_3d"} else None
    out = {}
    if names & {"iou_bev", "giou_bev"}:
        union = p.area_a + p.area_b - inter
        iou = np.clip(_ratio(inter, union), 0.0, 1.0)
        out["iou_bev"] = iou
        if "giou_bev" in names:
            out["giou_bev"] = _giou(iou, union, hull)
    if names & {"iou_3d", "giou_3d"}:
        inter3 = inter * p.overlap
        union3 = p.vol_a + p.vol_b - inter3
        iou3 = np.clip(_ratio(inter3, union3), 0.0, 1.0)
        out["iou_3d"] = iou3
        if "giou_3d" in names:
            out["giou_3d"] = _giou(iou3, union3, hull * p.span)
    return {k: v for k, v in out.items() if k in names}


def pairwise_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(_bev_iou, a, b)


def pairwise_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(_bev_giou, a, b)


def pairwise_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(_iou_3d, a, b)


def pairwise_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(_giou_3d, a, b)


def pairwise_centre_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV centre distance ``(N, M) float64`` in metres between ``a (N, >=2)`` and ``b (M, >=2)``."""
    a, b = _check_boxes(a, "a", min_cols=2), _check_boxes(b, "b", min_cols=2)
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
