"""Recall thresholds, per-class metric data and their aggregation (AMOTA, AMOTP, best-MOTA metrics): the
devkit's ``TrackingEvaluation.accumulate`` and ``TrackingEval.evaluate`` on the fast accumulation.

The thresholds come from the scores of the MATCH events without a threshold; their de-duplication, the padding
of unachieved recalls, the worst values when none is achieved, the best-MOTA pick and the AMOTA / AMOTP
averaging follow the devkit. The result is a ``TrackingMetrics`` / ``TrackingMetricDataList`` of
:mod:`grutrack.evaluation.tracking_classes` (the devkit's classes and config, serialised the same way, without
importing the devkit package, whose import alone takes 2-3 s).
"""

from __future__ import annotations

import os
import time

import numpy as np

from grutrack.evaluation.nuscenes_fast.accumulate import ClassAccumulator, NeedsDevkit
from grutrack.evaluation.nuscenes_fast.clear import CLEAR_METRICS, clear_metrics
from grutrack.evaluation.nuscenes_fast.flatten import flatten
from grutrack.evaluation.nuscenes_fast.loading import default_config, load_tracks

__all__ = ["class_metric_data", "evaluate_tracks", "fast_tracking_eval", "summarise"]


def _recall_thresholds(
    scores: np.ndarray, gt_box_count: int, min_recall: float, num_thresholds: int
) -> tuple[list[float], list[float]]:
    """``TrackingEvaluation.compute_thresholds``: (score thresholds, recalls), ``num_thresholds`` each, from the
    highest recall down; NaN thresholds where the recall is not achieved."""
    if len(scores) == 0:
        return [np.nan] * num_thresholds, [np.nan] * num_thresholds
    scores = np.array(scores)
    scores.sort()
    scores = scores[::-1]
    tps = np.array(range(1, len(scores) + 1))
    rec = tps / gt_box_count
    assert len(scores) / gt_box_count <= 1
    max_recall_achieved = np.max(rec)
    rec_interp = np.linspace(min_recall, 1, num_thresholds).round(12)
    thresholds = np.interp(rec_interp, rec, scores, right=0)
    thresholds[rec_interp > max_recall_achieved] = np.nan
    thresholds = list(thresholds.tolist())
    rec_interp = list(rec_interp.tolist())
    thresholds.reverse()
    rec_interp.reverse()
    return thresholds, rec_interp


def class_metric_data(acc: ClassAccumulator, cfg, nelem: int):
    """``TrackingEvaluation.accumulate`` of one class: a ``TrackingMetricData`` (``nelem`` values per metric).

    ``cfg``: what is read of a tracking config, ``min_recall`` and ``metric_worst``. Raises :class:`NeedsDevkit`
    for ground truth the fast path does not model (an id repeated in a frame).
    """
    from grutrack.evaluation.tracking_classes import TrackingMetricData

    md = TrackingMetricData()
    if acc.n_gt == 0:
        return md
    if acc.has_duplicate_gt:
        raise NeedsDevkit()

    all_kept = np.ones(len(acc.ps), dtype=bool)
    scores = acc.match_scores(acc.run_pass(all_kept))
    thresholds, recalls = _recall_thresholds(scores, acc.n_gt, cfg.min_recall, nelem)
    md.confidence = thresholds
    md.recall_hypo = recalls

    distinct = [th for t, th in enumerate(thresholds) if not np.isnan(th) and th not in thresholds[:t]]
    per_threshold = clear_metrics(acc.events([acc.run_pass(acc.ps >= th) for th in distinct])) if distinct else {}

    num_unachieved = len([t for t in thresholds if np.isnan(t)])
    valid = [t for t in thresholds if not np.isnan(t)]
    assert valid == sorted(valid)
    assert num_unachieved + len(valid) - len(np.unique(valid)) + len(distinct) == nelem
    rep_counts = [int(np.sum(np.asarray(thresholds) == t)) for t in np.unique(valid)]

    for name in CLEAR_METRICS:
        if not distinct:
            worst = cfg.metric_worst[name]
            if worst == -1:
                if name == "ml":
                    worst = acc.n_gt_ids
                elif name in ("gt", "fn"):
                    worst = acc.n_gt
                elif name in ("fp", "ids", "frag"):
                    worst = np.nan
                else:
                    raise NotImplementedError
            values = [worst] * nelem
        else:
            per = per_threshold[name].tolist()
            assert len(rep_counts) == len(per)
            values = [np.nan] * num_unachieved
            for v, r in zip(per, rep_counts):
                values.extend([v] * r)
        md.set_metric(name, values)
    return md


def _devkit_class_metric_data(tracks_gt, tracks_pred, class_name: str, cfg, nelem: int):
    """The devkit's own accumulation of one class (inputs the fast path does not model)."""
    from nuscenes.eval.tracking.algo import TrackingEvaluation

    from grutrack.evaluation.tracking_classes import devkit_config

    cfg = devkit_config(cfg)  # sets the devkit's TrackingMetricData.nelem
    ev = TrackingEvaluation(
        tracks_gt,
        tracks_pred,
        class_name,
        cfg.dist_fcn_callable,
        cfg.dist_th_tp,
        cfg.min_recall,
        num_thresholds=nelem,
        metric_worst=cfg.metric_worst,
        verbose=False,
    )
    return ev.accumulate()


def summarise(md_list, cfg):
    """``TrackingEval.evaluate``'s aggregation of per-class metric data: a ``TrackingMetrics`` with each class's
    metrics at its best-MOTA threshold and AMOTA / AMOTP (the mean over thresholds of MOTAR / MOTP, the
    config's worst value where a threshold is not achieved); ``eval_time`` left to the caller."""
    from grutrack.evaluation.tracking_classes import AVG_METRIC_MAP, MOT_METRIC_MAP, TrackingMetrics

    metrics = TrackingMetrics(cfg)
    for class_name in cfg.class_names:
        md = md_list[class_name]
        best = None if np.all(np.isnan(md.mota)) else np.nanargmax(md.mota)
        if best is not None:
            for metric_name in MOT_METRIC_MAP.values():
                if metric_name == "":
                    continue
                metrics.add_label_metric(metric_name, class_name, md.get_metric(metric_name)[best])
        for metric_name, per_threshold in AVG_METRIC_MAP.items():
            values = np.array(md.get_metric(per_threshold))
            if np.all(np.isnan(values)):
                value = np.nan
            else:
                values[np.isnan(values)] = cfg.metric_worst[metric_name]
                value = float(np.nanmean(values))
            metrics.add_label_metric(metric_name, class_name, value)
    return metrics


def evaluate_tracks(tracks_gt, tracks_pred, config=None):
    """The fast equivalent of ``TrackingEval.evaluate`` on tracks from :func:`load_tracks`.

    Returns ``(TrackingMetrics, TrackingMetricDataList)`` (:mod:`grutrack.evaluation.tracking_classes`: the
    devkit's classes without the devkit import, same ``serialize()``), ``eval_time`` this call's seconds. A class
    whose ground truth repeats an id in a frame is accumulated by the devkit's own code.
    """
    from grutrack.evaluation.tracking_classes import TrackingMetricData, TrackingMetricDataList

    start = time.time()
    cfg = config if config is not None else default_config()
    assert cfg.dist_fcn == "center_distance"
    TrackingMetricData.nelem = nelem = cfg.num_thresholds
    md_list = TrackingMetricDataList()

    flat = flatten(tracks_gt, tracks_pred, cfg.class_names)
    for c, class_name in enumerate(cfg.class_names):
        try:
            md = class_metric_data(ClassAccumulator(flat, c, cfg.dist_th_tp), cfg, nelem)
        except NeedsDevkit:
            md = _devkit_class_metric_data(tracks_gt, tracks_pred, class_name, cfg, nelem)
        md_list.set(class_name, md)

    metrics = summarise(md_list, cfg)
    metrics.add_runtime(time.time() - start)
    return metrics, md_list


def fast_tracking_eval(
    nusc,
    submission: dict | str | os.PathLike,
    eval_split: str,
    config=None,
    verbose: bool = False,
    *,
    loader: str = "fast",
) -> dict:
    """Evaluate a nuScenes tracking submission: what ``TrackingEval.main`` writes as ``metrics_summary.json``
    (``TrackingMetrics.serialize()`` plus ``meta``), with the same numbers.

    ``nusc``: a loaded ``NuScenes`` (or the toolkit's tables); ``submission``: the tracking-submission dict
    (``{"meta": ..., "results": {sample_token: [box, ...]}}``) or its JSON file; ``eval_split``: a predefined
    split (``mini_val``, ``val``, ...) or a custom one of ``<dataroot>/<version>/splits.json``; ``config``: a
    devkit ``TrackingConfig`` or :class:`grutrack.evaluation.tracking_classes.TrackingConfig` (default
    ``tracking_nips_2019``); ``verbose``: print the loading messages and the final metrics table; ``loader``:
    see :func:`load_tracks`. ``eval_time`` is the accumulation + metrics time (what the devkit times there too).
    """
    cfg = config if config is not None else default_config()
    tracks_gt, tracks_pred, meta = load_tracks(nusc, submission, eval_split, cfg, verbose=verbose, loader=loader)
    metrics, _ = evaluate_tracks(tracks_gt, tracks_pred, cfg)
    summary = metrics.serialize()
    summary["meta"] = meta.copy()
    if verbose:
        from nuscenes.eval.tracking.utils import print_final_metrics

        print_final_metrics(metrics)
    return summary
