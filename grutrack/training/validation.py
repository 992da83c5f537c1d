"""Validation during training: track the validation scenes with the current network and score them (AMOTA), and
the tracker preset's own EKF once on the same scenes as the reference line of the learning curve."""

from __future__ import annotations

import contextlib
import io

import numpy as np

from grutrack.classes import TRACKING_CLASSES
from grutrack.data.scene import BoxSet, Scene
from grutrack.export.nuscenes_json import build_submission
from grutrack.tracking.config import TrackerConfig
from grutrack.tracking.factory import ekf_groups, network_groups
from grutrack.tracking.tracker import Tracker, track_scenes


class Validator:
    """callable(net) -> overall AMOTA of the GRU-KF tracker on ``scenes`` of nuScenes(-format) ``split`` (official
    semantics, grutrack's exact fast evaluator; labels are the 7 tracking classes). With ``held_out`` the scenes are
    part of ``split`` held out of training and only their tracks and ground truth are scored.

    ``dets``: the detections by frame token, or several sets ``{name: detections}`` (e.g. one per detector
    profile the training draws from): the AMOTA is then the mean over the sets, so that a step which fails on one
    kind of detector error is not selected for its score on another.

    :meth:`scores` gives the AMOTA of each set (the spread between sets is what the one-standard-error selection
    rule reads). ``split``, ``scene_names``, ``detection_sets``, ``reference_name`` and :meth:`reference_scores`
    (the AMOTA of ``tracker_cfg``'s own EKF on the same scenes and sets, computed once) describe it in
    ``validation.json``."""

    def __init__(self, nusc, split: str, scenes: list[Scene], dets: dict, tracker_cfg: TrackerConfig,
                 device: str = "auto", held_out: bool = False, reference_name: str = "ekf"):
        first = next(iter(dets.values()), None) if dets else None
        self.sets = dets if isinstance(first, dict) else {"given": dets}
        self.nusc, self.split, self.scenes = nusc, split, scenes
        self.tracker_cfg, self.device, self.held_out = tracker_cfg, device, held_out
        self.scene_names = [sc.name for sc in scenes]
        self.detection_sets = list(self.sets)
        self.reference_name = reference_name
        self._reference: np.ndarray | None = None
        self._others: set[str] | None = None     # held out: the split's other samples (empty in submissions)

    def __call__(self, net) -> float:
        """The mean of :meth:`scores` over the detection sets."""
        return float(np.mean(self.scores(net)))

    def scores(self, net) -> np.ndarray:
        """(n_sets,) float64: AMOTA of the GRU-KF tracker with ``net`` on each detection set."""
        was_training = net.training
        net.eval()
        groups = network_groups(net, self.tracker_cfg, np.arange(len(TRACKING_CLASSES)), self.device)
        try:
            return self._score(Tracker(self.tracker_cfg, groups))
        finally:
            net.train(was_training)

    def reference_amota(self) -> float:
        """Mean AMOTA of the tracker preset with its own EKF motion models on the validation scenes."""
        return float(np.mean(self.reference_scores()))

    def reference_scores(self) -> np.ndarray:
        """(n_sets,) float64: :meth:`reference_amota` per detection set (computed once)."""
        if self._reference is None:
            groups = ekf_groups(self.tracker_cfg, np.arange(len(TRACKING_CLASSES)))
            self._reference = self._score(Tracker(self.tracker_cfg, groups))
        return self._reference

    def _score(self, tracker: Tracker) -> np.ndarray:
        """(n_sets,) float64: AMOTA of ``tracker`` on each detection set."""
        return np.array([self._score_set(tracker, d) for d in self.sets.values()], dtype=np.float64)

    def _score_set(self, tracker: Tracker, dets: dict[str, BoxSet]) -> float:
        from grutrack.evaluation.fast_amota import evaluate_tracks, fast_tracking_eval, load_tracks

        tokens = [f.token for s in self.scenes for f in s.frames]
        sub = build_submission(track_scenes(tracker, self.scenes, dets).results, tokens,
                               self.tracker_cfg.max_boxes_per_sample)
        with contextlib.redirect_stdout(io.StringIO()):
            if not self.held_out:
                return float(fast_tracking_eval(self.nusc, sub, self.split)["amota"])
            keep = {sc.token for sc in self.scenes}
            if self._others is None:
                in_split = _split_scene_tokens(self.nusc, self.split)
                self._others = {s["token"] for s in self.nusc.sample if s["scene_token"] in in_split} - set(tokens)
            sub["results"].update({t: [] for t in self._others})   # the loader wants every sample of the split
            gt, pred, _ = load_tracks(self.nusc, sub, self.split)
            metrics, _ = evaluate_tracks({k: v for k, v in gt.items() if k in keep},
                                         {k: v for k, v in pred.items() if k in keep})
        return float(metrics.serialize()["amota"])


def _split_scene_tokens(nusc, split: str) -> set[str]:
    """Tokens of the scenes of ``split`` (a devkit split or a custom one of the dataset's splits.json)."""
    from grutrack.data.nuscenes import split_scene_names

    names = set(split_scene_names(nusc, split))
    return {s["token"] for s in nusc.scene if s["name"] in names}


def make_validator(nusc, split: str, scenes: list[Scene], dets: dict[str, BoxSet], tracker_cfg: TrackerConfig,
                   device: str = "auto") -> Validator:
    """A :class:`Validator` of a whole validation split."""
    return Validator(nusc, split, scenes, dets, tracker_cfg, device)


def held_out_scenes(scenes: list[Scene], n: int) -> list[Scene]:
    """``n`` of ``scenes``, evenly spaced in name order (the middle scene of each of n equal runs)."""
    ordered = sorted(scenes, key=lambda sc: sc.name)
    if n <= 0:
        return []
    return [ordered[int((i + 0.5) * len(ordered) / n)] for i in range(n)]
