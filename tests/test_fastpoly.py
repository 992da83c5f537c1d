"""Fast-Poly components: A-GIoU, distance gate, scale NMS, decoupled geometry, score update and termination."""

import numpy as np
import pytest

from grutrack.tracking.fastpoly import (GeometryWindow, ScoreHistory, a_giou_3d, a_giou_bev, aligned_extents,
                                        distance_mask, pairwise_a_giou, predict_scores, scale_nms_keep,
                                        update_scores)


def box(x=0.0, y=0.0, z=0.0, w=1.0, l=1.0, h=1.0, yaw=0.0):
    return np.array([x, y, z, w, l, h, yaw, 0.0, 0.0])


def test_aligned_extents_of_rotated_and_scaled_boxes():
    b = np.stack([box(w=2.0, l=4.0), box(x=1.0, yaw=np.pi / 4)])
    e = aligned_extents(b)
    np.testing.assert_allclose(e[0], [-2.0, -1.0, 2.0, 1.0])          # l along x, w along y
    r = np.sqrt(0.5)
    np.testing.assert_allclose(e[1], [1 - r, -r, 1 + r, r])
    np.testing.assert_allclose(aligned_extents(b[:1], 1.5)[0], [-3.0, -1.5, 3.0, 1.5])


def test_a_giou_bev_values():
    a = np.stack([box()])
    b = np.stack([box(), box(x=0.5), box(x=2.0)])
    # identical: 1; half overlap: I 0.5, U 1.5, C 1.5 -> 1/3; gap of 1 m: I 0, U 2, C 3 -> -1/3
    np.testing.assert_allclose(a_giou_bev(a, b), [[1.0, 1 / 3, -1 / 3]])


def test_a_giou_bev_uses_the_enclosing_rectangle_of_a_rotated_box():
    a = np.stack([box(yaw=np.pi / 4)])            # enclosing square of side sqrt(2), area 2
    b = np.stack([box()])                         # unit square inside it: I 1, U 2, C 2
    np.testing.assert_allclose(a_giou_bev(a, b), [[0.5]])


def test_a_giou_3d_values():
    a = np.stack([box(z=0.0, h=2.0)])
    b = np.stack([box(z=1.0, h=2.0), box(z=0.0, h=2.0, x=0.5)])
    # same footprint, heights overlap 1 of span 3: I3 1, U3 3, C3 3 -> 1/3
    # half footprint overlap, same height: I3 1, U3 3, C3 3 -> 1/3
    np.testing.assert_allclose(a_giou_3d(a, b), [[1 / 3, 1 / 3]])
    e = aligned_extents(a)
    np.testing.assert_allclose(pairwise_a_giou(e, e, a[:, [2, 5]], a[:, [2, 5]]), [[1.0]])


def test_distance_mask_is_3d_and_strict():
    a = np.stack([box()])
    b = np.stack([box(x=3.0), box(x=2.9), box(x=2.0, z=2.5)])
    assert distance_mask(a, b, 3.0).tolist() == [[False, True, False]]   # sqrt(4 + 6.25) > 3


def test_scale_nms_enlarged_footprints_suppress():
    # two bicycles 1.1 m apart along x, 1 m long: disjoint as they are, overlapping when enlarged by 1.4
    b = np.stack([box(), box(x=1.1), box(x=30.0)])
    s = np.array([0.9, 0.8, 0.7])
    lab = np.array([0, 0, 0])
    metric = ("a_giou_bev",) * 7
    thr, radius = np.full(7, 0.08), np.full(7, 5.0)
    plain = scale_nms_keep(b, s, lab, metric, thr, np.ones(7), radius)
    assert plain.tolist() == [0, 1, 2]
    scaled = scale_nms_keep(b, s, lab, metric, thr, np.full(7, 1.4), radius)
    # enlarged extents [-0.7, 0.7] and [0.4, 1.8] in x, same in y: I 0.3*1.4, U 2*1.96 - I, C 2.5*1.4
    I, U, C = 0.3 * 1.4, 2 * 1.96 - 0.3 * 1.4, 2.5 * 1.4
    assert I / U - (C - U) / C > 0.08
    assert scaled.tolist() == [0, 2]
    # the same pair outside the distance gate is never compared
    assert scale_nms_keep(b, s, lab, metric, thr, np.full(7, 1.4), np.full(7, 1.0)).tolist() == [0, 1, 2]


def test_scale_nms_is_per_class_and_orders_by_class_then_score():
    b = np.stack([box(), box(x=0.1), box(x=0.05), box(x=20.0)])
    s = np.array([0.5, 0.9, 0.8, 0.6])
    lab = np.array([2, 2, 4, 0])
    keep = scale_nms_keep(b, s, lab, ("iou_bev",) * 7, np.full(7, 0.08), np.ones(7), np.full(7, 5.0))
    # class 0 first; car 1 (0.9) suppresses car 0 (0.5, IoU 0.9/1.1); the pedestrian is another class
    assert keep.tolist() == [3, 1, 2]


def test_scale_nms_rejects_unknown_metric():
    with pytest.raises(ValueError, match="unknown NMS metric"):
        scale_nms_keep(np.stack([box(), box()]), np.array([0.9, 0.8]), np.array([1, 1]), ("giou_3d",) * 7,
                       np.full(7, 0.08), np.ones(7), np.full(7, 5.0))


def test_geometry_window_median_and_mean():
    z0 = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]])
    g = GeometryWindow.start(z0, np.array([3, 3]), np.array([False, True]))
    np.testing.assert_allclose(g.estimate(), z0)
    both = np.array([0, 1])
    g.push(both, np.full((2, 4), 2.0), np.array([3, 3]))
    np.testing.assert_allclose(g.estimate(), np.full((2, 4), 1.5))          # median of 2 = mean of 2
    g.push(both, np.full((2, 4), 10.0), np.array([3, 3]))
    np.testing.assert_allclose(g.estimate()[:, 0], [2.0, 13.0 / 3.0])
    g.push(both[:1], np.full((1, 4), 4.0), np.array([3]))                   # 1 drops out: [2, 10, 4]
    np.testing.assert_allclose(g.estimate()[:, 0], [4.0, 13.0 / 3.0])
    sub = GeometryWindow.concat(g.select(np.array([False, True])), GeometryWindow.start(
        np.full((1, 4), 7.0), np.array([2]), np.array([False])))
    np.testing.assert_allclose(sub.estimate()[:, 0], [13.0 / 3.0, 7.0])


def test_geometry_window_respects_a_smaller_window():
    g = GeometryWindow.start(np.zeros((1, 4)), np.array([3]), np.array([True]))
    g.push(np.array([0]), np.full((1, 4), 3.0), np.array([2]))
    g.push(np.array([0]), np.full((1, 4), 6.0), np.array([2]))
    np.testing.assert_allclose(g.estimate()[0], np.full(4, 4.5))   # mean of the last 2


def test_score_predict_update_and_average():
    s = np.array([0.6, 0.5])
    pred = predict_scores(s, np.array([0.5, 0.2]))
    np.testing.assert_allclose(pred, [0.3, 0.1])
    np.testing.assert_allclose(update_scores(pred, np.array([0.4, 0.5])), [1 - 0.6 * 0.7, 1 - 0.5 * 0.9])
    np.testing.assert_allclose(update_scores(pred, np.array([0.4, 0.5]), "detection"), [0.4, 0.5])
    h = ScoreHistory.start(s)
    h.add(pred)
    h.add(np.array([0.0, 0.9]))
    np.testing.assert_allclose(h.average(), [0.3, 0.5])
    assert h.select(np.array([1])).count.tolist() == [3]
    with pytest.raises(ValueError, match="unknown score update"):
        update_scores(pred, pred, "max")
