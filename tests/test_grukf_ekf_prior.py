"""GRU-KF with an EKF gain prior (training key ``gain_prior: ekf``): the network's gain is a residual added to the
per-track EKF gain, so the untrained network is the EKF; the option survives a checkpoint round trip."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from grutrack.errors import ConfigError
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig


@pytest.fixture(scope="module")
def scenes_and_dets(nusc_mini, tmp_path_factory):
    """Two mini_train scenes (first 12 frames) with simulated CenterPoint-like detections (SYNTHETIC, seed 5)."""
    from support.grukf_data import mini_train_scenes_and_dets

    return mini_train_scenes_and_dets(nusc_mini, tmp_path_factory.mktemp("dets"), 2, 12)


def _trainer(scenes, dets, out, **over):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config(
        "paper",
        {
            "epochs": 1,
            "checkpoint_every": 0,
            "device": "cpu",
            "lr": 1e-3,
            "gap_bins": 5,
            "gain_prior": "ekf",
            "yaw_flip": True,
            **over,
        },
    )
    return Trainer(cfg, scenes, dets, out, progress=False)


def _paired_run(t, scenes, dets):
    """Track ``scenes`` with the trainer's network and the parallel EKF on the same tracks; returns the largest
    |GRU-KF posterior - EKF posterior| over all updates (measurement space, yaw wrapped; m, rad, m/s), the
    largest relative covariance difference at the scene ends, and the number of updates."""
    from grutrack.tracking.factory import grukf_group
    from grutrack.tracking.tracker import Tracker, TrackGroup
    from grutrack.training.loss import PairedBackend
    from grutrack.training.network import ekf_backend

    gru = grukf_group(t.net, len(t.index), "cpu", class_index=t.index).backend
    pb = PairedBackend(gru, ekf_backend(t.cfg, t.index))
    tracker = Tracker(t.tracker_cfg, [TrackGroup(pb, np.ones(len(t.index), dtype=bool))])
    diffs, p_rel, n = [0.0], [0.0], [0]
    for s in scenes:
        for f in s.frames:
            _, updates = tracker.step_with_updates(dets[f.token], f.timestamp)
            for u in (u for u in updates if len(u.rows)):
                g, e = pb.posterior(u)
                d = g.detach().numpy() - e
                d[:, 6] = (d[:, 6] + np.pi) % (2 * np.pi) - np.pi
                diffs.append(float(np.abs(d).max()))
                n[0] += len(u.rows)
        g, e = tracker.groups[0].state
        p_rel.append(float(np.abs(g.P - e.P).max() / np.abs(e.P).max()))
    return max(diffs), max(p_rel), n[0]


def test_untrained_ekf_prior_grukf_is_the_ekf(scenes_and_dets, tmp_path):
    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path)
    assert (
        float(t.net.fc_gain[2].weight.detach().abs().max()) == 0.0
        and float(t.net.fc_gain[2].bias.detach().abs().max()) == 0.0
    )
    assert float(t.net.gain_table.detach().abs().max()) == 0.0
    # the network carries the parallel EKF's noise: car's R is the motion config's
    from grutrack.training.network import ekf_backend

    assert torch.equal(t.net.ekf_R[2], torch.as_tensor(ekf_backend(t.cfg, t.index).R[2]))
    diff, p_rel, n = _paired_run(t, scenes, dets)
    assert n > 200
    # states agree to rounding; the covariances, propagated through the arc Jacobian at those states (its small
    # turn-rate branch cancels digits), to a relative 1e-8
    assert diff < 1e-9 and p_rel < 1e-7


def test_training_moves_the_ekf_prior_grukf_from_the_ekf_and_the_checkpoint_keeps_the_option(scenes_and_dets, tmp_path):
    from grutrack.motion.checkpoint import load_network
    from grutrack.tracking.factory import build_tracker, network_groups
    from grutrack.tracking.tracker import Tracker, track_scenes

    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path)
    final = t.run()
    assert all(r.gt_terms > 0 for r in t.log.steps)
    diff, _, _ = _paired_run(t, scenes, dets)
    assert diff > 1e-4  # the learned residual changes the posterior
    net = load_network(final)
    assert net.cfg.gain_prior == "ekf" and net.cfg.yaw_flip
    own = t.net.state_dict()
    assert all(torch.equal(v, own[k]) for k, v in net.state_dict().items())
    assert torch.equal(net.ekf_P0, t.net.ekf_P0) and float(net.ekf_Q.abs().max()) > 0
    # the tracker built from the checkpoint gives the boxes of the network trained in-process
    a = track_scenes(build_tracker("grukf", checkpoint=final, device="cpu"), scenes[:1], dets).results
    cfg = replace(t.tracker_cfg, matched_box=t.cfg.matched_box)
    b = track_scenes(Tracker(cfg, network_groups(t.net, cfg, t.index, "cpu")), scenes[:1], dets).results
    assert sum(len(r) for r in a.values()) > 0
    for tok in a:
        np.testing.assert_allclose(a[tok].boxes, b[tok].boxes, atol=1e-12)


def test_ekf_prior_needs_the_ekf_gain_and_is_a_named_option():
    from grutrack.training.config import load_train_config

    net = GRUKalmanNet(GRUKFConfig(gain_prior="ekf")).double()
    x = torch.zeros(1, 10, dtype=torch.float64)
    x[:, 3:6] = 1.0
    y = net.ss.h(x) + 0.5
    with pytest.raises(ValueError, match="EKF gain"):
        net.correct(x, y, y, x, x, x, net.init_hidden(1))
    # untrained: the posterior is x^- + K_ekf r whatever the network's inputs
    K = torch.zeros(1, 10, 9, dtype=torch.float64)
    K[0, 0, 0] = 0.25
    post, _, _ = net.correct(x, y, y, x, x, x, net.init_hidden(1), K_prior=K)
    assert float(post[0, 0].detach()) == pytest.approx(0.125, abs=1e-15) and torch.equal(post[0, 1:], x[0, 1:])
    with pytest.raises(ValueError, match="gain_prior"):
        GRUKalmanNet(GRUKFConfig(gain_prior="kalman"))
    with pytest.raises(ConfigError, match="'network.gain_prior' must be 'constant' or 'ekf'"):
        load_train_config("grukf", {"gain_prior": "kalman"})
    assert load_train_config("paper").network["gain_prior"] == "constant"  # the paper's form
    assert load_train_config("grukf").network["gain_prior"] == "ekf"  # the default recipe
