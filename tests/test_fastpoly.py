"""Fast-Poly components: A-GIoU, distance gate, scale NMS, decoupled geometry, score update and termination."""

import numpy as np
import pytest

from grutrack.tracking.association import a_giou_3d, a_giou_bev, aligned_extents, distance_mask, pairwise_a_giou
from grutrack.tracking.geometry_filter_backend import GeometryWindow
from grutrack.tracking.lifecycle import lifecycle_kernel
from grutrack.tracking.preprocess import scale_nms_keep


def box(x=0.0, y=0.0, z=0.0, w=1.0, l=1.0, h=1.0, yaw=0.0):
    return np.array([x, y, z, w, l, h, yaw, 0.0, 0.0])


def test_aligned_extents_of_rotated_and_scaled_boxes():
    b = np.stack([box(w=2.0, l=4.0), box(x=1.0, yaw=np.pi / 4)])
    e = aligned_extents(b)
    np.testing.assert_allclose(e[0], [-2.0, -1.0, 2.0, 1.0])  # l along x, w along y
    r = np.sqrt(0.5)
    np.testing.assert_allclose(e[1], [1 - r, -r, 1 + r, r])
    np.testing.assert_allclose(aligned_extents(b[:1], 1.5)[0], [-3.0, -1.5, 3.0, 1.5])


def test_a_giou_bev_values():
    a = np.stack([box()])
    b = np.stack([box(), box(x=0.5), box(x=2.0)])
    # identical: 1; half overlap: I 0.5, U 1.5, C 1.5 -> 1/3; gap of 1 m: I 0, U 2, C 3 -> -1/3
    np.testing.assert_allclose(a_giou_bev(a, b), [[1.0, 1 / 3, -1 / 3]])


def test_a_giou_bev_uses_the_enclosing_rectangle_of_a_rotated_box():
    a = np.stack([box(yaw=np.pi / 4)])  # enclosing square of side sqrt(2), area 2
    b = np.stack([box()])  # unit square inside it: I 1, U 2, C 2
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
    assert distance_mask(a, b, 3.0).tolist() == [[False, True, False]]  # sqrt(4 + 6.25) > 3


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
        scale_nms_keep(
            np.stack([box(), box()]),
            np.array([0.9, 0.8]),
            np.array([1, 1]),
            ("giou_3d",) * 7,
            np.full(7, 0.08),
            np.ones(7),
            np.full(7, 5.0),
        )


def test_geometry_window_median_and_mean():
    z0 = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]])
    g = GeometryWindow.start(z0, np.array([3, 3]), np.array([False, True]))
    np.testing.assert_allclose(g.estimate(), z0)
    both = np.array([0, 1])
    g.push(both, np.full((2, 4), 2.0), np.array([3, 3]))
    np.testing.assert_allclose(g.estimate(), np.full((2, 4), 1.5))  # median of 2 = mean of 2
    g.push(both, np.full((2, 4), 10.0), np.array([3, 3]))
    np.testing.assert_allclose(g.estimate()[:, 0], [2.0, 13.0 / 3.0])
    g.push(both[:1], np.full((1, 4), 4.0), np.array([3]))  # 1 drops out: [2, 10, 4]
    np.testing.assert_allclose(g.estimate()[:, 0], [4.0, 13.0 / 3.0])
    sub = GeometryWindow.concat(
        g.select(np.array([False, True])), GeometryWindow.start(np.full((1, 4), 7.0), np.array([2]), np.array([False]))
    )
    np.testing.assert_allclose(sub.estimate()[:, 0], [13.0 / 3.0, 7.0])


def test_geometry_window_respects_a_smaller_window():
    g = GeometryWindow.start(np.zeros((1, 4)), np.array([3]), np.array([True]))
    g.push(np.array([0]), np.full((1, 4), 3.0), np.array([2]))
    g.push(np.array([0]), np.full((1, 4), 6.0), np.array([2]))
    np.testing.assert_allclose(g.estimate()[0], np.full(4, 4.5))  # mean of the last 2


def _lifecycle(scores, rows, det_scores, multiply, average_score, totals=None, counts=None, delete=0.0):
    """One frame of the tracker's compiled lifecycle for tracks of labels 0 and 1 (decay 0.5 and 0.2)."""
    n = len(scores)
    scores = np.array(scores, dtype=np.float64)
    total = np.array(totals if totals is not None else scores, dtype=np.float64)
    count = np.array(counts if counts is not None else [1] * n, dtype=np.int64)
    per_class = np.array([0.5, 0.2, 1, 1, 1, 1, 1], dtype=np.float64)
    matched, alive, emit = (np.empty(n, dtype=bool) for _ in range(3))
    lifecycle_kernel(
        np.asarray(rows, dtype=np.int64),
        np.asarray(det_scores, dtype=np.float64),
        np.arange(n, dtype=np.int64),
        scores,
        np.zeros(n, dtype=np.int64),
        np.ones(n, dtype=np.int64),
        total,
        count,
        per_class,
        np.full(7, 5.0),
        np.ones(7),
        np.full(7, delete),
        multiply,
        average_score,
        np.ones(7),
        2,
        0,  # write_first_frames (MCTrack's option; not used here)
        matched,
        alive,
        emit,
    )
    return scores, total, count, alive


def test_score_update_and_average_termination():
    """Fast-Poly's scores in the tracker's lifecycle: predict s- = s d, update s+ = 1 - (1 - s_det)(1 - s-)
    ('multiply'), or s+ = s_det ('detection'); the average termination keeps the running mean of the final scores
    since birth and ends a track whose mean falls below its class's delete threshold."""
    s, *_ = _lifecycle([0.6, 0.5], [], [], True, False)
    np.testing.assert_allclose(s, [0.3, 0.1])  # predicted only
    s, *_ = _lifecycle([0.6, 0.5], [0, 1], [0.4, 0.5], True, False)
    np.testing.assert_allclose(s, [1 - 0.6 * 0.7, 1 - 0.5 * 0.9])
    s, *_ = _lifecycle([0.6, 0.5], [0, 1], [0.4, 0.5], False, False)
    np.testing.assert_allclose(s, [0.4, 0.5])
    s, total, count, alive = _lifecycle([0.6, 0.5], [1], [0.9], True, True, delete=0.4)
    np.testing.assert_allclose(total, [0.6 + 0.3, 0.5 + (1 - 0.1 * 0.9)])
    assert count.tolist() == [2, 2]
    assert alive.tolist() == [True, True]  # means 0.45 and 0.7
    *_, alive = _lifecycle([0.6, 0.5], [1], [0.9], True, True, delete=0.5)
    assert alive.tolist() == [False, True]  # 0.45 < 0.5


# ---- the pieces wired into the tracker ----------------------------------------------------------------------

import copy  # noqa: E402

import yaml  # noqa: E402

from grutrack.classes import CLASS_INDEX  # noqa: E402
from grutrack.data.scene import BoxSet  # noqa: E402
from grutrack.errors import ConfigError  # noqa: E402
from grutrack.tracking.association import gated_costs  # noqa: E402
from grutrack.tracking.config import PRESET_DIR, config_from_dict, load_tracker_config  # noqa: E402
from grutrack.tracking.factory import build_tracker  # noqa: E402
from grutrack.tracking.geometry_filter_backend import GeometryFilterBackend  # noqa: E402
from grutrack.tracking.preprocess import preprocess_frame  # noqa: E402

CAR, PED, BUS = CLASS_INDEX["car"], CLASS_INDEX["pedestrian"], CLASS_INDEX["bus"]


def test_gated_costs_stage_one_gate_and_stage_two_rows_and_columns():
    dets = np.stack([box(x=0.0), box(x=10.0), box(x=50.0), box(x=0.5)])
    trks = np.stack([box(x=1.0), box(x=11.0), box(x=0.2)])
    dl, tl = np.array([CAR, CAR, CAR, PED]), np.array([CAR, CAR, PED])
    metric = ("a_giou_3d",) * 7
    c1, c2 = gated_costs(dets, dl, trks, tl, metric, "a_giou_bev", np.full(7, 3.0))
    # stage 1: only same-class pairs within 3 m
    assert np.isfinite(c1).tolist() == [
        [True, False, False],
        [False, True, False],
        [False, False, False],
        [False, False, True],
    ]
    np.testing.assert_allclose(c1[0, 0], 1.0 - a_giou_3d(dets[:1], trks[:1])[0, 0])
    # stage 2: every same-class pair between gated-in detections (0, 1, 3) and tracks (0, 1, 2), 10 m apart or not
    assert np.isfinite(c2).tolist() == [
        [True, True, False],
        [True, True, False],
        [False, False, False],
        [False, False, True],
    ]
    np.testing.assert_allclose(c2[0, 1], 1.0 - a_giou_bev(dets[:1], trks[1:2])[0, 0])
    # no gate: every same-class pair is scored in stage 1
    c1, _ = gated_costs(dets, dl, trks, tl, metric, "a_giou_bev", np.zeros(7))
    assert np.isfinite(c1).sum() == 7


def test_geometry_filter_backend_takes_the_window_median():
    cfg = load_tracker_config("fastpoly")
    tracker = build_tracker("ekf", "fastpoly")
    g = next(g for g in tracker.groups if g.classes[CAR])
    assert isinstance(g.backend, GeometryFilterBackend)
    be = g.backend
    z0 = np.array([box(w=1.8, l=4.0, h=1.5, z=1.0)])
    s = be.initiate(z0, np.array([CAR]))
    for w, l, h, z in ((2.2, 4.4, 1.7, 1.2), (1.9, 5.0, 1.4, 0.7)):
        s = be.predict(s, 0.5)
        s = be.update(s, np.array([0]), np.array([box(w=w, l=l, h=h, z=z)]))
    out = be.boxes(s)
    # medians of (1.0, 1.2, 0.7), (1.8, 2.2, 1.9), (4.0, 4.4, 5.0), (1.5, 1.7, 1.4)
    np.testing.assert_allclose(out[0, 2:6], [1.0, 1.9, 4.4, 1.5])
    assert cfg.geometry_window[CAR] == 3 and cfg.geometry_filter[PED] == "mean"


def test_preprocess_frame_scale_nms_order_and_score_filter():
    cfg = load_tracker_config("fastpoly")
    dets = BoxSet(
        np.stack([box(), box(x=0.1), box(x=30.0), box(x=60.0, w=2.5, l=10.0, h=3.0)]),
        np.array([0.5, 0.9, 0.15, 0.2]),
        np.array([CAR, CAR, CAR, BUS]),
    )
    kept = preprocess_frame(dets, cfg)
    # car 2 (0.15) is below the car threshold 0.16; the bus (label 1) comes before the cars (label 2); car 0 is
    # suppressed by car 1 (same class, 0.1 m apart)
    assert kept.scores.tolist() == [0.2, 0.9]


def test_fastpoly_score_update_and_average_score_termination():
    tracker = build_tracker("ekf", "fastpoly")
    car = BoxSet(np.array([box(z=1.0, w=1.8, l=4.5, h=1.6)]), np.array([0.5]), np.array([CAR]))
    none = BoxSet(np.zeros((0, 9)), np.zeros(0), np.zeros(0, dtype=np.int64))
    out = [tracker.step(car, 1_000_000), tracker.step(car, 1_500_000), tracker.step(none, 2_000_000)]
    s1 = 1 - (1 - 0.5) * (1 - 0.5 * 0.52)  # multiply: 1 - (1 - s_det)(1 - s * decay)
    assert [o.scores.tolist() for o in out] == [[0.5], [pytest.approx(s1)], [pytest.approx(s1 * 0.52)]]

    # a pedestrian at 0.2 decays by 0.56 per missed frame; its mean score drops below 0.1 at the 5th frame
    tracker = build_tracker("ekf", "fastpoly")
    ped = BoxSet(np.array([box()]), np.array([0.2]), np.array([PED]))
    tracker.step(ped, 0)
    g = next(g for g in tracker.groups if g.classes[PED])
    alive = []
    for k in range(1, 6):
        tracker.step(none, 500_000 * k)
        alive.append(len(g))
    scores = 0.2 * 0.56 ** np.arange(6)
    assert (np.cumsum(scores) / np.arange(1, 7) >= 0.1).tolist()[1:] == [bool(a) for a in alive]
    assert alive == [1, 1, 1, 0, 0]


def test_fastpoly_preset_values_and_comments():
    cfg = load_tracker_config("fastpoly")
    assert cfg.nms_method == "scale" and cfg.score_update == "multiply" and cfg.termination == "average_score"
    assert cfg.first_metric[BUS] == "a_giou_bev" and cfg.second_metric == "a_giou_bev"
    assert cfg.distance_gate.tolist() == [3.0] * 7 and cfg.time_step == 0.5
    text = (PRESET_DIR / "fastpoly.yaml").read_text().splitlines()
    for i, line in enumerate(text):
        s = line.strip()
        if s and not s.startswith("#") and ":" in s and not s.endswith(":") and line.startswith("  "):
            assert text[i - 1].strip().startswith("#"), f"key without a comment above it: {s}"


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda r: r["preprocessing"].__setitem__("nms_method", "soft"), "'preprocessing.nms_method' must be one of"),
        (
            lambda r: r["preprocessing"]["nms_metric"].__setitem__("car", "giou_3d"),
            "'preprocessing.nms_metric.car' must be one of",
        ),
        (lambda r: r["preprocessing"]["nms_scale"].__setitem__("car", 0), "must be a positive scale factor"),
        (lambda r: r["association"]["distance_gate"].__setitem__("bus", -1), "'association.distance_gate.bus' must be"),
        (lambda r: r["lifecycle"].__setitem__("termination", "score"), "'lifecycle.termination' must be one of"),
        (lambda r: r["lifecycle"].__setitem__("score_update", "max"), "'lifecycle.score_update' must be one of"),
        (
            lambda r: r["motion"]["geometry_filter"].__setitem__("truck", "mode"),
            "'motion.geometry_filter.truck' must be",
        ),
        (lambda r: r["motion"]["geometry_window"].__setitem__("truck", 0), "'motion.geometry_window.truck' must be"),
        (
            lambda r: r["lifecycle"].pop("delete_threshold"),
            "'lifecycle.delete_threshold' is required with 'lifecycle.termination: average_score'",
        ),
    ],
)
def test_bad_fastpoly_keys(mutate, message):
    raw = copy.deepcopy(yaml.safe_load((PRESET_DIR / "fastpoly.yaml").read_text()))
    mutate(raw)
    with pytest.raises(ConfigError, match=message):
        config_from_dict(raw, "preset.yaml")


def test_aligned_extents_of_a_tilted_box_use_its_bottom_face():
    b = np.stack([box(x=1.0, y=2.0, z=0.0, w=2.0, l=4.0, h=1.0, yaw=0.3)])
    yaw_q = np.array([[np.cos(0.15), 0.0, 0.0, np.sin(0.15)]])
    np.testing.assert_allclose(aligned_extents(b, 1.2, yaw_q), aligned_extents(b, 1.2), atol=1e-12)
    # roll phi about +x (yaw 0): bottom corners at y = +-w/2 cos(phi) + h/2 sin(phi), x = +-l/2
    phi = 0.2
    flat = np.stack([box(w=2.0, l=4.0, h=1.0)])
    roll_q = np.array([[np.cos(phi / 2), np.sin(phi / 2), 0.0, 0.0]])
    shift = 0.5 * np.sin(phi)
    np.testing.assert_allclose(
        aligned_extents(flat, 1.0, roll_q), [[-2.0, -np.cos(phi) + shift, 2.0, np.cos(phi) + shift]], atol=1e-12
    )


def test_score_filter_above_drops_scores_equal_to_the_threshold():
    from grutrack.tracking.preprocess import score_filter

    dets = BoxSet(
        np.stack([box(), box(x=10.0), box(x=20.0)]),
        np.array([0.0, 0.16, 0.17]),
        np.array([CLASS_INDEX["truck"], CAR, CAR]),
    )
    thr = load_tracker_config("fastpoly").score_threshold  # truck 0.0, car 0.16
    assert score_filter(dets, thr).scores.tolist() == [0.0, 0.16, 0.17]
    assert score_filter(dets, thr, strict=True).scores.tolist() == [0.17]
    assert preprocess_frame(dets, load_tracker_config("fastpoly")).scores.tolist() == [0.17]


def test_gated_costs_never_pass_a_track_kilometres_away():
    """A diverged track far away (1e12 m) costs at least 2 in both stages: the dense GIoU loses its digits there
    (it returns 0), and the similarity bound keeps the pair from passing any threshold below 2; near pairs keep
    their exact dense cost."""
    from grutrack.tracking.association import _dense_similarity, gated_costs

    det = np.array([[1723.6, 858.5, 1.4, 0.9, 0.8, 1.8, -0.6, 0.0, 0.0]])
    far = np.array([[-2.733e11, -1.929e12, 1.5, 1.06, 1.16, 2.1, -0.63, 0.0, 0.0]])
    near = det + np.array([[0.3, -0.2, 0.0, 0.1, 0.0, 0.0, 0.05, 0.0, 0.0]])
    trk = np.concatenate([far, near])
    labels = np.array([4])
    gate = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 5.0, 0.0])  # a gate on another class: the gated path for all
    metrics = ("giou_3d",) * 7
    c1, c2 = gated_costs(det, labels, trk, np.array([4, 4]), metrics, "giou_bev", gate)
    assert c1[0, 0] >= 2.0 - 1e-9 and c2[0, 0] >= 2.0 - 1e-9
    assert c1[0, 1] == 1.0 - _dense_similarity("giou_3d", det, near)[0, 0]
    assert c2[0, 1] == 1.0 - _dense_similarity("giou_bev", det, near)[0, 0]


def test_a_gate_on_some_classes_gates_both_stages_of_the_compiled_path(nusc_mini, pointpillars_mini_val):
    """The default's trailer gate (both stages) runs in the compiled (sparse) association, not Fast-Poly's dense one;
    on the real PointPillars file both give the same tracks, box for box, and so does a gate on every class but one."""
    from dataclasses import replace

    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes
    from grutrack.tracking.association import gated_association, gated_association_needed
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes, two_stage_association

    scenes = load_scenes(nusc_mini, "mini_val")
    dets = load_detections(pointpillars_mini_val, [f.token for s in scenes for f in s.frames])

    def boxes(tracker):
        out = track_scenes(tracker, scenes, dets).results
        return {t: (b.ids.tolist(), b.boxes.round(9).tolist()) for t, b in out.items()}

    ekf = build_tracker("ekf")
    assert ekf.cfg.distance_gate.max() > 0 and not gated_association_needed(ekf.cfg)
    gates = [ekf.cfg.distance_gate, np.where(np.arange(7) == 2, 0.0, 2.0)]  # the preset's; all but car at 2 m
    # the crowded rows' Ro_GDIoU (the preset's cars and pedestrians) and a gate grown with the missed time (the
    # preset's buses) and the size gate are part of the compiled path only
    plain = {
        "crowded_threshold": np.zeros(7),
        "crowded_skips_lost_newborns": False,
        "distance_gate_growth": ("fixed",) * 7,
        "size_gate": np.zeros(7),
    }
    for gate in gates:
        sparse = build_tracker("ekf")
        sparse.cfg = replace(sparse.cfg, distance_gate=gate, **plain)
        sparse.associate = two_stage_association(sparse.cfg)
        dense = build_tracker("ekf")
        dense.cfg = replace(dense.cfg, distance_gate=gate, **plain)
        dense.associate = gated_association(dense.cfg)
        assert boxes(sparse) == boxes(dense)
    assert gated_association_needed(replace(ekf.cfg, distance_gate=np.full(7, 3.0)))  # Fast-Poly's stage 2 rows
