"""Pre-processing, association and the lifecycle of the tracker on small hand-made scenes."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from support.association_bounds import similarity_upper_bound

from grutrack import geometry
from grutrack.classes import CLASS_INDEX
from grutrack.data.scene import BoxSet, Frame, Scene
from grutrack.tracking.association import associate, size_consistent
from grutrack.tracking.config import PRESET_DIR, load_tracker_config
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.preprocess import nms_keep, score_filter
from grutrack.tracking.tracker import gate_scale, track_scenes

CAR, PED = CLASS_INDEX["car"], CLASS_INDEX["pedestrian"]


def _box(x, y, yaw=0.0, w=1.8, l=4.5, h=1.6, z=0.8, vx=0.0, vy=0.0):
    return [x, y, z, w, l, h, yaw, vx, vy]


def test_nms_blend_class_aware():
    boxes = np.array([_box(0, 0), _box(0.3, 0), _box(0.2, 0.1), _box(20, 0)])
    scores = np.array([0.5, 0.9, 0.7, 0.4])
    labels = np.array([CAR, CAR, PED, CAR])
    assert nms_keep(boxes, scores, labels, 0.08, class_aware=True).tolist() == [1, 2, 3]
    assert nms_keep(boxes, scores, labels, 0.08, class_aware=False).tolist() == [1, 3]


def test_score_filter_per_class():
    cfg = load_tracker_config("ekf")
    dets = BoxSet(
        np.array([_box(0, 0), _box(10, 0), _box(20, 0)]),
        np.array([0.10, 0.20, 0.13]),
        np.array([CAR, CAR, CLASS_INDEX["bus"]]),
    )
    kept = score_filter(dets, cfg.score_threshold)
    assert kept.scores.tolist() == [0.20, 0.13]  # car threshold 0.16, bus 0.12
    assert len(score_filter(BoxSet(dets.boxes[2:], np.array([0.11]), dets.labels[2:]), cfg.score_threshold)) == 0


def test_upper_bound_never_below_true_similarity():
    rng = np.random.default_rng(3)
    n = 4000
    a = np.column_stack(
        [
            rng.uniform(-15, 15, (n, 2)),
            rng.uniform(-1, 1, n),
            rng.uniform(0.3, 8, (n, 3)),
            rng.uniform(-np.pi, np.pi, n),
            np.zeros((n, 2)),
        ]
    )
    b = np.column_stack(
        [
            rng.uniform(-15, 15, (n, 2)),
            rng.uniform(-1, 1, n),
            rng.uniform(0.3, 8, (n, 3)),
            rng.uniform(-np.pi, np.pi, n),
            np.zeros((n, 2)),
        ]
    )
    for name, fn in (
        ("giou_3d", geometry.paired_giou_3d),
        ("giou_bev", geometry.paired_bev_giou),
        ("iou_bev", geometry.paired_bev_iou),
        ("iou_3d", geometry.paired_iou_3d),
    ):
        ub, true = similarity_upper_bound(a, b, name), fn(a, b)
        assert np.all(ub >= true - 1e-12), name
        assert (ub < 1).mean() > 0.5  # the bound prunes most far pairs


def _assoc(det, dl, trk, tl, **kw):
    cfg = load_tracker_config("ekf")
    args = dict(
        first_metric=cfg.first_metric,
        first_threshold=cfg.first_threshold,
        two_stage=True,
        second_metric="giou_bev",
        second_threshold=cfg.second_threshold,
    )
    args.update(kw)
    return associate(np.array(det), np.array(dl), np.array(trk), np.array(tl), **args)


def test_association_classes_never_match_and_threshold():
    m = _assoc([_box(0, 0)], [PED], [_box(0, 0)], [CAR])
    assert len(m.dets) == 0 and m.unmatched_dets.tolist() == [0] and m.unmatched_tracks.tolist() == [0]
    m = _assoc([_box(0, 0), _box(30, 0)], [CAR, CAR], [_box(30.5, 0), _box(0.4, 0.2)], [CAR, CAR])
    assert sorted(zip(m.dets.tolist(), m.tracks.tolist())) == [(0, 1), (1, 0)]
    m = _assoc([_box(0, 0)], [CAR], [_box(12, 0)], [CAR])  # far apart: cost above 1.31
    assert len(m.dets) == 0


def test_second_stage_rescues_vertical_offset():
    # same footprint, 3 m apart vertically: 3D GIoU is low (stage 1 rejects), BEV GIoU is 1 (stage 2 accepts)
    det, trk = [_box(0, 0, z=4.0)], [_box(0, 0, z=0.8)]
    thr = np.full(7, 1.0)  # stage-1 cost threshold 1.0: needs 3D GIoU > 0
    m1 = _assoc(det, [CAR], trk, [CAR], first_threshold=thr, two_stage=False)
    m2 = _assoc(det, [CAR], trk, [CAR], first_threshold=thr, two_stage=True)
    assert len(m1.dets) == 0 and m2.dets.tolist() == [0]


def test_distance_gate_holds_in_both_stages():
    # a 12 m trailer 6 m ahead of its track along its length: the footprints overlap (BEV GIoU > 0, stage 2 would
    # match), the 3D GIoU is too low for stage 1; a 5 m gate keeps the pair out of both stages
    trl = CLASS_INDEX["trailer"]
    det, trk = [_box(6.0, 0, w=2.5, l=12.0, h=3.8)], [_box(0, 0, w=2.5, l=12.0, h=3.8)]
    tight = np.full(7, 0.3)  # stage 1 needs a 3D GIoU above 0.7
    assert _assoc(det, [trl], trk, [trl], first_threshold=tight).dets.tolist() == [0]  # stage 2, no gate
    gate = np.where(np.arange(7) == trl, 5.0, 0.0)
    m = _assoc(det, [trl], trk, [trl], first_threshold=tight, distance_gate=gate)
    assert len(m.dets) == 0 and m.unmatched_tracks.tolist() == [0]
    assert _assoc(det, [trl], trk, [trl], distance_gate=np.where(gate > 0, 7.0, 0.0)).dets.tolist() == [0]


def test_size_consistent_compares_footprint_areas_against_each_tracks_ratio():
    # footprints 8.1 m^2 (car), 33 m^2 (bus, 11 x 3) and 0.49 m^2 (pedestrian): the car against the bus is a ratio
    # of 0.245, the pedestrian against the car 0.06; ratio 0 admits every pair, 0.2 the car for the bus track
    dets = np.array([_box(0, 0), _box(0, 0, w=0.7, l=0.7)])
    trks = np.array([_box(0, 0, w=3.0, l=11.0), _box(0, 0)])
    assert size_consistent(dets, trks, np.zeros(2)).all()
    assert size_consistent(dets, trks, np.array([0.2, 0.2])).tolist() == [[True, True], [False, False]]
    assert size_consistent(dets, trks, np.array([0.25, 0.07])).tolist() == [[False, True], [False, False]]
    assert size_consistent(dets, trks, np.array([1.0, 1.0]))[0, 1]  # equal areas pass any ratio


def test_size_gate_holds_in_both_stages_and_per_class():
    # a car-sized box labelled bus inside a bus track's footprint: BEV and 3D GIoU 0.245 (cost 0.755, below
    # either stage's threshold), refused by a 0.3 bus size gate in both stages; the gate of another class
    # leaves the pair, and a bus-sized detection 1 m off is still taken
    bus = CLASS_INDEX["bus"]
    trk = [_box(0, 0, w=3.0, l=11.0, h=3.5)]
    det = [_box(2.0, 0, h=3.5)]
    assert _assoc(det, [bus], trk, [bus]).dets.tolist() == [0]
    gate = np.where(np.arange(7) == bus, 0.3, 0.0)
    m = _assoc(det, [bus], trk, [bus], size_gate=gate)
    assert len(m.dets) == 0 and m.unmatched_tracks.tolist() == [0]
    stage2 = dict(first_threshold=np.full(7, 0.1))  # stage 1 refuses the pair, stage 2 alone matches it
    assert _assoc(det, [bus], trk, [bus], **stage2).dets.tolist() == [0]
    assert len(_assoc(det, [bus], trk, [bus], size_gate=gate, **stage2).dets) == 0
    assert _assoc(det, [bus], trk, [bus], size_gate=np.where(gate > 0, 0.0, 0.3)).dets.tolist() == [0]
    own = [_box(1.0, 0, w=2.9, l=10.5, h=3.4)]
    assert _assoc(own, [bus], trk, [bus], size_gate=gate).dets.tolist() == [0]


def test_gate_scale_widens_each_tracks_gate():
    # the trailer 6 m ahead of its track (test above): outside a 5 m gate, inside it for a track whose gate is
    # doubled (missed in the frame before); the other track keeps the class's 5 m
    trl = CLASS_INDEX["trailer"]
    det, trk = [_box(6.0, 0, w=2.5, l=12.0, h=3.8)], [_box(0, 0, w=2.5, l=12.0, h=3.8)]
    gate = np.where(np.arange(7) == trl, 5.0, 0.0)
    kw = dict(first_threshold=np.full(7, 0.3), distance_gate=gate)
    assert len(_assoc(det, [trl], trk, [trl], gate_scale=np.array([1.0]), **kw).dets) == 0
    assert _assoc(det, [trl], trk, [trl], gate_scale=np.array([2.0]), **kw).dets.tolist() == [0]
    two = _assoc(det, [trl], trk * 2, [trl] * 2, gate_scale=np.array([1.0, 2.0]), **kw)
    assert two.dets.tolist() == [0] and two.tracks.tolist() == [1]


def test_gate_scale_per_class_rule():
    # classes 0: fixed, 1: missed_frames, 2: 3 m/s on a 4 m radius; tracks missed 1 (matched the frame before) and 3
    # frames at 0.5 s: fixed 1; missed_frames 1, 3; 3 m/s: (4 + 3 * 0) / 4, (4 + 3 * 1.0) / 4
    frames, speed, radius = np.array([False, True, False]), np.array([0.0, 0.0, 3.0]), np.array([2.0, 2.0, 4.0])
    labels, misses = np.array([0, 0, 1, 1, 2, 2]), np.array([1, 3, 1, 3, 1, 3])
    got = gate_scale(frames, speed, radius, labels, misses, 0.5)
    assert got.tolist() == [1.0, 1.0, 1.0, 3.0, 1.0, 1.75]
    # the speed's gate depends on the missed time, not the frame rate: 1 s missed at 10 Hz (11 frames since the last
    # match) is 1.75 too, while missed_frames counts the frames (11)
    at_10hz = gate_scale(frames, speed, radius, np.array([1, 2]), np.array([11, 11]), 0.1)
    assert at_10hz.tolist() == pytest.approx([11.0, 1.75])


@pytest.mark.parametrize("growth, taken_back", [("fixed", False), ("missed_frames", True), (3.0, True), (0.5, False)])
def test_distance_gate_growth(tmp_path, growth, taken_back):
    # a car at 10 m/s along x, detected in frames 0-4, missed in 5 and 6, seen again in frame 7 3 m to the side of
    # its prediction: a fixed 2 m gate starts a new track there; grown with the missed frames (3 frames since its
    # last detection: 6 m) or at 3 m/s (1 s missed: 5 m) the track takes its car back, at 0.5 m/s (2.5 m) not;
    # the same growth for another class leaves the car's gate fixed
    det = [[_box(5.0 * i, 0, vx=10.0)] for i in range(5)] + [[], [], [_box(35.0, 3.0, vx=10.0)]]
    scene, dets = _scene(det)
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["association"]["distance_gate"].update(car=2.0, bus=2.0)
    ids = {}
    for grows in ("car", "bus"):
        raw["association"]["distance_gate_growth"] = {
            c: growth if c == grows else "fixed" for c in raw["association"]["distance_gate"]
        }
        (tmp_path / f"{grows}.yaml").write_text(yaml.safe_dump(raw))
        run = track_scenes(build_tracker("ekf", tmp_path / f"{grows}.yaml"), [scene], dets)
        ids[grows] = [run.results[f.token].ids.tolist() for f in (scene.frames[4], scene.frames[7])]
    assert ids == {"car": [[0], [0] if taken_back else [1]], "bus": [[0], [1]]}


def _scene(dets_per_frame):
    frames = [
        Frame(f"s{i}", 1_000_000 + 500_000 * i, np.zeros(3), np.array([1.0, 0, 0, 0]))
        for i in range(len(dets_per_frame))
    ]
    dets = {
        f.token: BoxSet(np.array(d).reshape(-1, 9), np.full(len(d), 0.9), np.full(len(d), CAR))
        for f, d in zip(frames, dets_per_frame)
    }
    return Scene("synthetic", "tok", frames), dets


def test_lifecycle_ids_punish_decay_and_death():
    # a car moving at 10 m/s along x, detected for 6 frames, then missed for 20 frames
    det = [[_box(5.0 * i, 0, vx=10.0)] for i in range(6)] + [[] for _ in range(20)]
    scene, dets = _scene(det)
    tracker = build_tracker("ekf")
    run = track_scenes(tracker, [scene], dets)
    out = [run.results[f.token] for f in scene.frames]
    ids = {int(i) for o in out for i in o.ids}
    assert ids == {0}  # one identity throughout
    assert [len(o) for o in out[:8]] == [1] * 7 + [0]  # punish_num = 1: one predicted box after the last hit
    s = 0.9  # born with the detection's score; matched: 1 - (1 - s_det)(1 - 0.52 s)
    for _ in range(5):
        s = 1 - (1 - 0.9) * (1 - 0.52 * s)
    young = 1 - tracker.cfg.young_track_discount**6  # written at s (1 - d^hits), 6 hits
    assert np.allclose([o.scores[0] for o in out[5:7]], [s * young, s * 0.52 * young])  # car decay 0.52, multiply
    assert out[6].boxes[0, 0] == pytest.approx(30.0, abs=1.0)  # predicted ahead at ~10 m/s
    assert len(tracker.groups[[g.classes[CAR] for g in tracker.groups].index(True)]) == 0  # died (max_age 15)


def test_young_track_discount_scales_written_scores_only(tmp_path):
    # car 0 detected in every frame, car 1 missed in frame 2, car 2 a single false detection in frame 1
    det = [[_box(5.0 * i, 0, vx=10.0)] for i in range(5)]
    for i in (0, 1, 3, 4):
        det[i].append(_box(5.0 * i, 10, vx=10.0))
    det[1].append(_box(0, 40))
    scene, dets = _scene(det)
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    runs = {}
    for d in (0.0, 0.4):
        raw["lifecycle"]["young_track_discount"] = d
        (tmp_path / f"{d}.yaml").write_text(yaml.safe_dump(raw))
        runs[d] = track_scenes(build_tracker("ekf", tmp_path / f"{d}.yaml"), [scene], dets)
    # matched frames since birth of each written track, per frame (a missed track keeps its count)
    hits = [{0: 1, 1: 1}, {0: 2, 1: 2, 2: 1}, {0: 3, 1: 2, 2: 1}, {0: 4, 1: 3}, {0: 5, 1: 4}]
    for f, h in zip(scene.frames, hits):
        a, b = runs[0.0].results[f.token], runs[0.4].results[f.token]
        assert sorted(a.ids.tolist()) == sorted(h)
        assert np.array_equal(a.ids, b.ids) and np.array_equal(a.boxes, b.boxes)  # tracks and boxes unchanged
        want = [a.scores[k] * (1 - 0.4 ** h[int(t)]) for k, t in enumerate(a.ids)]
        assert np.allclose(b.scores, want)


def test_punish_num_per_class():
    # the ekf preset coasts bicycles two missed frames, cars one
    det = [[_box(0.5 * i, 0, vx=1.0)] for i in range(4)] + [[] for _ in range(4)]
    scene, dets = _scene(det)
    bike = {t: BoxSet(b.boxes, b.scores, np.full(len(b), CLASS_INDEX["bicycle"])) for t, b in dets.items()}
    counts = {}
    for name, d in (("car", dets), ("bicycle", bike)):
        run = track_scenes(build_tracker("ekf"), [scene], d)
        counts[name] = [len(run.results[f.token]) for f in scene.frames]
    assert counts == {"car": [1] * 5 + [0] * 3, "bicycle": [1] * 6 + [0] * 2}


def test_track_ids_unique_across_scenes():
    scene, dets = _scene([[_box(0, 0)], [_box(0.5, 0)]])
    scene2 = Scene(
        "b", "t2", [Frame(f"b{i}", f.timestamp, f.ego_translation, f.ego_rotation) for i, f in enumerate(scene.frames)]
    )
    dets.update({f"b{i}": dets[f"s{i}"] for i in range(2)})
    run = track_scenes(build_tracker("ekf"), [scene, scene2], dets)
    assert int(run.results["s0"].ids[0]) != int(run.results["b0"].ids[0])


def test_param_classes_keep_labels_distinct():
    # two dataset labels that both take car parameters (e.g. AV2 BOX_TRUCK and TRUCK -> truck) never match
    tracker = build_tracker("ekf", param_classes=("car", "car"))
    scene, dets = _scene([[_box(0, 0)], [_box(0.2, 0)]])
    dets["s0"] = BoxSet(dets["s0"].boxes, dets["s0"].scores, np.array([0]))
    dets["s1"] = BoxSet(dets["s1"].boxes, dets["s1"].scores, np.array([1]))
    run = track_scenes(tracker, [scene], dets)
    s1 = run.results["s1"]
    assert sorted(s1.labels.tolist()) == [0, 1]  # the label-0 track coasts (punish_num), a label-1 track is born
    assert int(s1.ids[s1.labels == 1][0]) != int(run.results["s0"].ids[0])
    assert tracker.cfg.max_age.tolist() == [15, 15]


def test_step_with_updates_reports_each_groups_correction_before_the_lifecycle():
    # a car (matched in frames 0-2, missed in 3, matched in 4) and a bicycle of another track group (frames 0-1)
    bike = CLASS_INDEX["bicycle"]
    frames = [
        [(_box(0, 0, vx=10.0), CAR), (_box(30, 5), bike)],
        [(_box(5.1, 0, vx=10.0), CAR), (_box(30, 5.2), bike)],
        [(_box(10, 0, vx=10.0), CAR)],
        [],
        [(_box(20.2, 0, vx=10.0), CAR)],
    ]
    plain, recording, silent = build_tracker("ekf"), build_tracker("ekf"), build_tracker("ekf")
    car_group = int(recording.group_of_class[CAR])
    bike_group = int(recording.group_of_class[bike])
    assert car_group != bike_group
    reports = []
    for i, f in enumerate(frames):
        d = BoxSet(
            np.array([b for b, _ in f]).reshape(-1, 9),
            np.full(len(f), 0.9),
            np.array([c for _, c in f], dtype=np.int64),
        )
        out, updates = recording.step_with_updates(d, 1_000_000 + 500_000 * i)
        ref = plain.step(d, 1_000_000 + 500_000 * i)
        assert np.array_equal(out.boxes, ref.boxes) and np.array_equal(out.ids, ref.ids)  # same tracking
        nothing, same = silent.step_with_updates(d, 1_000_000 + 500_000 * i, output=False)  # as training runs it
        assert nothing is None
        assert [(u.group, u.rows.tolist(), u.ids.tolist(), u.hits.tolist(), u.posterior.x.tolist()) for u in same] == [
            (u.group, u.rows.tolist(), u.ids.tolist(), u.hits.tolist(), u.posterior.x.tolist()) for u in updates
        ]
        reports.append({u.group: u for u in updates})
    assert reports[0] == {}  # no track existed at the first predict
    assert sorted(reports[1]) == sorted([car_group, bike_group])
    car = reports[1][car_group]
    assert (car.rows.tolist(), car.det_rows.tolist(), car.ids.tolist(), car.labels.tolist()) == ([0], [0], [0], [CAR])
    assert reports[1][bike_group].det_rows.tolist() == [1]
    # the correction pulls the predicted x (5 m at 10 m/s) towards the detection (5.1 m), not beyond it
    assert 5.0 < car.posterior.x[0, 0] < 5.1 and car.prior.x[0, 0] == pytest.approx(5.0)
    missed = reports[3][car_group]
    assert len(missed.rows) == 0 and missed.posterior is missed.prior and missed.misses.tolist() == [1]
    late = reports[4][car_group]  # hits and misses as they were before this frame
    assert (late.rows.tolist(), late.hits.tolist(), late.misses.tolist()) == ([0], [3], [2])
    assert late.prior.x[0, 0] < late.posterior.x[0, 0] < 20.2
    assert not hasattr(recording, "update_hook")


@pytest.mark.parametrize("name", ["ekf", "grukf"])
def test_warm_up_leaves_no_trace(name):
    # track_scenes warms the tracker up (two synthetic frames, then reset): the results, ids included, are those
    # of a tracker that never saw them, and the start is reported apart from the loop's seconds
    det = [[_box(5.0 * i, 0, vx=10.0), _box(20.0, 5.0 + 0.5 * i, vy=1.0)] for i in range(5)]
    scene, dets = _scene(det)

    def tracker():
        if name == "ekf":
            return build_tracker("ekf")
        import torch

        from grutrack.motion.grukf import GRUKalmanNet
        from grutrack.tracking.factory import grukf_group
        from grutrack.tracking.tracker import Tracker

        net = GRUKalmanNet(generator=torch.Generator().manual_seed(0))
        return Tracker(load_tracker_config("ekf"), [grukf_group(net, 7, "cpu")])

    plain = tracker()
    cold = {f.token: plain.step(dets[f.token], f.timestamp) for f in scene.frames}
    t = tracker()
    run = track_scenes(t, [scene], dets)
    assert run.start_seconds > 0 and run.frames == 5
    for f in scene.frames:
        a, b = cold[f.token], run.results[f.token]
        assert np.array_equal(a.boxes, b.boxes) and np.array_equal(a.ids, b.ids) and len(a) == 2
    assert t.next_id == plain.next_id == 2


def test_kalman_backend_counts_updates_and_tests_only_established_tracks():
    """The EKF backend counts each track's corrections through update, select and concat, and passes them to the
    robust update (``motion.nis_min_hits``): a far-off detection of a track with fewer matched detections than
    min_hits is the plain update, bit for bit; with enough, it pulls the track less."""
    from grutrack.motion.kalman import RobustUpdate
    from grutrack.motion.models import make_model
    from grutrack.tracking.ekf_backend import KalmanBackend

    m = make_model("CV")
    d = m.dim_x
    tables = (np.tile(np.eye(d) * 0.1, (7, 1, 1)), np.tile(np.eye(9) * 0.1, (7, 1, 1)), np.tile(np.eye(d), (7, 1, 1)))
    robust = KalmanBackend(m, *tables, robust=RobustUpdate(2.0, min_hits=3))
    plain = KalmanBackend(m, *tables)
    z0 = np.array([_box(0, 0), _box(20, 0), _box(40, 0)])
    labels = np.array([1, 1, 1])

    def run(backend):
        s = backend.initiate(z0, labels)
        s = backend.update(backend.predict(s, 0.5), np.array([0, 1]), z0[:2])  # tracks 0, 1: 2 hits; track 2: 1
        s = backend.concat(backend.select(s, np.array([2, 0])), backend.initiate(z0[:1], labels[:1]))
        assert s.counts().tolist() == [0, 1, 0]
        s = backend.update(backend.predict(s, 0.5), np.array([1]), z0[:1])  # track 0 of before: 3 hits
        assert s.counts().tolist() == [0, 2, 0]
        far = np.array([_box(45, 0), _box(5, 0)])  # 5 m off: tracks with 1 and 3 hits
        return backend.update(backend.predict(s, 0.5), np.array([0, 1]), far)

    r, p = run(robust), run(plain)
    assert r.counts().tolist() == [1, 3, 0]
    np.testing.assert_array_equal(r.x[0], p.x[0])  # 1 hit before: not tested
    assert abs(r.x[1, 0]) < abs(p.x[1, 0]) - 0.1  # 3 hits before: its pull bounded


def test_tracker_passes_detection_scores_to_confidence_weighted_noise(tmp_path):
    """``motion.r_score_exponent`` through the tracker: the scores of the matched detections reach the filter, so a
    car's track moves less toward a detection scored 0.2 than toward the same detection scored 0.9 (R / score);
    with the exponent 0 both moves are equal."""
    from grutrack.tracking.factory import build_tracker

    def moved(exponent, score):
        raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
        raw["motion"]["r_score_exponent"] = exponent
        path = tmp_path / f"e{exponent}.yaml"
        path.write_text(yaml.safe_dump(raw))
        t = build_tracker("ekf", path)
        for i in range(3):  # a parked car seen three times at x = 0, then 1 m off
            t.step(BoxSet(np.array([_box(0, 0)]), np.array([0.9]), np.array([CAR])), 1_000_000 + 500_000 * i)
        out = t.step(BoxSet(np.array([_box(1.0, 0)]), np.array([score]), np.array([CAR])), 2_500_000)
        assert len(out) == 1
        return out.boxes[0, 0]

    low, high = moved(1.0, 0.2), moved(1.0, 0.9)
    assert 0.05 < low < high - 0.1 < 1.0
    assert moved(0.0, 0.2) == moved(0.0, 0.9)


def _ro_preset(tmp_path, threshold: float):
    """The ekf preset with stage 1 of pedestrians on Ro_GDIoU (weights [1, 1]) at ``threshold``."""
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["association"]["first_metric"]["pedestrian"] = "ro_gdiou_bev"
    raw["association"]["first_threshold"]["pedestrian"] = threshold
    crowded = raw["association"].setdefault("crowded_threshold", dict.fromkeys(raw["association"]["first_metric"], 0.0))
    crowded["pedestrian"] = 0.0  # stage 1 Ro_GDIoU for every pair instead
    path = tmp_path / f"ro_{threshold}.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


def test_ro_gdiou_for_some_classes_is_stage_one_of_the_two_stage_association(tmp_path):
    from grutrack.tracking.ro_gdiou import WORK_ROWS, ro_gdiou_pair

    ped, car = CLASS_INDEX["pedestrian"], CLASS_INDEX["car"]
    person = {"w": 0.6, "l": 0.6, "h": 1.7, "z": 0.85}
    trk = np.array([_box(0, 0, **person), _box(20, 0)])
    labels = np.array([ped, car])

    def matched(preset, dx):  # pedestrian detection dx metres from its track, car 1 m from its own
        dets = BoxSet(np.array([_box(dx, 0, **person), _box(21, 0)]), np.full(2, 0.9), labels)
        m = build_tracker("ekf", preset).associate(dets, trk, labels, 0.5)
        return sorted(zip(m.dets.tolist(), m.tracks.tolist()))

    # 3 m apart, no overlap: the 3D GIoU cost (1.67) is below the pedestrians' 1.69, Ro_GDIoU's (2.34) above 2.06,
    # and stage 2 (BEV GIoU, cost below 1: an overlap) takes neither; the car is matched either way
    assert matched(None, 3.0) == [(0, 0), (1, 1)]
    assert matched(_ro_preset(tmp_path, 2.06), 3.0) == [(1, 1)]
    # a Tracker built without an association (GRU-KF training) runs the same stage 1
    from grutrack.tracking.tracker import two_stage_association

    dets = BoxSet(np.array([_box(3.0, 0, **person), _box(21, 0)]), np.full(2, 0.9), labels)
    m = two_stage_association(load_tracker_config(_ro_preset(tmp_path, 2.06)))(dets, trk, labels, 0.5)
    assert m.dets.tolist() == [1] and m.tracks.tolist() == [1]
    # 1 m apart: stage 1 takes the pair exactly when 1 - Ro_GDIoU (the predicted box against the detection) is
    # below the threshold
    cost = 1.0 - ro_gdiou_pair(trk[0], np.array(_box(1.0, 0, **person)), 1.0, 1.0, False, np.empty((WORK_ROWS, 2)))
    assert 1.5 < cost < 1.7
    assert matched(_ro_preset(tmp_path, cost + 1e-9), 1.0) == [(0, 0), (1, 1)]
    assert matched(_ro_preset(tmp_path, cost - 1e-9), 1.0) == [(1, 1)]


def test_crowded_stage_one_takes_the_strict_cost_in_crowded_rows_and_columns():
    from grutrack.tracking.association import crowded_stage_one

    # one class, threshold 1.0, crowded limit 0.8: detection 0 has two tracks below 1.0 (a crowded row), detection 1
    # none, and each column one (no crowded column)
    cost = np.array([[0.5, 0.6], [2.0, 1e6]])
    table = np.array([[0.7, 0.9], [0.1, 0.1]])
    asked = []

    def strict(rows, cols, need):  # the strict costs of those rows and columns, as the tracker's Ro_GDIoU gives them
        asked.append((rows.tolist(), cols.tolist(), need.tolist()))
        return np.where(need, table[np.ix_(rows, cols)], np.nan)  # pairs not needed are not read

    out = crowded_stage_one(cost, np.zeros(2, dtype=np.int64), np.array([1.0]), np.array([0.8]), strict)
    assert np.allclose(out, [[0.9, 1.1], [2.0, 1e6]])  # strict + (1.0 - 0.8) in row 0; forbidden pair kept
    assert asked == [([0], [0, 1], [[True, True]])]  # only the crowded row's pairs are scored strictly
    # a crowded column: two detections below 1.0 against track 0
    cost = np.array([[0.5, 3.0], [0.6, 3.0]])
    out = crowded_stage_one(cost, np.zeros(2, dtype=np.int64), np.array([1.0]), np.array([0.8]), strict)
    assert np.allclose(out, [[0.9, 3.0], [0.3, 3.0]])
    # limit 0: off
    off = crowded_stage_one(cost, np.zeros(2, dtype=np.int64), np.array([1.0]), np.array([0.0]), strict)
    assert np.array_equal(off, cost)
    # nothing crowded: the strict measure is not asked for
    asked.clear()
    lone = np.array([[0.5, 3.0], [3.0, 0.6]])
    assert np.array_equal(
        crowded_stage_one(lone, np.zeros(2, dtype=np.int64), np.array([1.0]), np.array([0.8]), strict), lone
    )
    assert asked == []


def test_ro_gdiou_costs_of_the_needed_pairs_equal_the_full_matrix():
    from grutrack.tracking.ro_gdiou import predicted_pose_costs

    rng = np.random.default_rng(3)
    cfg = load_tracker_config("ekf")
    classes = cfg.crowded_threshold > 0
    det, trk = np.zeros((9, 9)), np.zeros((7, 9))
    for b in (det, trk):
        b[:, :2] = rng.uniform(0, 6, (len(b), 2))
        b[:, 3:6] = rng.uniform(0.5, 4.5, (len(b), 3))
        b[:, 6] = rng.uniform(-np.pi, np.pi, len(b))
    det_labels, trk_labels = rng.integers(0, 7, 9), rng.integers(0, 7, 7)
    det_labels[:4] = trk_labels[:3] = CLASS_INDEX["car"]
    costs = predicted_pose_costs(classes, cfg)
    full = costs(det, det_labels, trk, trk_labels)
    need = rng.random((9, 7)) < 0.5
    part = costs(det, det_labels, trk, trk_labels, need)
    scored = need & classes[det_labels][:, None] & (det_labels[:, None] == trk_labels)
    assert scored.sum() >= 2 and (full < 1e6).sum() > scored.sum()
    assert np.array_equal(part[scored], full[scored]) and (part[~scored] == 1e6).all()


def test_crowded_threshold_judges_a_lone_pair_by_the_first_metric_and_a_crowded_one_by_ro_gdiou(tmp_path):
    person = {"w": 0.6, "l": 0.6, "h": 1.7, "z": 0.85}
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["association"]["crowded_threshold"] = {**dict.fromkeys(raw["association"]["first_threshold"], 0.0)}
    weights = raw["association"].pop("ro_gdiou_weights", None)
    raw["association"].pop("crowded_skips_lost_newborns", None)
    plain = tmp_path / "plain.yaml"
    plain.write_text(yaml.safe_dump(raw))
    raw["association"]["crowded_threshold"]["pedestrian"] = 2.06
    raw["association"]["ro_gdiou_weights"] = weights or dict.fromkeys(raw["association"]["first_threshold"], [1.0, 1.0])
    crowded = tmp_path / "crowded.yaml"
    crowded.write_text(yaml.safe_dump(raw))

    def matched(preset, tracks_x):  # one pedestrian detection at x = 3 m, pedestrian tracks at tracks_x
        trk = np.array([_box(x, 0, **person) for x in tracks_x])
        labels = np.full(len(trk), PED)
        dets = BoxSet(np.array([_box(3.0, 0, **person)]), np.full(1, 0.9), np.array([PED]))
        m = build_tracker("ekf", preset).associate(dets, trk, labels, 0.5)
        return sorted(zip(m.dets.tolist(), m.tracks.tolist()))

    # 3 m from a lone track: 3D GIoU cost 1.67 < 1.69 admits it, Ro_GDIoU's 2.34 would not; alone, it is matched
    assert matched(plain, [0.0]) == matched(crowded, [0.0]) == [(0, 0)]
    # a second track 3.2 m on the other side (3D GIoU cost 1.68, also below 1.69): the row is crowded, Ro_GDIoU
    # decides and admits neither (2.34 and more, above 2.06); without the option the nearer track takes it
    assert matched(plain, [0.0, 6.2]) == [(0, 0)]
    assert matched(crowded, [0.0, 6.2]) == []


def test_one_classs_settings_leave_another_classs_tracks_unchanged(tmp_path):
    # Each class is tracked on its own (class-aware NMS, per-class association, motion and lifecycle), so a preset's
    # AMOTA is the mean of per-class figures each of which depends on its class's settings only: what
    # benchmarks/bench_default_tracker.py --compose rests on. Cars and trucks side by side, overlapping in
    # bird's-eye view, some detections missed; every car setting changed must leave the trucks' boxes, scores
    # and track partition as they were (track ids are numbered across classes, so only their partition is compared).
    TRUCK = CLASS_INDEX["truck"]
    rng = np.random.default_rng(3)
    frames, labels = [], []
    for i in range(12):
        boxes, lab = [], []
        for k in range(3):
            if rng.random() < 0.8:
                boxes.append(_box(4.0 * i + rng.normal(0, 0.3), 3.0 * k + rng.normal(0, 0.2), vx=8.0))
                lab.append(CAR)
            if rng.random() < 0.8:
                boxes.append(_box(1.5 * i + 4.0 * k, 3.0 * k + 0.8 + rng.normal(0, 0.2), w=2.5, l=7.0, h=3.0, vx=3.0))
                lab.append(TRUCK)
        frames.append(boxes)
        labels.append(lab)
    scene, dets = _scene(frames)
    for f, lab in zip(scene.frames, labels):
        d = dets[f.token]
        dets[f.token] = BoxSet(d.boxes, rng.uniform(0.2, 0.95, len(lab)), np.array(lab, dtype=np.int64))
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    base = tmp_path / "base.yaml"
    base.write_text(yaml.safe_dump(raw))
    raw["preprocessing"]["score_threshold"]["car"] = 0.8
    raw["association"]["first_metric"]["car"] = "ro_gdiou_bev"
    raw["association"]["first_threshold"]["car"] = 1.1
    raw["association"].setdefault("crowded_threshold", dict.fromkeys(raw["association"]["first_metric"], 0.0))[
        "car"
    ] = 0
    raw["association"]["second_threshold"]["car"] = 1.4
    raw["lifecycle"]["max_age"]["car"] = 2
    raw["lifecycle"]["punish_num"]["car"] = 0
    raw["lifecycle"]["decay_rate"]["car"] = 0.9
    raw["motion"]["model_override"] = {"car": "CV"}
    changed = tmp_path / "car.yaml"
    changed.write_text(yaml.safe_dump(raw))

    def trucks(preset):
        run = track_scenes(build_tracker("ekf", preset), [scene], dets)
        out, first_seen = [], {}
        for f in scene.frames:
            r = run.results[f.token]
            keep = r.labels == TRUCK
            ids = [first_seen.setdefault(int(t), len(first_seen)) for t in r.ids[keep]]
            out.append((r.boxes[keep], r.scores[keep], ids))
        return out, run

    (a, run_a), (b, run_b) = trucks(base), trucks(changed)
    cars = [int((run_a.results[f.token].labels == CAR).sum()) for f in scene.frames]
    cars_b = [int((run_b.results[f.token].labels == CAR).sum()) for f in scene.frames]
    assert cars != cars_b  # the car settings did change the cars
    assert sum(len(ids) for _, _, ids in a) > 20
    for (boxes_a, scores_a, ids_a), (boxes_b, scores_b, ids_b) in zip(a, b):
        assert np.array_equal(boxes_a, boxes_b) and np.array_equal(scores_a, scores_b) and ids_a == ids_b


def test_the_lost_newborn_penalty_loses_a_near_tie_but_never_refuses_a_pair():
    from grutrack.tracking.association import penalized
    from grutrack.tracking.tracker import lost_newborns

    # tracks: confirmed (3 hits), newborn matched in the frame before (misses 1), lost newborn (1 hit, missed since),
    # an old track missed since (4 hits)
    lost = lost_newborns(np.array([3, 1, 1, 4]), np.array([2, 1, 3, 5]), 0.5)
    assert lost.tolist() == [False, False, True, False]
    extra = np.where(lost, 0.1, 0.0)  # the penalty of each track's class, as the association adds it
    # lost after 0.25 s without a match at any rate: at 10 Hz a newborn missed for two sweeps is not yet lost
    ten_hz = lost_newborns(np.ones(3, dtype=np.int64), np.array([2, 3, 4]), 0.1)
    assert ten_hz.tolist() == [False, False, True]
    # detection 0 lies between the confirmed track 0 (cost 0.52) and the lost newborn 2 (cost 0.50); detection 1
    # has the lost newborn alone, 0.05 below its threshold; the second row's class has threshold 1.0
    cost = np.array([[0.52, 9.0, 0.50, 9.0], [9.0, 9.0, 0.95, 9.0]])
    thr = np.array([1.2, 1.0])
    out = penalized(cost, thr, extra)
    assert np.allclose(out[0], [0.52, 9.0, 0.60, 9.0])  # the tie now goes to the confirmed track
    assert out[1, 2] < 1.0 and out[1, 2] > 0.999  # capped just below the threshold: still admitted
    assert out[1, 0] == 9.0  # inadmissible pairs unchanged

    def pairs(penalty):  # detection 0 at x = 0 between track 0 (x = 0.3) and the lost newborn 2 (x = -0.25)
        m = associate(
            np.array([_box(0.0, 0), _box(30.0, 0)]),
            np.zeros(2, dtype=np.int64),
            np.array([_box(0.3, 0), _box(60.0, 0), _box(-0.25, 0), _box(90.0, 0)]),
            np.zeros(4, dtype=np.int64),
            ("giou_3d",) * 7,
            np.full(7, 1.5),
            False,
            "giou_bev",
            np.full(7, 1.0),
            "threshold_margin",
            track_penalty=penalty,
        )
        return sorted(zip(m.dets.tolist(), m.tracks.tolist()))

    assert pairs(None) == [(0, 2)]  # the nearer lost newborn wins without the penalty
    assert pairs(extra) == [(0, 0)]  # the confirmed track with it


def test_the_lost_newborn_penalty_is_refused_where_stage_one_is_not_the_two_stage_hungarian(tmp_path):
    from grutrack.errors import ConfigError

    raw = yaml.safe_load((PRESET_DIR / "fastpoly.yaml").read_text())
    raw["association"]["lost_newborn_penalty"] = dict.fromkeys(raw["association"]["first_threshold"], 0.1)
    path = tmp_path / "fastpoly_penalty.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"'association.lost_newborn_penalty' above 0 needs"):
        load_tracker_config(path)
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["association"]["lost_newborn_penalty"] = dict.fromkeys(raw["association"]["first_threshold"], 0.1)
    path.write_text(yaml.safe_dump(raw))
    cfg = load_tracker_config(path)
    assert cfg.lost_newborn_penalty.tolist() == [0.1] * 7
    assert build_tracker("ekf", path).associate.wants_tracks
    assert not build_tracker("ekf", "polymot").associate.wants_tracks  # off: no tracks asked for


def test_crowded_stage_one_leaves_skipped_tracks_out_of_the_crowded_test():
    from grutrack.tracking.association import crowded_stage_one

    # detection 0 near track 0 (confirmed) and track 1 (skipped: a lost newborn); detection 1 near tracks 0 and 2
    cost = np.array([[0.5, 0.6, 1e6], [0.7, 1e6, 0.8]])  # 1e6: a forbidden pair
    table = np.full((2, 3), 0.1)

    def strict(rows, cols, need):
        return table[np.ix_(rows, cols)]

    args = (np.zeros(2, dtype=np.int64), np.array([1.0]), np.array([0.8]), strict)
    every = crowded_stage_one(cost, *args)
    assert np.allclose(every, [[0.3, 0.3, 1e6], [0.3, 1e6, 0.3]])  # both rows and column 0 crowded
    skipped = crowded_stage_one(cost, *args, skip=np.array([False, True, False]))
    # row 0 alone is no longer crowded by track 1, but column 0 still is (detections 0 and 1); track 1's pair keeps
    # its first cost all the same
    assert np.allclose(skipped, [[0.3, 0.6, 1e6], [0.3, 1e6, 0.3]])
    lone = crowded_stage_one(cost[:1], args[0][:1], *args[1:], skip=np.array([False, True, False]))
    assert np.array_equal(lone, cost[:1])  # only the skipped track makes row 0 crowded: nothing changes


def test_crowded_skips_lost_newborns_judges_a_row_by_the_first_metric_when_a_lost_newborn_crowds_it(tmp_path):
    from grutrack.errors import ConfigError
    from grutrack.tracking.tracker import TrackView

    person = {"w": 0.6, "l": 0.6, "h": 1.7, "z": 0.85}
    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    assert raw["association"]["crowded_threshold"]["pedestrian"] == 2.06  # the preset's crowded pedestrians
    raw["association"]["crowded_skips_lost_newborns"] = False
    off = tmp_path / "off.yaml"
    off.write_text(yaml.safe_dump(raw))
    raw["association"]["crowded_skips_lost_newborns"] = True
    path = tmp_path / "skip.yaml"
    path.write_text(yaml.safe_dump(raw))
    trk = np.array([_box(0.0, 0, **person), _box(6.2, 0, **person)])
    dets = BoxSet(np.array([_box(3.0, 0, **person)]), np.full(1, 0.9), np.array([PED]))

    def matched(preset, hits, misses):  # the crowded row of the test above: both tracks' 3D GIoU costs admit it
        run = build_tracker("ekf", preset).associate
        view = TrackView(np.arange(2), trk, np.array(hits), np.array(misses))
        extra = {"tracks": view} if run.wants_tracks else {}
        m = run(dets, trk, np.full(2, PED), 0.5, **extra)
        return sorted(zip(m.dets.tolist(), m.tracks.tolist()))

    assert matched(off, [5, 1], [1, 3]) == []  # without the skip: a crowded row, Ro_GDIoU admits neither
    assert matched(path, [5, 4], [1, 3]) == []  # two tracks with evidence: still crowded
    assert matched(path, [5, 1], [1, 3]) == [(0, 0)]  # track 1 a lost newborn: a lone pair, first metric
    # refused without a crowded class, and outside the two-stage Hungarian association
    raw["association"]["crowded_threshold"] = dict.fromkeys(raw["association"]["first_threshold"], 0.0)
    raw["association"].pop("ro_gdiou_weights")
    path.write_text(yaml.safe_dump(raw))
    key = r"'association.crowded_skips_lost_newborns: true' needs"
    with pytest.raises(ConfigError, match=key + r" 'association.crowded_threshold'"):
        load_tracker_config(path)
    raw = yaml.safe_load((PRESET_DIR / "fastpoly.yaml").read_text())
    raw["association"]["crowded_skips_lost_newborns"] = True
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=key + r" 'association.algorithm"):
        load_tracker_config(path)
