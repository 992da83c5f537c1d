"""Fast, exact nuScenes tracking evaluation (AMOTA, AMOTP, MOTA, IDS, ... as ``tracking_nips_2019``).

The official evaluation (``nuscenes.eval.tracking.evaluate.TrackingEval`` in nuscenes-devkit 1.2.0) runs a
motmetrics 1.4.0 ``MOTAccumulator`` frame by frame for every class and every one of its 40 recall thresholds,
builds pandas event tables and computes per-object metrics (FRAG, TID, LGD) with one pandas filter per object.
This package gives the same numbers (every entry of ``metrics_summary.json`` and of ``metrics_details.json``),
much faster, one module per stage, each handing the next a data class:

* :mod:`.loading`: ground truth and predictions to tracks exactly as ``TrackingEval.__init__`` (the devkit's
  loaders, filters and ``create_tracks``, re-implemented; the devkit's own for any input it does not
  reproduce);
* :mod:`.flatten`: the tracks as arrays (:class:`~.flatten.FlatBoxes`), frames in the devkit's order;
* :mod:`.accumulate`: one class's motmetrics events at any threshold (:class:`~.accumulate.ClassAccumulator`,
  contested boxes assigned by :mod:`.motmetrics_assignment`), stacked over thresholds as
  :class:`~.clear.ThresholdEvents`;
* :mod:`.clear`: the per-threshold metrics of a class, thresholds as an array axis;
* :mod:`.amota`: recall thresholds, per-class metric data, AMOTA / AMOTP and the best-MOTA metrics
  (``TrackingMetrics`` / ``TrackingMetricDataList`` of :mod:`grutrack.evaluation.tracking_classes`);
* :mod:`.decisions`: the decision behind every counted TP, FP, FN and IDS, box by box.

Public entry points: :func:`fast_tracking_eval` (the ``metrics_summary.json`` dict), :func:`load_tracks`,
:func:`evaluate_tracks` (accumulation and metrics on loaded tracks) and :func:`match_decisions` (what
``grutrack render`` draws). :mod:`grutrack.evaluation.devkit_plugin` runs :class:`ClassAccumulator` and
:func:`class_metric_data` inside the devkit's own ``TrackingEval``.
"""

from __future__ import annotations

from grutrack.evaluation.nuscenes_fast.accumulate import ClassAccumulator, NeedsDevkit, exact_center_distances
from grutrack.evaluation.nuscenes_fast.amota import class_metric_data, evaluate_tracks, fast_tracking_eval
from grutrack.evaluation.nuscenes_fast.decisions import (
    BELOW_THRESHOLD,
    MATCH,
    MISS_OR_FP,
    SWITCH,
    UNSCORED,
    MatchDecisions,
    match_decisions,
)
from grutrack.evaluation.nuscenes_fast.flatten import FlatBoxes, flatten
from grutrack.evaluation.nuscenes_fast.loading import load_tracks

__all__ = [
    "fast_tracking_eval",
    "load_tracks",
    "evaluate_tracks",
    "exact_center_distances",
    "match_decisions",
    "MatchDecisions",
    "MATCH",
    "SWITCH",
    "MISS_OR_FP",
    "BELOW_THRESHOLD",
    "UNSCORED",
    "ClassAccumulator",
    "NeedsDevkit",
    "FlatBoxes",
    "class_metric_data",
    "flatten",
]
