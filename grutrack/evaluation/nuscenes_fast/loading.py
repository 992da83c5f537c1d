"""Loading and filtering: ground truth and predictions to tracks exactly as ``TrackingEval.__init__`` makes them.

``TrackingEval.__init__`` (nuscenes-devkit 1.2.0) builds one ``TrackingBox`` per box (tens of microseconds each:
shape and NaN assertions through numpy), estimates a velocity for every ground-truth annotation, filters the
boxes one by one and interpolates track gaps in a loop over timestamps x track ids. :func:`fast_load_tracks`
produces the same tracks (same scenes, frames, boxes, order, translations, track-averaged scores, interpolated
boxes) with light records (:class:`LiteBox`: what the metrics read). It mirrors, step by step:

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
:class:`NeedsDevkitLoader`; :func:`load_tracks` then runs the devkit's own loaders, which give their own result
or error. Box velocities, sizes and rotations are validated but not kept: the tracking metrics never read them.

Tracks, either loader: ``{scene token: {timestamp (us): [box, ...]}}``, boxes with ``tracking_id``,
``tracking_name``, ``translation`` (global frame, metres) and ``tracking_score``.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
from bisect import bisect
from collections import defaultdict
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

__all__ = ["LiteBox", "NeedsDevkitLoader", "default_config", "fast_load_tracks", "load_tracks"]

_BIKE_CLASSES = ("bicycle", "motorcycle")
_BIKE_RACK = "static_object.bicycle_rack"


def default_config():
    """``config_factory('tracking_nips_2019')``'s content (a ``TrackingConfig``), without importing the devkit."""
    from grutrack.evaluation.tracking_classes import load_config

    return load_config("tracking_nips_2019")


def load_tracks(
    nusc,
    submission: dict | str | os.PathLike,
    eval_split: str,
    config=None,
    verbose: bool = False,
    loader: str = "fast",
):
    """``(tracks_gt, tracks_pred, meta)`` as the devkit's ``create_tracks`` gives them in ``TrackingEval.__init__``.

    ``loader``: ``"fast"`` (default): :func:`fast_load_tracks`, the same tracks with :class:`LiteBox` records,
    falling back to the devkit's loaders for any input it does not reproduce (the devkit then gives its own
    result or error); ``"devkit"``: the devkit's loaders (``TrackingBox`` objects).
    """
    cfg = config if config is not None else default_config()
    if loader == "fast":
        try:
            return fast_load_tracks(nusc, submission, eval_split, cfg)
        except NeedsDevkitLoader as exc:
            if verbose:
                print(f"fast loader: {exc}; using the devkit's loaders")
    elif loader != "devkit":
        raise ValueError(f"loader must be 'fast' or 'devkit', not {loader!r}")
    return _devkit_load_tracks(nusc, submission, eval_split, cfg, verbose)


# ----------------------------------------------------------------------------------------------------------------
# The devkit's own loaders
# ----------------------------------------------------------------------------------------------------------------


def _quiet(verbose: bool):
    """The devkit's GT loaders draw a tqdm bar on stderr even when not verbose; hide it unless verbose."""
    return contextlib.nullcontext() if verbose else contextlib.redirect_stderr(io.StringIO())


def _devkit_load_tracks(nusc, submission, eval_split: str, cfg, verbose: bool):
    from nuscenes.eval.common.data_classes import EvalBoxes
    from nuscenes.eval.common.loaders import (
        add_center_dist,
        filter_eval_boxes,
        get_samples_of_custom_split,
        load_gt,
        load_gt_of_sample_tokens,
        load_prediction,
        load_prediction_of_sample_tokens,
    )
    from nuscenes.eval.tracking.data_classes import TrackingBox
    from nuscenes.eval.tracking.loaders import create_tracks
    from nuscenes.utils.splits import is_predefined_split

    from grutrack.evaluation.tracking_classes import devkit_config

    cfg = devkit_config(cfg)  # also sets the devkit's TRACKING_NAMES, which TrackingBox checks
    predefined = is_predefined_split(split_name=eval_split)
    custom_tokens = None if predefined else get_samples_of_custom_split(split_name=eval_split, nusc=nusc)

    if isinstance(submission, (str, os.PathLike)):
        path = os.fspath(submission)
        assert os.path.exists(path), "Error: The result file does not exist!"
        with _quiet(verbose):
            if predefined:
                pred_boxes, meta = load_prediction(path, cfg.max_boxes_per_sample, TrackingBox, verbose=verbose)
            else:
                pred_boxes, meta = load_prediction_of_sample_tokens(
                    path, cfg.max_boxes_per_sample, TrackingBox, sample_tokens=custom_tokens, verbose=verbose
                )
    else:
        # Same steps as load_prediction / load_prediction_of_sample_tokens, on an in-memory submission.
        data = submission
        assert "results" in data, "Error: No field `results` in result file."
        if predefined:
            results = data["results"]
        else:
            assert isinstance(data["results"], dict), "Error: results must be a dict."
            results = {token: data["results"][token] for token in custom_tokens}
        pred_boxes = EvalBoxes.deserialize(results, TrackingBox)
        meta = data["meta"]
        for sample_token in pred_boxes.sample_tokens:
            assert len(pred_boxes.boxes[sample_token]) <= cfg.max_boxes_per_sample, (
                f"Error: Only <= {cfg.max_boxes_per_sample} boxes per sample allowed!"
            )

    with _quiet(verbose):
        if predefined:
            gt_boxes = load_gt(nusc, eval_split, TrackingBox, verbose=verbose)
        else:
            gt_boxes = load_gt_of_sample_tokens(nusc, custom_tokens, TrackingBox, verbose=verbose)

    assert set(pred_boxes.sample_tokens) == set(gt_boxes.sample_tokens), (
        "Samples in split don't match samples in predicted tracks."
    )

    pred_boxes = add_center_dist(nusc, pred_boxes)
    gt_boxes = add_center_dist(nusc, gt_boxes)
    pred_boxes = filter_eval_boxes(nusc, pred_boxes, cfg.class_range, verbose=verbose)
    gt_boxes = filter_eval_boxes(nusc, gt_boxes, cfg.class_range, verbose=verbose)

    tracks_gt = create_tracks(gt_boxes, nusc, eval_split, gt=True)
    tracks_pred = create_tracks(pred_boxes, nusc, eval_split, gt=False)
    return tracks_gt, tracks_pred, meta


# ----------------------------------------------------------------------------------------------------------------
# The fast loader: records and validation
# ----------------------------------------------------------------------------------------------------------------


class LiteBox(NamedTuple):
    """What the tracking metrics read from a ``TrackingBox`` (``sample_token``: the sample the box is filed
    under; for an interpolated box, that of its right neighbour, as the devkit does); ``translation``: global
    frame, metres."""

    sample_token: str
    translation: tuple[float, float, float]
    tracking_id: Any
    tracking_name: str
    tracking_score: float


class NeedsDevkitLoader(Exception):
    """The input is outside what the fast loader reproduces exactly; use the devkit's loaders."""


def _require(cond: bool, why: str) -> None:
    if not cond:
        raise NeedsDevkitLoader(why)


def _numeric(rows: list[Any], width: int, what: str) -> np.ndarray:
    """(N, width) float64 from rows of numbers (bool/int/float), no NaN: as the devkit's ``len`` and ``np.isnan``
    asserts."""
    if not rows:
        return np.zeros((0, width))
    try:
        arr = np.array(rows)
    except (ValueError, TypeError) as exc:
        raise NeedsDevkitLoader(f"{what}: {exc}") from exc
    _require(arr.ndim == 2 and arr.shape[1] == width and arr.dtype.kind in "biuf", f"{what}: shape/type")
    arr = arr.astype(np.float64)
    _require(not np.isnan(arr).any(), f"{what}: NaN")
    return arr


class _Boxes:
    """Flat box arrays of one side (ground truth or predictions), in the devkit's sample/box order.

    xyz: (N, 3) float64 translations, global frame, metres; num_pts: (N,) int64 (-1: not given).
    """

    def __init__(
        self,
        tokens: list[str],
        counts: list[int],
        xyz: np.ndarray,
        raw_translation: list[Any],
        ids: list[Any],
        names: list[str],
        scores: list[float],
        num_pts: np.ndarray,
    ):
        self.tokens = tokens  # sample tokens, in EvalBoxes order
        self.counts = counts  # boxes per sample token
        self.xyz = xyz
        self.raw_translation = raw_translation
        self.ids = ids
        self.names = names
        self.scores = scores
        self.num_pts = num_pts
        self.tokens_of_box = [t for t, c in zip(tokens, counts) for _ in range(c)]


# ----------------------------------------------------------------------------------------------------------------
# The fast loader: loading
# ----------------------------------------------------------------------------------------------------------------


def _split_tokens(nusc, eval_split: str) -> tuple[list[str], bool]:
    """Sample tokens of the split in the devkit's order (``load_gt`` / ``get_samples_of_custom_split``), and
    whether the split is predefined."""
    from grutrack.data.nusc_tables import predefined_split_scenes

    if eval_split not in predefined_split_scenes():
        names = _custom_split_scenes(nusc, eval_split)
        _require(len(nusc.sample) > 0, "no samples")
        return [
            s["token"]
            for s in nusc.sample
            if nusc.get("scene", nusc.get("sample", s["token"])["scene_token"])["name"] in names
        ], False
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


def _custom_split_scenes(nusc, eval_split: str) -> list[str]:
    """Scene names of a custom split (``<dataroot>/<version>/splits.json``, as the devkit's
    ``get_scenes_of_custom_split``); anything the devkit would reject is left to the devkit."""
    path = os.path.join(nusc.dataroot, nusc.version, "splits.json")
    _require(os.path.isfile(path), "no splits.json")
    with open(path) as f:
        splits = json.load(f)
    _require(eval_split in splits and isinstance(splits[eval_split], list), "custom split")
    return splits[eval_split]


def _load_predictions(submission, split_tokens: list[str], predefined: bool, cfg, tracking_names) -> tuple[_Boxes, Any]:
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
    _require(all(type(b["sample_token"]) == str for b in boxes), "sample_token")  # noqa: E721 (devkit check)
    names = [b["tracking_name"] for b in boxes]
    _require(all(n is not None and n in tracking_names for n in names), "tracking_name")
    try:
        scores = [float(b["tracking_score"]) if "tracking_score" in b else -1.0 for b in boxes]
        num_pts = [int(b["num_pts"]) if "num_pts" in b else -1 for b in boxes]
    except (TypeError, ValueError) as exc:
        raise NeedsDevkitLoader("score/num_pts") from exc
    _require(not np.isnan(np.asarray(scores, dtype=np.float64)).any(), "NaN score")
    ids = [b["tracking_id"] for b in boxes]
    return _Boxes(tokens, counts, xyz, raw_translation, ids, names, scores, np.asarray(num_pts, dtype=np.int64)), meta


def _load_gt(nusc, split_tokens: list[str], tracking_names) -> _Boxes:
    from grutrack.data.nuscenes import category_to_tracking_name

    counts: list[int] = []
    raw_translation: list[Any] = []
    sizes: list[Any] = []
    rotations: list[Any] = []
    ids: list[Any] = []
    names: list[str] = []
    num_pts: list[int] = []
    for token in split_tokens:
        n = 0
        for ann_token in nusc.get("sample", token)["anns"]:
            ann = nusc.get("sample_annotation", ann_token)
            name = category_to_tracking_name(ann["category_name"])
            if name is None:
                continue
            pts = ann["num_lidar_pts"] + ann["num_radar_pts"]
            _require(type(pts) == int, "num_pts")  # noqa: E721 (devkit check)
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
    return _Boxes(
        list(split_tokens),
        counts,
        xyz,
        raw_translation,
        ids,
        names,
        [-1.0] * len(ids),
        np.asarray(num_pts, dtype=np.int64),
    )


# ----------------------------------------------------------------------------------------------------------------
# The fast loader: filtering (add_center_dist + filter_eval_boxes)
# ----------------------------------------------------------------------------------------------------------------


class _SampleInfo:
    """Per sample token: ego position (global frame, metres), scene token, timestamp (us); bike racks on demand."""

    def __init__(self, nusc, tokens: Sequence[str]):
        self.nusc = nusc
        self.ego: dict[str, tuple[float, float, float]] = {}
        self.scene: dict[str, str] = {}
        self.timestamp: dict[str, int] = {}
        self._racks: dict[str, list] = {}
        for token in tokens:
            sample = nusc.get("sample", token)
            sd = nusc.get("sample_data", sample["data"]["LIDAR_TOP"])
            self.ego[token] = nusc.get("ego_pose", sd["ego_pose_token"])["translation"]
            self.scene[token] = sample["scene_token"]
            self.timestamp[token] = sample["timestamp"]

    def racks(self, token: str) -> list:
        """(3, 8) corners of every bicycle rack annotated in the sample."""
        boxes = self._racks.get(token)
        if boxes is None:
            nusc = self.nusc
            recs = [
                nusc.get("sample_annotation", a)
                for a in nusc.get("sample", token)["anns"]
                if nusc.get("sample_annotation", a)["category_name"] == _BIKE_RACK
            ]
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


def _keep_mask(b: _Boxes, info: _SampleInfo, class_range: dict[str, float]) -> np.ndarray:
    """(N,) bool: the boxes ``filter_eval_boxes`` keeps (class range in metres from the ego, points, bike racks)."""
    n = len(b.names)
    _require(n > 0, "no boxes at all (the devkit's filter raises)")
    tok_of_box = np.repeat(np.arange(len(b.tokens)), b.counts)
    ego = np.asarray([info.ego[t] for t in b.tokens], dtype=np.float64).reshape(-1, 3)[tok_of_box]
    # EvalBox.ego_dist: sqrt(sum(array(ego_translation[:2]) ** 2)) with ego_translation = translation - pose.
    ex = b.xyz[:, 0] - ego[:, 0]
    ey = b.xyz[:, 1] - ego[:, 1]
    dist = np.sqrt(ex**2 + ey**2)
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
# The fast loader: create_tracks
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
    frames: dict[str, dict[int, list[int]]] = {}
    for scene_token in scene_tokens:
        scene = nusc.get("scene", scene_token)
        per_ts: dict[int, list[int]] = {}
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
        frames[info.scene[token]][info.timestamp[token]] = idx[keep[start : start + count]].tolist()
        start += count

    xyz = b.xyz
    scores: list[float] = list(b.scores)
    if not gt:
        # Track score: np.mean of the scores of an id in the scene, in the devkit's order.
        for per_ts in frames.values():
            by_id: dict[Any, list[int]] = {}
            for boxes in per_ts.values():
                for i in boxes:
                    by_id.setdefault(b.ids[i], []).append(i)
            for members in by_id.values():
                mean = np.mean(np.asarray([b.scores[i] for i in members]))
                for i in members:
                    scores[i] = mean

    tracks: dict[str, dict[int, list[LiteBox]]] = defaultdict(lambda: defaultdict(list))
    for scene_token, per_ts in frames.items():

        def lite(i: int) -> LiteBox:
            return LiteBox(
                b.tokens_of_box[i],
                (float(xyz[i, 0]), float(xyz[i, 1]), float(xyz[i, 2])),
                b.ids[i],
                b.names[i],
                scores[i],
            )

        out: dict[int, list[LiteBox]] = defaultdict(list)
        for ts, boxes in per_ts.items():
            out[ts] = [lite(i) for i in boxes]
        # interpolate_tracks: ids in order of first appearance, their timestamps (chronological).
        track_boxes: dict[Any, list[int]] = {}
        track_ts: dict[Any, list[int]] = {}
        for ts, boxes in per_ts.items():
            for i in boxes:
                track_boxes.setdefault(b.ids[i], []).append(i)
                track_ts.setdefault(b.ids[i], []).append(ts)
        timestamps = list(per_ts)
        position = {ts: k for k, ts in enumerate(timestamps)}
        added: list[tuple[int, int, LiteBox]] = []
        for order, (tid, tss) in enumerate(track_ts.items()):
            if tss[-1] == tss[0]:
                continue
            present = set(tss)
            members = track_boxes[tid]
            for ts in timestamps[position[tss[0]] : position[tss[-1]] + 1]:
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
                added.append(
                    (
                        position[ts],
                        order,
                        LiteBox(b.tokens_of_box[ri], (float(x), float(y), float(z)), b.ids[ri], b.names[ri], score),
                    )
                )
        added.sort(key=lambda item: (item[0], item[1]))
        for pos, _, box in added:
            out[timestamps[pos]].append(box)
        if not gt:
            out = defaultdict(list, sorted(out.items(), key=lambda kv: kv[0]))
        tracks[scene_token] = out
    return tracks


def fast_load_tracks(nusc, submission, eval_split: str, cfg):
    """``(tracks_gt, tracks_pred, meta)`` equal to the devkit's loading in ``TrackingEval.__init__``, boxes as
    :class:`LiteBox`. Raises :class:`NeedsDevkitLoader` for inputs it does not reproduce (the devkit then
    decides)."""
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
