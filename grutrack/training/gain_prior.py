"""The untrained network's starting point (the gain prior, ``gain_prior`` of the network options).

``constant``: the output layer's bias (and the gain table's cells) at the EKF's mean heading-frame gain on the
training data (:func:`mean_ekf_gain`), so an untrained network is a constant-gain filter close to the EKF (with a
gain table, one that follows the EKF's gain schedule). ``ekf``: the network carries the motion config's per-class
Q, R, P0 (:func:`~grutrack.training.network.ekf_noise`) and its output is a residual on the per-track EKF gain,
starting at zero: the untrained network is that EKF."""

from __future__ import annotations

import numpy as np
import torch

from grutrack.data.scene import BoxSet, Scene
from grutrack.motion.grukf import MEAS_PLANAR, STATE_PLANAR, GRUKalmanNet
from grutrack.tracking.config import TrackerConfig
from grutrack.tracking.ekf_backend import KalmanBackend
from grutrack.tracking.factory import network_models
from grutrack.tracking.tracker import GroupUpdate, Tracker
from grutrack.training.config import TrainConfig
from grutrack.training.network import ekf_backend, ekf_noise, network_config, track_groups, training_arch


def ekf_gain(backend: KalmanBackend, u: GroupUpdate) -> np.ndarray:
    """The heading-frame Kalman gains (K, m, 9) ``backend`` applied in the update ``u`` of its tracks ``u.rows``:
    the gain K = P^- H^T S^-1 its update computed (:class:`~grutrack.motion.kalman.Correction`), rotated by each
    track's predicted yaw."""
    return _rotate_gain(u.posterior.corrected.K, u.prior.x[u.rows, backend.model.yaw_index])


def _rotate_gain(K: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Global-frame gains (N, m, 9) -> heading-frame gains: Rs(-yaw) K Rm(-yaw)^T."""

    def rot(n, pairs):
        R = np.tile(np.eye(n), (len(yaw), 1, 1))
        c, s = np.cos(yaw), np.sin(yaw)
        for i, j in pairs:
            R[:, i, i], R[:, i, j], R[:, j, i], R[:, j, j] = c, s, -s, c
        return R

    return rot(K.shape[1], STATE_PLANAR) @ K @ np.swapaxes(rot(9, MEAS_PLANAR), -1, -2)


def mean_ekf_gain(
    scenes: list[Scene], dets: dict[str, BoxSet], tracker_cfg: TrackerConfig, cfg: TrainConfig, index: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's mean heading-frame gain over all updates on the training scenes, (m, 9), and per cell of the
    gain table (*table_shape, m, 9): by class (``class_gain``), by update count 1..age_bins and by frames
    since the last update 1..gap_bins (the last bin takes the larger values too); NaN in cells without an
    update, zeros overall when there was none. ``index``: as for :func:`run_scene` (the class axis is the
    tracking class)."""
    from threadpoolctl import threadpool_limits

    arch = training_arch(network_config(cfg), cfg)
    ekfs = [ekf_backend(cfg, index, model) for model, _ in network_models(arch, tracker_cfg, index)]
    shape = arch.table_shape
    total = np.zeros((*shape, ekfs[0].model.dim_x, 9))
    count = np.zeros(shape, dtype=np.int64)
    tracker = Tracker(tracker_cfg, track_groups(ekfs, arch, tracker_cfg, index))
    with threadpool_limits(limits=1, user_api="blas"):  # tiny batched solves: threads only add stalls
        for scene in scenes:
            tracker.reset()
            for frame in scene.frames:
                for u in tracker.step_with_updates(dets[frame.token], frame.timestamp, output=False)[1]:
                    if u.group >= len(ekfs) or not len(u.rows):
                        continue
                    rows = u.rows
                    c = index[u.labels[rows]] if arch.class_gain else np.zeros(len(rows), dtype=np.int64)
                    a = np.minimum(u.hits[rows], shape[1]) - 1  # hits = 1 + the updates before this one
                    g = np.minimum(u.misses[rows], shape[2]) - 1  # misses = frames since the last update
                    np.add.at(total, (c, a, g), ekf_gain(ekfs[u.group], u))
                    np.add.at(count, (c, a, g), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        table = total / count[..., None, None]
    shared = total.sum((0, 1, 2)) / max(int(count.sum()), 1)
    return shared, table


def init_gain_prior(
    net: GRUKalmanNet,
    cfg: TrainConfig,
    scenes: list[Scene],
    dets: dict[str, BoxSet],
    tracker_cfg: TrackerConfig,
    index: np.ndarray,
    generator: torch.Generator | None = None,
) -> None:
    """The untrained network's starting point. ``gain_prior: constant``: the output layer's bias (and gain table)
    at the EKF's mean gain on the training data (:func:`mean_ekf_gain`). ``gain_prior: ekf``: the EKF's per-class
    Q, R, P0 of the motion config (``ss_model`` for every class) in the network; the output layer and table
    stay zero, so the untrained GRU-KF is that EKF. ``generator``: draws the output layer's small starting
    weights (constant prior)."""
    if net.cfg.gain_prior == "ekf":
        net.set_ekf_noise(*(torch.as_tensor(a) for a in ekf_noise(cfg)))
        return
    shared, table = mean_ekf_gain(scenes, dets, tracker_cfg, cfg, index)
    net.set_gain_prior(torch.as_tensor(shared), torch.as_tensor(table), generator=generator)
