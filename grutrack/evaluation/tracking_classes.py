"""The nuScenes tracking-evaluation data classes the fast evaluator fills, without importing the devkit.

``nuscenes.eval.tracking.data_classes`` (devkit 1.2.0) cannot be imported without the package's ``__init__``,
which imports ``NuScenes`` and with it matplotlib, OpenCV and scikit-learn (2-3 s, more than the fast
evaluation itself). These classes hold and serialise the same values the same way (``serialize()`` gives the
devkit's ``metrics_summary.json`` / ``metrics_details.json`` content, value types included); the configuration
is read from the devkit's own ``tracking_nips_2019.json``. tests/test_tracking_classes.py compares them with the
devkit's. The devkit's classes are accepted wherever these are (same attributes).
"""

from __future__ import annotations

import functools
import importlib.util
import json
from pathlib import Path
from typing import Any

import numpy as np

# nuscenes/eval/tracking/constants.py (devkit 1.2.0)
AMOT_METRICS = ["amota", "amotp"]
INTERNAL_METRICS = ["recall", "motar", "gt"]
LEGACY_METRICS = ["mota", "motp", "mt", "ml", "faf", "tp", "fp", "fn", "ids", "frag", "tid", "lgd"]
TRACKING_METRICS = [*AMOT_METRICS, *INTERNAL_METRICS, *LEGACY_METRICS]
AVG_METRIC_MAP = {"amota": "motar", "amotp": "motp"}
MOT_METRIC_MAP = {
    "num_frames": "",
    "num_objects": "gt",
    "pred_frequencies": "",
    "num_predictions": "",
    "num_matches": "tp",
    "motar": "motar",
    "mota_custom": "mota",
    "motp_custom": "motp",
    "faf": "faf",
    "mostly_tracked": "mt",
    "mostly_lost": "ml",
    "num_false_positives": "fp",
    "num_misses": "fn",
    "num_switches": "ids",
    "num_fragmentations_custom": "frag",
    "recall": "recall",
    "tid": "tid",
    "lgd": "lgd",
}
#: per-threshold metrics of TrackingMetricData, in the devkit's order (a list built from a set there: the order
#: of that set in this interpreter, so serialised keys come out in the same order as the devkit's)
MD_METRICS = [m for m in list(set(TRACKING_METRICS) - set(AMOT_METRICS))]


def devkit_package_dir() -> Path:
    """The installed ``nuscenes`` package folder, located without importing it."""
    spec = importlib.util.find_spec("nuscenes")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("nuscenes-devkit is not installed")
    return Path(next(iter(spec.submodule_search_locations)))


class TrackingConfig:
    """The devkit's ``TrackingConfig`` fields, read from its JSON (``tracking_nips_2019`` by default)."""

    FIELDS = (
        "tracking_names",
        "pretty_tracking_names",
        "tracking_colors",
        "class_range",
        "dist_fcn",
        "dist_th_tp",
        "min_recall",
        "max_boxes_per_sample",
        "metric_worst",
        "num_thresholds",
    )

    def __init__(self, content: dict[str, Any]):
        for key in self.FIELDS:
            setattr(self, key, content[key])
        assert set(self.class_range) == set(self.tracking_names), "Class count mismatch."
        self.class_names = sorted(self.class_range.keys())

    def serialize(self) -> dict:
        return {key: getattr(self, key) for key in self.FIELDS}

    @property
    def dist_fcn_callable(self):
        """The devkit's distance function (imports the devkit: used only by its fallback accumulation)."""
        return devkit_config(self).dist_fcn_callable


@functools.cache
def _config_content(name: str) -> str:
    task = name.split("_")[0]
    return (devkit_package_dir() / "eval" / task / "configs" / f"{name}.json").read_text()


def load_config(name: str = "tracking_nips_2019") -> TrackingConfig:
    """The devkit's named tracking configuration, without the devkit import (``config_factory(name)``)."""
    return TrackingConfig(json.loads(_config_content(name)))


def devkit_config(cfg):
    """The devkit's own ``TrackingConfig`` for ``cfg`` (for its fallback paths); constructing it also sets the
    devkit's module globals (``TRACKING_NAMES``, ``TrackingMetricData.nelem``) as a fresh evaluation would."""
    from nuscenes.eval.tracking.data_classes import TrackingConfig as DevkitConfig

    return DevkitConfig.deserialize(cfg.serialize())


class TrackingMetricData:
    """Per-threshold metric arrays of one class (the devkit's ``TrackingMetricData``); ``nelem`` from the
    configuration's ``num_thresholds``."""

    nelem = 40

    def __init__(self):
        init = np.full(TrackingMetricData.nelem, np.nan)
        for name in ["confidence", "recall_hypo", *MD_METRICS]:
            self.set_metric(name, init)

    def __setattr__(self, name, values):
        values = np.array(values)
        assert len(values) == TrackingMetricData.nelem
        super().__setattr__(name, values)

    def set_metric(self, metric_name: str, values) -> None:
        self.__setattr__(metric_name, values)

    def get_metric(self, metric_name: str) -> np.ndarray:
        return self.__getattribute__(metric_name)

    def serialize(self) -> dict:
        return {name: self.get_metric(name).tolist() for name in ["confidence", "recall_hypo", *MD_METRICS]}


class TrackingMetricDataList:
    """Class name -> :class:`TrackingMetricData` (the devkit's ``TrackingMetricDataList``)."""

    def __init__(self):
        self.md: dict[str, Any] = {}

    def __getitem__(self, key):
        return self.md[key]

    def set(self, tracking_name: str, data) -> None:
        self.md[tracking_name] = data

    def serialize(self) -> dict:
        return {key: value.serialize() for key, value in self.md.items()}


class TrackingMetrics:
    """Per-class metrics and their class averages/sums (the devkit's ``TrackingMetrics``)."""

    def __init__(self, cfg):
        self.cfg = cfg
        self.eval_time = None
        self.class_names = cfg.class_names
        self.metric_names = list(TRACKING_METRICS)
        self.label_metrics: dict[str, dict[str, float]] = {
            m: {c: np.nan for c in self.class_names} for m in self.metric_names
        }

    def add_label_metric(self, metric_name: str, tracking_name: str, value: float) -> None:
        assert metric_name in self.label_metrics
        self.label_metrics[metric_name][tracking_name] = float(value)

    def add_runtime(self, eval_time: float) -> None:
        self.eval_time = eval_time

    def compute_metric(self, metric_name: str, class_name: str = "all") -> float:
        if class_name != "all":
            return float(self.label_metrics[metric_name][class_name])
        data = list(self.label_metrics[metric_name].values())
        if not data:
            return np.nan
        if metric_name in ("mt", "ml", "tp", "fp", "fn", "ids", "frag"):
            return float(np.nansum(data))  # counts are summed over classes, NaN ignored
        if np.all(np.isnan(np.asarray(data, dtype=np.float64))):
            return np.nan  # no class has a value: NaN, as the devkit's mean of an empty slice (without its warning)
        return float(np.nanmean(data))

    def serialize(self) -> dict[str, Any]:
        metrics: dict[str, Any] = {
            "label_metrics": self.label_metrics,
            "eval_time": self.eval_time,
            "cfg": self.cfg.serialize(),
        }
        for metric_name in self.label_metrics:
            metrics[metric_name] = self.compute_metric(metric_name)
        return metrics
