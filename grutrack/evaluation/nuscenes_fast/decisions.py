"""Per-box decisions of the tracking evaluation: the event behind every counted TP, FP, FN and IDS, at each
class's best-MOTA threshold (what ``grutrack render`` draws)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from grutrack.evaluation.nuscenes_fast.accumulate import ClassAccumulator, NeedsDevkit
from grutrack.evaluation.nuscenes_fast.amota import class_metric_data, summarise
from grutrack.evaluation.nuscenes_fast.flatten import flatten
from grutrack.evaluation.nuscenes_fast.loading import default_config

__all__ = ["BELOW_THRESHOLD", "MATCH", "MISS_OR_FP", "SWITCH", "UNSCORED", "MatchDecisions", "match_decisions"]

#: decision codes of :class:`MatchDecisions` (GT and prediction boxes)
MATCH, SWITCH, MISS_OR_FP, BELOW_THRESHOLD, UNSCORED = 0, 1, 2, 3, 4


@dataclass
class MatchDecisions:
    """The evaluator's own decision for every evaluated box, at each class's best-MOTA threshold.

    Boxes are those the metrics read (after the class-range / zero-point filter and, for predictions, the
    track-gap interpolation), in the devkit's frame order. Decision codes: ``MATCH`` (TP), ``SWITCH`` (matched,
    counted as an id switch, not a TP), ``MISS_OR_FP`` (GT: missed, FN; prediction: kept but unmatched, FP),
    ``BELOW_THRESHOLD`` (prediction whose track score is under its class's threshold: not scored) and
    ``UNSCORED`` (every box of a class for which no threshold is achieved: the devkit reports TP 0, FN = GT
    and no FP / IDS; its GT are still counted as misses, code ``MISS_OR_FP``).

    frame_keys: (scene token, timestamp in microseconds) of every frame index.
    g_frame, g_cls, g_status: (G,) int64; g_id: (G,) tracking ids (instance tokens); g_xy: (G, 2) float64,
    global frame, metres. p_frame, p_cls, p_status: (P,) int64; p_id: (P,) track ids; p_xy: (P, 2) float64,
    metres; p_score: (P,) float64 track score (mean box score of the track, as the devkit computes it).
    g_partner: (G,) int64 index of the matched prediction, -1 if none.
    thresholds: {class: best-MOTA threshold, or None when the class has none}.
    """

    frame_keys: list[tuple[Any, Any]]
    g_frame: np.ndarray
    g_cls: np.ndarray
    g_id: list[Any]
    g_xy: np.ndarray
    g_status: np.ndarray
    g_partner: np.ndarray
    p_frame: np.ndarray
    p_cls: np.ndarray
    p_id: list[Any]
    p_xy: np.ndarray
    p_score: np.ndarray
    p_status: np.ndarray
    thresholds: dict[str, Any]
    class_names: list[str]


def match_decisions(tracks_gt, tracks_pred, config=None):
    """Per-box decisions of the tracking evaluation (what
    :func:`~grutrack.evaluation.nuscenes_fast.amota.evaluate_tracks` counts at each class's best-MOTA
    threshold): summing them per class gives the summary's TP, FP, FN and IDS exactly.

    One accumulation per class gives both. Returns ``(MatchDecisions, TrackingMetrics)``, the metrics those of
    ``evaluate_tracks`` (``eval_time`` this call's seconds). Raises ValueError for ground truth the fast path
    does not model (an id repeated in a frame).
    """
    from grutrack.evaluation.tracking_classes import TrackingMetricData, TrackingMetricDataList

    start = time.time()
    cfg = config if config is not None else default_config()
    assert cfg.dist_fcn == "center_distance"
    TrackingMetricData.nelem = nelem = cfg.num_thresholds
    md_list = TrackingMetricDataList()
    flat = flatten(tracks_gt, tracks_pred, cfg.class_names)
    g_status = np.full(len(flat.g_frame), MISS_OR_FP, dtype=np.int64)
    g_partner = np.full(len(flat.g_frame), -1, dtype=np.int64)
    p_status = np.full(len(flat.p_frame), UNSCORED, dtype=np.int64)
    thresholds: dict[str, Any] = {}
    for c, class_name in enumerate(cfg.class_names):
        acc = ClassAccumulator(flat, c, cfg.dist_th_tp)
        try:
            md = class_metric_data(acc, cfg, nelem)
        except NeedsDevkit as exc:
            raise ValueError(
                f"ground truth with a repeated id in one frame (class {class_name}): per-box "
                "decisions are not available"
            ) from exc
        md_list.set(class_name, md)
        thresholds[class_name] = None
        if acc.n_gt == 0 or np.all(np.isnan(md.mota)):
            continue
        threshold = md.confidence[int(np.nanargmax(md.mota))]
        if threshold is None or np.isnan(threshold):
            continue
        thresholds[class_name] = float(threshold)
        kept = acc.ps >= threshold
        res = acc.run_pass(kept)  # the best threshold's pass, already run (cached)
        gi = np.flatnonzero(flat.g_cls == c)
        pi = np.flatnonzero(flat.p_cls == c)
        p_status[pi] = np.where(kept, MISS_OR_FP, BELOW_THRESHOLD)
        g_status[gi[res.g]] = np.where(res.switch, SWITCH, MATCH)
        p_status[pi[res.p]] = np.where(res.switch, SWITCH, MATCH)
        g_partner[gi[res.g]] = pi[res.p]
    metrics = summarise(md_list, cfg)
    metrics.add_runtime(time.time() - start)
    decisions = MatchDecisions(
        frame_keys=flat.frame_keys,
        g_frame=flat.g_frame,
        g_cls=flat.g_cls,
        g_id=[flat.obj_raw_id[o] for o in flat.g_obj.tolist()],
        g_xy=flat.g_xy,
        g_status=g_status,
        g_partner=g_partner,
        p_frame=flat.p_frame,
        p_cls=flat.p_cls,
        p_id=flat.p_raw_id,
        p_xy=flat.p_xy,
        p_score=flat.p_score,
        p_status=p_status,
        thresholds=thresholds,
        class_names=list(cfg.class_names),
    )
    return decisions, metrics
