"""What one rendered frame shows: ground truth, tracks and detections joined with the evaluator's decisions.

:class:`FrameView` is the drawn frame of either dataset. For nuScenes, :func:`build_views` takes the decisions
from :func:`grutrack.evaluation.nuscenes_fast.match_decisions` (the fast exact evaluator's own matching at each
class's best-MOTA threshold), so the counts of a frame summed over frames and scenes are the metrics JSON's
TP / FP / FN / IDS; AV2 frames are built by :mod:`grutrack.render.av2`. Boxes keep the global frame here;
:mod:`grutrack.render.draw` moves them into the ego frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grutrack.boxes import yaw_from_quaternion
from grutrack.data.scene import Scene
from grutrack.evaluation.nuscenes_fast import BELOW_THRESHOLD, MATCH, MISS_OR_FP, SWITCH, UNSCORED, MatchDecisions

#: ground-truth states drawn: matched (TP), matched with an id switch, missed (FN), not evaluated
#: (outside the class range or without lidar/radar points: the evaluator drops it)
GT_MATCH, GT_SWITCH, GT_MISS, GT_IGNORED = 0, 1, 2, 3
#: track states drawn: matched (TP), matched with an id switch, false positive, below its class's threshold,
#: class without an achieved threshold, not evaluated (outside the class range)
TR_MATCH, TR_SWITCH, TR_FP, TR_BELOW, TR_UNSCORED, TR_IGNORED = 0, 1, 2, 3, 4, 5

_GT_STATE = {MATCH: GT_MATCH, SWITCH: GT_SWITCH, MISS_OR_FP: GT_MISS}
_TR_STATE = {MATCH: TR_MATCH, SWITCH: TR_SWITCH, MISS_OR_FP: TR_FP, BELOW_THRESHOLD: TR_BELOW, UNSCORED: TR_UNSCORED}
COUNT_KEYS = ("tp", "fp", "fn", "ids")


@dataclass
class FrameView:
    """One frame to draw. Boxes are ``(N, 5) [x, y, w, l, yaw]`` float64, global frame, metres / radians.

    gt_state / tr_state: (N,) int64 codes above; gt_cls / tr_cls: (N,) class names; gt_ids / tr_ids: instance
    tokens / track ids. trails: one ``(K, 2)`` float64 array per track (its last centres, oldest first, global
    metres). counts: ``{class: {tp, fp, fn, ids}}`` of the frame (evaluated classes only).
    """

    scene: str
    index: int
    sample_token: str
    timestamp: int
    ego_xy: np.ndarray
    ego_yaw: float
    gt_boxes: np.ndarray
    gt_state: np.ndarray
    gt_cls: list
    gt_ids: list
    tr_boxes: np.ndarray
    tr_state: np.ndarray
    tr_cls: list
    tr_ids: list
    det_boxes: np.ndarray
    trails: list
    counts: dict
    false_positives: list = field(default_factory=list)
    missed: list = field(default_factory=list)
    id_switches: list = field(default_factory=list)
    caption: str = ""  # what names the frame under the title (default: its sample token)
    #: heights for the 3D view (:mod:`grutrack.render.rerun_log`): ``(N, 2) [z of the centre, height]`` metres
    #: of gt / tracks / detections, and the ego's z; None: not known (drawn on the ground, 1.5 m high)
    gt_zh: np.ndarray | None = None
    tr_zh: np.ndarray | None = None
    det_zh: np.ndarray | None = None
    ego_z: float = 0.0

    def totals(self) -> dict:
        """TP, FP, FN and IDS of the frame summed over classes."""
        return {k: sum(c[k] or 0 for c in self.counts.values()) for k in COUNT_KEYS}


def _frame_ranges(frames: np.ndarray, n: int) -> np.ndarray:
    """Start offsets of each frame index 0..n in a non-decreasing (M,) frame array -> (n + 1,) int64."""
    return np.searchsorted(frames, np.arange(n + 1))


def _sub_boxes(records: list) -> tuple[np.ndarray, list, list, np.ndarray]:
    """Submission box dicts -> ((N, 5) [x, y, w, l, yaw], class names, track ids, (N,) scores)."""
    if not records:
        return np.zeros((0, 5)), [], [], np.zeros(0)
    xy = np.array([b["translation"][:2] for b in records], dtype=np.float64)
    wl = np.array([b["size"][:2] for b in records], dtype=np.float64)
    yaw = yaw_from_quaternion(np.array([b["rotation"] for b in records], dtype=np.float64))
    return (
        np.column_stack([xy, wl, yaw]),
        [b["tracking_name"] for b in records],
        [b["tracking_id"] for b in records],
        np.array([b["tracking_score"] for b in records], dtype=np.float64),
    )


def update_trails(history: dict, index: int, ids: list, boxes: np.ndarray, trail_frames: int) -> list[np.ndarray]:
    """Add frame ``index``'s track centres to ``history`` ({track id: [(frame, x, y), ...]}) and return, per
    track of ``ids`` (boxes ``(N, >=2)``, global metres), its ``(K, 2)`` centres of the last ``trail_frames``
    frames, oldest first."""
    trails = []
    for k, tid in enumerate(ids):
        h = history.setdefault(tid, [])
        h.append((index, boxes[k, 0], boxes[k, 1]))
        trails.append(np.array([(x, y) for j, x, y in h if j > index - trail_frames]))
    return trails


def _sub_zh(records: list) -> np.ndarray:
    """Submission box dicts -> ``(N, 2) [z of the centre, height]`` metres."""
    return np.array([[b["translation"][2], b["size"][2]] for b in records], dtype=np.float64).reshape(-1, 2)


def build_views(
    scene: Scene, results: dict, decisions: MatchDecisions, detections: dict | None = None, trail_frames: int = 6
) -> list[FrameView]:
    """The frames of one scene, joined with the evaluator's decisions.

    :param scene: canonical scene with ground truth (``load_scenes(..., with_gt=True)``).
    :param results: the tracking submission's ``results`` ({sample token: [box dict, ...]}).
    :param decisions: the split's :class:`MatchDecisions`.
    :param detections: optional {sample token: BoxSet} of raw detections (drawn faint).
    :param trail_frames: frames of history drawn behind each track (current one included).
    """
    n_frames = len(decisions.frame_keys)
    frame_of = {key: f for f, key in enumerate(decisions.frame_keys)}
    g_ptr = _frame_ranges(decisions.g_frame, n_frames)
    p_ptr = _frame_ranges(decisions.p_frame, n_frames)
    classes = decisions.class_names
    evaluated = [
        c for c in classes if decisions.thresholds[c] is not None or np.any(decisions.g_cls == classes.index(c))
    ]
    last_box: dict[Any, np.ndarray] = {}  # track id -> its last submitted box (for interpolated boxes)
    history: dict[Any, list] = {}  # track id -> [(frame index, x, y), ...]
    last_partner: dict[Any, Any] = {}  # GT instance -> track id of its last match
    views = []
    for i, frame in enumerate(scene.frames):
        f = frame_of.get((scene.token, frame.timestamp))
        g0, g1 = (int(g_ptr[f]), int(g_ptr[f + 1])) if f is not None else (0, 0)
        p0, p1 = (int(p_ptr[f]), int(p_ptr[f + 1])) if f is not None else (0, 0)
        # A class without an achieved threshold has no FP / IDS in the devkit's summary (None), only misses.
        counts = {
            c: {
                "tp": 0,
                "fp": 0 if decisions.thresholds[c] is not None else None,
                "fn": 0,
                "ids": 0 if decisions.thresholds[c] is not None else None,
            }
            for c in evaluated
        }

        # Ground truth: the dataset's boxes, with the evaluator's decision where it evaluated them.
        gt = frame.gt
        g_eval = {decisions.g_id[g]: g for g in range(g0, g1)}
        gt_ids = list(gt.ids) if gt is not None else []
        gt_boxes = gt.boxes[:, [0, 1, 3, 4, 6]] if gt is not None else np.zeros((0, 5))
        gt_cls = [classes[int(lab)] for lab in gt.labels] if gt is not None else []
        gt_state = np.full(len(gt_ids), GT_IGNORED, dtype=np.int64)
        switches, missed = [], []
        for k, gid in enumerate(gt_ids):
            g = g_eval.get(gid)
            if g is None:
                continue
            status = int(decisions.g_status[g])
            gt_state[k] = _GT_STATE[status]
            cls = classes[int(decisions.g_cls[g])]
            if status == MATCH:
                counts[cls]["tp"] += 1
            elif status == SWITCH:
                counts[cls]["ids"] += 1
            else:
                counts[cls]["fn"] += 1
                missed.append({"instance": gid, "class": cls, "xy": [round(float(v), 3) for v in gt_boxes[k, :2]]})
            partner = int(decisions.g_partner[g])
            if partner >= 0:
                track = decisions.p_id[partner]
                if status == SWITCH:
                    switches.append(
                        {
                            "instance": gid,
                            "class": cls,
                            "track_id": track,
                            "previous_track_id": last_partner.get(gid),
                            "xy": [round(float(v), 3) for v in gt_boxes[k, :2]],
                        }
                    )
                last_partner[gid] = track

        # Tracks: the submitted boxes plus the evaluator's interpolated ones (track gaps).
        token = frame.token
        tr_boxes, tr_cls, tr_ids, _ = _sub_boxes(results.get(token, []))
        tr_zh = _sub_zh(results.get(token, []))
        p_eval = {decisions.p_id[p]: p for p in range(p0, p1)}
        tr_state = np.full(len(tr_ids), TR_IGNORED, dtype=np.int64)
        for k, tid in enumerate(tr_ids):
            p = p_eval.pop(tid, None)
            if p is not None:
                tr_state[k] = _TR_STATE[int(decisions.p_status[p])]
            last_box[tid] = np.r_[tr_boxes[k], tr_zh[k]]
        extra = [(tid, p) for tid, p in p_eval.items() if tid in last_box]  # interpolated by the evaluator
        if extra:
            add = np.array([np.r_[decisions.p_xy[p], last_box[tid][2:]] for tid, p in extra])
            tr_boxes = np.vstack([tr_boxes, add[:, :5]])
            tr_zh = np.vstack([tr_zh, add[:, 5:]])
            tr_ids = tr_ids + [tid for tid, _ in extra]
            tr_cls = tr_cls + [classes[int(decisions.p_cls[p])] for _, p in extra]
            tr_state = np.r_[tr_state, [_TR_STATE[int(decisions.p_status[p])] for _, p in extra]]
        false_positives = []
        for p in range(p0, p1):
            if decisions.p_status[p] == MISS_OR_FP:
                cls = classes[int(decisions.p_cls[p])]
                counts[cls]["fp"] += 1
                false_positives.append(
                    {"track_id": decisions.p_id[p], "class": cls, "xy": [round(float(v), 3) for v in decisions.p_xy[p]]}
                )

        trails = update_trails(history, i, tr_ids, tr_boxes, trail_frames)

        det = detections.get(token) if detections is not None else None
        det_boxes = det.boxes[:, [0, 1, 3, 4, 6]] if det is not None and len(det) else np.zeros((0, 5))
        views.append(
            FrameView(
                scene=scene.name,
                index=i,
                sample_token=token,
                timestamp=int(frame.timestamp),
                ego_xy=np.asarray(frame.ego_translation[:2], dtype=np.float64),
                ego_yaw=float(yaw_from_quaternion(frame.ego_rotation)[0]),
                gt_boxes=np.asarray(gt_boxes, dtype=np.float64).reshape(-1, 5),
                gt_state=gt_state,
                gt_cls=gt_cls,
                gt_ids=gt_ids,
                tr_boxes=np.asarray(tr_boxes, dtype=np.float64).reshape(-1, 5),
                tr_state=tr_state,
                tr_cls=tr_cls,
                tr_ids=tr_ids,
                det_boxes=det_boxes,
                trails=trails,
                counts=counts,
                false_positives=false_positives,
                missed=missed,
                id_switches=switches,
                gt_zh=gt.boxes[:, [2, 5]] if gt is not None else np.zeros((0, 2)),
                tr_zh=tr_zh,
                det_zh=det.boxes[:, [2, 5]] if det is not None and len(det) else np.zeros((0, 2)),
                ego_z=float(frame.ego_translation[2]),
            )
        )
    return views


def choose_scenes(scenes: list, names: list[str] | None, worst: int | None, errors, key, what: str) -> list:
    """The ``scenes`` named (``--scene``, in the given order), or the ``worst`` of them by id switches + FP + FN
    (``errors()``: a dict keyed by ``key(scene)``; ties keep the order of ``scenes``); ``what``: "scene" or
    "log", for messages."""
    from grutrack.errors import ConfigError, DatasetError

    by_name = {s.name: s for s in scenes}
    if names:
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise DatasetError(f"--scene {unknown[0]}: not a {what} of this split ({what}s: {', '.join(by_name)})")
        return [by_name[n] for n in dict.fromkeys(names)]
    if worst is None or worst < 1:
        raise ConfigError("--worst must be at least 1")
    counts = errors()
    return sorted(scenes, key=lambda s: -counts.get(key(s), 0))[:worst]


def scene_errors(decisions: MatchDecisions) -> dict:
    """{scene token: id switches + false positives + misses} over the scene's evaluated boxes."""
    tokens = [s for s, _ in decisions.frame_keys]
    bad_g = np.isin(decisions.g_status, (SWITCH, MISS_OR_FP))
    bad_p = decisions.p_status == MISS_OR_FP
    per_frame = np.bincount(decisions.g_frame[bad_g], minlength=len(tokens)) + np.bincount(
        decisions.p_frame[bad_p], minlength=len(tokens)
    )
    out: dict = {}
    for f in range(len(tokens)):
        out[tokens[f]] = out.get(tokens[f], 0) + int(per_frame[f])
    return out
