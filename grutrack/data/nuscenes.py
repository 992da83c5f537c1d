"""nuScenes adapter: the scenes of a split (standard, mini or custom ``splits.json``) as canonical scenes.

Reads the dataset's tables (the devkit's records without importing it). Ground truth, when asked for, is mapped
to a vocabulary's classes: the 7 tracking classes (default) or the 10 detection classes (what the detector
simulator and the dataset statistics read), annotations of other categories dropped, with the devkit's
centred-difference velocity (NaN -> 0). This module is the one place nuScenes ground truth is read for
tracking, training, simulation and statistics (the evaluator's loader, grutrack/evaluation/nuscenes_fast/loading.py,
reproduces the devkit's own loading and filters instead).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np

from grutrack.boxes import yaw_from_quaternion
from grutrack.classes import DETECTION_CLASSES
from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet, Frame, Scene, Vocabulary
from grutrack.errors import DatasetError

PREDEFINED_SPLITS = ("train", "val", "test", "mini_train", "mini_val", "train_detect", "train_track")


def open_nuscenes(dataroot: str | Path, version: str, verbose: bool = False, devkit: bool = False):
    """The tables of ``<dataroot>/<version>`` after checking that the folder exists and holds that version.

    Default: :class:`grutrack.data.nusc_tables.NuScenesTables` (the devkit's records, reverse indexes and
    lookups, without importing the devkit); ``devkit=True``: ``nuscenes.NuScenes(version, dataroot)``.
    """
    root = Path(dataroot)
    if not root.is_dir():
        raise DatasetError(f"nuScenes dataroot {root} does not exist (expected a folder holding {version}/)")
    if not (root / version).is_dir():
        found = sorted(p.name for p in root.iterdir() if p.is_dir() and (p / "scene.json").exists())
        raise DatasetError(
            f"nuScenes dataroot {root} has no version folder {version}/ (found: {', '.join(found) or 'none'})"
        )
    if not devkit:
        from grutrack.data.nusc_tables import NuScenesTables

        return NuScenesTables(version, root)
    from nuscenes import NuScenes

    if verbose:
        return NuScenes(version=version, dataroot=str(root), verbose=True)
    with contextlib.redirect_stdout(io.StringIO()):
        return NuScenes(version=version, dataroot=str(root), verbose=False)


def available_splits(nusc) -> list[str]:
    """Split names usable with this dataset: predefined ones matching the version, plus custom ones."""
    names = [s for s in PREDEFINED_SPLITS if _split_matches_version(s, nusc.version)]
    custom = Path(nusc.dataroot) / nusc.version / "splits.json"
    if custom.is_file():
        names += list(json.loads(custom.read_text()).keys())
    return names


def _split_matches_version(split: str, version: str) -> bool:
    if split in ("mini_train", "mini_val"):
        return version.endswith("mini")
    if split == "test":
        return version.endswith("test")
    return version.endswith("trainval")


def split_scene_names(nusc, split: str) -> list[str]:
    """Scene names of ``split``; a predefined split, or one from ``<dataroot>/<version>/splits.json``."""
    from grutrack.data.nusc_tables import predefined_split_scenes

    if split in PREDEFINED_SPLITS:
        if not _split_matches_version(split, nusc.version):
            raise DatasetError(
                f"split '{split}' does not belong to nuScenes version {nusc.version} "
                f"(available: {', '.join(available_splits(nusc))})"
            )
        names = predefined_split_scenes()[split]
    else:
        custom = Path(nusc.dataroot) / nusc.version / "splits.json"
        splits = json.loads(custom.read_text()) if custom.is_file() else {}
        if split not in splits:
            raise DatasetError(
                f"unknown split '{split}' for {nusc.dataroot}/{nusc.version} "
                f"(available: {', '.join(available_splits(nusc))}; custom splits are read "
                f"from {custom})"
            )
        names = list(splits[split])
    present = {s["name"] for s in nusc.scene}
    missing = [n for n in names if n not in present]
    if len(missing) == len(names):
        raise DatasetError(f"none of the {len(names)} scenes of split '{split}' is in {nusc.dataroot}/{nusc.version}")
    return [n for n in names if n in present]


def load_scenes(nusc, split: str, with_gt: bool = False, vocabulary: Vocabulary = NUSCENES_VOCABULARY) -> list[Scene]:
    """Canonical scenes of ``split`` in the order of the dataset's scene table.

    Each frame is a keyframe (sample) with its LIDAR_TOP ego pose; ``gt`` holds, when ``with_gt``, the
    annotations of the classes of ``vocabulary`` (:data:`NUSCENES_VOCABULARY`: the 7 tracking classes, or
    :data:`DETECTION_VOCABULARY`: the 10 detection classes); ids = instance tokens, ``extra``:
    ``num_lidar_pts``, ``num_radar_pts`` and ``num_pts`` (their sum).
    """
    if vocabulary.names not in _CATEGORY_MAPS:
        raise ValueError(f"no nuScenes category mapping for the classes {vocabulary.names}")
    to_class = _CATEGORY_MAPS[vocabulary.names]
    label = {name: i for i, name in enumerate(vocabulary.names)}
    to_label = {cat: label[name] for cat, name in to_class.items()}
    wanted = set(split_scene_names(nusc, split))
    scenes = []
    for rec in nusc.scene:
        if rec["name"] not in wanted:
            continue
        frames, token = [], rec["first_sample_token"]
        while token:
            sample = nusc.get("sample", token)
            frames.append(_frame(nusc, sample, to_label if with_gt else None))
            token = sample["next"]
        scenes.append(Scene(name=rec["name"], token=rec["token"], frames=frames, vocabulary=vocabulary))
    return scenes


def _frame(nusc, sample: dict, to_label: dict[str, int] | None) -> Frame:
    """One keyframe; its ground truth when ``to_label`` (category -> label) is given."""
    sd = nusc.get("sample_data", sample["data"]["LIDAR_TOP"])
    pose = nusc.get("ego_pose", sd["ego_pose_token"])
    return Frame(
        token=sample["token"],
        timestamp=int(sample["timestamp"]),
        ego_translation=np.asarray(pose["translation"], dtype=np.float64),
        ego_rotation=np.asarray(pose["rotation"], dtype=np.float64),
        gt=_gt_boxes(nusc, sample, to_label) if to_label is not None else None,
    )


#: nuScenes category -> tracking class: the devkit's ``category_to_tracking_name`` (other categories: None)
TRACKING_NAME_OF_CATEGORY = {
    "vehicle.bicycle": "bicycle",
    "vehicle.bus.bendy": "bus",
    "vehicle.bus.rigid": "bus",
    "vehicle.car": "car",
    "vehicle.motorcycle": "motorcycle",
    "human.pedestrian.adult": "pedestrian",
    "human.pedestrian.child": "pedestrian",
    "human.pedestrian.construction_worker": "pedestrian",
    "human.pedestrian.police_officer": "pedestrian",
    "vehicle.trailer": "trailer",
    "vehicle.truck": "truck",
}


#: nuScenes category -> detection class: the devkit's ``category_to_detection_name`` (other categories: None)
DETECTION_NAME_OF_CATEGORY = {
    **TRACKING_NAME_OF_CATEGORY,
    "movable_object.barrier": "barrier",
    "vehicle.construction": "construction_vehicle",
    "movable_object.trafficcone": "traffic_cone",
}

#: the 10 detection classes; the three without a tracking class take the tracker parameters of the nearest one
#: (static objects: pedestrian, as AV2's bollards and cones; construction vehicles: truck)
DETECTION_VOCABULARY = Vocabulary(
    DETECTION_CLASSES,
    tuple(
        {"barrier": "pedestrian", "traffic_cone": "pedestrian", "construction_vehicle": "truck"}.get(c, c)
        for c in DETECTION_CLASSES
    ),
)

#: vocabulary class names -> the category mapping that labels ground truth with them
_CATEGORY_MAPS = {
    NUSCENES_VOCABULARY.names: TRACKING_NAME_OF_CATEGORY,
    DETECTION_VOCABULARY.names: DETECTION_NAME_OF_CATEGORY,
}


def category_to_tracking_name(category_name: str) -> str | None:
    """The tracking class of a nuScenes category, or None (as nuscenes-devkit's function of that name)."""
    return TRACKING_NAME_OF_CATEGORY.get(category_name)


def _gt_boxes(nusc, sample: dict, to_label: dict[str, int]) -> BoxSet:
    """Ground-truth boxes of one sample, of the categories ``to_label`` maps (category -> label)."""
    rows, labels, ids, lidar, radar = [], [], [], [], []
    for ann_token in sample["anns"]:
        ann = nusc.get("sample_annotation", ann_token)
        lab = to_label.get(ann["category_name"])
        if lab is None:
            continue
        vel = nusc.box_velocity(ann_token)[:2]
        vel = np.where(np.isfinite(vel), vel, 0.0)
        yaw = yaw_from_quaternion(np.asarray(ann["rotation"]))[0]
        rows.append([*ann["translation"], *ann["size"], yaw, *vel])
        labels.append(lab)
        ids.append(ann["instance_token"])
        lidar.append(ann["num_lidar_pts"])
        radar.append(ann["num_radar_pts"])
    if not rows:
        return BoxSet.empty(with_ids=True)
    lidar, radar = np.asarray(lidar, dtype=np.int64), np.asarray(radar, dtype=np.int64)
    return BoxSet(
        np.asarray(rows),
        np.ones(len(rows)),
        np.asarray(labels),
        np.asarray(ids, dtype=object),
        {"num_pts": lidar + radar, "num_lidar_pts": lidar, "num_radar_pts": radar},
    )
