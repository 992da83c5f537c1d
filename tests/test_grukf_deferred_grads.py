"""Training sums the Linear layers' and GRU cells' weight gradients over a scene in one product per layer
(:class:`grutrack.motion.grukf.DeferredWeightGrads`); the gradient must be the one plain autograd gives."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture(scope="module")
def scenes_and_dets(nusc_mini, tmp_path_factory):
    """Two mini_train scenes (first 10 frames) with simulated CenterPoint-like detections (SYNTHETIC, seed 5)."""
    from support.grukf_data import mini_train_scenes_and_dets

    return mini_train_scenes_and_dets(nusc_mini, tmp_path_factory.mktemp("dets"), 2, 10)


def _grads(t, scene, deferred: bool) -> dict[str, torch.Tensor]:
    from grutrack.training.loss import run_scene

    t.net.zero_grad(set_to_none=True)
    if deferred:
        with t.net.deferring_weight_grads() as d:
            loss = run_scene(t.net, scene, t.dets, t.tracker_cfg, t.cfg, t.device, t.index).value()
            d.backward(loss, list(t.net.parameters()))
    else:
        run_scene(t.net, scene, t.dets, t.tracker_cfg, t.cfg, t.device, t.index).value().backward()
    return {k: p.grad.clone() for k, p in t.net.named_parameters() if p.grad is not None}


@pytest.mark.parametrize(
    "over", [{}, {"four_gru": True, "aux_inputs": True, "gain_prior": "ekf"}], ids=["paper", "four_gru-aux-ekf_prior"]
)
def test_deferred_weight_gradients_equal_plain_autograd(scenes_and_dets, tmp_path, over):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    scenes, dets = scenes_and_dets
    cfg = load_train_config("grukf", {"epochs": 1, "checkpoint_every": 0, "device": "cpu", **over})
    t = Trainer(cfg, scenes, dets, tmp_path, progress=False)
    with torch.no_grad():  # a trained-looking output layer: gradients reach every layer through K
        g = torch.Generator().manual_seed(3)
        t.net.fc_gain[2].weight.add_(torch.randn(t.net.fc_gain[2].weight.shape, generator=g) * 1e-2)
    plain, deferred = _grads(t, scenes[0], False), _grads(t, scenes[0], True)
    assert plain.keys() == deferred.keys()
    assert {"fc_gain.0.weight", "gru_s.weight_ih", "gru_q.weight_hh", "fc_back2.0.bias"} <= plain.keys()
    for k in plain:
        scale = plain[k].abs().max().item()
        assert scale > 0, k
        torch.testing.assert_close(deferred[k], plain[k], rtol=1e-4, atol=1e-5 * scale, msg=k)
