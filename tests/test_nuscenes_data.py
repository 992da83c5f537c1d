"""The nuScenes adapter and the detection-JSON loader on the real v1.0-mini fragment, plus bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from grutrack.classes import CLASS_INDEX
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes, split_scene_names
from grutrack.errors import DatasetError, InputFormatError


def test_mini_val_scenes_frames_in_time_order(nusc_mini):
    scenes = load_scenes(nusc_mini, "mini_val", with_gt=True)
    assert [s.name for s in scenes] == ["scene-0103", "scene-0916"]
    assert sum(len(s) for s in scenes) == 81
    for s in scenes:
        ts = np.array([f.timestamp for f in s.frames])
        assert np.all(np.diff(ts) > 0)
        assert 0.4e6 < np.median(np.diff(ts)) < 0.6e6  # 2 Hz keyframes, microseconds
        for f in s.frames:
            assert f.ego_translation.shape == (3,)
            assert abs(np.linalg.norm(f.ego_rotation) - 1) < 1e-6
    gt = scenes[0].frames[0].gt
    assert gt.boxes.shape[1] == 9 and len(gt) == len(gt.ids) > 0
    assert np.all(np.isfinite(gt.boxes))


def test_mini_train_has_8_scenes(nusc_mini):
    assert len(split_scene_names(nusc_mini, "mini_train")) == 8


def test_custom_split_from_splits_json(tmp_path, nusc_root):
    # a copy of the tables with a splits.json: custom splits are read from <dataroot>/<version>/splits.json
    import shutil

    dst = tmp_path / "v1.0-mini"
    shutil.copytree(nusc_root / "v1.0-mini", dst)
    (tmp_path / "maps").symlink_to(nusc_root / "maps")
    (dst / "splits.json").write_text(json.dumps({"my_split": ["scene-0916"]}))
    nusc = open_nuscenes(tmp_path, "v1.0-mini")
    scenes = load_scenes(nusc, "my_split")
    assert [s.name for s in scenes] == ["scene-0916"] and len(scenes[0]) == 41


def test_bad_dataroot_and_split(tmp_path, nusc_mini, nusc_root):
    with pytest.raises(DatasetError, match="does not exist"):
        open_nuscenes(tmp_path / "nope", "v1.0-mini")
    with pytest.raises(DatasetError, match="no version folder v1.0-trainval"):
        open_nuscenes(nusc_root, "v1.0-trainval")
    with pytest.raises(DatasetError, match="unknown split 'mini_vall'.*mini_val"):
        split_scene_names(nusc_mini, "mini_vall")
    with pytest.raises(DatasetError, match="does not belong to nuScenes version"):
        split_scene_names(nusc_mini, "val")


@pytest.fixture(scope="module")
def mini_val_tokens(nusc_mini):
    return [f.token for s in load_scenes(nusc_mini, "mini_val") for f in s.frames]


def test_pointpillars_detections_load(pointpillars_mini_val, mini_val_tokens):
    dets = load_detections(pointpillars_mini_val, mini_val_tokens)
    assert set(dets) == set(mini_val_tokens)
    raw = json.loads(pointpillars_mini_val.read_text())["results"]
    tracked = {"car", "truck", "bus", "trailer", "pedestrian", "motorcycle", "bicycle"}
    n_raw = sum(1 for t in mini_val_tokens for b in raw[t] if b["detection_name"] in tracked)
    assert sum(len(d) for d in dets.values()) == n_raw
    # the first tracked box converts field by field
    t = mini_val_tokens[0]
    b0 = next(b for b in raw[t] if b["detection_name"] in tracked)
    d0 = dets[t]
    assert np.allclose(d0.boxes[0, :3], b0["translation"]) and np.allclose(d0.boxes[0, 3:6], b0["size"])
    w, x, y, z = b0["rotation"]
    assert math.isclose(d0.boxes[0, 6], math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)), abs_tol=1e-9)
    assert d0.labels[0] == CLASS_INDEX[b0["detection_name"]]


def _write(tmp_path, results):
    p = tmp_path / "det.json"
    p.write_text(json.dumps({"meta": {"use_lidar": True}, "results": results}))
    return p


def _box(token, **over):
    b = {
        "sample_token": token,
        "translation": [1.0, 2.0, 0.5],
        "size": [1.8, 4.5, 1.6],
        "rotation": [1.0, 0.0, 0.0, 0.0],
        "velocity": [0.0, 0.0],
        "detection_name": "car",
        "detection_score": 0.9,
        "attribute_name": "",
    }
    b.update(over)
    return b


def test_detection_file_bad_input(tmp_path):
    toks = ["a", "b"]
    with pytest.raises(InputFormatError, match="1 of 2 sample tokens .* missing"):
        load_detections(_write(tmp_path, {"a": [_box("a")]}), toks)
    with pytest.raises(InputFormatError, match=r"\.translation' must be a list of 3 finite numbers"):
        load_detections(_write(tmp_path, {"a": [_box("a", translation=[float("nan"), 0, 0])], "b": []}), toks)
    with pytest.raises(InputFormatError, match=r"\.detection_name' must be one of car, .*, got 'cyclist'"):
        load_detections(_write(tmp_path, {"a": [_box("a", detection_name="cyclist")], "b": []}), toks)
    with pytest.raises(InputFormatError, match=r"\.size' must be a list of 3 positive finite numbers"):
        load_detections(_write(tmp_path, {"a": [_box("a", size=[1, 0, 1])], "b": []}), toks)
    with pytest.raises(InputFormatError, match="unit quaternion"):
        load_detections(_write(tmp_path, {"a": [_box("a", rotation=[2, 0, 0, 0])], "b": []}), toks)
    with pytest.raises(InputFormatError, match=r"\.velocity' is missing"):
        b = _box("a")
        del b["velocity"]
        load_detections(_write(tmp_path, {"a": [b], "b": []}), toks)
    with pytest.raises(InputFormatError, match="does not exist"):
        load_detections(tmp_path / "none.json", toks)


def test_detection_file_empty_frames_and_untracked_classes(tmp_path):
    p = _write(tmp_path, {"a": [], "b": [_box("b", detection_name="barrier"), _box("b")], "c": [_box("c")]})
    dets = load_detections(p, ["a", "b"])
    assert len(dets["a"]) == 0 and dets["a"].boxes.shape == (0, 9)
    assert len(dets["b"]) == 1 and dets["b"].labels[0] == CLASS_INDEX["car"]
