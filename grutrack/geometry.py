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
touching boxes are exact to rounding.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

TOL = 1e-10
"""Slack in metres of the inside / on-the-edge tests (points this close to a boundary count as on it).

It is far above the rounding of coordinates in the pair frame (~1e-13 m) and bounds the error it can
add to an area by ``TOL`` times the perimeter (under 1e-9 in the IoU of 0.3 m boxes)."""

HULL_EPS = 1e-12
"""Hull areas below ``HULL_EPS * D**2`` (``D`` bounding the pair's extent) are rounding noise of a
collinear point set and count as 0 (so, e.g., two collinear segments have GIoU 0, not -1)."""

CHUNK_PAIRS = 1 << 16
"""Pairs handled at once by the ``pairwise_*`` functions (bounds temporary memory)."""

BLOCK = 512
"""Pairs per block of the polygon work: keeps each temporary array under 128 KiB, which avoids
fresh memory mappings (and their page faults) for every numpy temporary."""

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


# Internally, per-pair quantities are laid out points-first, ``(P, K)`` with the K pairs last, so
# that every numpy operation runs over long contiguous rows.


def _corners_a(f: _PairFrame) -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``a`` in ``b``'s frame: x, y ``(4, K)`` metres, counter-clockwise."""
    su, sv = _SU[:, None], _SV[:, None]
    x = f.cx + su * (f.al * f.c) - sv * (f.aw * f.s)
    y = f.cy + su * (f.al * f.s) + sv * (f.aw * f.c)
    return x, y


def _corners_b(f: _PairFrame) -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``b`` in its own frame: x, y ``(4, K)`` metres, counter-clockwise."""
    return _SU[:, None] * f.bl, _SV[:, None] * f.bw


def _rows(*rows: np.ndarray) -> np.ndarray:
    """Stack equal-shaped arrays along a new first axis (a cheaper ``np.stack(rows)``)."""
    out = np.empty((len(rows),) + rows[0].shape)
    for i, row in enumerate(rows):
        out[i] = row
    return out


def _pseudo_angle(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """A key in [0, 4) increasing with the angle of ``(dx, dy)`` (any equal shapes) from +x, CCW.

    ``(0, 0)`` gets key 1.
    """
    p = dx / (np.abs(dx) + np.abs(dy) + 1e-300)
    return 1.0 - p + (dy < 0.0) * (2.0 + 2.0 * p)


def _batcher_network(n: int) -> list[tuple[int, int]]:
    """Comparators ``(i, j)``, ``i < j``, of Batcher's odd-even merge sort of ``n`` keys (a power of 2)."""
    pairs = []
    p = 1
    while p < n:
        k = p
        while k >= 1:
            for j in range(k % p, n - k, 2 * k):
                for i in range(min(k, n - j - k)):
                    if (i + j) // (2 * p) == (i + j + k) // (2 * p):
                        pairs.append((i + j, i + j + k))
            k //= 2
        p *= 2
    return pairs


_NETWORKS = {8: _batcher_network(8), 16: _batcher_network(16)}


def _sort_columns(keys: np.ndarray) -> np.ndarray:
    """``keys (P, K)`` (P = 8 or 16) sorted ascending within each column, by a sorting network."""
    rows = list(keys)
    for i, j in _NETWORKS[len(rows)]:
        lo = np.minimum(rows[i], rows[j])
        rows[j] = np.maximum(rows[i], rows[j])
        rows[i] = lo
    return np.stack(rows)


def _ring_area(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Area ``(K,) float64`` m² of the convex polygon through the valid points of each column.

    ``x, y`` (metres, finite) and ``valid`` are ``(P, K)`` with P = 8 or 16. The valid points of a
    column must lie on the boundary of its convex polygon and include its vertices; repeats and
    points along edges add nothing. They are sorted by angle about their mean and summed by the
    shoelace formula. No valid point gives area 0.
    """
    p, k = x.shape
    vf = valid.astype(np.float64)
    n = vf.sum(axis=0)
    nn = np.maximum(n, 1.0)
    dx = (x - (x * vf).sum(axis=0) / nn) * vf  # invalid points sit on the mean: they add no area
    dy = (y - (y * vf).sum(axis=0) / nn) * vf
    key = _pseudo_angle(dx, dy) + 8.0 * (1.0 - vf)  # in [0, 12); invalid points sort last
    # Quantise to integers and put the row index in the low 4 bits: distinct keys that carry
    # their point along through the sort.
    ikey = (key * 2.0**44).astype(np.int64) * 16 + np.arange(p)[:, None]
    idx = (_sort_columns(ikey) & 15) * k + np.arange(k)
    sx, sy = dx.ravel()[idx], dy.ravel()[idx]  # (P, K) in angular order
    twice = (sx[:-1] * sy[1:] - sy[:-1] * sx[1:]).sum(axis=0)
    last = np.maximum(n.astype(np.intp) - 1, 0)  # close the ring: last valid point -> first
    cols = np.arange(k)
    twice += sx[last, cols] * sy[0] - sy[last, cols] * sx[0]
    return 0.5 * twice


_NEXT = np.array([1, 2, 3, 0])  # corner k+1 (end of edge k)
_PREV = np.array([3, 0, 1, 2])  # corner k-1


def _intersection_area(f: _PairFrame) -> np.ndarray:
    """BEV intersection area ``(K,) float64`` m² of each pair (frame from :func:`_pairs`)."""
    ax, ay = _corners_a(f)  # (4, K) in b's frame, where b is the box |x| <= bl, |y| <= bw
    bx, by = _corners_b(f)
    a_in = (np.abs(ax) <= f.bl + TOL) & (np.abs(ay) <= f.bw + TOL)
    ex, ey = bx - f.cx, by - f.cy  # corners of b along a's axes
    b_in = ((np.abs(ex * f.c + ey * f.s) <= f.al + TOL)
            & (np.abs(ey * f.c - ex * f.s) <= f.aw + TOL))
    # Edges of a against the lines of b's edges y = bw, x = -bl, y = -bw, x = bl:
    # s0[i, j] / s1[i, j] = signed distance outside line j of the start / end of a's edge i.
    s0 = np.stack([ay - f.bw, -ax - f.bl, -ay - f.bw, ax - f.bl], axis=1)  # (4, 4, K)
    s1 = s0[_NEXT]
    crosses = (((s0 <= 0.0) & (s1 >= 0.0)) | ((s0 >= 0.0) & (s1 <= 0.0))) & (s0 != s1)
    den = s0 - s1
    den[~crosses] = 1.0
    t = s0 / den  # in [0, 1] where the edge crosses the line
    dxe, dye = ax[_NEXT] - ax, ay[_NEXT] - ay  # (4, K) edge vectors
    px, py = ax[:, None] + t * dxe[:, None], ay[:, None] + t * dye[:, None]
    # The crossing must fall within b's edge (|x| <= bl on lines 0 and 2, |y| <= bw on 1 and 3).
    along = np.stack([np.abs(px[:, 0]) - f.bl, np.abs(py[:, 1]) - f.bw,
                      np.abs(px[:, 2]) - f.bl, np.abs(py[:, 3]) - f.bw], axis=1)
    bad = ~(crosses & (along <= TOL))
    # Each edge of a enters and leaves b at most once: keep its first and last valid crossing.
    t_in = np.where(bad, 2.0, t).min(axis=1)  # (4, K); > 1 if none
    t_out = np.where(bad, -1.0, t).max(axis=1)  # < 0 if none
    x = np.concatenate([ax, bx, ax + t_in * dxe, ax + t_out * dxe])
    y = np.concatenate([ay, by, ay + t_in * dye, ay + t_out * dye])
    valid = np.concatenate([a_in, b_in, t_in <= 1.0, t_out >= 0.0])
    return _ring_area(x, y, valid)


def _hull_area(f: _PairFrame) -> np.ndarray:
    """Area ``(K,) float64`` m² of the convex hull of the 8 BEV corners of each pair.

    A corner of ``a`` is on the hull iff, for some direction ``m`` in its normal cone, ``a`` reaches
    at least as far as ``b`` along ``m``; checking ``a``'s two edge normals at the corner and ``b``'s
    edge normals inside the cone suffices (the support of ``b`` is linear between those). Likewise
    for the corners of ``b``.
    """
    c, s, al, aw, bl, bw = f.c, f.s, f.al, f.aw, f.bl, f.bw
    # Outward normals of a's edges (left, rear, right, front) in b's frame, (4, K) components.
    nax, nay = _rows(-s, -c, s, c), _rows(c, -s, -c, s)
    abs_s, abs_c = np.abs(s), np.abs(c)
    e_s = al * abs_s + aw * abs_c  # reach of a from its centre along b's y axis
    e_c = al * abs_c + aw * abs_s  # ... along b's x axis
    f_s = bl * abs_s + bw * abs_c  # reach of b from its centre along a's w axis
    f_c = bl * abs_c + bw * abs_s  # ... along a's l axis
    # Support of a and b along a's normals, and along b's normals (+y, -x, -y, +x).
    ha_na = nax * f.cx + nay * f.cy + _rows(aw, al, aw, al)
    hb_na = _rows(f_s, f_c, f_s, f_c)
    ha_nb = _rows(f.cy + e_s, e_c - f.cx, e_s - f.cy, f.cx + e_c)
    hb_nb = _rows(bw, bl, bw, bl)
    a_na, a_nb = ha_na >= hb_na - TOL, ha_nb >= hb_nb - TOL  # (4, K): a reaches as far as b
    b_na, b_nb = hb_na >= ha_na - TOL, hb_nb >= ha_nb - TOL
    # pos[i, j]: (a's normal i) . (b's normal j) >= 0.
    pos = _rows(nay, -nax, -nay, nax).transpose(1, 0, 2) >= 0.0  # (4, 4, K)
    a_cone = pos[_PREV] & pos  # [i, j]: b's normal j lies in the cone of a's corner i
    b_cone = pos[:, _PREV] & pos  # [i, j]: a's normal i lies in the cone of b's corner j
    a_on = a_na[_PREV] | a_na | (a_cone & a_nb[None]).any(axis=1)
    b_on = b_nb[_PREV] | b_nb | (b_cone & b_na[:, None]).any(axis=0)
    ax, ay = _corners_a(f)
    bx, by = _corners_b(f)
    return _ring_area(np.concatenate([ax, bx]), np.concatenate([ay, by]),
                      np.concatenate([a_on, b_on]))


def _subset(f: _PairFrame, mask: np.ndarray) -> _PairFrame:
    """The pairs of ``f`` selected by ``mask (K,) bool``."""
    return _PairFrame(*(arr[mask] for arr in f))


def _blocked(fn, f: _PairFrame) -> np.ndarray:
    """``fn(f) (K,)`` evaluated on blocks of at most :data:`BLOCK` pairs."""
    k = f.cx.shape[0]
    if k <= BLOCK:
        return fn(f)
    out = np.empty(k)
    for start in range(0, k, BLOCK):
        out[start:start + BLOCK] = fn(_PairFrame(*(arr[start:start + BLOCK] for arr in f)))
    return out


def _intersection(p: _Pairs) -> np.ndarray:
    """BEV intersection areas ``(K,) float64`` m² (0 for a zero-area box or far-apart boxes)."""
    inter = np.zeros(p.dist.shape[0])
    near = (p.dist <= p.reach + TOL) & (p.area_a > 0.0) & (p.area_b > 0.0)
    if np.any(near):
        inter[near] = _blocked(_intersection_area, _subset(p.frame, near))
    return np.clip(inter, 0.0, np.minimum(p.area_a, p.area_b))


def _hull(p: _Pairs) -> np.ndarray:
    """Areas ``(K,) float64`` m² of the convex hulls of the 8 BEV corners of the pairs."""
    hull = _blocked(_hull_area, p.frame)
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
