"""Fast, exact re-implementation of the devkit's loading for the tracking evaluation.

``TrackingEval.__init__`` (nuscenes-devkit 1.2.0) builds one ``TrackingBox`` per box (tens of microseconds each:
shape and NaN assertions through numpy), estimates a velocity for every ground-truth annotation, filters the
boxes one by one and interpolates track gaps in a loop over timestamps x track ids. This module produces the same
tracks (same scenes, frames, boxes, order, translations, track-averaged scores, interpolated boxes) with light
records, for what the metrics read: ``tracking_id``, ``tracking_name``, ``translation``, ``tracking_score``.
It mirrors, step by step:

* ``load_prediction`` / ``load_prediction_of_sample_tokens`` and ``TrackingBox.deserialize`` with its
  validation (required keys, 3/3/4/2 elements, no NaN, numeric values, string sample token, known class, float
  score, at most ``max_boxes_per_sample`` per sample);
* ``load_gt`` / ``load_gt_of_sample_tokens`` (split/version checks, category -> tracking class, instance token as
  id, lidar + radar points);
* ``add_center_dist`` and ``filter_eval_boxes`` (class range on the ego distance computed as the devkit does,
  zero-point boxes, bicycles and motorcycles in a bike rack via the devkit's own ``points_in_box``);
* ``create_tracks`` (track score = ``np.mean`` of the box scores of an id in a scene, in the devkit's order;
  ``interpolate_tracks`` with its weights, its right-box class/id, and its order of appended boxes).

Anything it does not model exactly (input the devkit would reject, an empty box set, ...) raises
:class:`NeedsDevkitLoader`; the caller then runs the devkit's loaders, which give their own result or error.
Box velocities, sizes and rotations are validated but not kept: the tracking metrics never read them.
"""

from __future__ import annotations

import json
import os
from bisect import bisect
from collections import defaultdict
from typing import Any, Dict, List, NamedTuple, Sequence, Tuple

import numpy as np

__all__ = ["LiteBox", "NeedsDevkitLoader", "fast_load_tracks"]

_BIKE_CLASSES = ("bicycle", "motorcycle")
_BIKE_RACK = "static_object.bicycle_rack"


class LiteBox(NamedTuple):
    """What the tracking metrics read from a ``TrackingBox`` (``sample_token``: the sample the box is filed
    under; for an interpolated box, that of its right neighbour, as the devkit does)."""
    sample_token: str
    translation: Tuple[float, float, float]
    tracking_id: Any
    tracking_name: str
    tracking_score: float


class NeedsDevkitLoader(Exception):
    """The input is outside what the fast loader reproduces exactly; use the devkit's loaders."""


def _require(cond: bool, why: str) -> None:
    if not cond:
        raise NeedsDevkitLoader(why)


def _numeric(rows: List[Any], width: int, what: str) -> np.ndarray:
    """Rows of ``width`` numbers (bool/int/float), no NaN: as the devkit's ``len`` and ``np.isnan`` asserts."""
    if not rows:
        return np.zeros((0, width))
    try:
        arr = np.array(rows)
    except (ValueError, TypeError) as exc:
        raise NeedsDevkitLoader("%s: %s" % (what, exc)) from exc
    _require(arr.ndim == 2 and arr.shape[1] == width and arr.dtype.kind in "biuf", "%s: shape/type" % what)
    arr = arr.astype(np.float64)
    _require(not np.isnan(arr).any(), "%s: NaN" % what)
    return arr


class _Boxes:
    """Flat box arrays of one side (ground truth or predictions), in the devkit's sample/box order."""

    def __init__(self, tokens: List[str], counts: List[int], xyz: np.ndarray, raw_translation: List[Any],
                 ids: List[Any], names: List[str], scores: List[float], num_pts: np.ndarray):
        self.tokens = tokens            # sample tokens, in EvalBoxes order
        self.counts = counts            # boxes per sample token
        self.xyz = xyz
        self.raw_translation = raw_translation
        self.ids = ids
        self.names = names
        self.scores = scores
        self.num_pts = num_pts
        self.tokens_of_box = [t for t, c in zip(tokens, counts) for _ in range(c)]


# ----------------------------------------------------------------------------------------------------------------
# Loading
# ----------------------------------------------------------------------------------------------------------------

def _split_tokens(nusc, eval_split: str) -> Tuple[List[str], bool]:
    """Sample tokens of the split in the devkit's order (``load_gt`` / ``get_samples_of_custom_split``)."""
    from grutrack.data.nusc_tables import predefined_split_scenes

    if eval_split not in predefined_split_scenes():
        names = _custom_split_scenes(nusc, eval_split)
        _require(len(nusc.sample) > 0, "no samples")
        return [s["token"] for s in nusc.sample
                if nusc.get("scene", nusc.get("sample", s["token"])["scene_token"])["name"] in names], False
    version = nusc.version
    if eval_split in {"train", "val", "train_detect", "train_track"}:
        _require(version.endswith("trainval"), "split/version")
    elif eval_split in {"mini_train", "mini_val"}:
        _require(version.endswith("mini"), "split/version")
    elif eval_split == "test":
        _require(version.endswith("test") and len(nusc.sample_annotation) > 0, "split/version")
    else:
        raise NeedsDevkitLoader("split")
    names = predefined_split_scenes()[eval_split]
    _require(len(nusc.sample) > 0, "no samples")
    tokens = []
    for sample in nusc.sample:
        if nusc.get("scene", sample["scene_token"])["name"] in names:
            tokens.append(sample["token"])
    return tokens, True


def _custom_split_scenes(nusc, eval_split: str) -> List[str]:
    """Scene names of a custom split (``<dataroot>/<version>/splits.json``, as the devkit's
    ``get_scenes_of_custom_split``); anything the devkit would reject is left to the devkit."""
    path = os.path.join(nusc.dataroot, nusc.version, "splits.json")
    _require(os.path.isfile(path), "no splits.json")
    with open(path) as f:
        splits = json.load(f)
    _require(eval_split in splits and isinstance(splits[eval_split], list), "custom split")
    return splits[eval_split]


def _load_predictions(submission, split_tokens: List[str], predefined: bool, cfg, tracking_names) -> Tuple[_Boxes, Any]:
    if isinstance(submission, (str, os.PathLike)):
        _require(os.path.exists(os.fspath(submission)), "result file does not exist")
        with open(os.fspath(submission)) as f:
            data = json.load(f)
    else:
        data = submission
    _require(isinstance(data, dict) and "results" in data, "no results")
    results = data["results"]
    _require(isinstance(results, dict), "results not a dict")
    if not predefined:
        _require(all(t in results for t in split_tokens), "custom split sample missing")
        results = {t: results[t] for t in split_tokens}
    _require("meta" in data, "no meta")
    meta = data["meta"]

    tokens = list(results)
    _require(all(isinstance(results[t], list) for t in tokens), "boxes not a list")
    counts = [len(results[t]) for t in tokens]
    _require(all(c <= cfg.max_boxes_per_sample for c in counts), "too many boxes")
    boxes = [b for t in tokens for b in results[t]]
    _require(all(isinstance(b, dict) for b in boxes), "box not a dict")
    required = ("sample_token", "translation", "size", "rotation", "velocity", "tracking_id", "tracking_name")
    _require(all(all(k in b for k in required) for b in boxes), "missing key")

    raw_translation = [b["translation"] for b in boxes]
    xyz = _numeric(raw_translation, 3, "translation")
    _numeric([b["size"] for b in boxes], 3, "size")
    _numeric([b["rotation"] for b in boxes], 4, "rotation")
    try:
        _require(all(len(b["velocity"]) == 2 for b in boxes), "velocity")
    except TypeError as exc:
        raise NeedsDevkitLoader("velocity") from exc
    ego = [b["ego_translation"] for b in boxes if "ego_translation" in b]
    _numeric(ego, 3, "ego_translation")
    _require(all(type(b["sample_token"]) == str for b in boxes), "sample_token")   # noqa: E721 (devkit check)
    names = [b["tracking_name"] for b in boxes]
    _require(all(n is not None and n in tracking_names for n in names), "tracking_name")
    try:
        scores = [float(b["tracking_score"]) if "tracking_score" in b else -1.0 for b in boxes]
        num_pts = [int(b["num_pts"]) if "num_pts" in b else -1 for b in boxes]
    except (TypeError, ValueError) as exc:
        raise NeedsDevkitLoader("score/num_pts") from exc
    _require(not np.isnan(np.asarray(scores, dtype=np.float64)).any(), "NaN score")
    ids = [b["tracking_id"] for b in boxes]
    return _Boxes(tokens, counts, xyz, raw_translation, ids, names, scores,
                  np.asarray(num_pts, dtype=np.int64)), meta


def _load_gt(nusc, split_tokens: List[str], tracking_names) -> _Boxes:
    from grutrack.data.nuscenes import category_to_tracking_name

    counts: List[int] = []
    raw_translation: List[Any] = []
    sizes: List[Any] = []
    rotations: List[Any] = []
    ids: List[Any] = []
    names: List[str] = []
    num_pts: List[int] = []
    for token in split_tokens:
        n = 0
        for ann_token in nusc.get("sample", token)["anns"]:
            ann = nusc.get("sample_annotation", ann_token)
            name = category_to_tracking_name(ann["category_name"])
            if name is None:
                continue
            pts = ann["num_lidar_pts"] + ann["num_radar_pts"]
            _require(type(pts) == int, "num_pts")   # noqa: E721 (devkit check)
            raw_translation.append(ann["translation"])
            sizes.append(ann["size"])
            rotations.append(ann["rotation"])
            ids.append(ann["instance_token"])
            names.append(name)
            num_pts.append(pts)
            n += 1
        counts.append(n)
    _require(all(n in tracking_names for n in names), "tracking_name")
    xyz = _numeric(raw_translation, 3, "translation")
    _numeric(sizes, 3, "size")
    _numeric(rotations, 4, "rotation")
    return _Boxes(list(split_tokens), counts, xyz, raw_translation, ids, names, [-1.0] * len(ids),
                  np.asarray(num_pts, dtype=np.int64))


# ----------------------------------------------------------------------------------------------------------------
# Filtering (add_center_dist + filter_eval_boxes)
# ----------------------------------------------------------------------------------------------------------------

class _SampleInfo:
    def __init__(self, nusc, tokens: Sequence[str]):
        self.nusc = nusc
        self.ego: Dict[str, Tuple[float, float, float]] = {}
        self.scene: Dict[str, str] = {}
        self.timestamp: Dict[str, int] = {}
        self._racks: Dict[str, list] = {}
        for token in tokens:
            sample = nusc.get("sample", token)
            sd = nusc.get("sample_data", sample["data"]["LIDAR_TOP"])
            self.ego[token] = nusc.get("ego_pose", sd["ego_pose_token"])["translation"]
            self.scene[token] = sample["scene_token"]
            self.timestamp[token] = sample["timestamp"]

    def racks(self, token: str) -> list:
        boxes = self._racks.get(token)
        if boxes is None:
            nusc = self.nusc
            recs = [nusc.get("sample_annotation", a) for a in nusc.get("sample", token)["anns"]
                    if nusc.get("sample_annotation", a)["category_name"] == _BIKE_RACK]
            boxes = [_box_corners(r["translation"], r["size"], r["rotation"]) for r in recs]
            self._racks[token] = boxes
        return boxes


def _box_corners(center, wlh, rotation) -> np.ndarray:
    """(3, 8) corners of a box: ``nuscenes.utils.data_classes.Box(center, wlh, Quaternion(rotation)).corners()``,
    the same operations in the same order (pyquaternion's rotation matrix)."""
    from pyquaternion import Quaternion

    w, l, h = np.array(wlh) * 1.0
    x_corners = l / 2 * np.array([1, 1, 1, 1, -1, -1, -1, -1])
    y_corners = w / 2 * np.array([1, -1, -1, 1, 1, -1, -1, 1])
    z_corners = h / 2 * np.array([1, 1, -1, -1, 1, 1, -1, -1])
    corners = np.dot(Quaternion(rotation).rotation_matrix, np.vstack((x_corners, y_corners, z_corners)))
    x, y, z = np.array(center)
    corners[0, :] = corners[0, :] + x
    corners[1, :] = corners[1, :] + y
    corners[2, :] = corners[2, :] + z
    return corners


def _points_in_box(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n,) bool: ``nuscenes.utils.geometry_utils.points_in_box`` for a box given by its (3, 8) corners and
    (3, n) points (projections on the box's three edges from corner 0)."""
    p1 = corners[:, 0]
    i, j, k = corners[:, 4] - p1, corners[:, 1] - p1, corners[:, 3] - p1
    v = points - p1.reshape((-1, 1))
    iv, jv, kv = np.dot(i, v), np.dot(j, v), np.dot(k, v)
    mask_x = np.logical_and(0 <= iv, iv <= np.dot(i, i))
    mask_y = np.logical_and(0 <= jv, jv <= np.dot(j, j))
    mask_z = np.logical_and(0 <= kv, kv <= np.dot(k, k))
    return np.logical_and(np.logical_and(mask_x, mask_y), mask_z)


def _keep_mask(b: _Boxes, info: _SampleInfo, class_range: Dict[str, float]) -> np.ndarray:
    n = len(b.names)
    _require(n > 0, "no boxes at all (the devkit's filter raises)")
    tok_of_box = np.repeat(np.arange(len(b.tokens)), b.counts)
    ego = np.asarray([info.ego[t] for t in b.tokens], dtype=np.float64).reshape(-1, 3)[tok_of_box]
    # EvalBox.ego_dist: sqrt(sum(array(ego_translation[:2]) ** 2)) with ego_translation = translation - pose.
    ex = b.xyz[:, 0] - ego[:, 0]
    ey = b.xyz[:, 1] - ego[:, 1]
    dist = np.sqrt(ex ** 2 + ey ** 2)
    try:
        max_dist = np.asarray([class_range[name] for name in b.names], dtype=np.float64)
    except KeyError as exc:
        raise NeedsDevkitLoader("class_range") from exc
    keep = (dist < max_dist) & (b.num_pts != 0)
    for i in np.flatnonzero(keep).tolist():
        if b.names[i] in _BIKE_CLASSES:
            racks = info.racks(b.tokens[tok_of_box[i]])
            point = np.expand_dims(np.array(b.raw_translation[i]), axis=1)
            for rack in racks:
                if np.sum(_points_in_box(rack, point)) > 0:
                    keep[i] = False
    return keep


# ----------------------------------------------------------------------------------------------------------------
# create_tracks
# ----------------------------------------------------------------------------------------------------------------

def _create_tracks(b: _Boxes, keep: np.ndarray, info: _SampleInfo, nusc, eval_split: str, gt: bool):
    from grutrack.data.nusc_tables import predefined_split_scenes

    predefined = predefined_split_scenes()
    scenes_of_split = predefined[eval_split] if eval_split in predefined else _custom_split_scenes(nusc, eval_split)
    scene_tokens = set()
    for token in b.tokens:
        scene_token = info.scene[token]
        if nusc.get("scene", scene_token)["name"] in scenes_of_split:
            scene_tokens.add(scene_token)
    _require(all(info.scene[t] in scene_tokens for t in b.tokens), "sample outside the split's scenes")

    # Frames of each scene (timestamps in sample-chain order) holding indices of the kept boxes.
    frames: Dict[str, Dict[int, List[int]]] = {}
    for scene_token in scene_tokens:
        scene = nusc.get("scene", scene_token)
        per_ts: Dict[int, List[int]] = {}
        token = scene["first_sample_token"]
        while True:
            sample = nusc.get("sample", token)
            per_ts[sample["timestamp"]] = []
            if token == scene["last_sample_token"]:
                break
            token = sample["next"]
        frames[scene_token] = per_ts
    start = 0
    for token, count in zip(b.tokens, b.counts):
        idx = np.arange(start, start + count)
        frames[info.scene[token]][info.timestamp[token]] = idx[keep[start:start + count]].tolist()
        start += count

    xyz = b.xyz
    scores: List[float] = list(b.scores)
    if not gt:
        # Track score: np.mean of the scores of an id in the scene, in the devkit's order.
        for per_ts in frames.values():
            by_id: Dict[Any, List[int]] = {}
            for boxes in per_ts.values():
                for i in boxes:
                    by_id.setdefault(b.ids[i], []).append(i)
            for members in by_id.values():
                mean = np.mean(np.asarray([b.scores[i] for i in members]))
                for i in members:
                    scores[i] = mean

    tracks: Dict[str, Dict[int, List[LiteBox]]] = defaultdict(lambda: defaultdict(list))
    for scene_token, per_ts in frames.items():
        def lite(i: int) -> LiteBox:
            return LiteBox(b.tokens_of_box[i], (float(xyz[i, 0]), float(xyz[i, 1]), float(xyz[i, 2])), b.ids[i],
                           b.names[i], scores[i])

        out: Dict[int, List[LiteBox]] = defaultdict(list)
        for ts, boxes in per_ts.items():
            out[ts] = [lite(i) for i in boxes]
        # interpolate_tracks: ids in order of first appearance, their timestamps (chronological).
        track_boxes: Dict[Any, List[int]] = {}
        track_ts: Dict[Any, List[int]] = {}
        for ts, boxes in per_ts.items():
            for i in boxes:
                track_boxes.setdefault(b.ids[i], []).append(i)
                track_ts.setdefault(b.ids[i], []).append(ts)
        timestamps = list(per_ts)
        position = {ts: k for k, ts in enumerate(timestamps)}
        added: List[Tuple[int, int, LiteBox]] = []
        for order, (tid, tss) in enumerate(track_ts.items()):
            if tss[-1] == tss[0]:
                continue
            present = set(tss)
            members = track_boxes[tid]
            for ts in timestamps[position[tss[0]]:position[tss[-1]] + 1]:
                if ts in present or not tss[0] <= ts <= tss[-1]:
                    continue
                right = bisect(tss, ts)
                left = right - 1
                ratio = float(tss[right] - ts) / (tss[right] - tss[left])
                li, ri = members[left], members[right]
                x = (1.0 - ratio) * xyz[li, 0] + ratio * xyz[ri, 0]
                y = (1.0 - ratio) * xyz[li, 1] + ratio * xyz[ri, 1]
                z = (1.0 - ratio) * xyz[li, 2] + ratio * xyz[ri, 2]
                score = (1.0 - ratio) * float(scores[li]) + ratio * float(scores[ri])
                added.append((position[ts], order, LiteBox(b.tokens_of_box[ri], (float(x), float(y), float(z)),
                                                           b.ids[ri], b.names[ri], score)))
        added.sort(key=lambda item: (item[0], item[1]))
        for pos, _, box in added:
            out[timestamps[pos]].append(box)
        if not gt:
            out = defaultdict(list, sorted(out.items(), key=lambda kv: kv[0]))
        tracks[scene_token] = out
    return tracks


# ----------------------------------------------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------------------------------------------

def fast_load_tracks(nusc, submission, eval_split: str, cfg):
    """``(tracks_gt, tracks_pred, meta)`` equal to the devkit's loading in ``TrackingEval.__init__``.

    Raises :class:`NeedsDevkitLoader` for inputs it does not reproduce (the devkit then decides).
    """
    tracking_names = list(cfg.tracking_names)  # what TrackingEval's config sets as the devkit's TRACKING_NAMES
    split_tokens, predefined = _split_tokens(nusc, eval_split)
    pred, meta = _load_predictions(submission, split_tokens, predefined, cfg, tracking_names)
    gt = _load_gt(nusc, split_tokens, tracking_names)
    _require(set(pred.tokens) == set(gt.tokens), "samples in split don't match samples in predicted tracks")
    info = _SampleInfo(nusc, gt.tokens)
    keep_pred = _keep_mask(pred, info, cfg.class_range)
    keep_gt = _keep_mask(gt, info, cfg.class_range)
    tracks_gt = _create_tracks(gt, keep_gt, info, nusc, eval_split, gt=True)
    tracks_pred = _create_tracks(pred, keep_pred, info, nusc, eval_split, gt=False)
    return tracks_gt, tracks_pred, meta
