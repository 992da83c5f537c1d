"""Validation during training: track the validation scenes with the current network and have the dataset score them
(its headline metric: nuScenes AMOTA, AV2 HOTA; :meth:`~grutrack.datasets.base.Dataset.score_tracks`), and the
tracker preset's own EKF once on the same scenes as the reference line of the learning curve.

The trainer asks a :class:`Validator` (the protocol) for scores; :class:`DatasetValidator` is grutrack's, on any
dataset that ``validates_training``."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol, runtime_checkable

import numpy as np

from grutrack.data.scene import BoxSet, Scene
from grutrack.documents import ValidationRecord
from grutrack.tracking.config import load_tracker_config
from grutrack.tracking.factory import ekf_groups, network_groups, param_index, remap_config
from grutrack.tracking.tracker import Tracker, track_scenes
from grutrack.training.config import TrainConfig


@runtime_checkable
class Validator(Protocol):
    """What the trainer asks of validation. ``metric``: the name of the score (``AMOTA``, ``HOTA``) for messages;
    the training log's ``val_amota`` columns hold it whatever its name."""

    metric: str

    def scores(self, net) -> Sequence[float]:
        """The score of the GRU-KF tracker with ``net`` (a ``GRUKalmanNet``, left in the mode it came in) on each
        validation detection set; the step's validation score is their mean."""
        ...

    def reference_scores(self) -> Sequence[float]:
        """The reference tracker's score on each detection set (the learning curve's reference line)."""
        ...

    def describe(self) -> ValidationRecord:
        """A new record of what is validated (``split``, ``scenes``, ``held_out``, ``detection_sets``,
        ``reference``); the trainer fills in the selection and the scores."""
        ...


class DatasetValidator:
    """The GRU-KF tracker (preset ``cfg.tracker_preset``, output ``cfg.matched_box``, ``cfg.device``) on ``scenes``
    of ``split`` of ``dataset`` (a :class:`~grutrack.datasets.base.Dataset`), scored by the dataset
    (:meth:`~grutrack.datasets.base.Dataset.score_tracks`). With ``held_out`` the scenes are part of the training
    split held out of training, and only they are scored.

    ``dets``: the detections by frame token, or several sets ``{name: detections}`` (e.g. one per detector
    profile the training draws from): the score is then the mean over the sets, so that a step which fails on one
    kind of detector error is not selected for its score on another. The reference is the preset's own EKF on the
    same scenes and sets, computed once."""

    def __init__(
        self,
        dataset,
        split: str,
        scenes: list[Scene],
        dets: dict,
        cfg: TrainConfig,
        held_out: bool = False,
        reference_name: str = "ekf",
    ):
        first = next(iter(dets.values()), None) if dets else None
        self.sets: dict[str, dict[str, BoxSet]] = dets if isinstance(first, dict) else {"given": dets}
        self.dataset, self.split, self.scenes, self.held_out = dataset, split, scenes, held_out
        self.metric = dataset.validation_metric
        self.index = param_index(dataset.vocabulary.param_classes)
        preset = remap_config(load_tracker_config(cfg.tracker_preset), self.index)
        self.tracker_cfg, self.device = replace(preset, matched_box=cfg.matched_box), cfg.device
        self.reference_name = reference_name
        self._reference: np.ndarray | None = None

    def describe(self) -> ValidationRecord:
        return ValidationRecord(
            rule="last",
            selected_step=0,
            split=self.split,
            scenes=[sc.name for sc in self.scenes],
            held_out=self.held_out,
            detection_sets=list(self.sets),
            reference=self.reference_name,
        )

    def scores(self, net) -> np.ndarray:
        """(n_sets,) float64: the score of the GRU-KF tracker with ``net`` on each detection set. Tracking runs on
        the device ``device`` names (``auto``: the CPU, :func:`~grutrack.tracking.grukf_backend.resolve_device`);
        when that is not the device ``net`` trains on, a copy of ``net`` is tracked there and ``net`` stays put."""
        from grutrack.tracking.grukf_backend import resolve_device

        device = resolve_device(self.device, "training config 'device'")
        if next(net.parameters()).device != device:
            net = copy.deepcopy(net)
        was_training = net.training
        net.eval()
        try:
            return self._score(Tracker(self.tracker_cfg, network_groups(net, self.tracker_cfg, self.index, device)))
        finally:
            net.train(was_training)

    def reference_scores(self) -> np.ndarray:
        """(n_sets,) float64: the tracker preset with its own EKF motion models on each set (computed once)."""
        if self._reference is None:
            self._reference = self._score(Tracker(self.tracker_cfg, ekf_groups(self.tracker_cfg, self.index)))
        return self._reference

    def _score(self, tracker: Tracker) -> np.ndarray:
        """(n_sets,) float64: the dataset's score of ``tracker`` on each detection set."""
        return np.array(
            [
                self.dataset.score_tracks(
                    self.split,
                    self.scenes,
                    track_scenes(tracker, self.scenes, d).results,
                    self.tracker_cfg.max_boxes_per_sample,
                )
                for d in self.sets.values()
            ],
            dtype=np.float64,
        )


def held_out_scenes(scenes: list[Scene], n: int) -> list[Scene]:
    """``n`` of ``scenes``, evenly spaced in name order (the middle scene of each of n equal runs)."""
    ordered = sorted(scenes, key=lambda sc: sc.name)
    if n <= 0:
        return []
    return [ordered[int((i + 0.5) * len(ordered) / n)] for i in range(n)]
