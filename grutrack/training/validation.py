"""Validation during training: track a split with the current network and score it (AMOTA)."""

from __future__ import annotations

import contextlib
import io

import numpy as np

from grutrack.classes import TRACKING_CLASSES
from grutrack.data.scene import BoxSet, Scene
from grutrack.export.nuscenes_json import build_submission
from grutrack.tracking.config import TrackerConfig
from grutrack.tracking.factory import network_groups
from grutrack.tracking.tracker import Tracker, track_scenes


def make_validator(nusc, split: str, scenes: list[Scene], dets: dict[str, BoxSet], tracker_cfg: TrackerConfig,
                   device: str = "auto"):
    """A callable(net) -> overall AMOTA of the GRU-KF tracker on nuScenes(-format) ``split`` (official
    semantics, computed by grutrack's exact fast evaluator); labels are the 7 tracking classes."""
    from grutrack.evaluation.fast_amota import fast_tracking_eval

    tokens = [f.token for s in scenes for f in s.frames]

    def validate(net) -> float:
        was_training = net.training
        net.eval()
        groups = network_groups(net, tracker_cfg, np.arange(len(TRACKING_CLASSES)), device)
        run = track_scenes(Tracker(tracker_cfg, groups), scenes, dets)
        net.train(was_training)
        sub = build_submission(run.results, tokens, tracker_cfg.max_boxes_per_sample)
        with contextlib.redirect_stdout(io.StringIO()):
            summary = fast_tracking_eval(nusc, sub, split)
        return float(summary["amota"])

    return validate
