"""The dataset interface: both datasets implement it, the commands reach every dataset through it, and each
dataset's submission round-trips (written by ``write_tracks``, accepted by ``write_submission``, refused when it
does not hold exactly the split's frames)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet
from grutrack.datasets import DATASETS, Dataset, DatasetOptions, open_dataset
from grutrack.errors import ConfigError, InputFormatError


def test_every_registered_dataset_implements_the_protocol_and_is_on_the_command_line(tmp_path, capsys):
    from grutrack.cli import main

    with pytest.raises(SystemExit):
        main(["track", "--help"])
    assert "{" + ",".join(DATASETS) + "}" in capsys.readouterr().out
    for name in DATASETS:
        ds = open_dataset(name, DatasetOptions(tmp_path, version="v1.0-mini"))
        assert isinstance(ds, Dataset) and ds.name == name
        assert ds.submission_suffix in (".json", ".pkl") and ds.evaluators
        assert len(ds.vocabulary.names) == len(ds.vocabulary.param_classes) > 0


def test_unknown_dataset_and_missing_version_are_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="--dataset: unknown dataset 'kitti' \\(available: nuscenes, av2\\)"):
        open_dataset("kitti", DatasetOptions(tmp_path))
    with pytest.raises(ConfigError, match="--version is required with --dataset nuscenes"):
        open_dataset("nuscenes", DatasetOptions(tmp_path))


def _one_box_per_frame(scenes, label: int) -> dict[str, BoxSet]:
    out = {}
    for s in scenes:
        for i, f in enumerate(s.frames):
            box = np.array([[*f.ego_translation[:2] + 10.0, f.ego_translation[2], 2.0, 4.5, 1.6, 0.0, 1.0, 0.0]])
            out[f.token] = BoxSet(box, np.array([0.9]), np.array([label]), ids=np.array([7]))
    return out


def test_nuscenes_tracks_round_trip_through_the_submission(nusc_root, tmp_path):
    ds = open_dataset("nuscenes", DatasetOptions(nusc_root, version="v1.0-mini"))
    scenes = ds.scenes("mini_val")
    assert [s.name for s in scenes] == ["scene-0103", "scene-0916"]
    assert all(s.vocabulary == NUSCENES_VOCABULARY for s in scenes)
    results = _one_box_per_frame(scenes, label=2)  # car
    counts = ds.write_tracks(tmp_path / "tracks.json", scenes, results, max_boxes=500)
    n = sum(len(s) for s in scenes)
    assert counts == {"samples": n, "boxes": n, "scenes": 2}
    assert ds.write_submission(tmp_path / "tracks.json", "mini_val", tmp_path / "sub.json") == {
        "samples": n,
        "boxes": n,
    }
    with pytest.raises(InputFormatError):  # a split whose samples it does not hold
        ds.write_submission(tmp_path / "tracks.json", "mini_train", tmp_path / "sub2.json")
    assert not (tmp_path / "sub2.json").exists()


def test_av2_tracks_round_trip_and_a_pickle_of_other_frames_is_refused(av2_root, tmp_path):
    ds = open_dataset("av2", DatasetOptions(av2_root, rate_hz=2.0))
    scenes = ds.scenes("val")
    assert all(s.vocabulary == ds.vocabulary for s in scenes) and ds.vocabulary.names[0] == "REGULAR_VEHICLE"
    results = _one_box_per_frame(scenes, label=0)
    counts = ds.write_tracks(tmp_path / "tracks.pkl", scenes, results, max_boxes=500)
    n = sum(len(s) for s in scenes)
    assert counts == {"logs": len(scenes), "frames": n, "boxes": n}
    assert (tmp_path / "tracks.feather").is_file()  # the same tracks as a table beside the pickle
    assert ds.write_submission(tmp_path / "tracks.pkl", "val", tmp_path / "sub.pkl") == counts
    with open(tmp_path / "sub.pkl", "rb") as f:
        assert set(pickle.load(f)) == {s.name for s in scenes}
    at_1hz = open_dataset("av2", DatasetOptions(av2_root, rate_hz=1.0))
    with pytest.raises(InputFormatError, match="frames must be exactly the"):
        at_1hz.write_submission(tmp_path / "tracks.pkl", "val", tmp_path / "sub1.pkl")
    assert not (tmp_path / "sub1.pkl").exists()


def test_lt3d_table_round_trips_through_the_reader(av2_root, tmp_path):
    """City-frame boxes written as an LT3D table (ego frame) read back to the same boxes."""
    from grutrack.data.detection_sim import load_profile, simulate_scenes
    from grutrack.data.lt3d_detections import detection_table, load_detections

    ds = open_dataset("av2", DatasetOptions(av2_root))
    scenes = ds.scenes("val", with_gt=True)
    sim = simulate_scenes(
        scenes,
        ("car", "pedestrian", "bicycle", "construction_vehicle", "bus", "truck", "trailer"),
        load_profile("centerpoint"),
        seed=3,
    )
    table = detection_table(scenes, sim)
    assert len(table) == sum(len(b) for b in sim.values()) > 100
    path = tmp_path / "dets.feather"
    table.to_feather(path)
    back, stats = load_detections(path, av2_root, "val", scenes, ds.vocabulary)
    assert stats.kept == len(table) and stats.off_frame == 0 and stats.other_category == 0
    for token, b in sim.items():
        order_a, order_b = np.lexsort(b.boxes.T[::-1]), np.lexsort(back[token].boxes.T[::-1])
        got = back[token].boxes[order_b]
        exp = b.boxes[order_a]
        exp[:, 6] = np.angle(np.exp(1j * exp[:, 6]))
        np.testing.assert_allclose(got, exp, atol=1e-6)
        assert (back[token].labels[order_b] == b.labels[order_a]).all()


def test_av2_through_the_same_commands_as_nuscenes(av2_root, tmp_path, capsys):
    """simulate-detections, track, submit and evaluate with --dataset av2, as for nuScenes."""
    from grutrack.cli import main

    dets, tracks, sub, metrics = (tmp_path / n for n in ("dets.feather", "tracks.pkl", "sub.pkl", "m.json"))
    common = ["--dataset", "av2", "--dataroot", str(av2_root), "--split", "val"]
    assert main(["simulate-detections", *common, "--profile", "centerpoint", "--seed", "1", "--out", str(dets)]) == 0
    assert "SYNTHETIC detections (centerpoint, seed 1)" in capsys.readouterr().out
    assert main(["track", *common, "--detections", str(dets), "--out", str(tracks), "--no-progress"]) == 0
    cfg = tmp_path / "ekf.yaml"
    assert main(["resolve-config", "tracker", "--base", "ekf", "--overrides", "{}", "--out", str(cfg)]) == 0
    assert (
        main(
            [
                "submit",
                *common,
                "--tracks",
                str(tracks),
                "--out",
                str(sub),
                "--detections",
                str(dets),
                "--tracker-config",
                str(cfg),
                "--tracker",
                "ekf",
            ]
        )
        == 0
    )
    assert main(["evaluate", *common, "--submission", str(sub), "--out", str(metrics), "--workers", "1"]) == 0
    from grutrack.documents import Manifest, MetricsDocument

    doc = MetricsDocument.read(metrics)
    assert doc.dataset == "av2" and doc.logs == 2 and 0.3 < doc.overall["hota"] <= 1.0
    assert Manifest.read(Manifest.path_for(sub)).counts["logs"] == 2
    assert main(["simulate-detections", *common, "--all-categories", "--out", str(tmp_path / "x.feather")]) == 2
    assert "drop --all-categories" in capsys.readouterr().err


def test_train_on_av2_then_track_av2_with_the_model(av2_root, tmp_path, capsys):
    """`grutrack train --dataset av2` (simulated detections, resampled every epoch through the AV2 simulator);
    the model tracks AV2 and the per-label parameters come from each AV2 class's tracking class."""
    from grutrack.cli import main
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    common = ["--dataset", "av2", "--dataroot", str(av2_root), "--split", "val"]
    dets, ck = tmp_path / "dets.feather", tmp_path / "ck"
    assert main(["simulate-detections", *common, "--seed", "4", "--out", str(dets)]) == 0
    cfg = tmp_path / "train.yaml"
    over = (
        '{"epochs": 2, "device": "cpu", "resample_profiles": ["pointpillars"], "sources": [], "validation_scenes": 1}'
    )
    assert main(["resolve-config", "training", "--base", "grukf", "--overrides", over, "--out", str(cfg)]) == 0
    assert (
        main(["train", *common, "--detections", str(dets), "--config", str(cfg), "--out", str(ck), "--no-progress"])
        == 0
    )
    out = capsys.readouterr()
    assert "after 2 steps" in out.out  # 1 log trained on (the other held out for validation) x 2 epochs
    assert "validating on 1 scenes held out of val" in out.out
    assert (
        main(
            [
                "track",
                *common,
                "--detections",
                str(dets),
                "--tracker",
                "grukf",
                "--checkpoint",
                str(ck / "model.pt"),
                "--out",
                str(tmp_path / "t.pkl"),
                "--no-progress",
            ]
        )
        == 0
    )

    ds = open_dataset("av2", DatasetOptions(av2_root))
    scenes = ds.scenes("val", with_gt=True)
    t = Trainer(
        load_train_config("grukf", {"device": "cpu"}),
        scenes,
        ds.load_detections(dets, "val", scenes).boxes,
        tmp_path / "ck3",
        progress=False,
    )
    # REGULAR_VEHICLE, PEDESTRIAN, BICYCLE, LARGE_VEHICLE, BUS, BOX_TRUCK, TRUCK -> car, pedestrian, bicycle,
    # truck, bus, truck, truck (indices of the 7 nuScenes tracking classes)
    assert t.index.tolist() == [2, 4, 0, 6, 1, 6, 6]
    assert t.tracker_cfg.first_threshold[3] == t.tracker_cfg.first_threshold[6]  # LARGE_VEHICLE as TRUCK


def test_dataset_stats_of_av2_per_category(av2_root, tmp_path, capsys):
    """`grutrack dataset-stats --dataset av2`: the ground truth of the tracked frames per Table I class."""
    from grutrack.cli import main

    out = tmp_path / "s.json"
    assert (
        main(["dataset-stats", "--dataset", "av2", "--dataroot", str(av2_root), "--split", "val", "--json", str(out)])
        == 0
    )
    text = capsys.readouterr().out
    assert "REGULAR_VEHICLE" in text and "7 classes" in text
    import json

    stats = json.loads(out.read_text())
    ds = open_dataset("av2", DatasetOptions(av2_root))
    scenes = ds.scenes("val", with_gt=True)
    n = sum(len(f.gt) for s in scenes for f in s.frames)
    assert stats["classes"]["all"]["boxes"] == n and stats["meta"]["dataset"] == "av2"
    assert sum(stats["classes"][c]["boxes"] for c in ds.vocabulary.names) == n
    car = stats["classes"]["REGULAR_VEHICLE"]
    assert 3.5 < car["l"] < 6.0 and 1.5 < car["w"] < 2.5  # metres: a car's length and width
