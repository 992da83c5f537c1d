"""The SYNTHETIC demo dataset: devkit loading, table integrity, official TrackingEval oracle, realism,
determinism, atomic replacement, the CLI, and the statistics module."""

from __future__ import annotations

import contextlib
import filecmp
import io
import json
import os
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from grutrack.cli import main
from grutrack.data import demo
from grutrack.data.detection_sim import nusc_gt_frames
from grutrack.data.gt_stats import class_statistics, format_comparison, format_table, yaw_rates
from grutrack.errors import ConfigError

VERSION = demo.VERSION


def _load(root: Path):
    from nuscenes import NuScenes

    with contextlib.redirect_stdout(io.StringIO()):
        return NuScenes(version=VERSION, dataroot=str(root), verbose=False)


@pytest.fixture(scope="module")
def small_demo(tmp_path_factory) -> Path:
    """5 scenes x 20 keyframes: 4 demo_train scenes, 1 demo_val scene."""
    root = tmp_path_factory.mktemp("demo") / "small"
    demo.generate_demo(root, scenes=5, frames=20, seed=7)
    return root


@pytest.fixture(scope="module")
def small_nusc(small_demo):
    return _load(small_demo)


@pytest.fixture(scope="module")
def default_frames(tmp_path_factory):
    """GT frames of the default demo (10 scenes x 40 keyframes, seed 0), for the realism checks."""
    root = tmp_path_factory.mktemp("demo") / "default"
    demo.generate_demo(root)
    return nusc_gt_frames(_load(root), "demo_all")


def test_devkit_loads_and_tables_are_consistent(small_demo, small_nusc):
    nusc = small_nusc
    assert len(nusc.scene) == 5 and len(nusc.sample) == 100 and len(nusc.sample_data) == 100
    assert {c["name"] for c in nusc.category} == set(demo.CATEGORIES)
    for scene in nusc.scene:
        assert "SYNTHETIC" in scene["description"]
        tokens, token = [], scene["first_sample_token"]
        while token:
            tokens.append(token)
            token = nusc.get("sample", token)["next"]
        assert tokens[-1] == scene["last_sample_token"] and len(tokens) == scene["nbr_samples"] == 20
        stamps = [nusc.get("sample", t)["timestamp"] for t in tokens]
        assert set(np.diff(stamps).tolist()) == {500_000}  # 2 Hz keyframes, microseconds
        for t in tokens:
            sample = nusc.get("sample", t)
            sd = nusc.get("sample_data", sample["data"]["LIDAR_TOP"])
            assert sd["is_key_frame"] and sd["timestamp"] == sample["timestamp"]
            assert nusc.get("ego_pose", sd["ego_pose_token"])["translation"][2] == 0.0
    for inst in nusc.instance:
        chain, token = [], inst["first_annotation_token"]
        while token:
            ann = nusc.get("sample_annotation", token)
            assert ann["instance_token"] == inst["token"]
            chain.append(token)
            token = ann["next"]
        assert chain[-1] == inst["last_annotation_token"] and len(chain) == inst["nbr_annotations"]
    assert (small_demo / "README.txt").read_text().startswith(demo.MARKER)
    assert (small_demo / nusc.map[0]["filename"]).read_bytes().startswith(b"\x89PNG")


def test_categories_attributes_and_points(small_nusc):
    from nuscenes.eval.detection.utils import category_to_detection_name, detection_name_to_rel_attributes

    nusc = small_nusc
    attr = {a["token"]: a["name"] for a in nusc.attribute}
    vis = {v["token"] for v in nusc.visibility}
    zero = positive = 0
    for ann in nusc.sample_annotation:
        det = category_to_detection_name(ann["category_name"])
        assert det is not None, ann["category_name"]
        rel = detection_name_to_rel_attributes(det)
        names = [attr[t] for t in ann["attribute_tokens"]]
        assert len(names) == (1 if rel else 0) and all(n in rel for n in names)
        assert ann["visibility_token"] in vis
        zero += ann["num_lidar_pts"] == 0
        positive += ann["num_lidar_pts"] > 0
        if ann["num_lidar_pts"] == 0:
            assert ann["num_radar_pts"] == 0  # occluded: no points at all
    assert positive > 2 * zero > 0  # mini: 20 % of boxes without points


def test_custom_splits(small_demo, small_nusc):
    from nuscenes.utils.splits import get_scenes_of_split

    splits = json.loads((small_demo / VERSION / "splits.json").read_text())
    assert splits["demo_val"] == ["demo-scene-0004"] and len(splits["demo_train"]) == 4
    assert get_scenes_of_split("demo_val", small_nusc) == ["demo-scene-0004"]
    assert sorted(splits["demo_train"] + splits["demo_val"]) == sorted(splits["demo_all"])


@pytest.mark.slow  # the devkit's TrackingEval on the demo is quick in test_demo_tracking
def test_tracking_eval_oracle_amota_is_one(small_demo, small_nusc, tmp_path):
    """Official TrackingEval with the demo_val ground truth fed back as tracks: AMOTA 1.0."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking.evaluate import TrackingEval
    from nuscenes.eval.tracking.utils import category_to_tracking_name

    nusc = small_nusc
    val_scene = next(s for s in nusc.scene if s["name"] == "demo-scene-0004")
    results, token = {}, val_scene["first_sample_token"]
    while token:
        sample = nusc.get("sample", token)
        results[token] = []
        for ann_token in sample["anns"]:
            ann = nusc.get("sample_annotation", ann_token)
            name = category_to_tracking_name(ann["category_name"])
            if name is None or ann["num_lidar_pts"] + ann["num_radar_pts"] == 0:
                continue
            vel = np.nan_to_num(nusc.box_velocity(ann_token)[:2]).tolist()
            results[token].append(
                {
                    "sample_token": token,
                    "translation": ann["translation"],
                    "size": ann["size"],
                    "rotation": ann["rotation"],
                    "velocity": vel,
                    "tracking_id": ann["instance_token"],
                    "tracking_name": name,
                    "tracking_score": 1.0,
                }
            )
        token = sample["next"]
    path = tmp_path / "oracle.json"
    path.write_text(
        json.dumps(
            {
                "meta": {
                    "use_camera": False,
                    "use_lidar": True,
                    "use_radar": False,
                    "use_map": False,
                    "use_external": False,
                },
                "results": results,
            }
        )
    )
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        metrics = TrackingEval(
            config_factory("tracking_nips_2019"),
            str(path),
            "demo_val",
            str(tmp_path / "eval"),
            nusc_version=VERSION,
            nusc_dataroot=str(small_demo),
            verbose=False,
        ).main()
    assert metrics["amota"] == pytest.approx(1.0)
    assert metrics["tp"] > 300 and metrics["ids"] == 0


def test_deterministic_for_a_seed(tmp_path):
    demo.generate_demo(tmp_path / "a", scenes=2, frames=8, seed=3)
    demo.generate_demo(tmp_path / "b", scenes=2, frames=8, seed=3)
    demo.generate_demo(tmp_path / "c", scenes=2, frames=8, seed=4)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(files) == 16  # 13 tables, splits, map, README
    for rel in files:
        assert filecmp.cmp(tmp_path / "a" / rel, tmp_path / "b" / rel, shallow=False), rel
    ann = Path(VERSION) / "sample_annotation.json"
    assert (tmp_path / "a" / ann).read_bytes() != (tmp_path / "c" / ann).read_bytes()


def test_scene_content_does_not_depend_on_scene_count(tmp_path):
    """Scene i is drawn from its own stream: a 3-scene demo is a prefix of a 5-scene one."""
    a = demo.build_tables(3, 6, 11, VERSION)[0]
    b = demo.build_tables(5, 6, 11, VERSION)[0]
    tokens_a = {r["token"] for r in a["sample_annotation"]}
    assert tokens_a and tokens_a <= {r["token"] for r in b["sample_annotation"]}


def test_atomic_replace_and_refusal(tmp_path):
    out = tmp_path / "d"
    demo.generate_demo(out, scenes=1, frames=4, seed=0)
    demo.generate_demo(out, scenes=2, frames=4, seed=0)  # a previous demo is replaced
    assert len(json.loads((out / VERSION / "scene.json").read_text())) == 2
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folders left
    other = tmp_path / "user_data"
    other.mkdir()
    (other / "keep.txt").write_text("x")
    with pytest.raises(ConfigError, match="not a grutrack demo"):
        demo.generate_demo(other, scenes=1, frames=4)
    with pytest.raises(ConfigError, match="at least 1 scene"):
        demo.generate_demo(tmp_path / "e", scenes=0)


def _tracks(frames) -> dict[str, list]:
    """instance -> [(time s, class, x, y, yaw, speed, lidar points, distance to ego)]."""
    tracks = defaultdict(list)
    for f in frames:
        dist = np.hypot(f.boxes[:, 0] - f.ego_translation[0], f.boxes[:, 1] - f.ego_translation[1])
        for i in range(len(f)):
            b = f.boxes[i]
            tracks[f.instance_ids[i]].append(
                (f.timestamp * 1e-6, f.names[i], b[0], b[1], b[6], np.hypot(b[7], b[8]), f.num_lidar_pts[i], dist[i])
            )
    return tracks


def test_default_demo_is_rich_enough_for_tracking(default_frames):
    frames = default_frames
    stats = class_statistics(frames)
    shares = {c: stats[c]["share"] for c in ("car", "pedestrian", "truck", "bus", "bicycle", "motorcycle", "trailer")}
    assert shares["car"] == max(shares.values()) and 0.4 < shares["car"] < 0.65
    assert shares["pedestrian"] == sorted(shares.values())[-2] and 0.25 < shares["pedestrian"] < 0.45
    assert all(v > 0 for v in shares.values())  # all 7 tracking classes present
    assert stats["all"]["boxes"] / len(frames) > 25  # mini: 36 tracking-class boxes per keyframe
    moved = [np.linalg.norm(frames[i + 39].ego_translation - frames[i].ego_translation) for i in range(0, 400, 40)]
    assert sum(m > 20 for m in moved) >= 5  # most scenes have a moving ego
    tracks = _tracks(frames)
    turn = stop = occlusion_gap = crosses_50m = 0
    for rows in tracks.values():
        t, cls, x, y, yaw, speed, pts, dist = (np.array(v) for v in zip(*rows))
        heading = np.unwrap(yaw)
        turn += cls[0] in ("car", "bus", "truck") and np.ptp(heading) > 1.0 and speed.max() > 2.0
        stop += cls[0] == "pedestrian" and speed.max() > 0.8 and speed[np.argmax(speed) :].min() < 0.1
        seen = np.flatnonzero(pts > 0)
        occlusion_gap += bool(((pts == 0) & (np.arange(len(pts)) > seen[0]) & (np.arange(len(pts)) < seen[-1])).any())
        crosses_50m += bool((dist < 50).any() and (dist > 50).any())
    assert turn >= 5 and stop >= 5 and occlusion_gap >= 50 and crosses_50m >= 50
    assert stats["car"]["yaw_rate"] > 0.01 and stats["pedestrian"]["moving"] > 0.5


def test_yaw_rates_and_statistics_table():
    inst = np.array(["a", "a", "a", "b", "b"], dtype=object)
    t = np.array([0.0, 0.5, 1.0, 0.0, 3.0])  # b's gap of 3 s is not differenced
    yaw = np.array([3.0, -3.1, -3.0, 0.0, 1.0])
    rates, idx = yaw_rates(inst, t, yaw)
    assert np.allclose(rates, [(2 * np.pi - 6.1) / 0.5, 0.1 / 0.5]) and idx.tolist() == [1, 2]
    stats = {
        "car": {
            "boxes": 2,
            "share": 1.0,
            "w": 1.9,
            "l": 4.6,
            "h": 1.7,
            "speed": 1.0,
            "moving": 0.5,
            "yaw_rate": 0.1,
            "zero_pts": 0.0,
            "instances": 1,
            "track_len": 2.0,
        }
    }
    assert "car" in format_table(stats) and "0.100" in format_comparison(stats, stats, ("a", "b"))


def test_nuscenes_statistics_of_mini(nusc_mini):
    stats = class_statistics(nusc_gt_frames(nusc_mini, "mini_val"))
    assert stats["car"]["boxes"] == 2568 and stats["pedestrian"]["boxes"] == 1358  # see shared/data NOTES.md
    assert stats["trailer"]["boxes"] == 0 and np.isnan(stats["trailer"]["speed"])


def test_cli_demo_data_and_stats(tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["demo-data", "--out", str(out), "--scenes", "2", "--frames-per-scene", "6", "--seed", "1"]) == 0
    assert "SYNTHETIC" in capsys.readouterr().out
    stats_json = tmp_path / "stats.json"
    assert (
        main(
            [
                "dataset-stats",
                "--dataroot",
                str(out),
                "--split",
                "demo_train",
                "--split",
                "demo_val",
                "--json",
                str(stats_json),
            ]
        )
        == 0
    )
    assert main(["dataset-stats", "--dataroot", str(out), "--split", "demo_all", "--compare", str(stats_json)]) == 0
    text = capsys.readouterr().out
    assert "pedestrian" in text and "|yaw rate|" in text and "this" in text
    assert json.loads(stats_json.read_text())["classes"]["car"]["boxes"] > 0
    assert main(["dataset-stats", "--dataroot", str(tmp_path / "missing"), "--split", "demo_val"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_the_same_demo_again_is_left_untouched(tmp_path, capsys):
    """Running the README's demo-data command over the workflow's demo leaves every file and time as it was (a
    workflow sees nothing new); other parameters, or an edited file, replace it."""

    out = tmp_path / "demo"
    argv = ["demo-data", "--out", str(out), "--scenes", "2", "--frames-per-scene", "6", "--seed", "1"]
    assert main(argv) == 0 and capsys.readouterr().out.startswith("wrote SYNTHETIC")
    (out / ".snakemake_timestamp").write_text("")  # what the workflow adds to the folder
    stamp = {p: p.stat().st_mtime_ns for p in [out, *out.rglob("*")]}
    os.utime(out / VERSION / "scene.json", ns=(1, 1))  # an old time that a rewrite would change
    stamp[out / VERSION / "scene.json"] = 1
    assert main(argv) == 0 and capsys.readouterr().out.startswith("already up to date (left untouched)")
    assert {p: p.stat().st_mtime_ns for p in [out, *out.rglob("*")]} == stamp
    (out / VERSION / "scene.json").write_text("[]")  # damaged: rewritten
    assert main(argv) == 0 and capsys.readouterr().out.startswith("wrote SYNTHETIC")
    assert len(json.loads((out / VERSION / "scene.json").read_text())) == 2
    assert main([*argv[:-1], "2"]) == 0 and capsys.readouterr().out.startswith("wrote SYNTHETIC")
