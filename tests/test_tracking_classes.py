"""The devkit-free tracking-evaluation classes and box helpers against nuscenes-devkit's own."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from grutrack.evaluation import tracking_classes as tc
from grutrack.evaluation.nuscenes_fast.loading import _box_corners, _points_in_box


def test_config_and_constants_equal_the_devkits():
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking import constants, data_classes

    ref, ours = config_factory("tracking_nips_2019"), tc.load_config("tracking_nips_2019")
    assert ours.serialize() == ref.serialize() and ours.class_names == ref.class_names
    assert ours.num_thresholds == 40 and len(ours.class_names) == 7
    assert ours.dist_fcn_callable is ref.dist_fcn_callable
    assert (tc.TRACKING_METRICS, tc.AMOT_METRICS, tc.AVG_METRIC_MAP, tc.MOT_METRIC_MAP) == (
        constants.TRACKING_METRICS,
        constants.AMOT_METRICS,
        constants.AVG_METRIC_MAP,
        constants.MOT_METRIC_MAP,
    )
    assert tc.MD_METRICS == data_classes.TrackingMetricData.metrics


def test_metric_classes_serialise_as_the_devkits():
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking import data_classes as dc

    cfg = config_factory("tracking_nips_2019")
    rng = np.random.default_rng(0)
    ours_m, ref_m = tc.TrackingMetrics(tc.load_config()), dc.TrackingMetrics(cfg)
    ours_l, ref_l = tc.TrackingMetricDataList(), dc.TrackingMetricDataList()
    for c, name in enumerate(cfg.class_names):
        o, r = tc.TrackingMetricData(), dc.TrackingMetricData()
        ints = rng.integers(0, 50, 40).tolist()  # counts stay ints in metrics_details.json
        mota = [np.nan] * 3 + rng.random(37).tolist() if c % 2 else [0.5] * 40
        for md in (o, r):
            md.set_metric("tp", ints)
            md.set_metric("mota", mota)
        ours_l.set(name, o)
        ref_l.set(name, r)
        for metric in ("amota", "mota", "tp", "ids"):
            value = np.nan if (c == 2 and metric == "ids") else float(rng.random())
            ours_m.add_label_metric(metric, name, value)
            ref_m.add_label_metric(metric, name, value)
    ours_m.add_runtime(1.5)
    ref_m.add_runtime(1.5)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # a class with no value: NaN, without numpy's warning
        ours = json.dumps(ours_m.serialize())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the devkit's "Mean of empty slice" for the same NaN
        assert ours == json.dumps(ref_m.serialize())
    assert json.dumps(ours_l.serialize()) == json.dumps(ref_l.serialize())
    with pytest.raises(AssertionError):
        tc.TrackingMetricData().set_metric("mota", [0.0] * 39)


def test_box_helpers_equal_the_devkits():
    from nuscenes.utils.data_classes import Box
    from nuscenes.utils.geometry_utils import points_in_box
    from pyquaternion import Quaternion

    rng = np.random.default_rng(1)
    inside = 0
    for _ in range(200):
        center = (rng.normal(0, 500, 3)).tolist()
        size = rng.uniform(0.3, 4.0, 3).tolist()
        q = rng.normal(size=4)
        rotation = (q / np.linalg.norm(q) * rng.uniform(0.99, 1.01)).tolist()
        box = Box(center, size, Quaternion(rotation))
        corners = _box_corners(center, size, rotation)
        np.testing.assert_array_equal(corners, box.corners())
        pts = np.asarray(center)[:, None] + rng.normal(0, 1.5, (3, 20))
        mask = _points_in_box(corners, pts)
        np.testing.assert_array_equal(mask, points_in_box(box, pts))
        inside += int(mask.sum())
    assert 0 < inside < 4000
