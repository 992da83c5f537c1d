"""The MCTrack options (preset ``mctrack``, docs/mctrack.md): Ro_GDIoU, the track pose, the decoupled filters, the
first frames written. Box-for-box parity with MCTrack's own output is in tests/test_reference_parity.py."""

from __future__ import annotations

import numpy as np
import pytest

from grutrack.data.scene import BoxSet
from grutrack.tracking.config import load_tracker_config
from grutrack.tracking.decoupled_backend import DecoupledCVBackend
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.ro_gdiou import WORK_ROWS, ro_gdiou_costs, ro_gdiou_pair

CAR = 2  # label of car among the 7 tracking classes


def _box(x, y, w=2.0, length=4.0, yaw=0.0, vx=0.0, vy=0.0):
    return np.array([x, y, 0.5, w, length, 1.5, yaw, vx, vy])


@pytest.mark.parametrize("f32", [False, True])
def test_ro_gdiou_values(f32):
    work = np.empty((WORK_ROWS, 2))
    a = _box(0.0, 0.0)
    assert ro_gdiou_pair(a, a, 1.0, 1.0, f32, work) == pytest.approx(1.0, abs=1e-6)
    # side by side, touching: IoU 0, enclosing rectangle 4 x 4 = the union, centre distance 2, diagonal^2 32
    b = _box(0.0, 2.0)
    assert ro_gdiou_pair(a, b, 1.0, 1.0, f32, work) == pytest.approx(-4.0 / 32.0, abs=1e-6)
    # half overlap along the length: IoU 1/3, enclosing 6 x 2 = union, d^2 = 4, diagonal^2 = 40
    c = _box(2.0, 0.0)
    assert ro_gdiou_pair(a, c, 0.5, 1.5, f32, work) == pytest.approx(1 / 3 - 1.5 * 4 / 40, abs=1e-6)


def test_float32_geometry_close_to_float64():
    rng = np.random.default_rng(3)
    work = np.empty((WORK_ROWS, 2))
    for _ in range(200):
        a = _box(*rng.normal(0, 2, 2), *rng.uniform(0.5, 5, 2), rng.uniform(-3, 3))
        b = _box(*rng.normal(0, 2, 2), *rng.uniform(0.5, 5, 2), rng.uniform(-3, 3))
        assert abs(ro_gdiou_pair(a, b, 1, 1, True, work) - ro_gdiou_pair(a, b, 1, 1, False, work)) < 1e-5


def test_footprints_apart_have_no_intersection_so_the_clipping_is_skipped():
    """ro_gdiou_pair takes the intersection as 0, without clipping, for footprints_apart pairs: both clippings
    (float64 and OpenCV's float32) give 0 for every such pair, and the rule is tight (a pair just inside overlaps)."""
    from grutrack.tracking.ro_gdiou import _corners, _f32_intersection_area, _intersection_area, footprints_apart

    rng = np.random.default_rng(5)
    work, ca, cb = np.empty((40, 2)), np.empty((4, 2)), np.empty((4, 2))
    apart = 0
    for _ in range(3000):
        la, wa, lb, wb = rng.uniform(0.3, 12.0, 4)
        reach = 0.5 * (np.hypot(la, wa) + np.hypot(lb, wb))
        d, ang = reach * rng.uniform(0.99, 1.05), rng.uniform(-np.pi, np.pi)
        x, y, ya, yb = d * np.cos(ang), d * np.sin(ang), *rng.uniform(-np.pi, np.pi, 2)
        if not footprints_apart(_box(0.0, 0.0, wa, la, ya), _box(x, y, wb, lb, yb)):
            continue
        apart += 1
        _corners(0.0, 0.0, la, wa, ya, False, ca)
        _corners(x, y, lb, wb, yb, False, cb)
        assert _intersection_area(ca, cb, work[8:24], work[24:40]) == 0.0
        assert _f32_intersection_area(x, y, la, wa, ya, lb, wb, yb, work) == 0.0
    assert 1500 < apart < 3000  # the draw straddles the rule's distance
    # tight: two 4 x 3 boxes with their diagonals on the line of centres overlap at 0.999 of 5 m, not apart
    yaw = -np.arctan2(3.0, 4.0)
    a, b = _box(0.0, 0.0, 3.0, 4.0, yaw), _box(0.999 * 5.0, 0.0, 3.0, 4.0, yaw)
    assert not footprints_apart(a, b)
    _corners(0.0, 0.0, 4.0, 3.0, yaw, False, ca)
    _corners(0.999 * 5.0, 0.0, 4.0, 3.0, yaw, False, cb)
    assert _intersection_area(ca, cb, work[8:24], work[24:40]) > 0.0
    assert footprints_apart(a, _box(1.002 * 5.0, 0.0, 3.0, 4.0, yaw))


def test_track_pose_rule_oldest_track():
    """MCTrack compares every pair at the pose of its oldest live track's class; own_class at each track's."""
    cfg = load_tracker_config("mctrack")
    det = np.stack([_box(10.0, 0.0, vx=4.0), _box(0.0, 20.0, vx=4.0)])
    det_labels = np.array([CAR, 4])  # car, pedestrian
    pred = np.stack([_box(10.0, 0.0), _box(0.0, 20.0)])  # predicted boxes on the detections
    last = np.stack([_box(8.0, 0.0), _box(0.0, 20.0)])  # last posterior: 2 m behind = the detection moved back
    labels = np.array([CAR, 4])
    oldest_bus = ro_gdiou_costs(det, det_labels, pred, last, labels, np.array([5, 7]), cfg, 0.5)
    assert oldest_bus[0, 0] == pytest.approx(0.0, abs=1e-6)  # car at last_update: back-moved detection on it
    # pedestrian compared at the car's pose (last_update): the detection moved back 2 m misses the track
    assert oldest_bus[1, 1] > 0.5
    from dataclasses import replace

    own = ro_gdiou_costs(
        det, det_labels, pred, last, labels, np.array([5, 7]), replace(cfg, track_pose_rule="own_class"), 0.5
    )
    assert own[1, 1] > 0.5 and own[0, 0] == pytest.approx(0.0, abs=1e-6)
    assert oldest_bus[0, 1] >= 1e6 and oldest_bus[1, 0] >= 1e6  # other classes never pair


def _backend(missed_update):
    eye = np.tile(np.eye(4), (7, 1, 1))
    return DecoupledCVBackend(
        {"P0": eye.copy(), "Q": 0.5 * eye, "R": eye.copy()},
        {"P0": eye.copy(), "Q": 0.5 * eye, "R": np.tile(np.eye(2), (7, 1, 1))},
        missed_update=missed_update,
    )


def test_missed_update_zero_innovation_keeps_state_shrinks_covariance():
    z = _box(1.0, 2.0, vx=2.0)[None]
    labels = np.array([CAR])
    out = {}
    for mode in ("predict", "zero_innovation"):
        be = _backend(mode)
        s = be.predict(be.initiate(z, labels), 0.5)
        s = be.miss(s, np.array([0]))
        out[mode] = s
        assert s.x[0, 0] == pytest.approx(2.0) and s.box[0, 0] == pytest.approx(2.0)  # x + 0.5 s * 2 m/s
        assert s.box[0, 7] == 2.0  # the last detection's velocity
    assert np.trace(out["zero_innovation"].P[0]) < np.trace(out["predict"].P[0])


def test_written_box_and_first_frames():
    """A matched track writes filtered x, y, l, w and the detection's z, h, yaw, velocity; every live track is
    written in the scene's first 3 frames (score 0 when predicted), a missed car later is hidden at once."""
    tr = build_tracker("ekf", "mctrack")
    tr.reset()
    z = _box(0.0, 0.0, vx=1.0)

    def frame(k, present):
        b = z.copy()
        b[0] += 0.5 * k
        b[6] = 0.1 * k
        if not present:
            return BoxSet(np.zeros((0, 9)), np.zeros(0), np.zeros(0, dtype=np.int64))
        return BoxSet(b[None], np.array([0.9]), np.array([CAR]))

    outs = [tr.step(frame(k, k not in (2, 4)), 500_000 * k) for k in range(6)]
    assert [len(o) for o in outs] == [1, 1, 1, 1, 0, 1]
    assert outs[2].scores[0] == 0.0 and outs[1].scores[0] == 0.9
    assert outs[1].boxes[0, 6] == pytest.approx(0.1) and outs[1].boxes[0, 7] == 1.0
    assert outs[5].ids[0] == outs[0].ids[0]  # the hidden car is still alive and matched again
