"""The fast exact accumulation inside the nuscenes-devkit's own tracking evaluation.

:class:`FastTrackingEvaluation` is a drop-in for the devkit's per-class accumulation
``nuscenes.eval.tracking.algo.TrackingEvaluation``: the same constructor and ``accumulate() -> TrackingMetricData``
(the devkit's class), computed by :mod:`grutrack.evaluation.nuscenes_fast` instead of a motmetrics accumulator per
recall threshold. :class:`FastTrackingEval` is the devkit's ``TrackingEval`` (its loading, filtering,
aggregation, metric files and plots: the devkit's code) with that accumulation: its ``evaluate`` is the devkit's
own function, run with ``TrackingEvaluation`` bound to :class:`FastTrackingEvaluation` in its namespace. No
module is modified; the devkit's own ``TrackingEval`` is unchanged beside it.

    from grutrack.evaluation.devkit_plugin import FastTrackingEval
    FastTrackingEval(config, result_path, eval_set, output_dir, nusc_version, nusc_dataroot).main()

``grutrack evaluate --evaluator fast`` uses the same accumulation with the toolkit's own loading and aggregation
(:func:`grutrack.evaluation.nuscenes_fast.fast_tracking_eval`), which does not import the devkit (its import
alone takes about 2 s).
"""

from __future__ import annotations

import types
from collections.abc import Callable

from nuscenes.eval.common.utils import center_distance
from nuscenes.eval.tracking import evaluate as _devkit_evaluate
from nuscenes.eval.tracking.algo import TrackingEvaluation
from nuscenes.eval.tracking.data_classes import TrackingMetricData

from grutrack.evaluation.nuscenes_fast import ClassAccumulator, NeedsDevkit, class_metric_data, flatten
from grutrack.evaluation.tracking_classes import TrackingMetricData as ours_md

__all__ = ["FastTrackingEval", "FastTrackingEvaluation"]


class _Settings:
    """What :func:`grutrack.evaluation.nuscenes_fast.class_metric_data` reads of a tracking config."""

    def __init__(self, min_recall: float, metric_worst: dict[str, float]):
        self.min_recall = min_recall
        self.metric_worst = metric_worst


class FastTrackingEvaluation:
    """The per-class accumulation of ``TrackingEvaluation`` (same arguments), exact and fast. Inputs the fast
    path does not model (another distance function than the centre distance, plots of the class asked for,
    ground truth with a repeated id in one frame) are handed to the devkit's own class."""

    def __init__(
        self,
        tracks_gt: dict,
        tracks_pred: dict,
        class_name: str,
        dist_fcn: Callable,
        dist_th_tp: float,
        min_recall: float,
        num_thresholds: int,
        metric_worst: dict[str, float],
        verbose: bool = True,
        output_dir: str | None = None,
        render_classes: list[str] | None = None,
    ):
        self.args = (tracks_gt, tracks_pred, class_name, dist_fcn, dist_th_tp, min_recall)
        self.kwargs = dict(
            num_thresholds=num_thresholds,
            metric_worst=metric_worst,
            verbose=verbose,
            output_dir=output_dir,
            render_classes=render_classes,
        )

    def accumulate(self) -> TrackingMetricData:
        """Metrics of every recall threshold of the class (the devkit's ``TrackingMetricData``)."""
        tracks_gt, tracks_pred, class_name, dist_fcn, dist_th_tp, min_recall = self.args
        kw = self.kwargs
        renders = kw["output_dir"] is not None and class_name in (kw["render_classes"] or [])
        if dist_fcn is not center_distance or renders:
            return self._devkit()
        ours_md.nelem = kw["num_thresholds"]
        acc = ClassAccumulator(flatten(tracks_gt, tracks_pred, [class_name]), 0, dist_th_tp)
        try:
            ours = class_metric_data(acc, _Settings(min_recall, kw["metric_worst"]), kw["num_thresholds"])
        except NeedsDevkit:
            return self._devkit()
        md = TrackingMetricData()
        for name, values in ours.serialize().items():
            md.set_metric(name, values)
        return md

    def _devkit(self) -> TrackingMetricData:
        return TrackingEvaluation(*self.args, **self.kwargs).accumulate()


class FastTrackingEval(_devkit_evaluate.TrackingEval):
    """The devkit's ``TrackingEval`` whose per-class accumulation is :class:`FastTrackingEvaluation`."""

    evaluate = types.FunctionType(
        _devkit_evaluate.TrackingEval.evaluate.__code__,
        {**vars(_devkit_evaluate), "TrackingEvaluation": FastTrackingEvaluation},
        "evaluate",
        _devkit_evaluate.TrackingEval.evaluate.__defaults__,
        _devkit_evaluate.TrackingEval.evaluate.__closure__,
    )
    evaluate.__doc__ = _devkit_evaluate.TrackingEval.evaluate.__doc__
