"""GRU-KF options beyond the paper's network: the box written for matched tracks (checkpoint's matched_box), the
heading-flip handling of the yaw innovation, the magnitude / age / gap inputs and detection resampling."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from grutrack.errors import ConfigError
from grutrack.motion.grukf import AUX_DIM, GRUKalmanNet, GRUKFConfig, aux_features
from grutrack.motion.torch_models import TorchCTRA
from grutrack.training.config import load_train_config


def _net(**kw) -> GRUKalmanNet:
    """A network whose gain is the constant K0 (0.6 on every box component, 0.5 yaw): learned part silent."""
    torch.manual_seed(0)
    net = GRUKalmanNet(GRUKFConfig(**kw))
    K0 = torch.zeros(10, 9)
    for i in range(6):
        K0[i, i] = 0.6
    K0[8, 6] = 0.5
    net.set_gain_prior(K0)
    with torch.no_grad():
        net.fc_gain[2].weight.zero_()
    return net.double()


def _prior(n: int = 2) -> torch.Tensor:
    x = torch.zeros(n, 10, dtype=torch.float64)
    x[:, 3:6] = torch.tensor([2.0, 4.5, 1.7], dtype=torch.float64)
    x[:, 6] = 5.0  # speed along the heading
    x[:, 8] = 0.3  # heading
    return x


def test_yaw_flip_turns_a_reversed_detection_instead_of_pulling_the_heading():
    y = TorchCTRA().h(_prior(1))
    y[0, 6] = 0.3 + math.pi - 0.1  # the detector returned the reversed heading, 0.1 rad off
    steps = {}
    for flip in (False, True):
        net = _net(yaw_flip=flip)
        with torch.no_grad():
            x, _, _ = net.correct(_prior(1), y, y, _prior(1), _prior(1), _prior(1), net.init_hidden(1))
        steps[flip] = float((x[0, 8] - 0.3 + math.pi) % (2 * math.pi) - math.pi)
    # plain wrap: residual -(pi + 0.1) wraps to pi - 0.1 -> heading pulled by 0.5 * (pi - 0.1)
    assert steps[False] == pytest.approx(0.5 * (math.pi - 0.1), abs=1e-9)
    # flip: the residual is taken as -0.1 (the measured heading turned by pi)
    assert steps[True] == pytest.approx(-0.05, abs=1e-9)


def test_aux_features_are_log_norms_and_log_counts():
    raw = {
        "innovation": torch.tensor([[3.0, 4.0], [0.0, 0.0]], dtype=torch.float64),
        "obs_diff": torch.tensor([[1.0, 0.0], [0.0, 2.0]], dtype=torch.float64),
        "fwd_evol": torch.zeros(2, 3, dtype=torch.float64),
        "fwd_update": torch.ones(2, 4, dtype=torch.float64),
    }
    a = aux_features(raw, torch.tensor([[1, 1], [8, 3]]))
    assert a.shape == (2, AUX_DIM)
    expect = [
        [math.log(6), math.log(2), 0.0, math.log(3), 0.0, 0.0],
        [0.0, math.log(3), 0.0, math.log(3), math.log(8), math.log(3)],
    ]
    assert torch.allclose(a, torch.tensor(expect, dtype=torch.float64), atol=1e-12)


def test_aux_inputs_reach_the_gain_and_are_required():
    net = _net(aux_inputs=True)
    with torch.no_grad():
        net.fc_gain[2].weight.normal_(0, 0.1)  # let the learned part speak
    prior = _prior(2)
    y = TorchCTRA().h(prior)
    y[:, 0] += 1.0
    args = (prior, y, y, prior, prior, prior)
    with torch.no_grad():
        x_young, _, _ = net.correct(*args, net.init_hidden(2), counts=torch.tensor([[1, 1], [1, 1]]))
        x_gap, _, _ = net.correct(*args, net.init_hidden(2), counts=torch.tensor([[1, 1], [20, 6]]))
    # same features, other track age and gap: the first track's correction is unchanged, the second's differs
    assert torch.allclose(x_young[0], x_gap[0]) and not torch.allclose(x_young[1], x_gap[1])
    with pytest.raises(ValueError, match="aux inputs need"):
        net.correct(*args, net.init_hidden(2))


def test_backend_passes_update_count_and_gap_to_aux_inputs():
    from grutrack.tracking.grukf_backend import GRUKFBackend

    net = _net(aux_inputs=True)
    seen = []
    real = net.correct
    net.correct = lambda *a, **k: (seen.append(a[-1].tolist()), real(*a, **k))[1]
    be = GRUKFBackend(net, "cpu")
    z = TorchCTRA().h(_prior(2)).numpy()
    s = be.initiate(z, np.array([0, 2]))
    s = be.update(be.predict(s, 0.5), np.array([0, 1]), z)
    s = be.predict(be.predict(s, 0.5), 0.5)
    be.update(s, np.array([1]), z[[1]])
    assert seen == [[[1.0, 1.0], [1.0, 1.0]], [[2.0, 2.0]]]


def test_new_training_keys_are_validated():
    cfg = load_train_config("grukf")
    assert cfg.matched_box == "filter"
    with pytest.raises(ConfigError, match="'matched_box' must be 'filter' or 'detection'"):
        load_train_config("grukf", {"matched_box": "posterior"})
    with pytest.raises(ConfigError, match="'resample_profiles' must be a list"):
        load_train_config("grukf", {"resample_profiles": "centerpoint"})
    with pytest.raises(ConfigError, match="'network.aux_inputs' must be true or false"):
        load_train_config("grukf", {"aux_inputs": 1})


def _save(path, matched_box):
    from grutrack.motion.checkpoint import save_checkpoint

    extra = {} if matched_box is None else {"train_config": {"matched_box": matched_box}}
    save_checkpoint(path, _net(gap_bins=0).float(), extra)


def test_default_grukf_preset_writes_what_the_checkpoint_asks(tmp_path):
    from grutrack.tracking.config import load_tracker_config
    from grutrack.tracking.factory import build_tracker

    for box, expect in (("filter", "filter"), ("detection", "detection"), (None, "detection")):
        p = tmp_path / f"{box}.pt"
        _save(p, box)
        assert build_tracker("grukf", checkpoint=p, device="cpu").cfg.matched_box == expect
        # an explicitly named preset is used as written, whatever the checkpoint asks
        for preset in ("ekf", "greedy"):
            written = load_tracker_config(preset).matched_box
            assert build_tracker("grukf", config=preset, checkpoint=p, device="cpu").cfg.matched_box == written


def test_resampling_trainer_draws_fresh_detections_after_the_first_epoch(tmp_path):
    from grutrack.training.resample import ResamplingTrainer, resample_seed

    calls = []
    given = {}

    def resampler(profile, seed):
        calls.append((profile, seed))
        return {"fresh": (profile, seed)}

    cfg = load_train_config(
        "grukf",
        {"resample_profiles": ["centerpoint", "pointpillars"], "seed": 3, "resample_mix": "epoch", "device": "cpu"},
    )
    t = ResamplingTrainer.__new__(ResamplingTrainer)  # the data-free part: which detections per epoch
    t.cfg, t.given, t.resampler = cfg, given, resampler
    assert t.detections_for(0) is given
    assert t.detections_for(1) == {"fresh": ("centerpoint", resample_seed(3, 1))}
    assert t.detections_for(2) == {"fresh": ("pointpillars", resample_seed(3, 2))}
    assert t.detections_for(3) == {"fresh": ("centerpoint", resample_seed(3, 3))}
    assert len({s for _, s in calls}) == 3 and all(s >= 100_000 for _, s in calls)


def test_scene_mix_gives_every_epoch_every_profile_and_every_scene_every_profile(tmp_path):
    """resample_mix scene: scene i in epoch e has profile (e - 1 + i) mod len, drawn with the epoch's seed; over
    len(profiles) epochs every scene meets every profile; epoch 0 stays the given detections."""
    from types import SimpleNamespace

    from grutrack.training.resample import ResamplingTrainer, resample_seed

    profiles = ["centerpoint", "pointpillars", "centerpoint_velfail"]
    scenes = [SimpleNamespace(sample_tokens=[f"s{i}f{j}" for j in range(3)]) for i in range(5)]
    calls = []

    def resampler(profile, seed):
        calls.append((profile, seed))
        return {f"s{i}f{j}": (profile, seed) for i in range(6) for j in range(3)}  # s5: not a training scene

    cfg = load_train_config(
        "grukf", {"resample_profiles": profiles, "resample_mix": "scene", "seed": 2, "device": "cpu"}
    )
    t = ResamplingTrainer.__new__(ResamplingTrainer)
    t.cfg, t.given, t.resampler, t.scenes = cfg, {"given": 1}, resampler, scenes
    assert t.detections_for(0) == {"given": 1}
    seen = {i: set() for i in range(5)}
    for epoch in (1, 2, 3):
        dets = t.detections_for(epoch)
        assert set(dets) == {f"s{i}f{j}" for i in range(5) for j in range(3)}
        for i in range(5):
            got = {dets[f"s{i}f{j}"] for j in range(3)}
            assert got == {(profiles[(epoch - 1 + i) % 3], resample_seed(2, epoch))}
            seen[i] |= got
        assert {p for p, _ in dets.values()} == set(profiles)  # every epoch mixes all three
    assert all({p for p, _ in v} == set(profiles) for v in seen.values())
    assert load_train_config("grukf").resample_mix == "scene" and load_train_config("paper").resample_mix == "epoch"
    with pytest.raises(ConfigError, match="'resample_mix' must be 'epoch' or 'scene'"):
        load_train_config("grukf", {"resample_mix": "frame"})


# ----- the network's options: one section of the training config, the architecture's fields -------------------
def test_every_network_option_is_an_architecture_field_with_its_default():
    """The training config's ``network`` section is the part of :class:`GRUKFConfig` a config sets: every option
    the schema names is a field, and an optional option's schema default is the field's default (what a checkpoint
    written before the option reads)."""
    from dataclasses import MISSING, fields

    from grutrack.config_loader import schema

    section = schema("training")["properties"]["network"]
    arch = {f.name: f.default for f in fields(GRUKFConfig)}
    assert set(section["properties"]) <= set(arch)
    for name, node in section["properties"].items():
        if name not in section["required"]:
            assert node["default"] == arch[name] and arch[name] is not MISSING, name


def test_network_options_are_read_nested_and_in_the_flat_layout_of_earlier_configs(tmp_path):
    import yaml

    from grutrack.training.network import network_config

    nested = load_train_config("paper", {"network": {"gap_bins": 5}})
    flat = load_train_config("paper", {"gap_bins": 5})  # an override in the layout before the section
    assert nested == flat and nested.network["gap_bins"] == 5 and network_config(nested).gap_bins == 5
    raw = yaml.safe_load(open(__import__("grutrack.config_loader", fromlist=["x"]).config_path("training", "paper")))
    old = {k: v for k, v in raw.items() if k != "network"} | raw["network"]  # a config file written before it
    (tmp_path / "old.yaml").write_text(yaml.safe_dump(old))
    assert load_train_config(tmp_path / "old.yaml") == load_train_config("paper")
    with pytest.raises(ConfigError, match=r"unknown key 'network.gap_bin'.*did you mean 'network.gap_bins'"):
        load_train_config("paper", {"network": {"gap_bin": 5}})


def test_min_size_bounds_the_posterior_sizes_from_config_to_checkpoint_to_tracker(tmp_path):
    """``network.min_size`` (optional; 0.05 m, the bound before the option): the trained network's and the tracked
    posterior's w, l, h never go below it; it travels in the checkpoint's architecture."""
    from grutrack.motion.checkpoint import load_network, save_checkpoint
    from grutrack.tracking.factory import build_tracker
    from grutrack.training.network import network_config

    assert network_config(load_train_config("grukf")).min_size == 0.05 == GRUKFConfig().min_size
    cfg = load_train_config("paper", {"network": {"min_size": 0.3}, "device": "cpu"})
    assert network_config(cfg).min_size == 0.3
    y = TorchCTRA().h(_prior(1))
    y[0, 3:6] = -10.0  # a detection that pulls every size below zero
    for bound in (0.05, 0.3):
        net = _net(min_size=bound)
        with torch.no_grad():
            x, _, _ = net.correct(_prior(1), y, y, _prior(1), _prior(1), _prior(1), net.init_hidden(1))
        assert x[0, 3:6].tolist() == [bound] * 3
    save_checkpoint(tmp_path / "m.pt", _net(min_size=0.3).float())
    assert load_network(tmp_path / "m.pt").cfg.min_size == 0.3
    tracker = build_tracker("grukf", checkpoint=tmp_path / "m.pt", device="cpu")
    assert all(g.backend.net.cfg.min_size == 0.3 for g in tracker.groups if hasattr(g.backend, "net"))
    # a checkpoint written before the option: the bound it had
    old = torch.load(tmp_path / "m.pt", weights_only=False)
    del old["arch"]["min_size"]
    torch.save(old, tmp_path / "old.pt")
    assert load_network(tmp_path / "old.pt").cfg.min_size == 0.05
