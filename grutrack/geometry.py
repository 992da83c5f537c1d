"""Rotated-box overlap measures (IoU / GIoU in bird's-eye view and 3D) between box sets, vectorised.

Boxes follow :mod:`grutrack.boxes`: rows ``[x, y, z, w, l, h, yaw, ...]`` (``(N, >=7)`` float, metres
and radians; ``w`` across the heading, ``l`` along it, ``z`` the box centre so the box spans
``z - h/2 .. z + h/2``). Extra columns (velocities) are ignored.

Two forms of every measure:

* ``paired_*(a, b)`` with ``a`` and ``b`` both ``(K, >=7)``: the measure of each aligned pair
  ``(a[k], b[k])``, a ``(K,) float64`` array. Use it for a selected list of pairs.
* ``pairwise_*(a, b)`` with ``a`` ``(N, >=7)`` and ``b`` ``(M, >=7)``: all pairs, an ``(N, M) float64``
  array (computed with the paired form in chunks of pairs).

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
* GIoU equals IoU (so 0) when the hull ``C`` (or ``V_C``) is 0; otherwise the formula applies, so two
  zero-area boxes with a hull of positive area have GIoU -1 (union 0, penalty term 1).

A zero-area box has zero intersection with anything, so its IoU with any box is 0. Negative sizes are
rejected with ``ValueError``.

Method: the intersection of two rectangles is a convex polygon whose vertices are among 24
candidates (corners of either box inside the other, and crossings of the edges of ``a`` with those of
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

TOL = 1e-9
"""Slack in metres of the inside / on-the-edge tests (points this close to a boundary count as on it)."""

CHUNK_PAIRS = 1 << 16
"""Pairs handled at once by the ``pairwise_*`` functions (bounds temporary memory)."""

# Corner order in the box frame (+x along l, +y along w): front-left, rear-left, rear-right,
# front-right, i.e. counter-clockwise. Edge k runs from corner k to corner k+1.
_SU = np.array([1.0, -1.0, -1.0, 1.0])
_SV = np.array([1.0, 1.0, -1.0, -1.0])
# Outward unit normals of the edges of an axis-aligned box (left, rear, right, front).
_AXIS_NORMALS = np.array([[0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0]])


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
    """``boxes`` as a ``(N, >=min_cols) float64`` array; ``ValueError`` on a bad shape or negative size."""
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < min_cols:
        raise ValueError(f"{name} must have shape (N, >={min_cols}), got {arr.shape}")
    if min_cols >= 7 and np.any(arr[:, 3:6] < 0.0):
        raise ValueError(f"{name} has negative sizes (columns w, l, h)")
    return arr


def _check_paired(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate two aligned ``(K, >=7)`` box arrays."""
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"paired boxes need equal counts, got {a.shape[0]} and {b.shape[0]}")
    return a, b


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


def _pair_frame(a: np.ndarray, b: np.ndarray) -> _PairFrame:
    """Express each ``a[k]`` ``(K, >=7)`` in the frame of ``b[k]`` ``(K, >=7)``."""
    cb, sb = np.cos(b[:, 6]), np.sin(b[:, 6])
    dx, dy = a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]
    dyaw = a[:, 6] - b[:, 6]
    return _PairFrame(cx=dx * cb + dy * sb, cy=-dx * sb + dy * cb, c=np.cos(dyaw), s=np.sin(dyaw),
                      al=0.5 * a[:, 4], aw=0.5 * a[:, 3], bl=0.5 * b[:, 4], bw=0.5 * b[:, 3])


def _corners_a(f: _PairFrame) -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``a`` in ``b``'s frame: x, y ``(K, 4)`` metres, counter-clockwise."""
    du = f.al[:, None] * _SU
    dv = f.aw[:, None] * _SV
    x = f.cx[:, None] + du * f.c[:, None] - dv * f.s[:, None]
    y = f.cy[:, None] + du * f.s[:, None] + dv * f.c[:, None]
    return x, y


def _corners_b(f: _PairFrame) -> tuple[np.ndarray, np.ndarray]:
    """Corners of ``b`` in its own frame: x, y ``(K, 4)`` metres, counter-clockwise."""
    return f.bl[:, None] * _SU, f.bw[:, None] * _SV


def _pseudo_angle(dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """A key in [0, 4) increasing with the angle of ``(dx, dy)`` (any equal shapes) from +x, CCW."""
    den = np.abs(dx) + np.abs(dy)
    p = np.divide(dx, den, out=np.zeros_like(dx), where=den > 0.0)
    return np.where(dy >= 0.0, 1.0 - p, 3.0 + p)


def _ring_area(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Area ``(K,)`` m² of the convex polygon through the valid points of each row.

    ``x, y, valid`` are ``(K, P)``; every valid point must lie on the boundary of the row's convex
    polygon, and together they must include its vertices (repeats and points on edges are harmless).
    Points are sorted by angle about their mean and summed by the shoelace formula.
    """
    if x.shape[0] == 0:
        return np.zeros(0)
    n = np.maximum(valid.sum(axis=1), 1)
    mx = np.where(valid, x, 0.0).sum(axis=1) / n
    my = np.where(valid, y, 0.0).sum(axis=1) / n
    dx, dy = x - mx[:, None], y - my[:, None]
    key = np.where(valid, _pseudo_angle(dx, dy), 5.0)
    order = np.argsort(key, axis=1)
    dx = np.take_along_axis(dx, order, axis=1)
    dy = np.take_along_axis(dy, order, axis=1)
    ok = np.take_along_axis(valid, order, axis=1)
    # Invalid points sort last; make them copies of the first point so they add no area.
    dx = np.where(ok, dx, dx[:, :1])
    dy = np.where(ok, dy, dy[:, :1])
    cross = dx * np.roll(dy, -1, axis=1) - dy * np.roll(dx, -1, axis=1)
    return 0.5 * cross.sum(axis=1)


def _intersection_area(f: _PairFrame) -> np.ndarray:
    """BEV intersection area ``(K,) float64`` m² of each pair (frame from :func:`_pair_frame`)."""
    ax, ay = _corners_a(f)  # (K, 4) in b's frame
    bx, by = _corners_b(f)
    bl, bw = f.bl[:, None], f.bw[:, None]
    # Corners of a inside b (b is the axis-aligned box |x| <= bl, |y| <= bw).
    a_in = (np.abs(ax) <= bl + TOL) & (np.abs(ay) <= bw + TOL)
    # Corners of b inside a: coordinates along a's axes.
    ex, ey = bx - f.cx[:, None], by - f.cy[:, None]
    u = ex * f.c[:, None] + ey * f.s[:, None]
    v = -ex * f.s[:, None] + ey * f.c[:, None]
    b_in = (np.abs(u) <= f.al[:, None] + TOL) & (np.abs(v) <= f.aw[:, None] + TOL)
    # Edges of a against the lines of b's edges: y = bw, x = -bl, y = -bw, x = bl.
    # sd[k, i, j]: signed distance of corner i of a outside line j.
    sd = np.stack([ay - bw, -ax - bl, -ay - bw, ax - bl], axis=-1)  # (K, 4, 4)
    s0, s1 = sd, np.roll(sd, -1, axis=1)  # edge i runs corner i -> corner i+1
    crosses = (np.minimum(s0, s1) <= 0.0) & (np.maximum(s0, s1) >= 0.0) & (s0 != s1)
    t = s0 / np.where(crosses, s0 - s1, 1.0)
    x0, y0 = ax[:, :, None], ay[:, :, None]
    x1, y1 = np.roll(ax, -1, axis=1)[:, :, None], np.roll(ay, -1, axis=1)[:, :, None]
    px, py = x0 + t * (x1 - x0), y0 + t * (y1 - y0)  # (K, 4, 4)
    # The crossing must fall within the extent of b's edge (along x for j even, y for j odd).
    along = np.where(np.arange(4) % 2 == 0, np.abs(px) - bl[:, :, None], np.abs(py) - bw[:, :, None])
    cross_ok = crosses & (along <= TOL)
    k = ax.shape[0]
    x = np.concatenate([ax, bx, px.reshape(k, 16)], axis=1)
    y = np.concatenate([ay, by, py.reshape(k, 16)], axis=1)
    valid = np.concatenate([a_in, b_in, cross_ok.reshape(k, 16)], axis=1)
    return _ring_area(x, y, valid)


def _hull_area(f: _PairFrame) -> np.ndarray:
    """Area ``(K,) float64`` m² of the convex hull of the 8 BEV corners of each pair."""
    ax, ay = _corners_a(f)
    bx, by = _corners_b(f)
    c, s = f.c[:, None], f.s[:, None]
    # Outward normals of a's edges (left, rear, right, front) in b's frame: (K, 4) components.
    nax = np.concatenate([-s, -c, s, c], axis=1)
    nay = np.concatenate([c, -s, -c, s], axis=1)
    a_off = np.stack([f.aw, f.al, f.aw, f.al], axis=1)
    b_off = np.stack([f.bw, f.bl, f.bw, f.bl], axis=1)
    # Support of a and b along a's normals, and along b's normals (the axes of b's frame).
    ha_na = nax * f.cx[:, None] + nay * f.cy[:, None] + a_off
    hb_na = f.bl[:, None] * np.abs(nax) + f.bw[:, None] * np.abs(nay)
    gx, gy = _AXIS_NORMALS[:, 0], _AXIS_NORMALS[:, 1]  # (4,)
    ha_nb = (gx * f.cx[:, None] + gy * f.cy[:, None]
             + f.al[:, None] * np.abs(gx * c + gy * s) + f.aw[:, None] * np.abs(-gx * s + gy * c))
    hb_nb = b_off
    a_wins_na = ha_na >= hb_na - TOL  # (K, 4): a reaches as far as b along a's normal j
    a_wins_nb = ha_nb >= hb_nb - TOL  # (K, 4): ... along b's normal j
    b_wins_na = hb_na >= ha_na - TOL
    b_wins_nb = hb_nb >= ha_nb - TOL
    # dot[k, i, j] = (a's normal i) . (b's normal j)
    dot = nax[:, :, None] * gx + nay[:, :, None] * gy
    pos = dot >= 0.0
    # Corner i of a has normal cone spanned by a's normals i-1 and i; likewise for b.
    a_cone = np.roll(pos, 1, axis=1) & pos  # (K, 4 corners of a, 4 normals of b)
    b_cone = np.roll(pos, 1, axis=2) & pos  # (K, 4 normals of a, 4 corners of b)
    a_on = (np.roll(a_wins_na, 1, axis=1) | a_wins_na
            | np.any(a_cone & a_wins_nb[:, None, :], axis=2))
    b_on = (np.roll(b_wins_nb, 1, axis=1) | b_wins_nb
            | np.any(b_cone & b_wins_na[:, :, None], axis=1))
    x = np.concatenate([ax, bx], axis=1)
    y = np.concatenate([ay, by], axis=1)
    return _ring_area(x, y, np.concatenate([a_on, b_on], axis=1))


def _may_overlap(f: _PairFrame) -> np.ndarray:
    """``(K,) bool``: the bounding circles of the pair touch (else the intersection is empty)."""
    ra = np.hypot(f.al, f.aw)
    rb = np.hypot(f.bl, f.bw)
    return np.hypot(f.cx, f.cy) <= ra + rb + TOL


def _subset(f: _PairFrame, mask: np.ndarray) -> _PairFrame:
    """The pairs of ``f`` selected by ``mask (K,) bool``."""
    return _PairFrame(*(arr[mask] for arr in f))


class _BevTerms(NamedTuple):
    """Per-pair BEV areas ``(K,) float64`` m²: intersection, both boxes, hull (None if not needed)."""

    inter: np.ndarray
    area_a: np.ndarray
    area_b: np.ndarray
    hull: np.ndarray | None


def _bev_terms(a: np.ndarray, b: np.ndarray, with_hull: bool) -> _BevTerms:
    """BEV areas of aligned pairs ``a, b (K, >=7)``; the hull only when ``with_hull``."""
    f = _pair_frame(a, b)
    area_a, area_b = a[:, 3] * a[:, 4], b[:, 3] * b[:, 4]
    inter = np.zeros(a.shape[0])
    near = _may_overlap(f) & (area_a > 0.0) & (area_b > 0.0)
    if np.any(near):
        inter[near] = _intersection_area(_subset(f, near))
    inter = np.clip(inter, 0.0, np.minimum(area_a, area_b))
    hull = _hull_area(f) if with_hull else None
    return _BevTerms(inter, area_a, area_b, hull)


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """``num / den`` elementwise, 0 where ``den <= 0``."""
    return np.divide(num, den, out=np.zeros_like(num), where=den > 0.0)


def _giou(iou: np.ndarray, union: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """``iou - (hull - union) / hull`` clipped to [-1, 1]; ``iou`` where ``hull`` is 0."""
    hull = np.maximum(hull, union)
    return np.clip(iou - _ratio(hull - union, hull), -1.0, 1.0)


def _vertical(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overlap and enclosing heights ``(K,) float64`` metres of aligned pairs."""
    a_lo, a_hi = a[:, 2] - 0.5 * a[:, 5], a[:, 2] + 0.5 * a[:, 5]
    b_lo, b_hi = b[:, 2] - 0.5 * b[:, 5], b[:, 2] + 0.5 * b[:, 5]
    overlap = np.maximum(0.0, np.minimum(a_hi, b_hi) - np.maximum(a_lo, b_lo))
    span = np.maximum(a_hi, b_hi) - np.minimum(a_lo, b_lo)
    return overlap, span


def paired_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    a, b = _check_paired(a, b)
    t = _bev_terms(a, b, with_hull=False)
    return np.clip(_ratio(t.inter, t.area_a + t.area_b - t.inter), 0.0, 1.0)


def paired_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing region is the convex hull of the 8 BEV corners.
    """
    a, b = _check_paired(a, b)
    t = _bev_terms(a, b, with_hull=True)
    union = t.area_a + t.area_b - t.inter
    iou = np.clip(_ratio(t.inter, union), 0.0, 1.0)
    return _giou(iou, union, t.hull)


def _volumes(a: np.ndarray, b: np.ndarray, t: _BevTerms) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """3D IoU ``(K,)``, union volume ``(K,)`` m³ and vertical span ``(K,)`` m of aligned pairs."""
    overlap, span = _vertical(a, b)
    inter = t.inter * overlap
    union = t.area_a * a[:, 5] + t.area_b * b[:, 5] - inter
    return np.clip(_ratio(inter, union), 0.0, 1.0), union, span


def paired_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(K,) float64`` in [0, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``."""
    a, b = _check_paired(a, b)
    return _volumes(a, b, _bev_terms(a, b, with_hull=False))[0]


def paired_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(K,) float64`` in [-1, 1] of aligned pairs ``a[k], b[k]``, both ``(K, >=7)``.

    The enclosing volume is the convex hull of the 8 BEV corners times the vertical span of both.
    """
    a, b = _check_paired(a, b)
    t = _bev_terms(a, b, with_hull=True)
    iou, union, span = _volumes(a, b, t)
    return _giou(iou, union, t.hull * span)


def _pairwise(fn, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Apply the paired measure ``fn`` to all pairs of ``a (N, >=7)`` x ``b (M, >=7)`` -> ``(N, M)``."""
    a, b = _check_boxes(a, "a"), _check_boxes(b, "b")
    n, m = a.shape[0], b.shape[0]
    out = np.zeros((n, m))
    if n == 0 or m == 0:
        return out
    rows = max(1, CHUNK_PAIRS // m)
    for start in range(0, n, rows):
        block = a[start:start + rows]
        out[start:start + block.shape[0]] = fn(np.repeat(block, m, axis=0),
                                               np.tile(b, (block.shape[0], 1))).reshape(-1, m)
    return out


def pairwise_bev_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(paired_bev_iou, a, b)


def pairwise_bev_giou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(paired_bev_giou, a, b)


def pairwise_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D IoU ``(N, M) float64`` in [0, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(paired_iou_3d, a, b)


def pairwise_giou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """3D GIoU ``(N, M) float64`` in [-1, 1] between ``a (N, >=7)`` and ``b (M, >=7)``."""
    return _pairwise(paired_giou_3d, a, b)


def pairwise_centre_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """BEV distance ``(N, M) float64`` in metres between the centres of ``a (N, >=2)`` and ``b (M, >=2)``."""
    a, b = _check_boxes(a, "a", min_cols=2), _check_boxes(b, "b", min_cols=2)
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
