"""All boxes of all scenes as flat arrays, frames numbered in the devkit's iteration order.

The devkit iterates the ground-truth scenes and, within each, the ground-truth timestamps, with one motmetrics
accumulator per scene: object and hypothesis ids are per scene. :func:`flatten` numbers the frames in that order
and gives every (scene, tracking id) a dense integer id, so the accumulation works on arrays only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FlatBoxes", "flatten"]


@dataclass
class FlatBoxes:
    """The boxes of the evaluated classes, G ground-truth and P predicted ones, in frame order.

    n_frames: F, frames of all scenes; frame_keys: (scene token, timestamp in microseconds) of every frame.
    g_frame, g_cls, g_obj: (G,) int64 frame, class index (into the config's ``class_names``) and dense object
    id; g_xy: (G, 2) float64 BEV centre, global frame, metres. p_frame, p_cls, p_hyp: (P,) int64 frame, class
    index and dense hypothesis id; p_xy: (P, 2) float64, global frame, metres; p_score: (P,) float64 track
    score. obj_raw_id: tracking id (instance token) of each dense object id; p_raw_id: (P,) tracking id of each
    prediction.
    """

    n_frames: int
    g_frame: np.ndarray
    g_cls: np.ndarray
    g_obj: np.ndarray
    g_xy: np.ndarray
    p_frame: np.ndarray
    p_cls: np.ndarray
    p_hyp: np.ndarray
    p_xy: np.ndarray
    p_score: np.ndarray
    obj_raw_id: list[Any]
    frame_keys: list[tuple[Any, Any]]
    p_raw_id: list[Any]


def _evaluated(boxes, cls_index: dict[str, int], ids: dict[Any, int], raw_ids: list[Any]):
    """``(class index, dense id, box)`` of each box of an evaluated class; a tracking id not in ``ids`` gets the
    next dense id (its raw id appended to ``raw_ids``)."""
    out = []
    for box in boxes:
        c = cls_index.get(box.tracking_name, -1)
        if c < 0:
            continue
        i = ids.get(box.tracking_id)
        if i is None:
            i = ids[box.tracking_id] = len(raw_ids)
            raw_ids.append(box.tracking_id)
        out.append((c, i, box))
    return out


def flatten(tracks_gt, tracks_pred, class_names: list[str]) -> FlatBoxes:
    """The boxes of ``class_names`` in tracks from :func:`~grutrack.evaluation.nuscenes_fast.loading.load_tracks`
    (either loader) as :class:`FlatBoxes`."""
    cls_index = {name: i for i, name in enumerate(class_names)}
    g_frame: list[int] = []
    g_cls: list[int] = []
    g_obj: list[int] = []
    g_xy: list[tuple[float, float]] = []
    p_frame: list[int] = []
    p_cls: list[int] = []
    p_hyp: list[int] = []
    p_xy: list[tuple[float, float]] = []
    p_score: list[float] = []
    obj_raw_id: list[Any] = []
    frame_keys: list[tuple[Any, Any]] = []
    p_raw_id: list[Any] = []
    hyp_raw_id: list[Any] = []  # one entry per dense hypothesis id (ids are per scene)
    f = 0
    for scene_token, scene_gt in tracks_gt.items():
        scene_pred = tracks_pred[scene_token]
        obj_ids: dict[Any, int] = {}
        hyp_ids: dict[Any, int] = {}
        for timestamp, frame_gt in scene_gt.items():
            frame_pred = scene_pred[timestamp]
            for c, o, box in _evaluated(frame_gt, cls_index, obj_ids, obj_raw_id):
                g_frame.append(f)
                g_cls.append(c)
                g_obj.append(o)
                g_xy.append((box.translation[0], box.translation[1]))
            for c, h, box in _evaluated(frame_pred, cls_index, hyp_ids, hyp_raw_id):
                p_frame.append(f)
                p_cls.append(c)
                p_hyp.append(h)
                p_xy.append((box.translation[0], box.translation[1]))
                p_score.append(box.tracking_score)
                p_raw_id.append(box.tracking_id)
            frame_keys.append((scene_token, timestamp))
            f += 1
    return FlatBoxes(
        n_frames=f,
        g_frame=np.asarray(g_frame, dtype=np.int64),
        g_cls=np.asarray(g_cls, dtype=np.int64),
        g_obj=np.asarray(g_obj, dtype=np.int64),
        g_xy=np.asarray(g_xy, dtype=np.float64).reshape(-1, 2),
        p_frame=np.asarray(p_frame, dtype=np.int64),
        p_cls=np.asarray(p_cls, dtype=np.int64),
        p_hyp=np.asarray(p_hyp, dtype=np.int64),
        p_xy=np.asarray(p_xy, dtype=np.float64).reshape(-1, 2),
        p_score=np.asarray(p_score, dtype=np.float64),
        obj_raw_id=obj_raw_id,
        frame_keys=frame_keys,
        p_raw_id=p_raw_id,
    )
