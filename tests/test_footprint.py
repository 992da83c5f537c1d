"""A detection's footprint as its bottom face (``preprocessing.footprint: bottom_face``, Poly-MOT's): the corners
against the nuScenes devkit's, the four measures against shapely and scipy computed as Poly-MOT computes them, the
association's pruning, and the two places the footprint decides: blend NMS and which track a tilted detection takes."""

from __future__ import annotations

import numpy as np
import pytest
from nuscenes.utils.data_classes import Box
from pyquaternion import Quaternion
from scipy.spatial import ConvexHull
from shapely.geometry import Polygon

from grutrack import geometry
from grutrack.boxes import quaternion_from_yaw
from grutrack.classes import CLASS_INDEX
from grutrack.data.scene import BoxSet
from grutrack.tracking import association
from grutrack.tracking.config import config_from_dict
from grutrack.tracking.preprocess import preprocess_frame
from grutrack.tracking.tracker import two_stage_association

NAMES = geometry.SIMILARITIES


def _tilted(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions [w, x, y, z] of yaw about z, then pitch about y, then roll about x (intrinsic)."""
    return np.array(
        [
            (
                Quaternion(axis=[0, 0, 1], angle=y)
                * Quaternion(axis=[0, 1, 0], angle=p)
                * Quaternion(axis=[1, 0, 0], angle=r)
            ).q
            for y, p, r in zip(yaw, pitch, roll)
        ]
    )


def _boxes(rng: np.random.Generator, n: int, spread: float = 4.0) -> np.ndarray:
    """(n, 9) random boxes about (1000, 2000) m: sizes 0.4-5 m, any yaw, no velocity."""
    b = np.zeros((n, 9))
    b[:, :2] = rng.uniform(-spread, spread, (n, 2)) + [1000.0, 2000.0]
    b[:, 2] = rng.uniform(0.0, 1.5, n)
    b[:, 3:6] = rng.uniform(0.4, 5.0, (n, 3))
    b[:, 6] = rng.uniform(-np.pi, np.pi, n)
    return b


def _poly_mot_measures(a, ca, b, cb) -> dict[str, float]:
    """Poly-MOT's giou_3d / iou_3d of one pair (geometry/nusc_distance.py): shapely's intersection of the bottom
    faces, scipy's convex hull of their 8 corners, areas w l and heights from the centre's z."""
    inter = Polygon(ca).intersection(Polygon(cb)).area
    union = a[3] * a[4] + b[3] * b[4] - inter
    hull = ConvexHull(np.vstack([ca, cb])).volume  # a 2-D hull's "volume" is its area
    overlap = max(0.0, min(a[2] + a[5] / 2, b[2] + b[5] / 2) - max(a[2] - a[5] / 2, b[2] - b[5] / 2))
    span = max(a[2] + a[5] / 2, b[2] + b[5] / 2) - min(a[2] - a[5] / 2, b[2] - b[5] / 2)
    union3 = a[3] * a[4] * a[5] + b[3] * b[4] * b[5] - inter * overlap
    return {
        "iou_bev": inter / union,
        "giou_bev": inter / union - (hull - union) / hull,
        "iou_3d": inter * overlap / union3,
        "giou_3d": inter * overlap / union3 - (hull * span - union3) / (hull * span),
    }


def test_bottom_corners_are_the_devkits_bottom_face_counter_clockwise():
    rng = np.random.default_rng(0)
    b = _boxes(rng, 50)
    q = _tilted(b[:, 6], rng.normal(0, 0.2, 50), rng.normal(0, 0.2, 50))
    c = geometry.bottom_corners(b, q)
    for k in range(50):
        devkit = Box(b[k, :3], b[k, 3:6], Quaternion(q[k])).bottom_corners()[:2].T  # (4, 2)
        # the same four points, in counter-clockwise order (positive shoelace area)
        assert min(np.abs(np.roll(devkit[::s], r, axis=0) - c[k]).max() for r in range(4) for s in (1, -1)) < 1e-9
        x, y = c[k, :, 0], c[k, :, 1]
        assert np.sum(x * np.roll(y, -1) - y * np.roll(x, -1)) > 0
    flipped = geometry.bottom_corners(b[:1], _tilted(b[:1, 6], [np.pi], [0.0]))  # upside down: still CCW
    x, y = flipped[0, :, 0], flipped[0, :, 1]
    assert np.sum(x * np.roll(y, -1) - y * np.roll(x, -1)) > 0


def test_bottom_corners_of_a_yaw_only_box_are_its_rectangle():
    b = _boxes(np.random.default_rng(1), 40)
    np.testing.assert_allclose(
        geometry.bottom_corners(b, quaternion_from_yaw(b[:, 6])), geometry.bev_corners(b), atol=1e-9
    )
    assert np.array_equal(geometry.bottom_corners(b), geometry.bev_corners(b))


def test_footprint_measures_are_poly_mots_on_tilted_boxes():
    rng = np.random.default_rng(2)
    a, b = _boxes(rng, 25), _boxes(rng, 20)
    ca = geometry.bottom_corners(a, _tilted(a[:, 6], rng.normal(0, 0.15, 25), rng.normal(0, 0.15, 25)))
    cb = geometry.bev_corners(b)
    got = geometry.footprint_similarities(a, ca, b, cb, NAMES)
    worst = 0.0
    for i in range(len(a)):
        for j in range(len(b)):
            want = _poly_mot_measures(a[i], ca[i], b[j], cb[j])
            worst = max(worst, max(abs(got[n][i, j] - want[n]) for n in NAMES))
    assert worst < 1e-9
    assert (got["iou_bev"] > 0).sum() > 20  # the set has overlapping pairs, not only far ones
    paired = geometry.footprint_similarities(a[:20], ca[:20], b, cb, NAMES, pairwise=False)
    for n in NAMES:
        np.testing.assert_array_equal(paired[n], np.diag(got[n][:20]))


def test_footprint_measures_of_rectangles_equal_the_rectangle_measures():
    rng = np.random.default_rng(3)
    a, b = _boxes(rng, 30), _boxes(rng, 30)
    got = geometry.footprint_similarities(a, geometry.bev_corners(a), b, geometry.bev_corners(b), NAMES)
    for n in NAMES:
        np.testing.assert_allclose(got[n], geometry._pairwise_measure(n, a, b), atol=1e-12)
    where = rng.random((30, 30)) < 0.5
    masked = geometry.footprint_similarities(a, geometry.bev_corners(a), b, geometry.bev_corners(b), NAMES, where=where)
    for n in NAMES:
        assert np.array_equal(masked[n], np.where(where, got[n], 0.0))


def test_two_equal_tilted_boxes_score_above_one_as_in_poly_mot():
    # the bottom face of a tilted box is smaller than w l, so U = 2 w l - I exceeds the hull C: GIoU = I/U + U/C - 1
    b = np.array([[0.0, 0.0, 1.0, 2.0, 4.5, 1.6, 0.3, 0.0, 0.0]])
    c = geometry.bottom_corners(b, _tilted([0.3], [0.1], [0.05]))
    got = geometry.footprint_similarities(b, c, b, c, NAMES)
    want = _poly_mot_measures(b[0], c[0], b[0], c[0])
    assert got["giou_bev"][0, 0] > 1.0
    for n in NAMES:
        assert got[n][0, 0] == pytest.approx(want[n], abs=1e-12)


def test_footprint_costs_prune_no_pair_that_could_pass():
    rng = np.random.default_rng(4)
    D, T = 60, 50
    det, trk = _boxes(rng, D, spread=8.0), _boxes(rng, T, spread=8.0)
    det_labels, trk_labels = rng.integers(0, 3, D), rng.integers(0, 3, T)
    corners = geometry.bottom_corners(det, _tilted(det[:, 6], rng.normal(0, 0.1, D), rng.normal(0, 0.1, D)))
    metric = ("giou_3d", "giou_bev", "iou_bev")  # per class 0, 1, 2 (the rest unused)
    stages = [(metric + ("giou_bev",) * 4, np.full(7, 1.3)), (("giou_bev",) * 7, np.full(7, 1.0))]
    costs = association._candidate_costs(det, det_labels, trk, trk_labels, stages, corners)
    dense = geometry.footprint_similarities(det, corners, trk, geometry.bev_corners(trk), NAMES)
    same = det_labels[:, None] == trk_labels[None, :]
    for st, (names, thr) in enumerate(stages):
        want = 1.0 - np.stack([dense[names[lab]][i] for i, lab in enumerate(det_labels)])  # (D, T)
        could = same & (want < thr[0])
        assert could.sum() > 15 and (same & ~could).sum() > 300  # pairs on both sides of the threshold
        np.testing.assert_allclose(costs[st][could], want[could], atol=1e-12)
        measured = costs[st] < association._INVALID
        assert not np.any(measured & ~same)  # other classes never measured
        np.testing.assert_allclose(costs[st][measured], want[measured], atol=1e-12)
        assert measured.sum() < same.sum()  # the bound skipped some far pairs


def _polymot(preset: str = "polymot", **preprocessing) -> object:
    import yaml

    from grutrack.tracking.config import preset_path

    raw = yaml.safe_load(preset_path(preset).read_text())
    raw["preprocessing"].update(preprocessing)
    return config_from_dict(raw)


def _car(x: float, yaw: float = 0.0) -> list[float]:
    return [x, 0.0, 1.0, 1.8, 4.5, 1.6, yaw, 0.0, 0.0]


def test_a_tilted_detection_takes_the_track_its_bottom_face_is_nearer():
    # a car pitched 5 degrees: its bottom face lies 0.07 m ahead of its centre on the ground. Track A is 0.5 m
    # ahead of the centre, track B 0.45 m behind: the yaw rectangle is nearer B, the bottom face nearer A.
    car = CLASS_INDEX["car"]
    det = np.array([_car(0.0)])
    q = _tilted([0.0], [np.radians(5.0)], [0.0])
    shift = float(np.mean(geometry.bottom_corners(det, q)[0, :, 0]))
    assert abs(shift) == pytest.approx(0.8 * np.sin(np.radians(5.0)), abs=1e-9)
    ahead = np.sign(shift)
    tracks = np.array([_car(0.5 * ahead), _car(-0.45 * ahead)])  # A, B
    labels = np.array([car, car])
    chosen = {}
    for footprint in ("bottom_face", "yaw_rectangle"):
        cfg = _polymot(footprint=footprint)
        dets = preprocess_frame(BoxSet(det, [0.9], [car], extra={"quaternion": q}), cfg)
        assert ("footprint" in dets.extra) == (footprint == "bottom_face")
        m = two_stage_association(cfg)(dets, tracks, labels, 0.5)
        chosen[footprint] = m.tracks.tolist()
    assert chosen == {"bottom_face": [0], "yaw_rectangle": [1]}


@pytest.mark.parametrize("preset", ["polymot", "fastpoly", "mctrack"])  # blend NMS; Fast-Poly's scale NMS (cars)
def test_nms_measures_the_bottom_faces(preset):
    # two cars end to end, overlapping so that the BEV IoU of their rectangles is 2 % above the preset's car NMS
    # threshold t. The second is pitched 3 degrees so that its bottom face moves away from the first: the IoU of the
    # bottom faces falls below t and both stay.
    car = CLASS_INDEX["car"]
    t = float(np.broadcast_to(_polymot(preset).nms_threshold, (7,))[car])
    overlap = 1.02 * 16.2 * t / (1.8 * (1.0 + t))  # IoU = 1.8 d / (2 * 1.8 * 4.5 - 1.8 d) = t at d / 1.02
    boxes = np.array([_car(0.0), _car(4.5 - overlap)])
    for sign in (1.0, -1.0):
        q = np.vstack([quaternion_from_yaw([0.0]), _tilted([0.0], [sign * np.radians(3.0)], [0.0])])
        if np.mean(geometry.bottom_corners(boxes[1:], q[1:])[0, :, 0]) > boxes[1, 0]:
            break
    corners = geometry.bottom_corners(boxes, q)
    rect = geometry.paired_bev_iou(boxes[:1], boxes[1:])[0]
    face = geometry.footprint_similarities(boxes[:1], corners[:1], boxes[1:], corners[1:], ["iou_bev"])["iou_bev"]
    assert rect > t > face[0, 0]
    dets = BoxSet(boxes, [0.9, 0.8], [car, car], extra={"quaternion": q})
    assert _polymot(preset).footprint == "bottom_face"
    assert len(preprocess_frame(dets, _polymot(preset, footprint="bottom_face"))) == 2
    assert len(preprocess_frame(dets, _polymot(preset, footprint="yaw_rectangle"))) == 1


def test_without_tilt_the_rectangle_measures_serve():
    # AV2 / LT3D tables carry no quaternion, simulated files yaw-only ones: the key changes nothing there
    car = CLASS_INDEX["car"]
    boxes = np.array([_car(0.0, 0.2), _car(3.9, 0.1), _car(20.0)])
    dets = BoxSet(boxes, [0.9, 0.8, 0.7], [car, car, car])
    kept = preprocess_frame(dets, _polymot(footprint="bottom_face"))
    assert "footprint" not in kept.extra  # the rectangle measures, exactly
    assert np.array_equal(kept.boxes, preprocess_frame(dets, _polymot(footprint="yaw_rectangle")).boxes)
    # nor do yaw-only quaternions (a simulated file's): their bottom faces are the rectangles
    flat = BoxSet(boxes, [0.9, 0.8, 0.7], [car, car, car], extra={"quaternion": quaternion_from_yaw(boxes[:, 6])})
    assert "footprint" not in preprocess_frame(flat, _polymot(footprint="bottom_face")).extra
    tilted = flat.extra["quaternion"].copy()
    tilted[2] = _tilted([0.0], [0.01], [0.0])[0]  # one box pitched: the frame's footprints are measured
    kept = preprocess_frame(BoxSet(boxes, [0.9, 0.8, 0.7], [car] * 3, extra={"quaternion": tilted}), _polymot())
    assert kept.extra["footprint"].shape == (len(kept), 4, 2)
