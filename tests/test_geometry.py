"""Tests of grutrack.geometry: rotated-box IoU / GIoU (BEV and 3D) against Shapely and exact values."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely

from grutrack import geometry as geo

MEASURES = {
    "bev_iou": (geo.paired_bev_iou, geo.pairwise_bev_iou),
    "bev_giou": (geo.paired_bev_giou, geo.pairwise_bev_giou),
    "iou_3d": (geo.paired_iou_3d, geo.pairwise_iou_3d),
    "giou_3d": (geo.paired_giou_3d, geo.pairwise_giou_3d),
}


# --------------------------------------------------------------------------------------------------
# Reference: Shapely areas, written independently of the module under test.


def _ref_corners(boxes: np.ndarray) -> np.ndarray:
    """(K, 4, 2) corners by rotation matrices: front-left, rear-left, rear-right, front-right."""
    local = np.stack(
        [
            np.stack([boxes[:, 4] / 2, boxes[:, 3] / 2], axis=-1),
            np.stack([-boxes[:, 4] / 2, boxes[:, 3] / 2], axis=-1),
            np.stack([-boxes[:, 4] / 2, -boxes[:, 3] / 2], axis=-1),
            np.stack([boxes[:, 4] / 2, -boxes[:, 3] / 2], axis=-1),
        ],
        axis=1,
    )
    yaw = boxes[:, 6]
    rot = np.stack(
        [np.stack([np.cos(yaw), -np.sin(yaw)], -1), np.stack([np.sin(yaw), np.cos(yaw)], -1)], axis=1
    )  # (K, 2, 2)
    return np.einsum("kij,kpj->kpi", rot, local) + boxes[:, None, :2]


def _reference(a: np.ndarray, b: np.ndarray) -> dict[str, np.ndarray]:
    """All four measures of aligned pairs from Shapely areas, with the documented conventions."""
    ca, cb = _ref_corners(a), _ref_corners(b)
    pa, pb = shapely.polygons(ca), shapely.polygons(cb)
    inter = shapely.area(shapely.intersection(pa, pb))
    union = shapely.area(shapely.union(pa, pb))
    points = np.concatenate([ca, cb], axis=1)
    hull = shapely.area(shapely.convex_hull(shapely.multipoints(points)))
    # Documented convention: a hull that is rounding noise of collinear points has area 0.
    extent = np.ptp(points, axis=1).max(axis=1)
    hull[hull <= 1e-13 * extent**2] = 0.0

    def iou_giou(i, u, c):
        iou = np.divide(i, u, out=np.zeros_like(i), where=u > 0)
        giou = iou - np.divide(c - u, c, out=np.zeros_like(c), where=c > 0)
        return iou, giou

    bev_iou, bev_giou = iou_giou(inter, union, hull)
    a_lo, a_hi = a[:, 2] - a[:, 5] / 2, a[:, 2] + a[:, 5] / 2
    b_lo, b_hi = b[:, 2] - b[:, 5] / 2, b[:, 2] + b[:, 5] / 2
    dz = np.maximum(0.0, np.minimum(a_hi, b_hi) - np.maximum(a_lo, b_lo))
    span = np.maximum(a_hi, b_hi) - np.minimum(a_lo, b_lo)
    inter3 = inter * dz
    union3 = a[:, 3] * a[:, 4] * a[:, 5] + b[:, 3] * b[:, 4] * b[:, 5] - inter3
    iou3, giou3 = iou_giou(inter3, union3, hull * span)
    return {"bev_iou": bev_iou, "bev_giou": bev_giou, "iou_3d": iou3, "giou_3d": giou3}


def _box(x=0.0, y=0.0, z=0.0, w=2.0, l=4.0, h=1.5, yaw=0.0) -> np.ndarray:
    """One (1, 9) box."""
    return np.array([[x, y, z, w, l, h, yaw, 0.0, 0.0]])


def _all_paired(a: np.ndarray, b: np.ndarray) -> dict[str, np.ndarray]:
    return {name: paired(a, b) for name, (paired, _) in MEASURES.items()}


def _assert_matches_reference(a: np.ndarray, b: np.ndarray, atol: float = 1e-6) -> dict:
    got, ref = _all_paired(a, b), _reference(a, b)
    for name in MEASURES:
        assert got[name].shape == (a.shape[0],)
        err = np.abs(got[name] - ref[name])
        worst = int(np.argmax(err)) if err.size else 0
        assert err.size == 0 or err[worst] <= atol, (
            f"{name}: error {err[worst]:.3g} at pair {worst}: a={a[worst].tolist()} b={b[worst].tolist()}"
        )
    return got


def _random_boxes(rng: np.random.Generator, k: int) -> np.ndarray:
    """(k, 9) boxes with sizes 0.3-15 m (log-uniform, independent w / l / h) and any yaw."""
    boxes = np.zeros((k, 9))
    boxes[:, 3:6] = np.exp(rng.uniform(np.log(0.3), np.log(15.0), (k, 3)))
    boxes[:, 6] = rng.uniform(-np.pi, np.pi, k)
    boxes[:, 2] = rng.uniform(-2.0, 2.0, k)
    boxes[:, 7:9] = rng.normal(size=(k, 2))
    return boxes


def _random_pairs(rng: np.random.Generator, k: int) -> tuple[np.ndarray, np.ndarray]:
    """k pairs whose centres are 0-1.3 x (sum of half diagonals) apart: about half overlap."""
    a, b = _random_boxes(rng, k), _random_boxes(rng, k)
    reach = np.hypot(a[:, 3], a[:, 4]) / 2 + np.hypot(b[:, 3], b[:, 4]) / 2
    dist = reach * rng.uniform(0.0, 1.3, k)
    ang = rng.uniform(-np.pi, np.pi, k)
    a[:, :2] = rng.uniform(-50.0, 50.0, (k, 2))
    b[:, :2] = a[:, :2] + dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=-1)
    return a, b


# --------------------------------------------------------------------------------------------------
# Corners.


def test_bev_corners_layout_and_orientation():
    got = geo.bev_corners(_box(x=1.0, y=2.0, w=2.0, l=4.0, yaw=0.0))
    np.testing.assert_allclose(got[0], [[3, 3], [-1, 3], [-1, 1], [3, 1]], atol=1e-12)
    # Heading +y: front is +y, left of the heading is -x.
    got = geo.bev_corners(_box(x=1.0, y=2.0, w=2.0, l=4.0, yaw=np.pi / 2))
    np.testing.assert_allclose(got[0], [[0, 4], [0, 0], [2, 0], [2, 4]], atol=1e-12)

    boxes = _random_boxes(np.random.default_rng(0), 200)
    corners = geo.bev_corners(boxes)
    assert corners.shape == (200, 4, 2)
    x, y = corners[..., 0], corners[..., 1]
    signed_area = 0.5 * (x * np.roll(y, -1, axis=1) - y * np.roll(x, -1, axis=1)).sum(axis=1)
    np.testing.assert_allclose(signed_area, boxes[:, 3] * boxes[:, 4], rtol=1e-12)  # CCW
    np.testing.assert_allclose(corners, _ref_corners(boxes), atol=1e-12)
    assert geo.bev_corners(np.zeros((0, 9))).shape == (0, 4, 2)


# --------------------------------------------------------------------------------------------------
# Random pairs against Shapely.


@pytest.mark.parametrize("seed", [0, 1])
def test_random_pairs_match_shapely(seed):
    rng = np.random.default_rng(seed)
    a, b = _random_pairs(rng, 2500)
    got = _assert_matches_reference(a, b)
    overlapping = got["bev_iou"] > 0
    assert 0.3 < overlapping.mean() < 0.8  # the sample covers both cases
    for name in ("bev_iou", "iou_3d"):
        assert np.all((got[name] >= 0) & (got[name] <= 1))
    for name in ("bev_giou", "giou_3d"):
        assert np.all((got[name] >= -1) & (got[name] <= 1))
        assert np.all(got[name] <= got[name.replace("giou", "iou")] + 1e-12)


def test_large_global_coordinates_match_shapely():
    """nuScenes-like global coordinates (kilometres away from the origin) lose no accuracy."""
    rng = np.random.default_rng(2)
    a, b = _random_pairs(rng, 1000)
    shift = np.array([1834.123, -2291.75])
    a[:, :2] += shift
    b[:, :2] += shift
    _assert_matches_reference(a, b)


def test_elongated_and_unequal_boxes_match_shapely():
    """Very thin / long boxes against large ones (many crossing edges)."""
    rng = np.random.default_rng(3)
    a, b = _random_pairs(rng, 1500)
    a[:, 3] = rng.uniform(0.3, 0.5, 1500)
    a[:, 4] = rng.uniform(10.0, 15.0, 1500)
    b[:, 3] = rng.uniform(5.0, 15.0, 1500)
    b[:, :2] = a[:, :2] + rng.uniform(-3, 3, (1500, 2))
    _assert_matches_reference(a, b)


def test_nearly_coincident_edges_match_shapely():
    """Edges collinear, or off by a hair in offset or angle: the numerically delicate cases."""
    rng = np.random.default_rng(4)
    base = _random_boxes(rng, 60)
    base[:, :2] = rng.uniform(-1000, 1000, (60, 2))
    pairs_a, pairs_b = [], []
    for eps_shift, eps_yaw in itertools.product([0.0, 1e-12, -1e-12, 1e-9, -1e-7], [0.0, 1e-12, -1e-10, 1e-7]):
        for along, across in [(1.0, 0.0), (0.0, 1.0), (0.5, 0.0), (0.3, 1.0), (1.0, 1.0), (0.0, 0.0)]:
            b = base.copy()
            c, s = np.cos(b[:, 6]), np.sin(b[:, 6])
            du = along * b[:, 4] + eps_shift  # along the heading, in metres
            dv = across * b[:, 3] + eps_shift  # across it
            b[:, 0] += du * c - dv * s
            b[:, 1] += du * s + dv * c
            b[:, 6] += eps_yaw
            pairs_a.append(base)
            pairs_b.append(b)
    a, b = np.concatenate(pairs_a), np.concatenate(pairs_b)
    _assert_matches_reference(a, b)


def test_same_yaw_and_right_angles_match_shapely():
    """Axis-aligned and right-angle configurations with integer sizes (exactly shared coordinates)."""
    rng = np.random.default_rng(5)
    k = 2000
    a = np.zeros((k, 9))
    b = np.zeros((k, 9))
    for boxes in (a, b):
        boxes[:, :2] = rng.integers(-4, 5, (k, 2)) * 0.5
        boxes[:, 3:5] = rng.integers(1, 7, (k, 2)).astype(float)
        boxes[:, 5] = 1.0
        boxes[:, 6] = rng.integers(-2, 3, k) * (np.pi / 2)
    got = _assert_matches_reference(a, b)
    touching = (got["bev_iou"] == 0) & (np.abs(got["bev_giou"]) < 1e-12)
    assert np.any(touching) and np.any(got["bev_iou"] > 0.8)  # the sample has the delicate cases


# --------------------------------------------------------------------------------------------------
# Special cases with exact values.


def test_identical_boxes_score_one():
    boxes = _random_boxes(np.random.default_rng(6), 300)
    flipped = boxes.copy()
    flipped[:, 6] += np.pi  # the same rectangle, heading reversed
    for other in (boxes, flipped):
        for name, value in _all_paired(boxes, other).items():
            np.testing.assert_allclose(value, 1.0, atol=1e-9, err_msg=name)


def test_nested_boxes():
    rng = np.random.default_rng(7)
    outer = _random_boxes(rng, 200)
    outer[:, 3:5] = rng.uniform(6.0, 12.0, (200, 2))
    inner = outer.copy()
    inner[:, 3:5] = rng.uniform(0.3, 1.5, (200, 2))
    inner[:, 6] = rng.uniform(-np.pi, np.pi, 200)
    inner[:, :2] += rng.uniform(-1.5, 1.5, (200, 2))  # stays inside: half extents >= 3 m
    inner[:, 5] = outer[:, 5]
    ratio = inner[:, 3] * inner[:, 4] / (outer[:, 3] * outer[:, 4])
    got = _all_paired(inner, outer)
    for name in MEASURES:  # hull = outer box and equal heights: GIoU = IoU = area ratio
        np.testing.assert_allclose(got[name], ratio, atol=1e-9, err_msg=name)
    _assert_matches_reference(inner, outer)


@pytest.mark.parametrize("yaw", [0.0, 0.3, np.pi / 2, -2.1, np.pi])
def test_touching_edge_to_edge(yaw):
    a = _box(x=12.5, y=-3.0, w=1.8, l=4.4, yaw=yaw)
    c, s = np.cos(yaw), np.sin(yaw)
    front = _box(x=12.5 + 4.4 * c, y=-3.0 + 4.4 * s, w=1.8, l=4.4, yaw=yaw)
    side = _box(x=12.5 - 1.8 * s, y=-3.0 + 1.8 * c, w=1.8, l=4.4, yaw=yaw + np.pi)
    for b in (front, side):
        for name, value in _all_paired(a, b).items():
            assert abs(value[0]) <= 1e-9, (name, value)  # IoU 0, and hull = union so GIoU 0


def test_touching_with_offset_along_the_edge():
    yaw = 0.7
    c, s = np.cos(yaw), np.sin(yaw)
    a = _box(w=2.0, l=4.0, yaw=yaw)
    b = _box(x=4.0 * c - 1.0 * s, y=4.0 * s + 1.0 * c, w=2.0, l=4.0, yaw=yaw)  # slid by 1 m
    got = _assert_matches_reference(a, b)
    assert abs(got["bev_iou"][0]) <= 1e-9
    # Union 16 m2; hull = union + two triangles of (4 x 1) / 2 and (4 x 1) / 2 = 20 m2.
    np.testing.assert_allclose(got["bev_giou"], -(20.0 - 16.0) / 20.0, atol=1e-9)


def test_corner_touching():
    yaw = -1.1
    c, s = np.cos(yaw), np.sin(yaw)
    w, l = 2.0, 4.0
    a = _box(w=w, l=l, yaw=yaw)
    b = _box(x=l * c - w * s, y=l * s + w * c, w=w, l=l, yaw=yaw)  # shares exactly one corner
    got = _assert_matches_reference(a, b)
    assert abs(got["bev_iou"][0]) <= 1e-9 and abs(got["iou_3d"][0]) <= 1e-9
    # Hull is a hexagon of area 3 w l around a union of 2 w l.
    np.testing.assert_allclose(got["bev_giou"], -1.0 / 3.0, atol=1e-9)
    np.testing.assert_allclose(got["giou_3d"], -1.0 / 3.0, atol=1e-9)


def test_same_centre_rotated():
    square = _box(w=2.0, l=2.0)
    rect = _box(w=2.0, l=4.0)
    # Square by 90 degrees: the same square.
    for name, value in _all_paired(square, _box(w=2.0, l=2.0, yaw=np.pi / 2)).items():
        np.testing.assert_allclose(value, 1.0, atol=1e-9, err_msg=name)
    # 2 x 4 rectangle by 90 degrees: I = 4, U = 12, hull = octagon of 16 - 4 * 0.5 = 14.
    got = _assert_matches_reference(rect, _box(w=2.0, l=4.0, yaw=np.pi / 2))
    np.testing.assert_allclose(got["bev_iou"], 1.0 / 3.0, atol=1e-9)
    np.testing.assert_allclose(got["bev_giou"], 1.0 / 3.0 - 2.0 / 14.0, atol=1e-9)
    # Square by 45 degrees: I = regular octagon 8 (sqrt2 - 1), IoU = 1/sqrt2, hull = 4 sqrt2.
    got = _assert_matches_reference(square, _box(w=2.0, l=2.0, yaw=np.pi / 4))
    inter = 8.0 * (np.sqrt(2.0) - 1.0)
    union = 8.0 - inter
    np.testing.assert_allclose(got["bev_iou"], 1.0 / np.sqrt(2.0), atol=1e-9)
    hull = 4.0 * np.sqrt(2.0)
    np.testing.assert_allclose(got["bev_giou"], inter / union - (hull - union) / hull, atol=1e-9)
    _assert_matches_reference(rect, _box(w=2.0, l=4.0, yaw=np.pi / 4))


def test_far_apart_boxes_giou_tends_to_minus_one():
    a = _box(w=2.0, l=4.0, yaw=0.2)
    # up to distances where the corners are lost in rounding (a diverged track): GIoU stays at -1, not 0
    for dist in (1e2, 1e4, 1e6, 1e12, 1e15, 1e18):
        b = _box(x=dist, y=0.5 * dist, w=1.0, l=1.0, yaw=-1.0)
        got = _all_paired(a, b)
        for name in ("bev_giou", "giou_3d"):
            assert MEASURES[name][1](a, b)[0, 0] == got[name][0], name
        assert got["bev_iou"][0] == 0.0 and got["iou_3d"][0] == 0.0
        assert -1.0 <= got["bev_giou"][0] < -1.0 + 100.0 / dist
        assert -1.0 <= got["giou_3d"][0] < -1.0 + 100.0 / dist
        if dist <= 1e4:
            _assert_matches_reference(a, b, atol=1e-9)


def test_degenerate_boxes_are_finite_and_follow_the_conventions():
    normal = _box(w=2.0, l=4.0, h=1.5, yaw=0.4)
    flat_w = _box(w=0.0, l=4.0, h=1.5, yaw=0.4)  # a segment in BEV
    flat_l = _box(w=2.0, l=0.0, h=1.5, yaw=0.4)
    flat_h = _box(w=2.0, l=4.0, h=0.0, yaw=0.4)  # a rectangle of zero volume
    point = _box(w=0.0, l=0.0, h=0.0, yaw=0.4)
    boxes = np.concatenate([normal, flat_w, flat_l, flat_h, point])
    for name, (_, pairwise) in MEASURES.items():
        got = pairwise(boxes, boxes)
        assert got.shape == (5, 5) and np.all(np.isfinite(got)), name
    a, b = np.repeat(boxes, 5, axis=0), np.tile(boxes, (5, 1))
    got = _assert_matches_reference(a, b, atol=1e-9)
    grid = {name: value.reshape(5, 5) for name, value in got.items()}
    # Any zero-area box has IoU 0 with anything, itself included (union 0 -> IoU 0).
    assert np.all(grid["bev_iou"][1:3] == 0) and np.all(grid["bev_iou"][:, 1:3] == 0)
    assert np.all(grid["bev_iou"][4] == 0)
    # Identical segments: union 0 and hull 0 -> GIoU = IoU = 0.
    assert grid["bev_giou"][1, 1] == 0.0 and grid["bev_giou"][4, 4] == 0.0
    # A segment inside the normal box: hull = union = the box -> GIoU 0.
    assert abs(grid["bev_giou"][0, 1]) <= 1e-12
    # Zero height: the BEV measures are untouched, the 3D IoU is 0.
    assert grid["bev_iou"][0, 3] == pytest.approx(1.0, abs=1e-12)
    assert grid["iou_3d"][0, 3] == 0.0 and grid["iou_3d"][3, 3] == 0.0
    # Two zero-area parallel segments apart: union 0 but hull > 0 -> GIoU -1.
    apart = _box(x=0.0, y=3.0, w=0.0, l=4.0)
    np.testing.assert_allclose(geo.paired_bev_giou(_box(w=0.0, l=4.0), apart), [-1.0])


def test_special_cases_raise_no_floating_point_errors():
    """Parallel / collinear edges and zero sizes must not divide by zero or make NaN on the way."""
    boxes = np.concatenate(
        [
            _box(),
            _box(x=4.0),
            _box(y=2.0),
            _box(x=4.0, y=2.0),
            _box(yaw=np.pi / 2),
            _box(w=0.0),
            _box(l=0.0, h=0.0),
            _box(w=0.0, l=0.0, h=0.0),
            _box(x=1e4),
            _box(yaw=np.pi),
        ]
    )
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        for _, (_, pairwise) in MEASURES.items():
            assert np.all(np.isfinite(pairwise(boxes, boxes)))


# --------------------------------------------------------------------------------------------------
# 3D.


def test_vertical_offsets():
    h = 2.0
    a = _box(z=1.0, h=h, yaw=0.9)
    half_up = _box(z=1.0 + h / 2, h=h, yaw=0.9)
    # Same footprint, half overlap in height: IoU = 1 / 3; enclosing volume = union -> GIoU = 1 / 3.
    np.testing.assert_allclose(geo.paired_iou_3d(a, half_up), [1 / 3], atol=1e-12)
    np.testing.assert_allclose(geo.paired_giou_3d(a, half_up), [1 / 3], atol=1e-12)
    # A gap g between them: IoU 0, GIoU = -g / (2 h + g); BEV untouched.
    gap = 0.5
    above = _box(z=1.0 + h + gap, h=h, yaw=0.9)
    np.testing.assert_allclose(geo.paired_iou_3d(a, above), [0.0], atol=1e-12)
    np.testing.assert_allclose(geo.paired_giou_3d(a, above), [-gap / (2 * h + gap)], atol=1e-12)
    np.testing.assert_allclose(geo.paired_bev_iou(a, above), [1.0], atol=1e-12)
    # Stacked exactly on top: IoU 0 and GIoU 0.
    stacked = _box(z=1.0 + h, h=h, yaw=0.9)
    np.testing.assert_allclose(geo.paired_iou_3d(a, stacked), [0.0], atol=1e-12)
    np.testing.assert_allclose(geo.paired_giou_3d(a, stacked), [0.0], atol=1e-12)
    # A shorter box inside the height of a taller one with the same footprint: volume ratio.
    short = _box(z=1.2, h=0.5, yaw=0.9)
    np.testing.assert_allclose(geo.paired_iou_3d(a, short), [0.25], atol=1e-12)
    np.testing.assert_allclose(geo.paired_giou_3d(a, short), [0.25], atol=1e-12)


def test_random_3d_offsets_match_shapely():
    rng = np.random.default_rng(8)
    a, b = _random_pairs(rng, 1500)
    b[:, 2] = a[:, 2] + rng.uniform(-1.2, 1.2, 1500) * (a[:, 5] + b[:, 5])
    got = _assert_matches_reference(a, b)
    # Some pairs overlap in BEV but not in height.
    assert np.any((got["bev_iou"] > 0) & (got["iou_3d"] == 0))


# --------------------------------------------------------------------------------------------------
# Shapes, validation, consistency.


@pytest.mark.parametrize("n, m", [(0, 5), (4, 0), (0, 0)])
def test_empty_inputs_give_empty_arrays(n, m):
    rng = np.random.default_rng(9)
    a, b = _random_boxes(rng, n), _random_boxes(rng, m)
    for name, (paired, pairwise) in MEASURES.items():
        out = pairwise(a, b)
        assert out.shape == (n, m) and out.dtype == np.float64, name
    assert geo.pairwise_centre_distance(a, b).shape == (n, m)
    for name, (paired, _) in MEASURES.items():
        assert paired(np.zeros((0, 7)), np.zeros((0, 9))).shape == (0,), name


def test_pairwise_equals_paired_and_is_symmetric(monkeypatch):
    rng = np.random.default_rng(10)
    a, b = _random_boxes(rng, 23), _random_boxes(rng, 31)
    a[:, :2] = rng.uniform(0, 20, (23, 2))
    b[:, :2] = rng.uniform(0, 20, (31, 2))
    ia, ib = np.repeat(np.arange(23), 31), np.tile(np.arange(31), 23)
    full = {}
    for name, (paired, pairwise) in MEASURES.items():
        full[name] = pairwise(a, b)
        assert full[name].shape == (23, 31)
        np.testing.assert_allclose(full[name], paired(a[ia], b[ib]).reshape(23, 31), atol=1e-12)
        np.testing.assert_allclose(full[name], pairwise(b, a).T, atol=1e-9)
        # Only the first 7 columns matter.
        np.testing.assert_allclose(full[name], pairwise(a[:, :7], b[:, :7]), atol=0)
    assert np.any(full["bev_iou"] > 0)
    # Small chunks give the same numbers.
    monkeypatch.setattr(geo, "CHUNK_PAIRS", 50)
    for name, (_, pairwise) in MEASURES.items():
        np.testing.assert_allclose(pairwise(a, b), full[name], atol=1e-12)


def test_rigid_motion_invariance():
    rng = np.random.default_rng(11)
    a, b = _random_pairs(rng, 500)
    theta, shift = 1.234, np.array([-523.5, 311.25])
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    moved = []
    for boxes in (a, b):
        m = boxes.copy()
        m[:, :2] = boxes[:, :2] @ rot.T + shift
        m[:, 6] = boxes[:, 6] + theta
        m[:, 2] += 7.0
        moved.append(m)
    before, after = _all_paired(a, b), _all_paired(*moved)
    for name in MEASURES:
        np.testing.assert_allclose(after[name], before[name], atol=1e-9, err_msg=name)


def test_centre_distance():
    a = np.array([[0.0, 0.0], [3.0, 4.0]])
    b = _random_boxes(np.random.default_rng(12), 3)
    b[:, :2] = [[3.0, 4.0], [-6.0, 8.0], [0.0, 0.0]]
    got = geo.pairwise_centre_distance(a, b)
    np.testing.assert_allclose(got, [[5.0, 10.0, 0.0], [0.0, np.hypot(9, 4), 5.0]], atol=1e-12)


@pytest.mark.parametrize("bad", [np.zeros(7), np.zeros((3, 6)), np.zeros((2, 2, 7))])
def test_bad_shapes_raise(bad):
    good = _random_boxes(np.random.default_rng(13), 3)
    with pytest.raises(ValueError):
        geo.pairwise_bev_iou(bad, good)
    with pytest.raises(ValueError):
        geo.bev_corners(bad)


def test_invalid_values_raise():
    good = _random_boxes(np.random.default_rng(14), 3)
    with pytest.raises(ValueError, match="equal counts"):
        geo.paired_bev_iou(good, good[:2])
    negative = good.copy()
    negative[1, 4] = -1.0
    nan = good.copy()
    nan[0, 6] = np.nan
    for bad in (negative, nan):
        for _, (paired, pairwise) in MEASURES.items():
            with pytest.raises(ValueError):
                pairwise(good, bad)
            with pytest.raises(ValueError):
                paired(bad, good)
    velocity_nan = good.copy()
    velocity_nan[:, 7] = np.nan  # ignored columns may hold anything
    assert np.all(np.isfinite(geo.pairwise_giou_3d(velocity_nan, good)))


def test_paired_similarities_equal_the_single_measures():
    from grutrack import geometry as g

    rng = np.random.default_rng(11)
    n = 3000
    a = np.column_stack(
        [rng.uniform(-8, 8, (n, 2)), rng.uniform(-1, 1, n), rng.uniform(0.3, 6, (n, 3)), rng.uniform(-np.pi, np.pi, n)]
    )
    b = np.column_stack(
        [rng.uniform(-8, 8, (n, 2)), rng.uniform(-1, 1, n), rng.uniform(0.3, 6, (n, 3)), rng.uniform(-np.pi, np.pi, n)]
    )
    got = g.paired_similarities(a, b, g.SIMILARITIES)
    for name, fn in (
        ("iou_bev", g.paired_bev_iou),
        ("giou_bev", g.paired_bev_giou),
        ("iou_3d", g.paired_iou_3d),
        ("giou_3d", g.paired_giou_3d),
    ):
        np.testing.assert_array_equal(got[name], fn(a, b))
    assert set(g.paired_similarities(a[:5], b[:5], ["giou_3d"])) == {"giou_3d"}
