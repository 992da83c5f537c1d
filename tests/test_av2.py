"""Argoverse 2 end to end on the two real val logs of ../shared/data/av2: adapter, LT3D detection converter,
tracking-challenge pickle + feather, the official AV2 tracking evaluation (HOTA), the Table I baselines.

There are no real AV2 detections in the fixture. Detections here are made from the annotations: the oracle
(annotations as detections, score 1) and SIMULATED detections sampled by grutrack.data.detection_sim (the
"centerpoint" detector profile: noise, misses, duplicates, false positives) at 2 Hz. The simulated numbers
compare trackers on the same input; they are not LT3D results and not comparable to the paper's Table I.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from grutrack.cli import main
from grutrack.data import av2
from grutrack.data.lt3d_detections import detection_table, load_detections
from grutrack.data.scene import BoxSet, Frame, Scene, Vocabulary
from grutrack.errors import DatasetError, InputFormatError
from grutrack.evaluation.av2_eval import default_workers, evaluate_sequences, metrics_from_result
from grutrack.export.av2_tracks import (
    build_sequences,
    expected_frames,
    gt_sequences,
    read_tracks_pickle,
    sequences_to_table,
    table_to_sequences,
    validate_sequences,
)
from grutrack.tracking.baselines import greedy_association
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes

LOG_A = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"
LOG_B = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"

# ------------------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def scenes(av2_root):
    """The two val logs at 2 Hz with Table I ground truth."""
    return av2.load_scenes(av2_root, "val", with_gt=True)


def lt3d_table(scenes: list[Scene], boxsets: dict[str, BoxSet]) -> pd.DataFrame:
    """City-frame canonical boxes written back as an LT3D detection table (ego frame of each sweep)."""
    return detection_table(scenes, boxsets)


def simulated_boxsets(scenes: list[Scene], vocab: Vocabulary, seed: int = 0) -> dict[str, BoxSet]:
    """SIMULATED detections of every frame from its ground truth (grutrack.data.detection_sim, centerpoint)."""
    from grutrack.data.detection_sim import load_profile, simulate_scenes

    return simulate_scenes(
        scenes, tuple(av2.SIMULATOR_CLASS[n] for n in vocab.names), load_profile("centerpoint"), seed
    )


def _track(root, dets, out, tracker="ekf", *extra) -> None:
    assert (
        main(
            [
                "track",
                "--dataset",
                "av2",
                "--dataroot",
                str(root),
                "--split",
                "val",
                "--detections",
                str(dets),
                "--tracker",
                tracker,
                "--out",
                str(out),
                "--no-progress",
                *extra,
            ]
        )
        == 0
    )


def _evaluate(root, sub, out) -> dict:
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                "av2",
                "--dataroot",
                str(root),
                "--split",
                "val",
                "--submission",
                str(sub),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return json.loads(out.read_text())


# ------------------------------------------------------------------------------------------------------------
# adapter
# ------------------------------------------------------------------------------------------------------------


def test_category_lists_match_av2():
    from av2.datasets.sensor.constants import AnnotationCategories
    from av2.evaluation import SensorCompetitionCategories

    assert av2.COMPETITION_CATEGORIES == tuple(c.value for c in SensorCompetitionCategories)
    assert set(av2.COMPETITION_CATEGORIES + av2.OTHER_ANNOTATION_CATEGORIES) == {c.value for c in AnnotationCategories}
    assert set(av2.PARAM_CLASS) == set(av2.COMPETITION_CATEGORIES)
    v = av2.vocabulary()
    assert v.names == av2.TABLE_I_CLASSES
    assert v.param_classes == ("car", "pedestrian", "bicycle", "truck", "bus", "truck", "truck")


def test_scenes_city_frame_and_rate(av2_root, scenes):
    assert [s.name for s in scenes] == [LOG_A, LOG_B] and [len(s) for s in scenes] == [32, 32]
    full = av2.load_scenes(av2_root, "val", rate_hz=None, log_ids=[LOG_A])[0]
    assert len(full) == 156
    ts = np.array([av2.token_timestamp_ns(f.token) for f in scenes[0].frames])
    assert np.allclose(np.diff(ts) * 1e-9, 0.5, atol=0.01)  # 2 Hz
    assert [f.token for f in scenes[0].frames] == [f.token for f in full.frames[::5]]
    assert scenes[0].frames[3].timestamp == ts[3] // 1000  # canonical frames are in microseconds
    # one box against an independent transform of the raw tables (scipy rotations)
    ann = pd.read_feather(av2_root / "val" / LOG_A / "annotations.feather")
    poses = pd.read_feather(av2_root / "val" / LOG_A / "city_SE3_egovehicle.feather").set_index("timestamp_ns")
    f = scenes[0].frames[7]
    row = ann[(ann.timestamp_ns == ts[7]) & (ann.track_uuid == f.gt.ids[0])].iloc[0]
    pose = poses.loc[ts[7]]
    r_ego = Rotation.from_quat([pose.qx, pose.qy, pose.qz, pose.qw])
    centre = r_ego.apply([row.tx_m, row.ty_m, row.tz_m]) + [pose.tx_m, pose.ty_m, pose.tz_m]
    heading = (r_ego * Rotation.from_quat([row.qx, row.qy, row.qz, row.qw])).apply([1.0, 0, 0])
    assert np.allclose(f.gt.boxes[0, 0:3], centre, atol=1e-6)
    assert np.allclose(f.gt.boxes[0, 3:6], [row.width_m, row.length_m, row.height_m])
    assert np.isclose(f.gt.boxes[0, 6], np.arctan2(heading[1], heading[0]), atol=1e-9)
    # velocities are plausible and the parked / moving split is there
    speeds = np.concatenate([np.hypot(*fr.gt.boxes[:, 7:9].T) for s in scenes for fr in s.frames])
    assert speeds.max() < 30 and (speeds < 0.2).mean() > 0.2 and (speeds > 2).mean() > 0.05
    assert set(np.concatenate([fr.gt.labels for s in scenes for fr in s.frames])) == set(range(7))


def test_empty_and_missing_logs(av2_root, tmp_path):
    root = tmp_path / "sensor"
    log = root / "val" / "0000-empty"
    log.mkdir(parents=True)
    (root / "val" / LOG_A).symlink_to(av2_root / "val" / LOG_A)
    src = av2_root / "val" / LOG_A
    pd.read_feather(src / "city_SE3_egovehicle.feather").to_feather(log / "city_SE3_egovehicle.feather")
    pd.read_feather(src / "annotations.feather").iloc[:0].to_feather(log / "annotations.feather")
    with pytest.raises(DatasetError, match="0000-empty: cannot determine its frames: its annotations.feather has no"):
        av2.load_scenes(root, "val")
    assert (
        main(
            [
                "track",
                "--dataset",
                "av2",
                "--dataroot",
                str(root),
                "--split",
                "val",
                "--detections",
                str(tmp_path / "none.feather"),
                "--out",
                str(tmp_path / "o.pkl"),
                "--no-progress",
            ]
        )
        == 2
    )
    with pytest.raises(DatasetError, match="no split folder 'test'"):
        av2.load_scenes(av2_root, "test")
    with pytest.raises(DatasetError, match="not in"):
        av2.load_scenes(av2_root, "val", log_ids=["nope"])


# ------------------------------------------------------------------------------------------------------------
# detections
# ------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def oracle_table(scenes):
    return lt3d_table(scenes, {f.token: f.gt for s in scenes for f in s.frames})


def test_lt3d_roundtrip_and_drop_policy(av2_root, scenes, oracle_table, tmp_path):
    # an extra detection at a 10 Hz sweep that is not a tracked frame, and one of an untracked category
    full = av2.load_scenes(av2_root, "val", rate_hz=None, log_ids=[LOG_A])[0]
    extra = oracle_table.iloc[[0, 1]].copy()
    extra["timestamp_ns"] = [av2.token_timestamp_ns(full.frames[1].token), extra["timestamp_ns"].iat[1]]
    extra["category"] = ["REGULAR_VEHICLE", "BOLLARD"]
    path = tmp_path / "d.csv"
    pd.concat([oracle_table, extra], ignore_index=True).to_csv(path, index=False)
    dets, stats = load_detections(path, av2_root, "val", scenes, av2.vocabulary())
    assert (stats.rows, stats.kept, stats.off_frame, stats.other_category) == (
        len(oracle_table) + 2,
        len(oracle_table),
        1,
        1,
    )
    for s in scenes:
        for f in s.frames[::7]:
            d = dets[f.token]
            assert np.allclose(d.boxes[:, :7], f.gt.boxes[:, :7], atol=1e-6) and (d.labels == f.gt.labels).all()
            # velocity travels as (vx, vy) in ego axes: the ego's small pitch / roll loses its vertical part
            assert np.allclose(d.boxes[:, 7:9], f.gt.boxes[:, 7:9], rtol=1e-2, atol=1e-3)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (
            lambda d: d.__setitem__("log_id", d["log_id"].where(d.index != 5, "00000000-not-a-log")),
            "field 'log_id' has 1 log.*00000000-not-a-log",
        ),
        (
            lambda d: d.__setitem__("timestamp_ns", d["timestamp_ns"].where(d.index != 5, 123)),
            "row 5 .*field 'timestamp_ns' 123 is not a sweep time",
        ),
        (
            lambda d: d.__setitem__("tx_m", d["tx_m"].where(d.index != 5, np.nan)),
            "row 5 .*field 'tx_m' must be a finite number .*, got nan",
        ),
        (
            lambda d: d.__setitem__("qw", d["qw"].where(d.index != 5, 3.0)),
            "row 5 .*'qw/qx/qy/qz' must be a unit quaternion",
        ),
        (
            lambda d: d.__setitem__("score", d["score"].where(d.index != 5, 1.5)),
            "row 5 .*'score' must be a number in \\[0, 1\\], got 1.5",
        ),
        (
            lambda d: d.__setitem__("category", d["category"].where(d.index != 5, "CAR")),
            "row 5 .*'category' must be an AV2",
        ),
        (lambda d: d.drop(columns=["height_m"], inplace=True), "missing column\\(s\\) \\['height_m'\\]"),
    ],
)
def test_lt3d_bad_input(av2_root, scenes, oracle_table, tmp_path, mutate, message):
    d = oracle_table.copy()
    mutate(d)
    path = tmp_path / "bad.feather"
    d.to_feather(path)
    with pytest.raises(InputFormatError, match=message) as err:
        load_detections(path, av2_root, "val", scenes, av2.vocabulary())
    assert str(path) in str(err.value)


def test_lt3d_pickle_and_empty_file(av2_root, scenes, oracle_table, tmp_path):
    oracle_table.to_pickle(tmp_path / "d.pkl")
    dets, _ = load_detections(tmp_path / "d.pkl", av2_root, "val", scenes, av2.vocabulary())
    assert sum(len(b) for b in dets.values()) == len(oracle_table)
    oracle_table.iloc[:0].to_feather(tmp_path / "e.feather")
    dets, stats = load_detections(tmp_path / "e.feather", av2_root, "val", scenes, av2.vocabulary())
    assert stats.rows == 0 and len(dets) == 64 and all(len(b) == 0 for b in dets.values())


# ------------------------------------------------------------------------------------------------------------
# export
# ------------------------------------------------------------------------------------------------------------


def test_pickle_layout_and_validation(scenes):
    vocab = av2.vocabulary()
    res = {
        f.token: BoxSet(f.gt.boxes, np.full(len(f.gt), 0.5), f.gt.labels, np.arange(len(f.gt)))
        for s in scenes
        for f in s.frames
    }
    seqs = build_sequences(scenes, res, vocab)
    exp = expected_frames(scenes)
    validate_sequences(seqs, exp)
    fr = seqs[LOG_B][4]
    n = len(fr["track_id"])
    assert fr["seq_id"] == LOG_B and fr["timestamp_ns"] == exp[LOG_B][4]
    assert fr["translation_m"].shape == (n, 3) and fr["size"].shape == (n, 3) and fr["velocity_m_per_s"].shape == (n, 3)
    assert isinstance(fr["ego_translation_m"], list) and fr["track_id"].dtype == np.int64
    assert set(fr["name"]) <= set(av2.TABLE_I_CLASSES)
    assert [av2.COMPETITION_CATEGORIES[i] for i in fr["label"]] == list(fr["name"])
    bad = {k: v for k, v in seqs.items()}
    bad[LOG_A] = seqs[LOG_A][:-1]
    with pytest.raises(InputFormatError, match=f"log {LOG_A}: frames must be exactly the 32 label frames"):
        validate_sequences(bad, exp, "sub.pkl")
    with pytest.raises(InputFormatError, match="logs must be exactly"):
        validate_sequences({LOG_A: seqs[LOG_A]}, exp)


def test_all_categories_track_and_export(av2_root, tmp_path):
    vocab = av2.vocabulary(all_categories=True)
    scenes = av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True)
    lt3d_table(scenes, {f.token: f.gt for s in scenes for f in s.frames}).to_feather(tmp_path / "d.feather")
    dets, stats = load_detections(tmp_path / "d.feather", av2_root, "val", scenes, vocab)
    assert stats.kept == stats.rows == sum(len(f.gt) for s in scenes for f in s.frames)
    for name in ("ekf", "greedy", "ab3dmot"):
        run = track_scenes(build_tracker(name, param_classes=vocab.param_classes), scenes, dets)
        seqs = build_sequences(scenes, run.results, vocab)
        validate_sequences(seqs, expected_frames(scenes))
        names = {n for fs in seqs.values() for f in fs for n in f["name"]}
        assert {"BOLLARD", "CONSTRUCTION_CONE", "REGULAR_VEHICLE"} <= names


# ------------------------------------------------------------------------------------------------------------
# tracking baselines
# ------------------------------------------------------------------------------------------------------------


def test_greedy_association_score_order_gate_and_labels():
    def dets(xy, scores, labels):
        b = np.zeros((len(xy), 9))
        b[:, 0:2], b[:, 3:6] = xy, 1.0
        return BoxSet(b, np.array(scores, float), np.array(labels))

    assoc = greedy_association(np.array([2.0, 5.0]))
    trk = np.zeros((2, 9))
    trk[:, 0] = [0.0, 3.0]
    # both detections are nearest to track 0; the higher score takes it, the other takes track 1 (within 5 m)
    m = assoc(dets([[0.5, 0], [0.2, 0]], [0.3, 0.9], [1, 1]), trk, np.array([1, 1]), 0.5)
    assert sorted(zip(m.dets.tolist(), m.tracks.tolist())) == [(0, 1), (1, 0)]
    m = assoc(dets([[0.5, 0], [0.2, 0]], [0.3, 0.9], [0, 0]), trk, np.array([0, 0]), 0.5)
    assert m.dets.tolist() == [1] and m.unmatched_dets.tolist() == [0]  # 2 m gate for label 0
    m = assoc(dets([[0.0, 0]], [0.9], [0]), trk, np.array([1, 1]), 0.5)
    assert len(m.dets) == 0  # different labels never match
    # velocity compensation: a detection 5 m ahead moving at 10 m/s was at the track 0.5 s ago
    d = dets([[5.0, 0]], [0.9], [0])
    d.boxes[0, 7] = 10.0
    assert assoc(d, trk[:1], np.array([0]), 0.5).dets.tolist() == [0]


def test_ab3dmot_min_hits_and_zero_velocity_start():
    t = build_tracker("ab3dmot")
    frames = [Frame(f"f{i}", 1_000_000 + 500_000 * i, np.zeros(3), np.array([1.0, 0, 0, 0])) for i in range(6)]
    box = lambda x: np.array([[x, 0, 0.8, 1.8, 4.5, 1.6, 0, 9.0, 0]])  # noqa: E731  (detector says 9 m/s)
    dets = {f"f{i}": BoxSet(box(2.0 * i), [0.9], [2]) for i in range(6)}
    dets["f4"] = BoxSet(np.zeros((0, 9)), [], [])
    scene = Scene("s", "s", frames)
    run = track_scenes(t, [scene], dets)
    # written in the first 3 frames of a scene (AB3DMOT frame_count <= min_hits), then from the 3rd hit on
    assert [len(run.results[f"f{i}"]) for i in range(6)] == [1, 1, 1, 1, 1, 1]
    assert abs(t.groups[0].backend.boxes(t.groups[0].state)[0, 7] - 4.0) < 1.0  # velocity from positions (4 m/s)
    # a new track born late is hidden until its third hit
    t.reset()
    late = {
        f"f{i}": BoxSet(box(2.0 * i) if i >= 3 else np.zeros((0, 9)), [0.9] * (i >= 3), [2] * (i >= 3))
        for i in range(6)
    }
    run = track_scenes(t, [scene], late)
    assert [len(run.results[f"f{i}"]) for i in range(6)] == [0, 0, 0, 0, 0, 1]


# ------------------------------------------------------------------------------------------------------------
# official evaluation end to end
# ------------------------------------------------------------------------------------------------------------


def duplicated_tracks(scenes: list[Scene], radius_m: float = 0.2) -> set[str]:
    """Track uuids annotated twice: the second uuid of every same-class pair whose centres are within
    ``radius_m`` in every frame where both exist (one such pair in log 7fab2350: a REGULAR_VEHICLE with two
    track_uuids through all 32 frames). No tracker can keep such twins apart, so the oracle loses AssA there."""
    close, seen = {}, {}
    for s in scenes:
        for f in s.frames:
            b = f.gt.boxes
            d = np.hypot(b[:, None, 0] - b[None, :, 0], b[:, None, 1] - b[None, :, 1])
            i, j = np.nonzero(np.triu((d < radius_m) & (f.gt.labels[:, None] == f.gt.labels[None, :]), 1))
            for u, v in zip(f.gt.ids[i], f.gt.ids[j]):
                close[(u, v)] = close.get((u, v), 0) + 1
            for u in f.gt.ids:
                seen[u] = seen.get(u, 0) + 1
    return {v for (u, v), n in close.items() if n == min(seen[u], seen[v])}


def test_oracle_hota_pickle_feather_and_metrics(av2_root, scenes, oracle_table, tmp_path):
    # the default ekf tracker on the annotations (score 1), through the CLI, official evaluator
    oracle_table.to_feather(tmp_path / "gt_dets.feather")
    sub = tmp_path / "sub.pkl"
    _track(av2_root, tmp_path / "gt_dets.feather", sub, "ekf")
    seqs = read_tracks_pickle(sub)
    labels = gt_sequences(
        av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True), av2.vocabulary(all_categories=True)
    )
    assert list(seqs) == list(labels)
    assert [[f["timestamp_ns"] for f in fs] for fs in seqs.values()] == [
        [f["timestamp_ns"] for f in fs] for fs in labels.values()
    ]
    # the feather table holds the same tracks
    table = pd.read_feather(sub.with_suffix(".feather"))
    assert len(table) == sum(len(f["track_id"]) for fs in seqs.values() for f in fs)
    back = table_to_sequences(table, expected_frames(scenes))
    for log in seqs:
        for a, b in zip(seqs[log], back[log]):
            for key in ("track_id", "translation_m", "size", "velocity_m_per_s", "label", "name", "score"):
                np.testing.assert_allclose(a[key], b[key]) if a[
                    key
                ].dtype.kind == "f" else np.testing.assert_array_equal(a[key], b[key])
            np.testing.assert_allclose(np.cos(a["yaw"] - b["yaw"]), 1.0, atol=1e-12)
    pd.testing.assert_frame_equal(sequences_to_table(back), table)
    # the official evaluator's own loader reads the leaderboard file
    from av2.evaluation.tracking import utils as official_utils

    assert official_utils.load(str(sub)).keys() == seqs.keys()
    m = _evaluate(av2_root, sub, tmp_path / "metrics.json")
    assert m["dataset"] == "av2" and m["split"] == "val" and set(m) >= {"evaluator", "overall", "per_class"}
    assert set(m["per_class"]) == set(av2.COMPETITION_CATEGORIES)
    present = m["overall"]["present_classes"]
    assert len(present) >= 5
    for c in present:  # REGULAR_VEHICLE: the doubly annotated car, see duplicated_tracks and the next test
        assert m["per_class"][c]["hota"] >= (0.98 if c == "REGULAR_VEHICLE" else 0.99), (c, m["per_class"][c])
    absent = [c for c in av2.TABLE_I_CLASSES if c not in present]
    assert all(m["per_class"][c]["hota"] == 0.0 and m["per_class"][c]["absent"] for c in absent)
    assert m["overall"]["absent_classes"] == absent
    # the Table I average is over the classes with ground truth (tests/test_av2_absent_classes.py)
    assert np.isclose(m["overall"]["hota"], np.mean([m["per_class"][c]["hota"] for c in present]))
    assert m["settings"]["drivable_area_roi"] and m["settings"]["max_range_m"] == 50
    assert m["settings"]["workers"] == default_workers()


def test_oracle_without_the_doubly_annotated_car(av2_root, scenes):
    twins = duplicated_tracks(scenes)
    assert len(twins) == 1
    vocab, all_vocab = av2.vocabulary(), av2.vocabulary(all_categories=True)
    gt = {f.token: f.gt.subset(~np.isin(f.gt.ids, list(twins))) for s in scenes for f in s.frames}
    tracker = build_tracker("ekf", param_classes=vocab.param_classes)
    run = track_scenes(tracker, scenes, gt)
    all_scenes = av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True)
    for s in all_scenes:
        for f in s.frames:
            f.gt = f.gt.subset(~np.isin(f.gt.ids, list(twins)))
    out = evaluate_sequences(
        build_sequences(scenes, run.results, vocab), gt_sequences(all_scenes, all_vocab), av2_root / "val"
    )
    overall, per_class = metrics_from_result(out)
    assert len(overall["present_classes"]) >= 5
    for c in overall["present_classes"]:
        assert per_class[c]["hota"] >= 0.99, (c, per_class[c])


@pytest.fixture(scope="module")
def simulated_ekf(av2_root, scenes):
    """(tracks, labels): the ekf tracker on SIMULATED detections (centerpoint profile, seed 0) of the Table I
    classes, and the labels of all 26 categories, both in the order the official evaluator regroups them."""
    vocab = av2.vocabulary()
    run = track_scenes(
        build_tracker("ekf", param_classes=vocab.param_classes), scenes, simulated_boxsets(scenes, vocab, seed=0)
    )
    labels = gt_sequences(
        av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True), av2.vocabulary(all_categories=True)
    )
    order = sorted(labels, key=lambda lg: labels[lg][0]["timestamp_ns"])
    tracks = build_sequences(scenes, run.results, vocab)
    return {lg: tracks[lg] for lg in order}, {lg: labels[lg] for lg in order}


def _assert_tree_equal(a, b, where=""):
    """Nested dicts of TrackEval results equal: integers and strings exactly, floats to 1e-12 (NaN == NaN)."""
    if isinstance(a, dict):
        assert set(a) == set(b), (where, set(a) ^ set(b))
        for k in a:
            _assert_tree_equal(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, np.ndarray) and a.dtype.kind == "f" or isinstance(a, float):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, err_msg=where)
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b, err_msg=where)
    else:
        assert a == b, (where, a, b)


@pytest.mark.slow
def test_composition_equals_the_unpatched_official_evaluate(av2_root, simulated_ekf, tmp_path):
    import contextlib
    import copy

    import av2.evaluation.tracking.eval as official
    from av2.evaluation.tracking import utils as official_utils

    tracks, labels = simulated_ekf
    ddir = str(av2_root / "val")
    # the official function as shipped (it writes its TrackEval files under ./trackeval and fails on an empty frame,
    # which this input does not have)
    with contextlib.chdir(tmp_path):
        res, tuned, mean = official.evaluate(
            copy.deepcopy(tracks), copy.deepcopy(labels), "HOTA", 50, ddir, "trackeval/metrics.json"
        )
    assert (tmp_path / "trackeval" / "TRACKER").is_dir()
    # its tuned thresholds: its own preprocessing and tuning, called as evaluate calls them
    ref_labels = official.filter_max_dist(copy.deepcopy(labels), 50)
    ref_tracks = copy.deepcopy(tracks)
    official_utils.annotate_frame_metadata(
        official_utils.ungroup_frames(ref_tracks), official_utils.ungroup_frames(ref_labels), ["ego_translation_m"]
    )
    ref_tracks = official.filter_max_dist(ref_tracks, 50)
    assert all(len(f["yaw"]) for seqs in (ref_labels, ref_tracks) for fs in seqs.values() for f in fs)
    ref_labels = official.filter_drivable_area(ref_labels, ddir)
    ref_tracks = official.filter_drivable_area(ref_tracks, ddir)
    thresholds, tuned_again, mean_again = official._tune_score_thresholds(
        ref_labels, ref_tracks, "HOTA", list(av2.COMPETITION_CATEGORIES), num_thresholds=10, match_distance_m=2
    )
    assert tuned_again == tuned and mean_again == mean  # the same tuning as inside evaluate
    ref_final = official_utils.filter_by_class_thresholds(ref_tracks, thresholds)

    combined = res["TrackEvalDataset"]["TRACKER"]["COMBINED_SEQ"]
    assert set(combined) >= set(av2.COMPETITION_CATEGORIES) and len(av2.COMPETITION_CATEGORIES) == 26
    for workers in (1, 2):  # in this process; a pool of 2
        out = evaluate_sequences(tracks, labels, av2_root / "val", workers=workers, keep_inputs=True)
        _assert_tree_equal(out["result"], res)  # every sequence, class, HOTA / CLEAR / Count field
        ours = out["result"]["TrackEvalDataset"]["TRACKER"]["COMBINED_SEQ"]
        for c in av2.COMPETITION_CATEGORIES:
            for k in ("CLR_TP", "CLR_FP", "CLR_FN", "IDSW", "MT", "ML", "Frag"):
                assert ours[c]["CLEAR"][k] == combined[c]["CLEAR"][k], (workers, c, k)
            assert abs(ours[c]["CLEAR"]["MOTA"] - combined[c]["CLEAR"]["MOTA"]) <= 1e-12
            assert abs(np.mean(ours[c]["HOTA"]["HOTA"]) - np.mean(combined[c]["HOTA"]["HOTA"])) <= 1e-12
            assert abs(out["tuned"][c] - tuned[c]) <= 1e-12 and abs(out["mean"][c] - mean[c]) <= 1e-12
            assert out["final"]["thresholds"][c] == float(thresholds[c]), (workers, c)
        assert set(out["others"]) >= set(av2.COMPETITION_CATEGORIES)
        assert all(set(out["others"][c]) == {"Identity"} for c in av2.COMPETITION_CATEGORIES)
        # the final inputs are the official ones
        for mine, ref in ((out["final"]["labels"], ref_labels), (out["final"]["predictions"], ref_final)):
            assert list(mine) == list(ref)
            for lg in ref:
                for a, b in zip(mine[lg], ref[lg], strict=True):
                    np.testing.assert_array_equal(a["track_id"], b["track_id"])
                    np.testing.assert_array_equal(a["translation_m"], b["translation_m"])
    # a real input: classes with ground truth and tracks, and thresholds that filter
    present = [c for c in av2.COMPETITION_CATEGORIES if combined[c]["CLEAR"]["CLR_TP"] > 0]
    assert {"REGULAR_VEHICLE", "PEDESTRIAN"} <= set(present)
    assert 0.2 < np.mean(combined["REGULAR_VEHICLE"]["HOTA"]["HOTA"]) < 0.95
    assert any(thresholds[c] > 0 for c in present)


@pytest.mark.slow  # a whole official evaluation in a fresh interpreter
def test_evaluation_patches_nothing(av2_root, tmp_path):
    import ast
    import inspect
    import os
    import subprocess
    import sys

    from grutrack.evaluation import av2_eval

    tree = ast.parse(inspect.getsource(av2_eval))
    imported = {a.name for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
    imported |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not {m for m in imported if m and ("mock" in m or m.startswith("unittest"))}, imported
    assert not [n for n in ast.walk(tree) if isinstance(n, ast.Name) and n.id in ("setattr", "patch")]
    # attribute assignments only on the module's own metrics document
    targets = [
        t
        for n in ast.walk(tree)
        if isinstance(n, (ast.Assign, ast.AugAssign))
        for t in (n.targets if isinstance(n, ast.Assign) else [n.target])
    ]
    attrs = [e for t in targets for e in (t.elts if isinstance(t, ast.Tuple) else [t]) if isinstance(e, ast.Attribute)]
    assert attrs and all(isinstance(e.value, ast.Name) and e.value.id == "doc" for e in attrs)
    # a whole evaluation (ROI, one worker) in a fresh interpreter imports no unittest.mock
    code = (
        "import sys, json; from grutrack.data import av2; from grutrack.export.av2_tracks import gt_sequences;"
        "from grutrack.evaluation.av2_eval import evaluate_sequences, metrics_from_result;"
        f"root = {str(av2_root)!r}; import numpy as np;"
        "lab = gt_sequences(av2.load_scenes(root, 'val', with_gt=True, all_categories=True),"
        " av2.vocabulary(all_categories=True));"
        "trk = {lg: [dict(f, score=np.ones(len(f['track_id']))) for f in fs] for lg, fs in lab.items()};"
        "out = evaluate_sequences(trk, lab, root + '/val', workers=1);"
        "print(json.dumps([metrics_from_result(out)[1]['REGULAR_VEHICLE']['tp'],"
        " sorted(m for m in sys.modules if m.startswith('unittest'))]))"
    )
    env = {**os.environ, "PYTHONPATH": str(Path(av2_eval.__file__).resolve().parents[2])}
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env, check=True
    )
    tp, unittest_modules = json.loads(run.stdout.strip().splitlines()[-1])
    assert tp > 100 and "unittest.mock" not in unittest_modules
    assert list(tmp_path.iterdir()) == []  # nothing written to the working directory


@pytest.mark.slow  # three trackers through track + evaluate; test_oracle_hota_pickle_feather_and_metrics is quick
def test_simulated_detections_table(av2_root, scenes, tmp_path, capsys):
    vocab = av2.vocabulary()
    table = lt3d_table(scenes, simulated_boxsets(scenes, vocab, seed=0))
    table.to_feather(tmp_path / "sim.feather")
    results = {}
    for tracker in ("greedy", "ab3dmot", "ekf"):
        sub = tmp_path / f"{tracker}.pkl"
        _track(av2_root, tmp_path / "sim.feather", sub, tracker)
        results[tracker] = _evaluate(av2_root, sub, tmp_path / f"{tracker}.json")
    lines = [
        "SIMULATED detections (grutrack.data.detection_sim, centerpoint profile, seed 0) on the 2 AV2 val "
        "logs at 2 Hz; official AV2 HOTA",
        f"{'tracker':<9}" + "".join(f"{c[:10]:>11}" for c in av2.TABLE_I_CLASSES) + f"{'AVG':>9}",
    ]
    for tracker, m in results.items():
        lines.append(
            f"{tracker:<9}"
            + "".join(
                "absent".rjust(11) if m["per_class"][c]["absent"] else f"{m['per_class'][c]['hota']:>11.3f}"
                for c in av2.TABLE_I_CLASSES
            )
            + f"{m['overall']['hota']:>9.3f}"
        )
    with capsys.disabled():
        print("\n" + "\n".join(lines))
    (tmp_path / "table.txt").write_text("\n".join(lines))
    assert results["ekf"]["overall"]["hota"] >= results["ab3dmot"]["overall"]["hota"]
    for m in results.values():
        assert 0.2 < m["overall"]["hota"] < 1.0


def test_frames_without_detections_never_trip_the_evaluator(av2_root, scenes, oracle_table, tmp_path):
    # log B has no detection at all; log A has none in frames 5-12
    ts_a = [av2.token_timestamp_ns(f.token) for f in scenes[0].frames]
    keep = (oracle_table["log_id"] == LOG_A) & ~oracle_table["timestamp_ns"].isin(ts_a[5:13])
    oracle_table[keep].reset_index(drop=True).to_feather(tmp_path / "holes.feather")
    sub = tmp_path / "holes.pkl"
    _track(av2_root, tmp_path / "holes.feather", sub, "greedy")
    seqs = read_tracks_pickle(sub)
    assert [len(f["track_id"]) for f in seqs[LOG_B]] == [0] * 32
    assert all(len(f["track_id"]) == 0 for f in seqs[LOG_A][5:13])  # greedy writes matched tracks only
    assert all(f["translation_m"].shape == (0, 3) for f in seqs[LOG_B])
    labels = gt_sequences(
        av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True), av2.vocabulary(all_categories=True)
    )
    out = evaluate_sequences(seqs, labels, None, workers=1)  # in-process, no ROI
    _, per_class = metrics_from_result(out)
    assert 0.2 < per_class["REGULAR_VEHICLE"]["hota"] < 0.9
    # a submission that lacks a frame is refused before the official evaluator's assertion
    seqs[LOG_A] = seqs[LOG_A][1:]
    with open(tmp_path / "short.pkl", "wb") as fh:
        pickle.dump(seqs, fh)
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                "av2",
                "--dataroot",
                str(av2_root),
                "--split",
                "val",
                "--submission",
                str(tmp_path / "short.pkl"),
                "--out",
                str(tmp_path / "m.json"),
            ]
        )
        == 2
    )
    assert not (tmp_path / "m.json").exists()


def test_empty_logs_are_named_by_track_and_evaluate_with_the_roi(av2_root, oracle_table, tmp_path, capsys):
    # only log A has detections: track says so; the official evaluation with the drivable-area ROI (the maps
    # are present) scores the submission whose log B has no track at all
    oracle_table[oracle_table["log_id"] == LOG_A].reset_index(drop=True).to_feather(tmp_path / "a.feather")
    _track(av2_root, tmp_path / "a.feather", tmp_path / "a.pkl", "greedy")
    err = capsys.readouterr().err
    assert f"a.feather: 1 of 2 logs have no detection of a tracked category (first: {LOG_B})" in err
    assert all(len(f["track_id"]) == 0 for f in read_tracks_pickle(tmp_path / "a.pkl")[LOG_B])
    m = _evaluate(av2_root, tmp_path / "a.pkl", tmp_path / "m.json")
    assert m["settings"]["drivable_area_roi"] is True and (m["logs"], m["frames"]) == (2, 64)
    car = m["per_class"]["REGULAR_VEHICLE"]
    assert 0.1 < car["hota"] < 0.9 and car["gt_boxes"] > 0 and np.isfinite(m["overall"]["hota"])


def test_cli_dataset_options(av2_root, tmp_path, capsys):
    assert (
        main(
            [
                "track",
                "--dataroot",
                str(av2_root),
                "--split",
                "val",
                "--detections",
                "x.json",
                "--out",
                str(tmp_path / "o.json"),
            ]
        )
        == 2
    )
    assert "--version is required with --dataset nuscenes" in capsys.readouterr().err
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                "av2",
                "--dataroot",
                str(av2_root),
                "--split",
                "val",
                "--submission",
                "x.pkl",
                "--out",
                str(tmp_path / "m.json"),
                "--evaluator",
                "fast",
            ]
        )
        == 2
    )
    assert "AV2 has the official evaluator only" in capsys.readouterr().err


def test_official_module_imports_without_the_numpy_alias_warnings():
    """av2's alias shim makes numpy warn once per alias on import; official_module() shows none of them, and any
    other FutureWarning would still fail this (-W error)."""
    import subprocess
    import sys

    code = (
        "from grutrack.evaluation.av2_eval import official_module; m = official_module(); "
        "assert hasattr(m, 'TrackEvalDataset')"
    )
    r = subprocess.run([sys.executable, "-W", "error::FutureWarning", "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
