"""One GRU-KF training over several sources: the command's split plus the config's ``sources`` and every
``--source`` (nuScenes-format splits, AV2 logs, generated SYNTHETIC demo datasets; detection files or detections
simulated per source), each scene with its own vocabulary."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import yaml

from grutrack.cli import main


@pytest.fixture(scope="module")
def mini_train_dets(nusc_root, tmp_path_factory):
    out = tmp_path_factory.mktemp("dets") / "cp.json"
    assert (
        main(
            [
                "simulate-detections",
                "--dataroot",
                str(nusc_root),
                "--version",
                "v1.0-mini",
                "--split",
                "mini_train",
                "--profile",
                "centerpoint",
                "--seed",
                "1",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out


def _train(nusc_root, dets, out, *extra) -> int:
    return main(
        [
            "train",
            "--dataroot",
            str(nusc_root),
            "--version",
            "v1.0-mini",
            "--split",
            "mini_train",
            "--detections",
            str(dets),
            "--out",
            str(out),
            "--epochs",
            "1",
            "--no-progress",
            *extra,
        ]
    )


@pytest.mark.slow
def test_training_over_nuscenes_av2_and_a_generated_demo(nusc_root, av2_root, mini_train_dets, tmp_path, capsys):
    """One epoch visits every scene of every source once; the data line of training.yaml names the sources."""
    out = tmp_path / "ck"
    assert (
        _train(
            nusc_root,
            mini_train_dets,
            out,
            "--no-config-sources",
            "--source",
            f"{{dataset: av2, dataroot: {av2_root}, split: val, profile: centerpoint, seed: 2}}",
            "--source",
            "{dataset: demo, scenes: 3, frames_per_scene: 8, split: demo_all, profile: pointpillars}",
        )
        == 0
    )
    # the default config holds two scenes of the command's split out for validation (never trained on)
    assert "training on 11 scenes, 330 frames from 3 sources" in capsys.readouterr().out
    scenes = [row["scene"] for row in csv.DictReader((out / "train_log.csv").open()) if row["step"] != "0"]
    assert len(scenes) == len(set(scenes)) == 11
    assert sum(s.startswith("scene-") for s in scenes) == 6  # mini_train less the held out
    assert not {"scene-0655", "scene-1094"} & set(scenes)
    assert sum(s.startswith("demo-scene-") for s in scenes) == 3  # the generated demo
    assert sum(len(s) == 36 and s.count("-") == 4 for s in scenes) == 2  # the two AV2 log ids
    data = next(ln for ln in (out / "training.yaml").read_text().splitlines() if ln.startswith("# data "))
    assert '"sources": [{"dataroot": "' in data and '"dataset": "demo"' in data
    assert (out / "sources" / "demo_n3_f8_s0" / "v1.0-demo").is_dir() and (out / "model.pt").is_file()
    # --no-config-sources left out the default recipe's 700-scene demo, and training.yaml says so
    assert yaml.safe_load((out / "training.yaml").read_text())["sources"] == []
    assert not (out / "sources" / "demo_n700_f40_s0").exists()


def test_the_default_recipe_brings_its_paper_scale_source():
    """The default config trains at the paper's scale by itself: the command's split plus a 700-scene, 40-frame
    SYNTHETIC demo with simulated detections, generated with a seed of its own (the workflow's demo datasets use 0
    and 3: the same seed would give their scenes again, demo_val among them); the paper's configuration has no
    extra source."""
    from grutrack.training.config import load_train_config

    assert load_train_config("grukf").sources == (
        {
            "dataset": "demo",
            "scenes": 700,
            "frames_per_scene": 40,
            "demo_seed": 700,
            "split": "demo_all",
            "profile": "centerpoint",
            "seed": 1,
        },
    )
    assert load_train_config("paper").sources == ()


def test_config_sources_and_resampling_cover_every_source(nusc_root, mini_train_dets, tmp_path):
    """Sources listed in the training config are read like --source ones; with resample_profiles every
    source's frames get fresh detections in epoch 1."""
    from grutrack.training.config import load_train_config
    from grutrack.training.sources import load_source, merge, merged_resampler

    cfg = dict(
        yaml.safe_load((Path(__file__).resolve().parents[1] / "grutrack/configs/training/paper.yaml").read_text())
    )
    cfg["sources"] = [
        {
            "dataset": "demo",
            "scenes": 2,
            "frames_per_scene": 6,
            "split": "demo_all",
            "profile": "centerpoint",
            "seed": 4,
        }
    ]
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(cfg))
    assert load_train_config(str(tmp_path / "t.yaml")).sources == tuple(cfg["sources"])
    assert _train(nusc_root, mini_train_dets, tmp_path / "ck", "--config", str(tmp_path / "t.yaml")) == 0
    assert len(list(csv.DictReader((tmp_path / "ck" / "train_log.csv").open()))) == 10

    demo = load_source(cfg["sources"][0], "euler_z", tmp_path / "cache", "test")
    other = load_source(
        {
            "dataset": "nuscenes",
            "dataroot": str(nusc_root),
            "version": "v1.0-mini",
            "split": "mini_val",
            "profile": "pointpillars",
            "seed": 1,
        },
        "euler_z",
        tmp_path,
        "test",
    )
    scenes, dets = merge([demo, other])
    fresh = merged_resampler([demo, other])("centerpoint", 9)
    assert set(fresh) == set(dets) == {f.token for s in scenes for f in s.frames}
    assert len(scenes) == 4 and any(len(fresh[t]) != len(dets[t]) for t in dets)


@pytest.mark.parametrize(
    "source, message",
    [
        ("{dataset: kitti, split: val}", "--source 1.dataset: 'kitti' is not one of"),
        ("{dataset: av2, split: val, profile: centerpoint}", "--source 1: 'dataroot' is required for a av2 source"),
        (
            "{dataset: demo, scenes: 2, frames_per_scene: 4, split: demo_all}",
            "--source 1: give either 'detections' (a file) or 'profile' (simulate them), not neither",
        ),
        ("{dataset: demo, scenes: 2, frames_per_scene: 4, split: demo_all, profile: x, detections: y}", "not both"),
        ("[1, 2]", "--source 1: expected a mapping"),
        (
            "{dataset: demo, scenes: 2, frames_per_scene: 4, split: demo_all, profile: centerpoint, colour: red}",
            "Additional properties are not allowed",
        ),
    ],
)
def test_bad_sources_are_refused_before_any_data_is_read(nusc_root, tmp_path, capsys, source, message):
    assert _train(nusc_root, tmp_path / "missing.json", tmp_path / "ck", "--source", source) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "ck").exists()


def test_the_same_split_twice_is_refused(nusc_root, mini_train_dets, tmp_path, capsys):
    src = (
        f"{{dataset: nuscenes, dataroot: {nusc_root}, version: v1.0-mini, split: mini_train, "
        f"detections: {mini_train_dets}}}"
    )
    assert _train(nusc_root, mini_train_dets, tmp_path / "ck", "--no-config-sources", "--source", src) == 2
    assert "repeats frames of an earlier source (323 frames" in capsys.readouterr().err
