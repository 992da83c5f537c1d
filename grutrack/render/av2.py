"""Render an Argoverse 2 tracking pickle: run the official AV2 tracking evaluation, replay its final CLEAR
matching frame by frame, pick logs, draw them and write ``counts.json``.

The decisions are the official evaluator's (``av2.evaluation.tracking.eval.evaluate``, as ``grutrack evaluate
--dataset av2`` runs it): labels and tracks within ``max_range_m`` of the ego and, when every log has its map, on
the drivable area; tracks at or above their class's tuned score threshold (HOTA objective); per class, TrackEval's
CLEAR matching on the centre-distance similarity ``max(0, 1 - d / 2 m) >= 0.5`` (a match within 1 m), replayed by
:mod:`grutrack.evaluation.clear_frames` on the very inputs of the final evaluation. As in CLEAR, an id-switch
match is also a TP. ``per_class`` of ``counts.json`` (sums over the rendered logs) is the metrics JSON's
``tp`` / ``fp`` / ``fn`` / ``ids`` (CLR_TP, CLR_FP, CLR_FN, IDSW) when every log is rendered.

``counts.json`` has the nuScenes render's layout (:mod:`grutrack.render.nuscenes`) with ``"dataset": "av2"``,
``rate_hz``, ``max_range_m``, ``drivable_area_roi``, and ``thresholds`` the tuned score threshold per category;
a scene is a log (``name`` and ``token`` the log id), a frame's ``sample_token`` is ``<log_id>:<timestamp_ns>``
and its ``timestamp`` is in microseconds.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grutrack.errors import DatasetError
from grutrack.io import write_json_atomic
from grutrack.render.records import scene_record
from grutrack.render.views import (
    COUNT_KEYS,
    GT_IGNORED,
    GT_MATCH,
    GT_MISS,
    GT_SWITCH,
    TR_BELOW,
    TR_FP,
    TR_IGNORED,
    TR_MATCH,
    TR_SWITCH,
    FrameView,
    choose_scenes,
    update_trails,
)

MATCHING = (
    "official AV2 tracking evaluation (av2.evaluation.tracking.eval.evaluate, HOTA objective): per class "
    "at its tuned score threshold, TrackEval CLEAR on centre distance (similarity 1 - d/2 m >= 0.5, i.e. "
    "within 1 m), replayed per frame; an id-switch match is also a TP"
)


def notes(max_range_m: int, roi: bool) -> tuple[str, ...]:
    """The text panel's lines on the matching (lines of at most 36 characters)."""
    where = f"beyond {max_range_m} m" + (", off the drivable" if roi else "")
    return (
        "TP includes id-switch matches",
        "     (CLEAR)",
        "thr: tuned track-score threshold",
        "     (official, HOTA objective)",
        "match: centres within 1 m",
        f"grey: {where}",
        ("      area, or below thr" if roi else "      or below thr"),
    )


@dataclass
class Av2Evaluation:
    """One official evaluation and its per-frame decisions.

    scenes: the split's logs (ego poses); labels / predictions: the submitted label and track frames
    ({log: [frame dict, ...]}, before any filtering); final: the evaluator's final inputs
    (:func:`grutrack.evaluation.av2_eval.evaluate_sequences` ``keep_inputs``); decisions: {log: {class:
    [StepDecisions per frame]}}; sequences: {log: {class: ClassSequence}}; official: {class: {tp, fp, fn, ids}}
    of the official result.
    """

    scenes: list
    labels: dict
    predictions: dict
    final: dict
    sequences: dict
    decisions: dict
    official: dict
    roi: bool
    rate_hz: float | None
    max_range_m: int

    @property
    def thresholds(self) -> dict:
        return self.final["thresholds"]

    @property
    def classes(self) -> list:
        return self.final["classes"]


def load_evaluation(
    root: str | Path,
    split: str,
    submission: str | Path,
    *,
    rate_hz: float | None = 2.0,
    max_range_m: int = 50,
    workers: int = 1,
) -> Av2Evaluation:
    """Evaluate ``submission`` with the official evaluator and replay its final CLEAR matching per frame.

    Raises InputFormatError / DatasetError (exit 2) for a missing or malformed pickle, one of other frames or
    logs, or an unknown split. The replay's sums are checked against the official CLEAR counts.
    """
    from grutrack.evaluation.av2_eval import evaluate_sequences, load_submission, metrics_from_result
    from grutrack.evaluation.clear_frames import official_sequence_data

    scenes, labels, preds, ddir, roi = load_submission(root, split, submission, rate_hz=rate_hz)
    out = evaluate_sequences(
        preds, labels, ddir if roi else None, max_range_m=max_range_m, workers=workers, keep_inputs=True
    )
    final = out["final"]
    seqs = official_sequence_data(final["labels"], final["predictions"], final["classes"])
    decisions = {
        log: {c: s.decisions(final["similarity_threshold"]) for c, s in by_cls.items()} for log, by_cls in seqs.items()
    }
    _, per_class = metrics_from_result(out)
    official = {c: {k: per_class[c][k] for k in COUNT_KEYS} for c in final["classes"]}
    ev = Av2Evaluation(scenes, labels, preds, final, seqs, decisions, official, roi, rate_hz, max_range_m)
    replay = class_sums(ev, list(decisions))
    if replay != official:  # a bug, not bad input: the replay must be the evaluator's own matching
        bad = next(c for c in official if replay[c] != official[c])
        raise RuntimeError(f"CLEAR replay differs from the official counts for {bad}: {replay[bad]} vs {official[bad]}")
    return ev


def class_sums(ev: Av2Evaluation, logs: list[str]) -> dict:
    """{class: {tp, fp, fn, ids}} of the replayed decisions summed over ``logs`` (every class evaluated)."""
    out = {c: dict.fromkeys(COUNT_KEYS, 0) for c in ev.classes}
    for log in logs:
        for c, steps in ev.decisions[log].items():
            for st in steps:
                for k, v in st.counts().items():
                    out[c][k] += v
    return out


def scene_errors(ev: Av2Evaluation) -> dict:
    """{log id: id switches + false positives + misses} of the replayed decisions."""
    sums = {log: class_sums(ev, [log]) for log in ev.decisions}
    return {log: sum(k["ids"] + k["fp"] + k["fn"] for k in s.values()) for log, s in sums.items()}


def select_scenes(ev: Av2Evaluation, names: list[str] | None, worst: int | None) -> list:
    """The logs named (in the given order), or the ``worst`` logs by id switches + FP + FN (ties: log id)."""
    logs = sorted(ev.scenes, key=lambda s: s.name)
    return choose_scenes(logs, names, worst, lambda: scene_errors(ev), lambda s: s.name, "log")


def _boxes(frame: dict) -> np.ndarray:
    """A label / track frame dict -> ``(N, 5) [x, y, w, l, yaw]`` float64, city frame (``size`` is l, w, h)."""
    t = np.asarray(frame["translation_m"], dtype=np.float64).reshape(-1, 3)
    size = np.asarray(frame["size"], dtype=np.float64).reshape(-1, 3)
    return np.column_stack([t[:, :2], size[:, 1], size[:, 0], np.asarray(frame["yaw"], dtype=np.float64)])


def _zh(frame: dict) -> np.ndarray:
    """A label / track frame dict -> ``(N, 2) [z of the centre, height]`` metres."""
    t = np.asarray(frame["translation_m"], dtype=np.float64).reshape(-1, 3)
    return np.column_stack([t[:, 2], np.asarray(frame["size"], dtype=np.float64).reshape(-1, 3)[:, 2]])


def _plain(x):
    """A track id as JSON holds it (numpy scalars -> int / str)."""
    return x.item() if isinstance(x, np.generic) else x


def _row_of(frame: dict) -> dict:
    return {_plain(t): r for r, t in enumerate(np.asarray(frame["track_id"]).tolist())}


def _frame_decisions(ev: Av2Evaluation, log: str, i: int):
    """One frame's decisions mapped onto the rows of the final label / track frames.

    Returns (gt_state, gt_track, gt_prev, tr_state, counts) with gt_* indexed by the final label frame's rows,
    tr_state by the final track frame's rows; gt_track: the row of the matched track or -1; gt_prev: the track
    id a switching GT was matched to before (None otherwise).
    """
    lab = ev.final["labels"][log][i]
    prd = ev.final["predictions"][log][i]
    gt_state = np.full(len(lab["track_id"]), GT_MISS, dtype=np.int64)
    gt_track = np.full(len(lab["track_id"]), -1, dtype=np.int64)
    gt_prev: list = [None] * len(lab["track_id"])
    tr_state = np.full(len(prd["track_id"]), TR_FP, dtype=np.int64)
    counts = {}
    for cls, steps in ev.decisions[log].items():
        seq, st = ev.sequences[log][cls], steps[i]
        g_rows, t_rows = seq.gt_rows[i], seq.tracker_rows[i]
        if len(g_rows) == 0 and len(t_rows) == 0:
            continue
        counts[cls] = st.counts()
        hit = st.gt_track >= 0
        gt_state[g_rows[hit]] = np.where(st.gt_switch[hit], GT_SWITCH, GT_MATCH)
        gt_track[g_rows[hit]] = t_rows[st.gt_track[hit]]
        for g in np.flatnonzero(st.gt_switch):
            gt_prev[g_rows[g]] = _plain(seq.tracker_names[st.gt_previous[g]])
        switched_tracks = set(st.gt_track[st.gt_switch].tolist())
        tr_state[t_rows[st.track_matched]] = TR_MATCH
        for k in switched_tracks:
            tr_state[t_rows[k]] = TR_SWITCH
    return gt_state, gt_track, gt_prev, tr_state, counts


def build_views(ev: Av2Evaluation, scene, detections: dict | None = None, trail_frames: int = 6) -> list[FrameView]:
    """The frames of one log with the official evaluation's decisions (boxes in the city frame)."""
    from grutrack.boxes import yaw_from_quaternion
    from grutrack.data.av2 import token_timestamp_ns

    log = scene.name
    history: dict = {}
    views = []
    # a frame's per-class counts list the classes with any decision in the split (not all 26 categories)
    shown = [c for c, k in class_sums(ev, list(ev.decisions)).items() if any(k.values())]
    for i, frame in enumerate(scene.frames):
        lab_all, prd_all = ev.labels[log][i], ev.predictions[log][i]
        lab_fin, prd_fin = ev.final["labels"][log][i], ev.final["predictions"][log][i]
        assert lab_all["timestamp_ns"] == token_timestamp_ns(frame.token) == prd_all["timestamp_ns"]
        gt_state_f, gt_track_f, gt_prev_f, tr_state_f, counts = _frame_decisions(ev, log, i)
        counts = {c: counts.get(c, dict.fromkeys(COUNT_KEYS, 0)) for c in shown}

        # ground truth: every label of the frame; the evaluated ones (in range / ROI) carry a decision
        gt_ids = [_plain(t) for t in np.asarray(lab_all["track_id"]).tolist()]
        gt_cls = [str(n) for n in lab_all["name"]]
        gt_boxes = _boxes(lab_all)
        g_fin = _row_of(lab_fin)
        p_fin = _row_of(prd_fin)
        prd_ids_fin = [_plain(t) for t in np.asarray(prd_fin["track_id"]).tolist()]
        gt_state = np.full(len(gt_ids), GT_IGNORED, dtype=np.int64)
        switches, missed = [], []
        for k, gid in enumerate(gt_ids):
            g = g_fin.get(gid)
            if g is None:
                continue
            gt_state[k] = gt_state_f[g]
            xy = [round(float(v), 3) for v in gt_boxes[k, :2]]
            if gt_state[k] == GT_MISS:
                missed.append({"instance": gid, "class": gt_cls[k], "xy": xy})
            elif gt_state[k] == GT_SWITCH:
                switches.append(
                    {
                        "instance": gid,
                        "class": gt_cls[k],
                        "track_id": prd_ids_fin[gt_track_f[g]],
                        "previous_track_id": gt_prev_f[g],
                        "xy": xy,
                    }
                )

        # tracks: every submitted box; the scored ones carry a decision, the others are below their class's
        # threshold or outside the range / drivable area
        tr_ids = [_plain(t) for t in np.asarray(prd_all["track_id"]).tolist()]
        tr_cls = [str(n) for n in prd_all["name"]]
        tr_boxes = _boxes(prd_all)
        scores = np.asarray(prd_all["score"], dtype=np.float64)
        tr_state = np.full(len(tr_ids), TR_IGNORED, dtype=np.int64)
        false_positives = []
        for k, tid in enumerate(tr_ids):
            p = p_fin.get(tid)
            if p is not None:
                tr_state[k] = tr_state_f[p]
                if tr_state[k] == TR_FP:
                    false_positives.append(
                        {"track_id": tid, "class": tr_cls[k], "xy": [round(float(v), 3) for v in tr_boxes[k, :2]]}
                    )
            elif scores[k] < ev.thresholds.get(tr_cls[k], 0.0):
                tr_state[k] = TR_BELOW
        trails = update_trails(history, i, tr_ids, tr_boxes, trail_frames)

        det = detections.get(frame.token) if detections is not None else None
        det_boxes = det.boxes[:, [0, 1, 3, 4, 6]] if det is not None and len(det) else np.zeros((0, 5))
        ts_ns = token_timestamp_ns(frame.token)
        views.append(
            FrameView(
                scene=log,
                index=i,
                sample_token=frame.token,
                timestamp=int(frame.timestamp),
                ego_xy=np.asarray(frame.ego_translation[:2], dtype=np.float64),
                ego_yaw=float(yaw_from_quaternion(frame.ego_rotation)[0]),
                gt_boxes=gt_boxes,
                gt_state=gt_state,
                gt_cls=gt_cls,
                gt_ids=gt_ids,
                tr_boxes=tr_boxes,
                tr_state=tr_state,
                tr_cls=tr_cls,
                tr_ids=tr_ids,
                det_boxes=det_boxes,
                trails=trails,
                counts=counts,
                false_positives=false_positives,
                missed=missed,
                id_switches=switches,
                caption=f"ts {ts_ns}\n{log}",
                gt_zh=_zh(lab_all),
                tr_zh=_zh(prd_all),
                det_zh=det.boxes[:, [2, 5]] if det is not None and len(det) else np.zeros((0, 2)),
                ego_z=float(frame.ego_translation[2]),
            )
        )
    return views


def render_av2(
    root: str | Path,
    split: str,
    submission: str | Path,
    out: str | Path,
    scene_names: list[str] | None = None,
    worst: int | None = None,
    detections: str | None = None,
    animation: bool = True,
    rerun: bool = False,
    rate_hz: float | None = 2.0,
    max_range_m: int = 50,
    workers: int = 1,
) -> dict:
    """Render the chosen logs into ``out`` and write ``out/counts.json``; returns that document."""
    from grutrack.render.draw import TRAIL_FRAMES, BevCanvas, render_scene

    t_start = time.perf_counter()
    if scene_names:  # before the evaluation: a wrong name fails at once
        from grutrack.data.av2 import list_logs

        logs = list_logs(root, split)
        unknown = [n for n in scene_names if n not in logs]
        if unknown:
            raise DatasetError(f"--scene {unknown[0]}: not a log of split '{split}' (logs: {', '.join(logs)})")
    ev = load_evaluation(root, split, submission, rate_hz=rate_hz, max_range_m=max_range_m, workers=workers)
    chosen = select_scenes(ev, scene_names, worst)
    det = None
    if detections:
        from grutrack.data.av2 import vocabulary
        from grutrack.data.lt3d_detections import load_detections

        det, _ = load_detections(detections, root, split, ev.scenes, vocabulary(all_categories=True))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    canvas = BevCanvas(thresholds=ev.thresholds, notes=notes(max_range_m, ev.roi))
    errors = scene_errors(ev)
    scene_docs = []
    for scene in chosen:
        views = build_views(ev, scene, det, trail_frames=TRAIL_FRAMES)
        pngs, gif = render_scene(views, out, ev.thresholds, canvas, animation=animation)
        scene_docs.append(scene_record(scene, errors.get(scene.name, 0), views, pngs, gif, out, rerun))
    doc = {
        "dataset": "av2",
        "version": "sensor",
        "split": split,
        "submission": str(submission),
        "detections": str(detections) if detections else None,
        "thresholds": ev.thresholds,
        "rate_hz": rate_hz,
        "max_range_m": int(max_range_m),
        "drivable_area_roi": ev.roi,
        "matching": MATCHING,
        "scenes": scene_docs,
        "per_class": class_sums(ev, [s.name for s in chosen]),
        "seconds": round(time.perf_counter() - t_start, 3),
    }
    write_json_atomic(out / "counts.json", doc, indent=1)
    return doc


def render_dataset(dataset, split: str, submission: str | Path, out: str | Path, **options) -> dict:
    """:func:`render_av2` for a :class:`grutrack.datasets.av2.AV2Dataset` (its dataroot and frame rate)."""
    return render_av2(dataset.options.dataroot, split, submission, out, rate_hz=dataset.options.rate_hz, **options)
