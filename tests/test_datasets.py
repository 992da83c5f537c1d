"""The dataset interface: both datasets implement it, the commands reach every dataset through it, and each
dataset's submission round-trips (written by ``write_tracks``, accepted by ``write_submission``, refused when it
does not hold exactly the split's frames)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from grutrack.cli.common import DATASETS as CLI_DATASETS
from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet
from grutrack.datasets import DATASETS, Dataset, DatasetOptions, open_dataset
from grutrack.errors import ConfigError, InputFormatError


def test_every_registered_dataset_implements_the_protocol_and_is_on_the_command_line(tmp_path):
    assert tuple(DATASETS) == CLI_DATASETS
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
    results = _one_box_per_frame(scenes, label=2)            # car
    counts = ds.write_tracks(tmp_path / "tracks.json", scenes, results, max_boxes=500)
    n = sum(len(s) for s in scenes)
    assert counts == {"samples": n, "boxes": n, "scenes": 2}
    assert ds.write_submission(tmp_path / "tracks.json", "mini_val", tmp_path / "sub.json") == {"samples": n,
                                                                                                "boxes": n}
    with pytest.raises(InputFormatError):                     # a split whose samples it does not hold
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
    assert (tmp_path / "tracks.feather").is_file()          # the same tracks as a table beside the pickle
    assert ds.write_submission(tmp_path / "tracks.pkl", "val", tmp_path / "sub.pkl") == counts
    with open(tmp_path / "sub.pkl", "rb") as f:
        assert set(pickle.load(f)) == {s.name for s in scenes}
    at_1hz = open_dataset("av2", DatasetOptions(av2_root, rate_hz=1.0))
    with pytest.raises(InputFormatError, match="frames must be exactly the"):
        at_1hz.write_submission(tmp_path / "tracks.pkl", "val", tmp_path / "sub1.pkl")
    assert not (tmp_path / "sub1.pkl").exists()
