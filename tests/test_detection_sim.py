"""The detector simulator: profiles, the format-free core, official DetectionEval APs on real nuScenes
mini_val against published CenterPoint numbers, determinism, and clear errors for bad input."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

from grutrack.cli import main
from grutrack.data import demo
from grutrack.data import detection_sim as ds
from grutrack.errors import ConfigError, DatasetError, GrutrackError


def _detection_eval(nusc, result_path: Path, split: str, out_dir: Path) -> dict:
    """Official DetectionEval (detection_cvpr_2019) metrics as a dict."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.detection.evaluate import DetectionEval

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        ev = DetectionEval(
            nusc, config_factory("detection_cvpr_2019"), str(result_path), split, str(out_dir), verbose=False
        )
        metrics, _ = ev.evaluate()
    return metrics.serialize()


@pytest.fixture(scope="module")
def mini_val_centerpoint(nusc_mini, tmp_path_factory):
    """Simulated CenterPoint detections on mini_val (seed 0) and their DetectionEval metrics."""
    out = tmp_path_factory.mktemp("sim") / "cp.json"
    sub = ds.simulate_nuscenes(None, None, "mini_val", "centerpoint", 0, out, nusc=nusc_mini)
    return out, sub, _detection_eval(nusc_mini, out, "mini_val", out.parent / "eval")


def _frame(n: int = 400, pts: float = 50.0, seed: int = 0) -> ds.GTFrame:
    """A hand-made GT frame: n cars 10-40 m ahead of an ego at the origin (no dataset involved)."""
    rng = np.random.default_rng(seed)
    boxes = np.zeros((n, 9))
    boxes[:, 0], boxes[:, 1] = rng.uniform(10, 40, n), rng.uniform(-20, 20, n)
    boxes[:, 2:6] = [0.8, 1.9, 4.6, 1.7]
    boxes[:, 7] = 5.0
    return ds.GTFrame(
        token=f"frame-{seed}",
        scene="s",
        timestamp=0,
        ego_translation=np.zeros(3),
        boxes=boxes,
        names=np.array(["car"] * n, dtype=object),
        num_lidar_pts=np.full(n, int(pts)),
        num_radar_pts=np.zeros(n, np.int64),
        instance_ids=np.arange(n).astype(str).astype(object),
    )


# ---------------------------------------------------------------------------------------------------- profiles


def test_shipped_profiles_load():
    assert {"centerpoint", "pointpillars", "centerpoint_velfail"} <= set(ds.available_profiles())
    for name in ds.available_profiles():
        prof = ds.load_profile(name)
        assert set(prof.classes) == set(ds.DETECTION_CLASSES)
        assert set(prof.reference["ap"]) == set(ds.DETECTION_CLASSES)
        assert 0 < prof.max_boxes_per_sample <= 500


def test_velfail_profile_is_centerpoint_with_velocity_failures():
    """centerpoint_velfail: CenterPoint's statistics for every class, plus velocity failing over whole tracks."""
    import dataclasses

    cp, vf = ds.load_profile("centerpoint"), ds.load_profile("centerpoint_velfail")
    assert (vf.detection_range_m, vf.score_threshold, vf.max_boxes_per_sample, vf.reference) == (
        cp.detection_range_m,
        cp.score_threshold,
        cp.max_boxes_per_sample,
        cp.reference,
    )
    for c in ds.DETECTION_CLASSES:
        assert vf.classes[c].vel_track_fail_prob == 0.3 and cp.classes[c].vel_track_fail_prob == 0.0
        assert dataclasses.replace(vf.classes[c], vel_track_fail_prob=0.0) == cp.classes[c]


def test_drift_profiles_are_centerpoint_with_a_drifting_centre():
    """centerpoint_drift (training) and the suite's drift profile (evaluation): CenterPoint's statistics for every
    class plus a centre error correlated over time, each with its own values."""
    import dataclasses

    cp = ds.load_profile("centerpoint")
    for prof, sigma, tau in (
        (ds.load_profile("centerpoint_drift"), 0.15, 3.0),
        (ds.load_profile(Path(__file__).parents[1] / "docs/results/grukf_eval/drift.yaml"), 0.2, 2.0),
    ):
        assert (prof.detection_range_m, prof.score_threshold, prof.max_boxes_per_sample) == (
            cp.detection_range_m,
            cp.score_threshold,
            cp.max_boxes_per_sample,
        )
        for c in ds.DETECTION_CLASSES:
            assert (prof.classes[c].pos_drift_sigma_m, prof.classes[c].pos_drift_time_s) == (sigma, tau)
            assert cp.classes[c].pos_drift_sigma_m == 0.0
            assert dataclasses.replace(prof.classes[c], pos_drift_sigma_m=0.0, pos_drift_time_s=2.0) == cp.classes[c]


def test_unknown_profile_name():
    with pytest.raises(ConfigError, match=r"unknown detector profile 'centrepoint'.*centerpoint"):
        ds.load_profile("centrepoint")


def test_misspelt_keys_are_named(tmp_path):
    text = (ds.PROFILE_DIR / "centerpoint.yaml").read_text()
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace("  pedestrian:\n    recall_max:", "  pedestrian:\n    recal_max:"))
    with pytest.raises(ConfigError) as err:
        ds.load_profile(bad)
    assert str(bad) in str(err.value) and "recal_max" in str(err.value) and "recall_max" in str(err.value)
    assert "classes.pedestrian" in str(err.value)
    bad.write_text(text.replace("score_threshold:", "score_treshold:"))
    with pytest.raises(ConfigError, match="score_treshold.*did you mean 'score_threshold'"):
        ds.load_profile(bad)
    bad.write_text(text.replace("  bicycle:\n", "  bicyle:\n"))
    with pytest.raises(ConfigError, match="bicyle"):
        ds.load_profile(bad)
    bad.write_text(text.replace("recall_max: 0.985", "recall_max: lots"))
    with pytest.raises(ConfigError, match="classes.car.recall_max"):
        ds.load_profile(bad)
    for value in ("0", "-1.0"):  # a correlation time must be positive
        bad.write_text(text.replace("  pedestrian:\n", f"  pedestrian:\n    pos_drift_time_s: {value}\n"))
        with pytest.raises(ConfigError, match="classes.pedestrian.pos_drift_time_s.*positive time"):
            ds.load_profile(bad)
    bad.write_text(text.replace("  pedestrian:\n", "  pedestrian:\n    pos_drift_sigma_m: -0.1\n"))
    with pytest.raises(ConfigError, match="classes.pedestrian.pos_drift_sigma_m"):
        ds.load_profile(bad)
    assert (
        main(
            [
                "simulate-detections",
                "--dataroot",
                str(tmp_path),
                "--split",
                "x",
                "--profile",
                str(bad),
                "--out",
                str(tmp_path / "o.json"),
            ]
        )
        == 2
    )


# -------------------------------------------------------------------------------------------- the format-free core


def test_core_without_any_dataset():
    prof = ds.load_profile("centerpoint")
    gt = _frame()
    det = ds.simulate_frame(gt, prof, ds.frame_rng(0, prof.name, gt.token))
    assert det.boxes.shape == (len(det), 9) and det.scores.shape == det.names.shape == (len(det),)
    assert np.all(np.diff(det.scores) <= 0) and det.scores.min() >= prof.score_threshold
    tp = det.is_tp
    assert 0.9 * len(gt) < tp.sum() <= len(gt)  # well-observed cars: high recall
    assert (~tp).sum() > 0  # duplicates and false positives
    err = np.hypot(*(det.boxes[tp, :2][:, None, :] - gt.boxes[None, :, :2]).transpose(2, 0, 1)).min(axis=1)
    assert np.median(err) < 0.3 and err.max() > 0.6  # heavy tails
    names = set(det.names[tp])
    assert "car" in names and len(names) > 1  # class confusions
    same = ds.simulate_frame(gt, prof, ds.frame_rng(0, prof.name, gt.token))
    assert np.array_equal(same.boxes, det.boxes)
    other = ds.simulate_frame(gt, prof, ds.frame_rng(1, prof.name, gt.token))
    assert not np.array_equal(other.boxes[:5], det.boxes[:5])


def test_recall_depends_on_points_and_distance():
    prof = ds.load_profile("centerpoint")
    tab = ds._Tables(prof)
    cls = np.full(4, ds.DET_INDEX["car"])
    p = ds.detection_probability(
        cls, np.array([20.0, 20.0, 20.0, 60.0]), np.array([1, 5, 0, 50]), tab, prof.detection_range_m
    )
    assert p[1] > p[0] > p[2] and p[3] == 0.0  # more points, more recall; none out of range
    few = ds.simulate([_frame(pts=1, seed=s) for s in range(3)], prof, 0)
    lots = ds.simulate([_frame(pts=100, seed=s) for s in range(3)], prof, 0)
    assert sum(d.is_tp.sum() for d in few) < sum(d.is_tp.sum() for d in lots)


def test_yaw_flips_and_score_separation():
    prof = ds.load_profile("centerpoint")
    frames = [_frame(pts=p, seed=s) for s, p in enumerate([2, 5, 20, 100, 400] * 4)]
    dets = ds.simulate(frames, prof, 5)
    dyaw = []
    for gt, det in zip(frames, dets):
        b = det.boxes[det.is_tp]
        nearest = np.argmin(
            np.hypot(b[:, None, 0] - gt.boxes[None, :, 0], b[:, None, 1] - gt.boxes[None, :, 1]), axis=1
        )
        dyaw.append(np.abs((b[:, 6] - gt.boxes[nearest, 6] + np.pi) % (2 * np.pi) - np.pi))
    dyaw = np.concatenate(dyaw)
    assert 0.002 < np.mean(dyaw > 2.5) < 0.1  # occasional 180 degree flips
    scores = np.concatenate([d.scores for d in dets])
    is_tp = np.concatenate([d.is_tp for d in dets])
    order = np.argsort(scores)
    ranks = np.empty(len(scores))
    ranks[order] = np.arange(len(scores))
    auc = (ranks[is_tp].mean() - (is_tp.sum() - 1) / 2) / (~is_tp).sum()
    assert 0.7 < auc < 0.995  # scores separate TP from FP, imperfectly


# ------------------------------------------------------------------------------------- real nuScenes mini_val


def test_centerpoint_ap_matches_published_on_mini_val(mini_val_centerpoint, nusc_mini):
    _, sub, metrics = mini_val_centerpoint
    ref = ds.load_profile("centerpoint").reference["ap"]
    aps = metrics["mean_dist_aps"]
    for cls in ("car", "pedestrian"):
        assert abs(aps[cls] - ref[cls]) < 0.1, (cls, aps[cls], ref[cls])
    assert 0.3 < metrics["mean_ap"] < 0.7
    assert metrics["tp_errors"]["trans_err"] < 0.5


def test_detection_json_format(mini_val_centerpoint, nusc_mini):
    from nuscenes.eval.common.data_classes import EvalBoxes
    from nuscenes.eval.detection.data_classes import DetectionBox
    from nuscenes.utils.splits import create_splits_scenes

    path, sub, _ = mini_val_centerpoint
    data = json.loads(path.read_text())
    assert data["meta"]["use_lidar"] is True and "SYNTHETIC" in data["synthetic"]["note"]
    val = set(create_splits_scenes()["mini_val"])
    tokens = {s["token"] for s in nusc_mini.sample if nusc_mini.get("scene", s["scene_token"])["name"] in val}
    assert set(data["results"]) == tokens  # every sample of the split, nothing else
    boxes = EvalBoxes.deserialize(data["results"], DetectionBox)  # the devkit's own validation
    names = {b.detection_name for b in boxes.all}
    assert "traffic_cone" in names  # mini_val GT has cones (no barrier / CV there)
    assert all(len(v) <= 500 for v in data["results"].values())


def test_non_tracking_classes_on_mini_train(nusc_mini):
    sub = ds.simulate_nuscenes(None, None, "mini_train", "centerpoint", 0, None, nusc=nusc_mini)
    names = {b["detection_name"] for v in sub["results"].values() for b in v}
    assert {"barrier", "traffic_cone", "construction_vehicle"} <= names
    assert len(sub["results"]) == 323


def test_pointpillars_is_weaker(nusc_mini, mini_val_centerpoint, tmp_path):
    out = tmp_path / "pp.json"
    ds.simulate_nuscenes(None, None, "mini_val", "pointpillars", 0, out, nusc=nusc_mini)
    pp = _detection_eval(nusc_mini, out, "mini_val", tmp_path / "eval")
    cp = mini_val_centerpoint[2]
    assert pp["mean_ap"] < cp["mean_ap"] - 0.1
    assert pp["mean_dist_aps"]["car"] < cp["mean_dist_aps"]["car"]


def test_deterministic_files(nusc_root, tmp_path):
    args = ["simulate-detections", "--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    assert main(args + ["--seed", "3", "--out", str(tmp_path / "a.json")]) == 0
    assert main(args + ["--seed", "3", "--out", str(tmp_path / "b.json")]) == 0
    assert main(args + ["--seed", "4", "--out", str(tmp_path / "c.json")]) == 0
    a, b, c = ((tmp_path / f"{x}.json").read_bytes() for x in "abc")
    assert a == b and a != c


# ------------------------------------------------------------------------------------------------- bad input


def test_missing_dataroot_and_unknown_split(tmp_path, nusc_root, capsys):
    with pytest.raises(DatasetError, match="does not exist"):
        ds.simulate_nuscenes(tmp_path / "nowhere", "v1.0-mini", "mini_val", "centerpoint", 0)
    with pytest.raises(DatasetError, match="v1.0-trainval"):
        ds.simulate_nuscenes(nusc_root, "v1.0-trainval", "val", "centerpoint", 0)
    with pytest.raises(DatasetError, match="demo_val"):
        ds.simulate_nuscenes(nusc_root, "v1.0-mini", "demo_val", "centerpoint", 0)
    assert (
        main(
            [
                "simulate-detections",
                "--dataroot",
                str(nusc_root),
                "--version",
                "v1.0-mini",
                "--split",
                "mini_vall",
                "--out",
                str(tmp_path / "x.json"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "mini_vall" in err and "splits.json" in err
    assert (
        main(
            [
                "simulate-detections",
                "--dataroot",
                str(nusc_root),
                "--version",
                "v1.0-mini",
                "--split",
                "mini_val",
                "--profile",
                "nosuch",
                "--out",
                str(tmp_path / "x.json"),
            ]
        )
        == 2
    )
    assert "unknown detector profile" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()
    assert issubclass(DatasetError, GrutrackError)


# -------------------------------------------------------------------------------------------- on the demo


def test_simulate_on_demo_split(tmp_path):
    root = tmp_path / "demo"
    demo.generate_demo(root, scenes=3, frames=10, seed=2)
    out = tmp_path / "det.json"
    assert main(["simulate-detections", "--dataroot", str(root), "--split", "demo_val", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert len(data["results"]) == 10 and sum(len(v) for v in data["results"].values()) > 50


def test_velocity_under_reported_per_object_over_its_life():
    """``vel_track_fail_prob``: a failing object's velocity is scaled by one factor in every frame (a function of
    seed, profile and instance id); the others, and profiles without the key, are drawn exactly as before."""
    import dataclasses

    prof = ds.load_profile("centerpoint")
    car = prof.classes["car"]
    fail = dataclasses.replace(
        prof,
        classes={**prof.classes, "car": dataclasses.replace(car, vel_track_fail_prob=0.5, vel_track_fail_scale=0.2)},
    )
    frames = []
    for k in range(3):  # the same 40 moving cars, 7 m apart, in three frames (same identities)
        gt = _frame(n=40, seed=k)
        gt.boxes[:, 0], gt.boxes[:, 1] = 10.0 + 7.0 * (np.arange(40) % 5) + k, -24.5 + 7.0 * (np.arange(40) // 5)
        gt.boxes[:, 7:9] = [8.0, 0.0]
        gt.instance_ids[:] = np.array([f"car{i}" for i in range(len(gt))], dtype=object)
        frames.append(gt)
    factors = []
    for gt in frames:
        base = ds.simulate_frame(gt, prof, ds.frame_rng(3, prof.name, gt.token), seed=3)
        out = ds.simulate_frame(gt, fail, ds.frame_rng(3, prof.name, gt.token), seed=3)
        assert np.array_equal(out.boxes[:, :7], base.boxes[:, :7]) and np.array_equal(out.scores, base.scores)
        ratio = np.hypot(*out.boxes[:, 7:9].T) / np.hypot(*base.boxes[:, 7:9].T)
        u = ds.object_uniforms(3, prof.name, gt.instance_ids)
        factors.append(np.where(u[:, 0] < 0.5, u[:, 1] * 0.2, 1.0))
        hit = base.is_tp & (base.names == "car")
        # each detected car: its object's factor (matched by the nearest GT centre)
        near = np.argmin(np.hypot(*(base.boxes[hit, None, :2] - gt.boxes[None, :, :2]).transpose(2, 0, 1)), axis=1)
        np.testing.assert_allclose(ratio[hit], factors[-1][near], rtol=1e-9)
        assert 0.3 < np.mean(ratio[hit] < 0.25) < 0.7
    assert all(np.array_equal(f, factors[0]) for f in factors)  # one factor per object over its life
    other_seed = ds.object_uniforms(4, prof.name, frames[0].instance_ids)
    assert not np.array_equal(other_seed, ds.object_uniforms(3, prof.name, frames[0].instance_ids))


def test_centre_drift_has_its_variance_and_exponential_autocorrelation():
    """``centre_drift``: over many objects the drift has variance sigma^2 and correlation exp(-dt / tau) between
    times dt apart; the same (seed, profile, object, time) gives the same error, another seed another one."""
    ids = np.array([f"obj{i}" for i in range(4000)], dtype=object)
    sigma, tau = np.full(len(ids), 0.3), np.full(len(ids), 2.0)
    t0 = 1.5e9  # absolute seconds, as timestamps give them
    e0 = ds.centre_drift(7, "p", ids, t0, sigma, tau)
    assert e0.shape == (len(ids), 2)
    assert abs(e0.std() / 0.3 - 1.0) < 0.06
    for dt in (0.5, 2.0, 6.0):
        e1 = ds.centre_drift(7, "p", ids, t0 + dt, sigma, tau)
        rho = np.mean(e0 * e1) / 0.3**2
        assert abs(rho - np.exp(-dt / 2.0)) < 0.06, (dt, rho)
    assert abs(np.corrcoef(e0[:, 0], e0[:, 1])[0, 1]) < 0.06  # the two axes independent
    np.testing.assert_array_equal(ds.centre_drift(7, "p", ids[::-1], t0, sigma, tau), e0[::-1])
    assert not np.allclose(ds.centre_drift(8, "p", ids, t0, sigma, tau), e0)
    assert ds.centre_drift(7, "p", ids[:0], t0, sigma[:0], tau[:0]).shape == (0, 2)


def test_drifting_centre_error_moves_only_the_centre_of_its_class():
    """``pos_drift_sigma_m`` on cars: each detected car's centre moves by its object's drift at the frame's time
    (a function of seed, profile, instance id and time); every other column, score and draw is as without it."""
    import dataclasses

    prof = ds.load_profile("centerpoint")
    drift = dataclasses.replace(
        prof,
        classes={
            **prof.classes,
            "car": dataclasses.replace(prof.classes["car"], pos_drift_sigma_m=0.5, pos_drift_time_s=3.0),
        },
    )
    for k in range(2):
        gt = _frame(n=40, seed=k)
        gt.boxes[:, 0], gt.boxes[:, 1] = 10.0 + 7.0 * (np.arange(40) % 5), -24.5 + 7.0 * (np.arange(40) // 5)
        gt.instance_ids[:] = np.array([f"car{i}" for i in range(len(gt))], dtype=object)
        gt.timestamp = 1_500_000_000_000_000 + 500_000 * k
        base = ds.simulate_frame(gt, prof, ds.frame_rng(3, prof.name, gt.token), seed=3)
        out = ds.simulate_frame(gt, drift, ds.frame_rng(3, prof.name, gt.token), seed=3)
        assert np.array_equal(out.boxes[:, 2:], base.boxes[:, 2:]) and np.array_equal(out.scores, base.scores)
        hit = base.is_tp & (base.names == "car")
        near = np.argmin(np.hypot(*(base.boxes[hit, None, :2] - gt.boxes[None, :, :2]).transpose(2, 0, 1)), axis=1)
        want = ds.centre_drift(
            3, prof.name, gt.instance_ids[near], gt.timestamp * 1e-6, np.full(len(near), 0.5), np.full(len(near), 3.0)
        )
        np.testing.assert_allclose(out.boxes[hit, :2] - base.boxes[hit, :2], want, atol=1e-12)
        assert np.abs(want).max() > 0.2
