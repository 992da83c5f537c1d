"""Semi-supervised training of the GRU-Kalman filter (ARCHITECTURE.md, "The method").

The tracker runs online over each training scene with the GRU-KF as its motion backend. An EKF with the
same SS model runs in parallel on every track (same births, deaths and matched detections) and its
posterior is the pseudo-label of a track in a frame where the track holds no ground truth. The loss of a
scene sums, over the frames and the tracks corrected in them, the weighted squared measurement-space error
of the GRU-KF posterior to the GT box (sticky GT association) or, in semi-supervised mode, to the EKF
posterior; it is divided by the number of terms. Gradients accumulate over the frames of a scene; one
AdamW step per scene; cosine annealing over all steps.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import math
import signal
import sys
import threading
import time
from dataclasses import MISSING, asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch

from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet, Scene
from grutrack.documents import TrainingLog, TrainingStep, ValidationRecord
from grutrack.errors import ConfigError, GrutrackError, InputFormatError
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig, MEAS_PLANAR, NETWORK_MODELS, STATE_PLANAR
from grutrack.motion.torch_models import wrap_angle_t
from grutrack.tracking.config import TrackerConfig, load_tracker_config
from grutrack.tracking.ekf_backend import KalmanBackend, KFState
from grutrack.tracking.factory import (ekf_groups, grukf_group, network_members, network_models, param_index,
                                      remap_config)
from grutrack.tracking.grukf_backend import GRUKFBackend, resolve_device
from grutrack.tracking.tracker import GroupUpdate, Tracker, TrackGroup
from grutrack.motion.checkpoint import load_weights, read_checkpoint, save_checkpoint
from grutrack.training.config import TrainConfig
from grutrack.training.gt_association import StickyGTAssociation
from grutrack.training.selection import next_selection

#: a gain entry beyond this (a correction of 1000x the innovation) means the learned filter has diverged
MAX_ABS_GAIN = 1e3

#: between periodic checkpoints, train_log.csv is rewritten after the first step and then at most this often (s)
LOG_EVERY_S = 30.0



def ekf_backend(cfg: TrainConfig, index: np.ndarray, model: str | None = None) -> KalmanBackend:
    """The parallel EKF: the training SS model (or ``model``, a network group's own, ``network_classes:
    own_model``) for every label, with the motion config's Q, R, P0 of the tracking class each label takes its
    parameters from (``index`` (n_labels,), :func:`param_index`) under that model."""
    form = "arc" if model is None else _model_forms(cfg).get(model.upper(), "arc")
    return _ekf_backend(cfg.motion_config, model or cfg.ss_model, tuple(int(c) for c in index), form)


@functools.lru_cache(maxsize=16)
def _ekf_backend(motion_config: str, ss_model: str, index: tuple[int, ...], form: str = "arc") -> KalmanBackend:
    """:func:`ekf_backend`, made once per process and settings (run once per training scene; the backend keeps
    no state of its own)."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.defaults import load_motion_config
    from grutrack.motion.models import make_model

    motion = load_motion_config(motion_config, ss_model)
    first = motion[TRACKING_CLASSES[0]]
    tables = {k: np.stack([motion[TRACKING_CLASSES[c]][k] for c in index]) for k in ("Q", "R", "P0")}
    return KalmanBackend(make_model(first["model"], form, **first["params"]), tables["Q"], tables["R"],
                         tables["P0"])


def training_network_classes(cfg: TrainConfig) -> str:
    """Which classes the network runs while training: ``network_classes``, or "own_model" with
    ``training_classes: own_model`` (validation and the checkpoint keep ``network_classes``)."""
    return "own_model" if cfg.training_classes == "own_model" else cfg.network_classes


def training_arch(arch: GRUKFConfig, cfg: TrainConfig) -> GRUKFConfig:
    """``arch`` with the classes the network runs while training (:func:`training_network_classes`)."""
    kind = training_network_classes(cfg)
    return arch if kind == arch.network_classes else replace(arch, network_classes=kind)


def _model_forms(cfg: TrainConfig) -> dict[str, str]:
    """The tracker preset's form ("arc" or "piecewise") of each model an ``own_model`` network runs besides its
    own (``{MODEL NAME: form}``; the network's own model is always the arc form)."""
    if training_network_classes(cfg) != "own_model":
        return {}
    preset = load_tracker_config(cfg.tracker_preset)
    forms = {"CTRA": "arc", "BICYCLE": preset.bicycle_form}   # CTRA's piecewise form has no torch model
    return {m: forms[m] for m in NETWORK_MODELS if m != cfg.ss_model.upper()}


class TrainingDiverged(GrutrackError):
    """The loss, a gradient or the learned gain became non-finite or exploded."""


class TrainingInterrupted(Exception):
    """Ctrl-C (SIGINT) stopped training after a completed step; ``path`` is the resumable checkpoint."""

    def __init__(self, path: Path, step: int):
        super().__init__(f"interrupted after step {step}; resumable checkpoint {path} (continue with --resume)")
        self.path, self.step = path, step


#: training-config keys a resumed run may change: they touch neither the weights, the scene order nor the schedule
RESUME_MAY_CHANGE = ("device", "val_every", "checkpoint_every")


def data_fingerprint(scenes: list[Scene], dets: dict[str, BoxSet]) -> str:
    """SHA-256 (hex) over the training scenes (names, frame tokens, timestamps, ground truth) and the
    detections of their frames: a resumed run must train on the same data."""
    h = hashlib.sha256()
    for s in scenes:
        h.update(f"{s.name}|{s.token}|{len(s.frames)}".encode())
        for f in s.frames:
            h.update(f"{f.token}|{f.timestamp}".encode())
            for bs in (f.gt, dets.get(f.token)):
                if bs is None:
                    h.update(b"-")
                    continue
                h.update(np.ascontiguousarray(bs.boxes, dtype=np.float64).tobytes())
                h.update(np.ascontiguousarray(bs.scores, dtype=np.float64).tobytes())
                h.update(np.ascontiguousarray(bs.labels, dtype=np.int64).tobytes())
                if bs.ids is not None:
                    h.update("|".join(map(str, bs.ids)).encode())
    return h.hexdigest()


class PairedBackend:
    """GRU-KF and EKF on the same tracks; boxes (for association and output) come from the GRU-KF.

    A state is the pair (GRU-KF state, EKF state); :meth:`measurements` reads the training targets from the
    states a :class:`GroupUpdate` reports.
    """

    def __init__(self, gru: GRUKFBackend, ekf: KalmanBackend):
        self.gru, self.ekf = gru, ekf

    def initiate(self, z, labels):
        return (self.gru.initiate(z, labels), self.ekf.initiate(z, labels))

    def predict(self, s, dt):
        return (self.gru.predict(s[0], dt), self.ekf.predict(s[1], dt))

    def update(self, s, rows, z):
        return (self.gru.update(s[0], rows, z), self.ekf.update(s[1], rows, z))

    def boxes(self, s):
        return self.gru.boxes(s[0])

    def select(self, s, index):
        return (self.gru.select(s[0], index), self.ekf.select(s[1], index))

    def concat(self, a, b):
        return (self.gru.concat(a[0], b[0]), self.ekf.concat(a[1], b[1]))

    def posterior(self, u: GroupUpdate) -> tuple[torch.Tensor, np.ndarray]:
        """The corrected tracks' GRU-KF measurement-space posterior (K, 9) tensor (with its graph) and EKF
        posterior (K, 9) numpy array."""
        return self.gru.measure_corrected(u.posterior[0]), self.ekf.model.h(u.posterior[1].x[u.rows])

    def prior(self, u: GroupUpdate) -> torch.Tensor:
        """Every track's GRU-KF measurement-space prior (N, 9) tensor (the box the association used)."""
        return self.gru.measure(u.prior[0])

    def max_abs_gain(self, u: GroupUpdate) -> torch.Tensor:
        """The largest |K| entry of the gains the GRU-KF applied in this update (0-d tensor; 0 when none)."""
        s = u.posterior[0]
        return s.corrected_gain.max() if len(u.rows) else s.rows.new_zeros(())


def _residual(pred: torch.Tensor, target: torch.Tensor, yaw_period: float = 2 * math.pi) -> torch.Tensor:
    """pred - target (K, 9) with the yaw component wrapped to [-period/2, period/2) (2 pi: a heading; pi: an
    axis, a reversed heading has no yaw residual)."""
    r = pred - target
    yaw = wrap_angle_t(r[:, 6:7]) if yaw_period == 2 * math.pi else \
        wrap_angle_t(r[:, 6:7] * (2 * math.pi / yaw_period)) * (yaw_period / (2 * math.pi))
    return torch.cat([r[:, :6], yaw, r[:, 7:]], dim=1)


class SceneLoss:
    """Collects the loss terms of one scene from the tracker's :class:`GroupUpdate` s, and the largest gain
    entry the GRU-KF applied (``max_abs_gain``, a 0-d tensor, for the divergence check).

    Each frame adds the rows of its predicted boxes (with their graph) and their targets; :meth:`value` forms the
    residuals of the whole scene at once (the same sum as term by term, a few operators instead of a dozen per
    frame)."""

    def __init__(self, cfg: TrainConfig, device: torch.device):
        self.cfg, self.device = cfg, device
        self.w = torch.tensor(cfg.loss_weights, dtype=torch.float64, device=device)
        self.assoc = StickyGTAssociation(cfg.gt_match_distance)
        self._pred: list[torch.Tensor] = []      # (k, 9) rows with their graph
        self._target: list[np.ndarray] = []     # (k, 9) float64 targets of those rows
        self._scale: list[np.ndarray] = []      # (k,) weight of each row's term (1, or the prediction weight)
        self.max_abs_gain = torch.zeros((), dtype=torch.float64, device=device)   # no sync per frame on a GPU
        self.gt_terms = self.pseudo_terms = self.prediction_terms = 0

    def _add_rows(self, pred: torch.Tensor, rows: np.ndarray | None, target: np.ndarray, scale: float) -> None:
        """Terms of ``pred[rows]`` ((k,) row indices of pred (K, 9); None: every row) against ``target`` (k, 9)."""
        self._pred.append(pred if rows is None else pred.index_select(0, torch.as_tensor(rows, device=pred.device)))
        self._target.append(np.asarray(target, dtype=np.float64))
        self._scale.append(np.full(len(target), scale))

    def add(self, u: GroupUpdate, backend: PairedBackend, gt: BoxSet) -> None:
        """Add the terms of one group's update in a frame with ground truth ``gt``: posterior terms of the
        tracks just corrected, and prediction terms of every track holding a GT instance."""
        if len(u.rows):
            self._posterior_terms(u, backend, gt)
            self.max_abs_gain = torch.maximum(self.max_abs_gain, backend.max_abs_gain(u).to(self.max_abs_gain))
        if self.cfg.prediction_weight > 0 and len(gt):
            prior = backend.prior(u)
            held = self.assoc.held_rows(u.ids, gt.ids)
            if self.cfg.gt_term_gate > 0:
                held = self._gated(held, prior.detach().cpu().numpy()[:, :2], gt)
            has = np.flatnonzero(held >= 0)
            if len(has):
                self._add_rows(prior, has, gt.boxes[held[has]], self.cfg.prediction_weight)
                self.prediction_terms += len(has)

    def _gated(self, rows: np.ndarray, xy: np.ndarray, gt: BoxSet) -> np.ndarray:
        """``rows`` (K,) GT row per track (-1: none), with -1 where the track's BEV centre ``xy`` (K, 2) metres is
        farther than ``gt_term_gate`` from its GT box's (0: no gate). The sticky association keeps a track's
        instance after the track has moved onto another object; such a term measures an association error
        of metres, not the filter's accuracy, and under a squared loss it outweighs every other term."""
        gate = self.cfg.gt_term_gate
        if gate <= 0 or not len(rows):
            return rows
        has = rows >= 0
        far = np.zeros(len(rows), dtype=bool)
        far[has] = np.hypot(*(xy[has] - gt.boxes[rows[has], :2]).T) > gate
        return np.where(far, -1, rows)

    def _posterior_terms(self, u: GroupUpdate, backend: PairedBackend, gt: BoxSet) -> None:
        pred, ekf = backend.posterior(u)
        ids, labels = u.ids[u.rows], u.labels[u.rows]
        xy = pred.detach().cpu().numpy()[:, :2]
        match = self._gated(self.assoc.match(ids, xy, labels, gt.ids, gt.boxes[:, :2], gt.labels), xy, gt) \
            if len(gt) else np.full(len(u.rows), -1)
        has = match >= 0
        if self.cfg.mode != "semi_supervised":
            if has.any():
                self._add_rows(pred, np.flatnonzero(has), gt.boxes[match[has]], 1.0)
                self.gt_terms += int(has.sum())
            return
        # semi-supervised: every corrected track has a term, to its GT box or to the EKF posterior
        target = ekf.copy()
        target[has] = gt.boxes[match[has]]
        self._add_rows(pred, None, target, 1.0)
        self.gt_terms += int(has.sum())
        self.pseudo_terms += int((~has).sum())

    def value(self) -> torch.Tensor:
        """Mean over terms (0 when the scene produced none): the weighted squared measurement-space residuals
        (yaw wrapped), times each term's weight, summed and divided by the number of terms."""
        n = self.gt_terms + self.pseudo_terms + self.prediction_terms
        if not self._pred:
            return torch.zeros((), dtype=torch.float64, device=self.device)
        pred = torch.cat(self._pred)
        target = torch.as_tensor(np.concatenate(self._target), device=pred.device)
        scale = torch.as_tensor(np.concatenate(self._scale), device=pred.device)
        period = math.pi if self.cfg.yaw_loss == "axis" else 2 * math.pi
        return ((self._cost(_residual(pred, target, period)) * self.w).sum(1) * scale).sum() / max(n, 1)

    def _cost(self, r: torch.Tensor) -> torch.Tensor:
        """Per-component cost (K, 9) of residuals ``r`` (K, 9): r^2, except with ``centre_huber_delta`` d > 0
        the centre's x, y components cost the Huber form rho(r) = r^2 for |r| <= d, 2 d |r| - d^2 beyond
        (value and slope continuous at d; the gradient of a residual of metres is bounded by 2 d)."""
        cost = r ** 2
        d = self.cfg.centre_huber_delta
        if d <= 0:
            return cost
        a = r[:, :2].abs()
        return torch.cat([torch.where(a <= d, cost[:, :2], 2 * d * a - d * d), cost[:, 2:]], dim=1)


def run_scene(net: GRUKalmanNet, scene: Scene, dets: dict[str, BoxSet], tracker_cfg: TrackerConfig,
              cfg: TrainConfig, device: torch.device, index: np.ndarray, lockstep=None, slot: int = 0) -> SceneLoss:
    """Track one scene with gradients on; returns its collected loss. ``index`` (n_labels,): the tracking
    class each label of the scene's vocabulary takes its parameters (and the network its class gain) from.
    With ``network_classes: ss_model`` the other labels run the preset's EKF groups and give no loss terms
    (``training_classes: own_model``: the network runs them too, :func:`training_arch`).
    ``lockstep``: a :class:`~grutrack.training.lockstep.LockstepCorrect` this scene (its ``slot``) shares the
    network's calls with (several scenes per step); None: the network is called directly."""
    correct = None if lockstep is None else lockstep.bind(slot)
    arch = training_arch(net.cfg, cfg)
    backends = [PairedBackend(grukf_group(net, len(index), device, train=True, class_index=index, correct=correct,
                                          ss_model=model).backend, ekf_backend(cfg, index, model))
                for model, _ in network_models(arch, tracker_cfg, index)]
    tracker = Tracker(tracker_cfg, _groups(backends, arch, tracker_cfg, index))
    loss = SceneLoss(cfg, device)
    for frame in scene.frames:
        _, updates = tracker.step_with_updates(dets[frame.token], frame.timestamp, output=False)
        if lockstep is not None:
            lockstep.frame_done(slot)
        for u in updates:
            if u.group < len(backends):      # the network's groups (the others are the preset's EKF)
                loss.add(u, backends[u.group], frame.gt)
    return loss


def run_scenes(net: GRUKalmanNet, jobs: list[tuple], cfg: TrainConfig, dets: dict[str, BoxSet],
               device: torch.device) -> list[SceneLoss]:
    """:func:`run_scene` for several scenes at once, the network called once per frame for all of them
    (:mod:`grutrack.training.lockstep`); ``jobs``: [(scene, label index, tracker config)]. One thread per scene;
    the first scene's failure is raised here (the others stop at their next network call)."""
    from grutrack.training.lockstep import LockstepAborted, LockstepCorrect

    lock = LockstepCorrect(net.correct, len(jobs))
    losses: list[SceneLoss | None] = [None] * len(jobs)
    errors: list[BaseException | None] = [None] * len(jobs)

    def work(slot: int) -> None:
        scene, index, tracker_cfg = jobs[slot]
        try:
            losses[slot] = run_scene(net, scene, dets, tracker_cfg, cfg, device, index, lock, slot)
        except BaseException as exc:   # noqa: BLE001 - handed to the caller's thread below
            errors[slot] = exc
            lock.abort(exc)
        finally:
            lock.leave(slot)

    # daemon: a second Ctrl-C (raised in this thread's join) does not wait for the scenes to finish
    threads = [threading.Thread(target=work, args=(i,), name=f"grukf-scene-{i}", daemon=True)
               for i in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    failed = [e for e in errors if e is not None]
    if failed:   # the cause, not the other scenes' LockstepAborted
        raise next((e for e in failed if not isinstance(e, LockstepAborted)), failed[0])
    return losses


def _groups(backends: list, arch: GRUKFConfig, tracker_cfg: TrackerConfig, index: np.ndarray) -> list[TrackGroup]:
    """The network's groups first, ``backends[i]`` for the labels of the i-th (:func:`network_models`); then the
    preset's EKF groups for the other labels (none with ``network_classes: all``)."""
    models = network_models(arch, tracker_cfg, index)
    members = network_members(arch, tracker_cfg, index)
    rest = ekf_groups(tracker_cfg, index, only=~members) if not members.all() else []
    return [*(TrackGroup(b, m) for b, (_, m) in zip(backends, models)), *rest]


def ekf_gain(backend: KalmanBackend, s: KFState, rows: np.ndarray) -> np.ndarray:
    """The heading-frame Kalman gains (K, m, 9) with which ``backend`` corrects tracks ``rows`` (K,) of the
    predicted state ``s``: K = P H^T S^-1, rotated by each track's yaw."""
    x, P = s.x[rows], s.P[rows]
    _, H, S = backend.kf.project(x, P, backend.R[s.labels[rows]])
    K = np.swapaxes(np.linalg.solve(S, H @ P), -1, -2)  # (K, m, 9) global frame
    return _rotate_gain(K, x[:, backend.model.yaw_index])


def _rotate_gain(K: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Global-frame gains (N, m, 9) -> heading-frame gains: Rs(-yaw) K Rm(-yaw)^T."""
    def rot(n, pairs):
        R = np.tile(np.eye(n), (len(yaw), 1, 1))
        c, s = np.cos(yaw), np.sin(yaw)
        for i, j in pairs:
            R[:, i, i], R[:, i, j], R[:, j, i], R[:, j, j] = c, s, -s, c
        return R
    return rot(K.shape[1], STATE_PLANAR) @ K @ np.swapaxes(rot(9, MEAS_PLANAR), -1, -2)


def mean_ekf_gain(scenes: list[Scene], dets: dict[str, BoxSet], tracker_cfg: TrackerConfig,
                  cfg: TrainConfig, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's mean heading-frame gain over all updates on the training scenes, (m, 9), and per cell of the
    gain table (*table_shape, m, 9): by class (``class_gain``), by update count 1..age_bins and by frames
    since the last update 1..gap_bins (the last bin takes the larger values too); NaN in cells without an
    update, zeros overall when there was none. ``index``: as for :func:`run_scene` (the class axis is the
    tracking class)."""
    from threadpoolctl import threadpool_limits

    arch = training_arch(_arch(cfg), cfg)
    ekfs = [ekf_backend(cfg, index, model) for model, _ in network_models(arch, tracker_cfg, index)]
    shape = arch.table_shape
    total = np.zeros((*shape, ekfs[0].model.dim_x, 9))
    count = np.zeros(shape, dtype=np.int64)
    tracker = Tracker(tracker_cfg, _groups(ekfs, arch, tracker_cfg, index))
    with threadpool_limits(limits=1, user_api="blas"):   # tiny batched solves: threads only add stalls
        for scene in scenes:
            tracker.reset()
            for frame in scene.frames:
                for u in tracker.step_with_updates(dets[frame.token], frame.timestamp, output=False)[1]:
                    if u.group >= len(ekfs) or not len(u.rows):
                        continue
                    rows = u.rows
                    c = index[u.labels[rows]] if cfg.class_gain else np.zeros(len(rows), dtype=np.int64)
                    a = np.minimum(u.hits[rows], shape[1]) - 1   # hits = 1 + the updates before this one
                    g = np.minimum(u.misses[rows], shape[2]) - 1  # misses = frames since the last update
                    np.add.at(total, (c, a, g), ekf_gain(ekfs[u.group], u.prior, rows))
                    np.add.at(count, (c, a, g), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        table = total / count[..., None, None]
    shared = total.sum((0, 1, 2)) / max(int(count.sum()), 1)
    return shared, table


def init_gain_prior(net: GRUKalmanNet, cfg: TrainConfig, scenes: list[Scene], dets: dict[str, BoxSet],
                    tracker_cfg: TrackerConfig, index: np.ndarray, generator: torch.Generator | None = None
                    ) -> None:
    """The untrained network's starting point. ``gain_prior: constant``: the output layer's bias (and gain table)
    at the EKF's mean gain on the training data (:func:`mean_ekf_gain`). ``gain_prior: ekf``: the EKF's per-class
    Q, R, P0 of the motion config (``ss_model`` for every class) in the network; the output layer and table
    stay zero, so the untrained GRU-KF is that EKF. ``generator``: draws the output layer's small starting
    weights (constant prior)."""
    if cfg.gain_prior == "ekf":
        net.set_ekf_noise(*(torch.as_tensor(a) for a in ekf_noise(cfg)))
        return
    shared, table = mean_ekf_gain(scenes, dets, tracker_cfg, cfg, index)
    net.set_gain_prior(torch.as_tensor(shared), torch.as_tensor(table), generator=generator)


def ekf_noise(cfg: TrainConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The prior EKF's Q, P0 (n_classes, m, m) and R (n_classes, 9, 9) per tracking class, from the motion config:
    every class under ``ss_model``; when the network runs ``own_model`` groups (``network_classes`` or
    ``training_classes: own_model``, :func:`training_network_classes`) a class whose own model is one of
    :data:`NETWORK_MODELS` keeps that model's noise (the network runs it with that model)."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.defaults import load_motion_config

    shared = load_motion_config(cfg.motion_config, cfg.ss_model)
    own = load_motion_config(cfg.motion_config) if training_network_classes(cfg) == "own_model" else {}
    rows = [own[c] if c in own and own[c]["model"].upper() in NETWORK_MODELS else shared[c]
            for c in TRACKING_CLASSES]
    return tuple(np.stack([r[k] for r in rows]) for k in ("Q", "R", "P0"))


def _arch(cfg: TrainConfig) -> GRUKFConfig:
    """The network architecture a training config asks for."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.defaults import load_motion_config

    def params(model: str) -> dict:
        return dict(load_motion_config(cfg.motion_config, model)[TRACKING_CLASSES[0]]["params"])

    others = {m: {**params(m), "form": form} for m, form in _model_forms(cfg).items()}
    return GRUKFConfig(ss_model=cfg.ss_model, ss_params=params(cfg.ss_model), four_gru=cfg.four_gru,
                       class_gain=cfg.class_gain, age_bins=cfg.age_bins, gap_bins=cfg.gap_bins,
                       yaw_flip=cfg.yaw_flip, aux_inputs=cfg.aux_inputs, gain_prior=cfg.gain_prior,
                       network_classes=cfg.network_classes, model_params=others,
                       coast_yaw_rate=cfg.coast_yaw_rate, coast_acceleration=cfg.coast_acceleration)


@dataclass
class TrainState:
    """Position of a run (saved in checkpoints so a resumed run continues exactly)."""

    step: int = 0
    epoch: int = 0
    index: int = 0              # position within the epoch's scene order
    order: list | None = None   # the epoch's scene order


def _plain(v):
    """Config values compared across a checkpoint round trip (tuples come back as lists)."""
    return list(v) if isinstance(v, tuple) else v


def _rng_state(np_rng: np.random.Generator, torch_rng: torch.Generator) -> dict:
    """The states of a run's own generators (for its checkpoints)."""
    return {"numpy": np_rng.bit_generator.state, "torch": torch_rng.get_state()}


def _set_rng_state(np_rng: np.random.Generator, torch_rng: torch.Generator, st: dict) -> None:
    """Restore :func:`_rng_state` (a checkpoint's ``python`` entry, written by older versions, is not used)."""
    np_rng.bit_generator.state = st["numpy"]
    torch_rng.set_state(st["torch"])


class Trainer:
    """Runs :func:`run_scene` over the training scenes, one optimizer step per scene (per ``scenes_per_step``
    scenes: their losses averaged, the network batched over them, :func:`run_scenes`), with logging, validation
    every ``val_every`` steps and resumable checkpoints in ``out_dir``."""

    def __init__(self, cfg: TrainConfig, scenes: list[Scene], dets: dict[str, BoxSet], out_dir: str | Path,
                 validate=None, progress: bool = True, source: dict | None = None):
        self.cfg, self.scenes, self.dets = cfg, scenes, dets
        self.source = dict(source or {})    # where the data came from (dataroot, split, detections), for messages
        self.fingerprint = data_fingerprint(scenes, dets)
        self._interrupted = False
        self._log_written = time.monotonic()
        self.out = Path(out_dir)
        self.validate = validate            # callable(net) -> AMOTA (a validation.Validator), or None
        # select_checkpoint: (the validated step of highest AMOTA so far, the step best.pt holds)
        self._best: TrainingStep | None = None
        self._chosen: TrainingStep | None = None
        self.progress = progress
        self.device = resolve_device(cfg.device, "training config 'device'")
        vocab = scenes[0].vocabulary if scenes else NUSCENES_VOCABULARY
        self._preset = load_tracker_config(cfg.tracker_preset)
        self._setups: dict = {}                          # vocabulary -> (label index, remapped preset)
        # the first scene's vocabulary (the command's own split): the gain prior and validation use it
        self.index, self.tracker_cfg = self._setup(vocab)
        # the run's own generators (no process-wide seeding): torch's for the initial weights, numpy's for the
        # scene order of every epoch
        self.torch_rng = torch.Generator().manual_seed(cfg.seed)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.net = GRUKalmanNet(_arch(cfg), generator=self.torch_rng)
        first = [sc for sc in scenes if sc.vocabulary == vocab]
        init_gain_prior(self.net, cfg, first, dets, self.tracker_cfg, self.index, generator=self.torch_rng)
        self.net.to(self.device)
        # foreach: the update of all parameters in a few multi-tensor operators (same AdamW, one Python loop less)
        self.opt = torch.optim.AdamW(self.net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay, foreach=True)
        self.total_steps = cfg.epochs * -(-len(scenes) // cfg.scenes_per_step)   # ceil: a short last step
        # eta_t = eta_min + (eta_0 - eta_min) (1 + cos(pi t / T)) / 2 (Loshchilov & Hutter 2017, without restarts)
        self.sched = torch.optim.lr_scheduler.CosineAnnealingLR(self.opt, T_max=max(self.total_steps, 1),
                                                                eta_min=min(cfg.lr_min, cfg.lr))
        self.state = TrainState()
        self.log = TrainingLog()

    def _setup(self, vocab) -> tuple[np.ndarray, TrackerConfig]:
        """The label index (n_labels,) (dataset label -> tracking class of its parameters) and the tracker
        preset re-indexed by label, of one vocabulary (sources of several datasets mix vocabularies)."""
        if vocab not in self._setups:
            index = param_index(vocab.param_classes)
            self._setups[vocab] = (index, remap_config(self._preset, index))
        return self._setups[vocab]

    # -- checkpoints ------------------------------------------------------------------------------------
    def save(self, name: str = "last.pt", net: GRUKalmanNet | None = None, extra: dict | None = None) -> Path:
        """Write a resumable checkpoint (and the CSV log) into the output folder (``net``: other weights than
        the training network's, e.g. the selected step's for model.pt; ``extra``: more fields)."""
        path = self.out / name
        save_checkpoint(path, self.net if net is None else net, {**(extra or {}),
            "optimizer": self.opt.state_dict(), "scheduler": self.sched.state_dict(),
            "rng": _rng_state(self.np_rng, self.torch_rng), "train_state": asdict(self.state),
            "train_config": asdict(self.cfg), "log": [s.to_row() for s in self.log.steps],
            "data_fingerprint": self.fingerprint, "data_source": self.source})
        self._write_log()
        return path

    def resume(self, path: str | Path) -> None:
        """Continue exactly from a checkpoint written by :meth:`save`; a checkpoint of other data or of other
        settings (anything but :data:`RESUME_MAY_CHANGE`) raises :class:`ConfigError`."""
        ck = read_checkpoint(path, map_location=self.device)
        self._check_resumable(path, ck)
        load_weights(self.net, ck, path)
        self.opt.load_state_dict(ck["optimizer"])
        self.sched.load_state_dict(ck["scheduler"])
        _set_rng_state(self.np_rng, self.torch_rng, ck["rng"])
        self.state = TrainState(**ck["train_state"])
        self.log = TrainingLog([TrainingStep.from_row(r, str(path)) for r in ck["log"]])
        self._best, self._chosen = self._resumed_selection()

    def _resumed_selection(self) -> tuple[TrainingStep | None, TrainingStep | None]:
        """(best, chosen) of the resumed log replayed through :func:`next_selection` when best.pt holds the chosen
        step, else (None, None) (a best.pt from beyond the resumed step is rewritten when that step is validated
        again)."""
        val = self.log.validated()
        if self.cfg.select_checkpoint == "last" or not val or not (self.out / "best.pt").is_file():
            return None, None
        best = chosen = None
        for row in val:
            best, chosen = next_selection(self.cfg.select_checkpoint, best, chosen, row)
        held = read_checkpoint(self.out / "best.pt").get("selected", {})
        return (best, chosen) if held.get("step") == chosen.step else (None, None)

    def _check_resumable(self, path: str | Path, ck: dict) -> None:
        """Refuse to resume ``ck`` unless it was written by a run of the same data and settings."""
        for key in ("train_state", "train_config", "optimizer", "rng", "log"):
            if key not in ck:
                raise InputFormatError(f"{path}: not a resumable checkpoint (no '{key}'; model.pt files of old "
                                       f"versions cannot be resumed)")
        # a key the run's version did not have yet reads as its default (the behaviour that version had)
        old = {**{f.name: f.default for f in fields(TrainConfig) if f.default is not MISSING}, **ck["train_config"]}
        new = asdict(self.cfg)
        changed = [k for k in new if k not in RESUME_MAY_CHANGE and _plain(old.get(k)) != _plain(new[k])]
        if changed:
            diff = ", ".join(f"{k} {old.get(k)!r} -> {new[k]!r}" for k in changed)
            raise ConfigError(f"{path}: cannot resume with other training settings ({diff}); use the settings "
                              f"of that run or another --out")
        if ck.get("data_fingerprint") != self.fingerprint:
            was = ck.get("data_source") or {}
            diff = ", ".join(f"{k} {was.get(k)!r} -> {self.source.get(k)!r}" for k in sorted(set(was) | set(
                self.source)) if was.get(k) != self.source.get(k))
            raise ConfigError(f"{path}: cannot resume on other training data (the scenes, ground truth or "
                              f"detections differ{': ' + diff if diff else ''}); use the data of that run or "
                              f"another --out")

    def _write_log(self) -> None:
        self._log_written = time.monotonic()
        self.log.write(self.out / "train_log.csv")

    # -- the loop --------------------------------------------------------------------------------------
    def run(self, max_steps: int | None = None) -> Path:
        """Train until all epochs are done (or ``max_steps`` more steps); returns the final checkpoint."""
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):  # tiny batched solves: threads only add stalls
            return self._run(max_steps)

    def _run(self, max_steps: int | None) -> Path:
        from tqdm import tqdm

        self.out.mkdir(parents=True, exist_ok=True)
        if self.validate is not None and self.state.step == 0 and not self.log.steps:
            self._validate_start()
        done = 0
        bar = tqdm(total=self.total_steps, initial=self.state.step, unit="step", desc="training GRU-KF",
                   disable=not self.progress)
        with self._sigint_deferred():
            while self.state.epoch < self.cfg.epochs and (max_steps is None or done < max_steps):
                if self.state.order is None:
                    self.state.order = [int(i) for i in self.np_rng.permutation(len(self.scenes))]
                batch = self.state.order[self.state.index:self.state.index + self.cfg.scenes_per_step]
                self._step([self.scenes[i] for i in batch])
                self._advance(len(batch))
                done += 1
                bar.update(1)
                if self._interrupted:
                    bar.close()
                    raise TrainingInterrupted(self.save(), self.state.step)
                if self.cfg.checkpoint_every and self.state.step % self.cfg.checkpoint_every == 0:
                    self.save()
        bar.close()
        if self.state.epoch >= self.cfg.epochs and self.validate is not None and \
                self.log.steps and self.log.steps[-1].val_amota is None:
            self._validate_into(self.log.steps[-1])
        self.save()
        return self._write_model() if self.state.epoch >= self.cfg.epochs else self.out / "last.pt"

    # -- validation and the selected checkpoint --------------------------------------------------------------
    def _validate_start(self) -> None:
        """Validate the network before any step: row 0 of the log (loss NaN), a candidate for model.pt."""
        self.net.eval()
        row = TrainingStep(step=0, epoch=0, scene="(before training)", loss=math.nan, seconds=0.0)
        self._validate_into(row)
        self.log.steps.append(row)

    def _validate_into(self, row: TrainingStep) -> None:
        """Validate the current network into ``row`` (``val_amota``, and ``val_amota_sets`` when the validator
        scores each detection set: :meth:`Validator.scores`), then consider it for model.pt."""
        scores = getattr(self.validate, "scores", None)
        if scores is None:
            row.val_amota = round(float(self.validate(self.net)), 6)
        else:
            per_set = np.asarray(scores(self.net), dtype=np.float64)
            row.val_amota = round(float(per_set.mean()), 6)
            row.val_amota_sets = tuple(round(float(x), 6) for x in per_set)
        self._consider(row)

    def _consider(self, row: TrainingStep) -> None:
        """With a ``select_checkpoint`` rule other than "last": keep the network just validated as best.pt when
        the rule chooses it (:func:`next_selection`)."""
        if self.cfg.select_checkpoint == "last" or row.val_amota is None:
            return
        self._best, chosen = next_selection(self.cfg.select_checkpoint, self._best, self._chosen, row)
        if chosen is row:
            self._chosen = row
            save_checkpoint(self.out / "best.pt", self.net, {
                "train_config": asdict(self.cfg), "selected": {"step": row.step, "val_amota": row.val_amota}})

    def _write_model(self) -> Path:
        """model.pt (the selected step's network with the final run's records) and validation.json."""
        v = self.validate
        record = ValidationRecord(rule="last", selected_step=self.state.step,
                                  split=getattr(v, "split", None), scenes=list(getattr(v, "scene_names", [])),
                                  held_out=bool(getattr(v, "held_out", False)),
                                  detection_sets=list(getattr(v, "detection_sets", [])),
                                  reference=getattr(v, "reference_name", None))
        val = self.log.validated()
        if val:
            last = val[-1] if val[-1].step == self.state.step else None
            record.selected_amota = None if last is None else last.val_amota
            record.selected_amota_sets = None if last is None or last.val_amota_sets is None else \
                list(last.val_amota_sets)
            per_set = getattr(v, "reference_scores", None)
            if per_set is not None:
                record.reference_amota_sets = [round(float(x), 6) for x in per_set()]
            ref = getattr(v, "reference_amota", None)
            record.reference_amota = None if ref is None else round(float(ref()), 6)
        net = None
        if self._chosen is not None:
            c = self._chosen
            net = copy.deepcopy(self.net)
            load_weights(net, read_checkpoint(self.out / "best.pt", map_location=self.device), self.out / "best.pt")
            record.rule, record.selected_step, record.selected_amota = self.cfg.select_checkpoint, c.step, c.val_amota
            record.selected_amota_sets = None if c.val_amota_sets is None else list(c.val_amota_sets)
        path = self.save("model.pt", net, {"selected": {"rule": record.rule, "step": record.selected_step,
                                                         "val_amota": record.selected_amota}})
        record.write(self.out / "validation.json")
        return path

    def _advance(self, n: int = 1) -> None:
        """Move the position past the ``n`` scenes of the step just taken (into the next epoch after its last
        scene), so that a checkpoint written now resumes with the next step."""
        self.state.index += n
        if self.state.index >= len(self.state.order):
            self.state.epoch, self.state.index, self.state.order = self.state.epoch + 1, 0, None

    def _sigint_deferred(self):
        """Context: the first Ctrl-C (SIGINT) lets the current step finish, then training saves last.pt and
        stops with :class:`TrainingInterrupted`; a second one interrupts at once (nothing more is saved)."""
        import contextlib

        @contextlib.contextmanager
        def ctx():
            if threading.current_thread() is not threading.main_thread():
                yield
                return
            previous = signal.getsignal(signal.SIGINT)
            self._interrupted = False

            def handler(signum, frame):
                if self._interrupted:
                    raise KeyboardInterrupt
                self._interrupted = True
                print("\ninterrupt: finishing the current step, then saving last.pt (Ctrl-C again to abort)",
                      file=sys.stderr, flush=True)

            signal.signal(signal.SIGINT, handler)
            try:
                yield
            finally:
                signal.signal(signal.SIGINT, previous)

        return ctx()

    def _diverged(self, scene: str, what: str) -> None:
        """Keep the last good state (the step was not applied) as last.pt and stop with a clear message
        (``scene``: the step's scene name(s))."""
        path = self.save()
        raise TrainingDiverged(f"training stopped at step {self.state.step + 1} (scene {scene}): {what}; "
                               f"the last good checkpoint is {path} (lower lr in the training config, then "
                               f"--resume)")

    def _scene_losses(self, scenes: list[Scene]) -> list[SceneLoss]:
        """The collected loss of each scene of a step (graphs kept): one scene directly, several in lockstep."""
        jobs = [(sc, *self._setup(sc.vocabulary)) for sc in scenes]
        if len(jobs) == 1:
            sc, index, tracker_cfg = jobs[0]
            return [run_scene(self.net, sc, self.dets, tracker_cfg, self.cfg, self.device, index)]
        return run_scenes(self.net, jobs, self.cfg, self.dets, self.device)

    def _clip(self, params: list[torch.Tensor]) -> float:
        """The L2 norm ||g|| of the step's gradient over ``params`` (those with a gradient; float), and with
        ``grad_clip_norm`` c > 0 the gradient rescaled in place to g * min(1, c / ||g||) (norm clipping against
        exploding gradients through the GRUs' recurrence, Pascanu et al. 2013). Unclipped, one such step (||g||
        1275 against a median of 1.7 in one default training) fills AdamW's second-moment estimate v for
        thousands of steps (decay 0.999), and every later update m / sqrt(v) of those weights is a fraction of
        its size."""
        norm = torch.nn.utils.get_total_norm([p.grad for p in params])
        if self.cfg.grad_clip_norm > 0:
            torch.nn.utils.clip_grads_with_norm_(params, self.cfg.grad_clip_norm, norm)
        return float(norm)

    def _step(self, scenes: list[Scene]) -> None:
        """One optimizer step on ``scenes`` (one, the paper's setting, or ``scenes_per_step``): the mean of their
        scene losses."""
        t0 = time.perf_counter()
        self.net.train()
        name = "+".join(sc.name for sc in scenes)
        with self.net.deferring_weight_grads() as deferred:
            try:
                losses = self._scene_losses(scenes)
            except np.linalg.LinAlgError as exc:   # S = H P^- H^T + R of the parallel EKF, at a diverged state
                self._diverged(name, f"the filter's state diverged ({exc} in the EKF gain prior's update)")
            value = torch.stack([lo.value() for lo in losses]).mean()
            if not torch.isfinite(value):
                self._diverged(name, f"the loss is {value.item()}")
            gain = max(float(lo.max_abs_gain) for lo in losses)
            if gain > MAX_ABS_GAIN:
                self._diverged(name, f"the gain diverged (max |K| = {gain:.3g} > {MAX_ABS_GAIN:g})")
            self.opt.zero_grad()
            if value.requires_grad:
                deferred.backward(value, list(self.net.parameters()))
        if value.requires_grad:
            grads = [p.grad for p in self.net.parameters() if p.grad is not None]
            # the largest |entry| over all gradients (the inf-norm: no overflow of a large finite gradient)
            if grads and not bool(torch.isfinite(torch.nn.utils.get_total_norm(grads, norm_type=math.inf))):
                self.opt.zero_grad()
                self._diverged(name, "a gradient is NaN or infinite")
            grad_norm = self._clip([p for p in self.net.parameters() if p.grad is not None])
            self.opt.step()
        else:
            grad_norm = math.nan
        lr = self.opt.param_groups[0]["lr"]
        self.sched.step()
        self.state.step += 1
        row = TrainingStep(step=self.state.step, epoch=self.state.epoch, scene=name,
                           loss=round(float(value.detach()), 8), gt_terms=sum(lo.gt_terms for lo in losses),
                           pseudo_terms=sum(lo.pseudo_terms for lo in losses),
                           prediction_terms=sum(lo.prediction_terms for lo in losses), lr=lr,
                           seconds=round(time.perf_counter() - t0, 4), grad_norm=round(grad_norm, 6))
        if self.validate is not None and self.cfg.val_every and self.state.step % self.cfg.val_every == 0:
            self.net.eval()
            self._validate_into(row)
        self.log.steps.append(row)
        if self.state.step == 1 or time.monotonic() - self._log_written >= LOG_EVERY_S:
            self._write_log()   # progress shows in train_log.csv from the first step on
