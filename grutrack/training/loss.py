"""The training loss (ARCHITECTURE.md, "The method"): the tracker runs online over a scene with the GRU-KF as its
motion backend and an EKF with the same SS model in parallel on every track (same births, deaths and matched
detections, :class:`PairedBackend`); the EKF's posterior is the pseudo-label of a track in a frame where the track
holds no ground truth. The loss of a scene (:class:`SceneLoss`) sums, over the frames and the tracks corrected in
them, the weighted squared measurement-space error of the GRU-KF posterior to the GT box (sticky GT association)
or, in semi-supervised mode, to the EKF posterior; it is divided by the number of terms. :func:`run_scene` tracks
one scene with gradients on, :func:`run_scenes` several in lockstep (one network call per frame and network group
for all)."""

from __future__ import annotations

import math
import threading

import numpy as np
import torch

from grutrack.data.scene import BoxSet, Scene
from grutrack.motion.grukf import GRUKalmanNet
from grutrack.motion.torch_models import wrap_angle_t
from grutrack.tracking.config import TrackerConfig
from grutrack.tracking.ekf_backend import KalmanBackend
from grutrack.tracking.factory import grukf_group, network_models, robust_update, velocity_check
from grutrack.tracking.grukf_backend import GRUKFBackend
from grutrack.tracking.tracker import GroupUpdate, Tracker
from grutrack.training.config import TrainConfig
from grutrack.training.gt_association import StickyGTAssociation
from grutrack.training.network import ekf_backend, track_groups, training_arch


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

    def update(self, s, rows, z, scores=None):
        return (self.gru.update(s[0], rows, z, scores), self.ekf.update(s[1], rows, z, scores))

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
    yaw = (
        wrap_angle_t(r[:, 6:7])
        if yaw_period == 2 * math.pi
        else wrap_angle_t(r[:, 6:7] * (2 * math.pi / yaw_period)) * (yaw_period / (2 * math.pi))
    )
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
        self._pred: list[torch.Tensor] = []  # (k, 9) rows with their graph
        self._target: list[np.ndarray] = []  # (k, 9) float64 targets of those rows
        self._scale: list[np.ndarray] = []  # (k,) weight of each row's term (1, or the prediction weight)
        self.max_abs_gain = torch.zeros((), dtype=torch.float64, device=device)  # no sync per frame on a GPU
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
        match = (
            self._gated(self.assoc.match(ids, xy, labels, gt.ids, gt.boxes[:, :2], gt.labels), xy, gt)
            if len(gt)
            else np.full(len(u.rows), -1)
        )
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
        cost = r**2
        d = self.cfg.centre_huber_delta
        if d <= 0:
            return cost
        a = r[:, :2].abs()
        return torch.cat([torch.where(a <= d, cost[:, :2], 2 * d * a - d * d), cost[:, 2:]], dim=1)


def run_scene(
    net: GRUKalmanNet,
    scene: Scene,
    dets: dict[str, BoxSet],
    tracker_cfg: TrackerConfig,
    cfg: TrainConfig,
    device: torch.device,
    index: np.ndarray,
    lockstep=None,
    slot: int = 0,
) -> SceneLoss:
    """Track one scene with gradients on; returns its collected loss. ``index`` (n_labels,): the tracking
    class each label of the scene's vocabulary takes its parameters (and the network its class gain) from.
    With ``network_classes: ss_model`` the other labels run the preset's EKF groups and give no loss terms
    (``training_classes: own_model``: the network runs them too, :func:`training_arch`).
    ``lockstep``: a :class:`~grutrack.training.lockstep.LockstepCorrect` this scene (its ``slot``) shares the
    network's calls with (several scenes per step; each network group its channel, named by its SS model,
    :func:`lockstep_channels`); None: the network is called directly."""
    arch = training_arch(net.cfg, cfg)
    backends = [
        PairedBackend(
            grukf_group(
                net,
                len(index),
                device,
                train=True,
                class_index=index,
                correct=None if lockstep is None else lockstep.bind(slot, model.upper()),
                ss_model=model,
                velocity_check=velocity_check(tracker_cfg),
                robust=robust_update(tracker_cfg),
            ).backend,
            ekf_backend(cfg, index, model, velocity_check(tracker_cfg), robust_update(tracker_cfg)),
        )
        for model, _ in network_models(arch, tracker_cfg, index)
    ]
    tracker = Tracker(tracker_cfg, track_groups(backends, arch, tracker_cfg, index))
    loss = SceneLoss(cfg, device)
    for frame in scene.frames:
        _, updates = tracker.step_with_updates(dets[frame.token], frame.timestamp, output=False)
        if lockstep is not None:
            lockstep.frame_done(slot)
        for u in updates:
            if u.group < len(backends):  # the network's groups (the others are the preset's EKF)
                loss.add(u, backends[u.group], frame.gt)
    return loss


def lockstep_channels(net: GRUKalmanNet, cfg: TrainConfig, jobs: list[tuple]) -> tuple[str, ...]:
    """The network track groups of the scenes ``jobs`` ([(scene, label index, tracker config)]) as lockstep
    channels: their SS model names (upper case) in the order a tracker updates its groups (the network's own model
    first, :func:`~grutrack.tracking.factory.network_models`), the union over the scenes (a scene whose vocabulary
    has no label of a model lacks that group)."""
    from grutrack.motion.grukf import NETWORK_MODELS

    arch = training_arch(net.cfg, cfg)
    own = arch.ss_model.upper()
    order = [own, *(m for m in NETWORK_MODELS if m != own)]
    present = {m.upper() for _, index, tracker_cfg in jobs for m, _ in network_models(arch, tracker_cfg, index)}
    return tuple(m for m in order if m in present)


def run_scenes(
    net: GRUKalmanNet, jobs: list[tuple], cfg: TrainConfig, dets: dict[str, BoxSet], device: torch.device
) -> list[SceneLoss]:
    """:func:`run_scene` for several scenes at once, the network called once per frame and network group for all
    of them (:mod:`grutrack.training.lockstep`: with ``own_model`` classes one call per SS model);
    ``jobs``: [(scene, label index, tracker config)]. One thread per scene and one making the network calls
    (:meth:`~grutrack.training.lockstep.LockstepCorrect.serve`); the first scene's failure is raised
    here (the others stop at their next network call)."""
    from grutrack.training.lockstep import LockstepAborted, LockstepCorrect

    lock = LockstepCorrect(net.correct, len(jobs), lockstep_channels(net, cfg, jobs))
    losses: list[SceneLoss | None] = [None] * len(jobs)
    errors: list[BaseException | None] = [None] * (len(jobs) + 1)  # the scenes', then the network thread's

    def work(slot: int) -> None:
        scene, index, tracker_cfg = jobs[slot]
        try:
            losses[slot] = run_scene(net, scene, dets, tracker_cfg, cfg, device, index, lock, slot)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread below
            errors[slot] = exc
            lock.abort(exc)
        finally:
            lock.leave(slot)

    def serve() -> None:
        try:
            lock.serve()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread below
            errors[-1] = exc
            lock.abort(exc)

    # daemon: a second Ctrl-C (raised in this thread's join) does not wait for the scenes to finish
    threads = [threading.Thread(target=work, args=(i,), name=f"grukf-scene-{i}", daemon=True) for i in range(len(jobs))]
    threads.append(threading.Thread(target=serve, name="grukf-network", daemon=True))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    failed = [e for e in errors if e is not None]
    if failed:  # the cause, not the other scenes' LockstepAborted
        raise next((e for e in failed if not isinstance(e, LockstepAborted)), failed[0])
    return losses
