"""GRU-KF training key ``network_classes``: with ``ss_model`` the network filters only the classes whose model in the
tracker preset is its SS model (CTRA: bus, car, truck in the ``ekf`` preset) and the preset's EKF the
others (bicycle and motorcycle: Bicycle; pedestrian: CV; trailer: CA), in tracking and in training."""

from __future__ import annotations

import numpy as np
import pytest

from grutrack.classes import TRACKING_CLASSES
from grutrack.errors import ConfigError
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

#: the ekf preset's classes run with CTRA (grutrack/configs/motion/grutrack_nusc.yaml)
CTRA_CLASSES = ("bus", "car", "truck")


@pytest.fixture(scope="module")
def scenes_and_dets(nusc_mini, tmp_path_factory):
    """Three mini_train scenes (first 15 frames) with simulated CenterPoint-like detections (SYNTHETIC, seed 5)."""
    from support.grukf_data import mini_train_scenes_and_dets

    return mini_train_scenes_and_dets(nusc_mini, tmp_path_factory.mktemp("dets"), 3, 15)


def _trainer(scenes, dets, out, **over):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config(
        "paper", {"epochs": 1, "checkpoint_every": 0, "device": "cpu", "lr": 1e-3, "gap_bins": 5, **over}
    )
    return Trainer(cfg, scenes, dets, out, progress=False)


def _loss_terms(trainer, scenes, dets) -> int:
    """Loss terms (ground truth and pseudo-label) of the untrained network of ``trainer`` over ``scenes``."""
    from grutrack.training.loss import run_scene

    t = trainer
    losses = [run_scene(t.net, s, dets, t.tracker_cfg, t.cfg, t.device, t.index) for s in scenes]
    return sum(loss.gt_terms + loss.pseudo_terms for loss in losses)


def _boxes_by_label(results) -> dict[str, np.ndarray]:
    """Every written box (M, 9), by class name, in frame order."""
    out = {}
    for c, name in enumerate(TRACKING_CLASSES):
        rows = [r.boxes[r.labels == c] for r in results.values()]
        out[name] = np.concatenate(rows) if rows else np.zeros((0, 9))
    return out


def test_untrained_ekf_prior_with_network_classes_ss_model_is_the_ekf_preset(
    scenes_and_dets, tmp_path, ekf_coasting_keep
):
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes

    scenes, dets = scenes_and_dets
    over = {"gain_prior": "ekf", "yaw_flip": True, "motion_config": "grutrack_nusc"}
    ck = _trainer(scenes, dets, tmp_path / "hyb", network_classes="ss_model", **over).save("model.pt")
    ck_all = _trainer(scenes, dets, tmp_path / "all", **over).save("model.pt")
    keep = ekf_coasting_keep
    hyb = build_tracker("grukf", keep, checkpoint=ck, device="cpu")
    # the network's group takes the CTRA classes, the preset's Bicycle, CV and CA groups the others: (classes born
    # slow, classes born moving) per model, as the motion config's `moving` blocks say
    assert [TRACKING_CLASSES[i] for i in np.flatnonzero(hyb.groups[0].classes)] == list(CTRA_CLASSES)

    def names(mask):
        return [TRACKING_CLASSES[i] for i in np.flatnonzero(mask)]

    rest = {
        type(g.backend.model).__name__: (
            names(g.classes),
            names(np.isfinite(g.moving_speed)) if g.moving_speed is not None else [],
        )
        for g in hyb.groups[1:]
    }
    assert rest == {
        "BicyclePiecewise": (["bicycle", "motorcycle"], []),
        "CV": (["pedestrian", "trailer"], ["bicycle", "motorcycle"]),
        "CA": ([], ["trailer"]),
    }
    assert len(build_tracker("grukf", ekf_coasting_keep, checkpoint=ck_all, device="cpu").groups) == 1

    ekf = _boxes_by_label(track_scenes(build_tracker("ekf", keep), scenes, dets).results)
    got = _boxes_by_label(track_scenes(hyb, scenes, dets).results)
    every_tracker = build_tracker("grukf", keep, checkpoint=ck_all, device="cpu")
    every = _boxes_by_label(track_scenes(every_tracker, scenes, dets).results)
    assert len(ekf["car"]) > 100 and len(ekf["bicycle"]) + len(ekf["motorcycle"]) > 10
    for name in TRACKING_CLASSES:  # untrained, the hybrid writes the preset's boxes for every class
        assert got[name].shape == ekf[name].shape
        np.testing.assert_allclose(got[name], ekf[name], atol=1e-8)
    # with network_classes "all" the Bicycle classes run the network's CTRA and their boxes differ
    two_wheel = np.concatenate([ekf["bicycle"], ekf["motorcycle"]])
    other = np.concatenate([every["bicycle"], every["motorcycle"]])
    assert two_wheel.shape != other.shape or np.abs(two_wheel - other).max() > 1e-3
    np.testing.assert_allclose(every["car"], ekf["car"], atol=1e-8)


def test_training_with_network_classes_ss_model_takes_loss_terms_of_the_network_classes_only(scenes_and_dets, tmp_path):
    from grutrack.motion.checkpoint import load_network

    scenes, dets = scenes_and_dets
    hyb = _trainer(scenes, dets, tmp_path / "hyb", network_classes="ss_model")
    full = _trainer(scenes, dets, tmp_path / "all")
    n_hyb, n_full = _loss_terms(hyb, scenes, dets), _loss_terms(full, scenes, dets)
    # the GT boxes of bicycles, motorcycles and trailers give no terms (their tracks run the preset's EKF)
    n_two_wheel = sum(int(np.isin(f.gt.labels, [0, 3, 5]).sum()) for s in scenes for f in s.frames)
    assert n_two_wheel > 0 and 0 < n_hyb < n_full
    final = hyb.run()
    assert all(r.gt_terms > 0 for r in hyb.log.steps)
    assert load_network(final).cfg.network_classes == "ss_model"


def test_network_classes_is_a_named_option():
    from grutrack.training.config import load_train_config

    assert load_train_config("paper").network["network_classes"] == "all"  # the paper: one network for all
    assert load_train_config("grukf").network["network_classes"] == "own_model"  # the default recipe
    assert GRUKFConfig().network_classes == "all"  # checkpoints written before the key: every class
    with pytest.raises(ConfigError, match="'network.network_classes' must be 'all', 'ss_model' or 'own_model'"):
        load_train_config("grukf", {"network_classes": "ctra"})
    with pytest.raises(ValueError, match="network_classes"):
        GRUKalmanNet(GRUKFConfig(network_classes="ctra"))


def test_untrained_ekf_prior_with_network_classes_own_model_runs_each_class_with_its_own_model(
    scenes_and_dets, tmp_path, ekf_coasting_keep
):
    """own_model: one network group per SS model (CTRA, Bicycle in the preset's piecewise form), the weights
    shared; untrained, each is the EKF of its classes' own model and noise, so the boxes are the preset's."""
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes

    scenes, dets = scenes_and_dets
    over = {"gain_prior": "ekf", "yaw_flip": True, "motion_config": "grutrack_nusc"}
    ck = _trainer(scenes, dets, tmp_path / "own", network_classes="own_model", **over).save("model.pt")
    own = build_tracker("grukf", ekf_coasting_keep, checkpoint=ck, device="cpu")
    nets = [(g.backend.ss.name, [TRACKING_CLASSES[i] for i in np.flatnonzero(g.classes)]) for g in own.groups[:2]]
    assert nets == [("CTRA", list(CTRA_CLASSES)), ("Bicycle", ["bicycle", "motorcycle"])]
    assert own.groups[0].backend.net is own.groups[1].backend.net  # one network, two SS models
    assert sorted(type(g.backend.model).__name__ for g in own.groups[2:]) == ["CA", "CV"]

    ekf = _boxes_by_label(track_scenes(build_tracker("ekf", ekf_coasting_keep), scenes, dets).results)
    got = _boxes_by_label(track_scenes(own, scenes, dets).results)
    for name in TRACKING_CLASSES:
        assert got[name].shape == ekf[name].shape
        np.testing.assert_allclose(got[name], ekf[name], atol=1e-6, err_msg=name)
    assert len(ekf["bicycle"]) + len(ekf["motorcycle"]) > 10


def test_training_with_network_classes_own_model_takes_loss_terms_of_both_models(scenes_and_dets, tmp_path):
    from grutrack.motion.checkpoint import load_network

    scenes, dets = scenes_and_dets
    over = {"gain_prior": "ekf", "motion_config": "grutrack_nusc"}
    own = _trainer(scenes, dets, tmp_path / "own", network_classes="own_model", **over)
    hyb = _trainer(scenes, dets, tmp_path / "hyb", network_classes="ss_model", **over)
    n_own, n_hyb = _loss_terms(own, scenes, dets), _loss_terms(hyb, scenes, dets)
    assert n_own > n_hyb > 0  # the bicycles' and motorcycles' tracks add terms
    own.run()
    net = load_network(tmp_path / "own" / "model.pt")
    assert net.cfg.network_classes == "own_model"
    assert net.cfg.model_params["BICYCLE"]["form"] == "piecewise"  # the ekf preset's form of the model
    # the Bicycle classes keep their own noise in the network's EKF prior (not CTRA's)
    from grutrack.motion.config import load_motion_config

    motion = load_motion_config("grutrack_nusc")
    np.testing.assert_array_equal(net.ekf_P0[TRACKING_CLASSES.index("bicycle")].numpy(), motion["bicycle"]["P0"])


def test_network_classes_own_model_takes_several_scenes_per_step():
    """Its groups of one model each run in lockstep, one network call per group and frame
    (tests/test_grukf_lockstep.py checks the gradient)."""
    from grutrack.training.config import load_train_config

    assert load_train_config("grukf", {"network_classes": "own_model", "scenes_per_step": 2}).scenes_per_step == 2


def test_training_classes_own_model_trains_on_the_two_wheelers_and_tracks_with_network_classes(
    scenes_and_dets, tmp_path, ekf_coasting_keep
):
    """training_classes own_model with network_classes ss_model: training runs the Bicycle classes through the
    network too (their loss terms), while validation and the checkpoint track them with the preset's EKF."""
    from grutrack.motion.checkpoint import load_network
    from grutrack.tracking.factory import build_tracker, network_members
    from grutrack.tracking.tracker import track_scenes

    scenes, dets = scenes_and_dets
    over = {"gain_prior": "ekf", "yaw_flip": True, "motion_config": "grutrack_nusc", "network_classes": "ss_model"}
    both = _trainer(scenes, dets, tmp_path / "both", training_classes="own_model", **over)
    hyb = _trainer(scenes, dets, tmp_path / "hyb", **over)
    own = _trainer(scenes, dets, tmp_path / "own", **{**over, "network_classes": "own_model"})
    assert _loss_terms(both, scenes, dets) == _loss_terms(own, scenes, dets) > _loss_terms(hyb, scenes, dets)

    untrained = build_tracker("grukf", ekf_coasting_keep, checkpoint=both.save("untrained.pt"), device="cpu")
    ekf = _boxes_by_label(track_scenes(build_tracker("ekf", ekf_coasting_keep), scenes, dets).results)
    got = _boxes_by_label(track_scenes(untrained, scenes, dets).results)
    for name in TRACKING_CLASSES:  # untrained it is the preset, as ss_model is
        np.testing.assert_allclose(got[name], ekf[name], atol=1e-8, err_msg=name)

    both.run()
    net = load_network(tmp_path / "both" / "model.pt")
    assert net.cfg.network_classes == "ss_model"
    assert net.cfg.model_params["BICYCLE"]["form"] == "piecewise"
    tracker = build_tracker("grukf", ekf_coasting_keep, checkpoint=tmp_path / "both" / "model.pt", device="cpu")
    members = network_members(net.cfg, tracker.cfg, np.arange(len(TRACKING_CLASSES)))
    assert [TRACKING_CLASSES[i] for i in np.flatnonzero(members)] == list(CTRA_CLASSES)
    # trained on the two-wheelers: its weights differ from the ss_model-only training of the same steps
    hyb.run()
    other = load_network(tmp_path / "hyb" / "model.pt")
    assert any(
        not np.allclose(a.detach().numpy(), b.detach().numpy()) for a, b in zip(net.parameters(), other.parameters())
    )
    trained = _boxes_by_label(track_scenes(tracker, scenes, dets).results)
    for name in ("bicycle", "motorcycle", "trailer"):  # tracked with the preset's EKF all the same
        np.testing.assert_allclose(trained[name], ekf[name], atol=1e-8, err_msg=name)


def test_training_classes_own_model_is_refused_where_it_cannot_apply():
    from grutrack.training.config import load_train_config

    assert load_train_config("grukf").training_classes == "own_model"  # the default recipe
    assert load_train_config("paper").training_classes == "tracked"  # optional key, the paper's behaviour
    with pytest.raises(ConfigError, match="'training_classes' must be 'tracked' or 'own_model'"):
        load_train_config("grukf", {"training_classes": "all"})
    assert load_train_config("grukf", {"training_classes": "own_model", "scenes_per_step": 2}).scenes_per_step == 2
    with pytest.raises(ConfigError, match="'training_classes' 'own_model' needs network.network_classes 'ss_model' or"):
        load_train_config("grukf", {"training_classes": "own_model", "network_classes": "all"})


def test_a_checkpoint_written_before_training_classes_resumes_with_its_default(scenes_and_dets, tmp_path):
    """A run saved by a version without the key trained on the tracked classes: resuming it with the key at that
    value is the same run; with the key changed it is refused, naming the key."""
    import torch

    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path / "old", network_classes="ss_model")
    path = t.save("last.pt")
    ck = torch.load(path, weights_only=False)
    del ck["train_config"]["training_classes"]
    torch.save(ck, path)
    _trainer(scenes, dets, tmp_path / "old", network_classes="ss_model").resume(path)
    with pytest.raises(ConfigError, match="training_classes 'tracked' -> 'own_model'"):
        _trainer(scenes, dets, tmp_path / "old", network_classes="ss_model", training_classes="own_model").resume(path)


def test_a_checkpoint_written_before_the_network_section_resumes(scenes_and_dets, tmp_path):
    """A run saved by a version with the network's options at the top level of its training config (and without
    the options added since) resumes as the same run; a changed network option is refused, naming it."""
    import torch

    from grutrack.training.config import config_record

    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path, network_classes="ss_model")
    path = t.save("last.pt")
    ck = torch.load(path, weights_only=False)
    network = ck["train_config"].pop("network")
    ck["train_config"].update({k: v for k, v in network.items() if k not in ("coast_acceleration", "min_size")})
    torch.save(ck, path)
    assert config_record(ck["train_config"])["network"] == network
    _trainer(scenes, dets, tmp_path, network_classes="ss_model").resume(path)
    with pytest.raises(ConfigError, match="cannot resume with other training settings \\(network.gap_bins 5 -> 2\\)"):
        _trainer(scenes, dets, tmp_path, network_classes="ss_model", gap_bins=2).resume(path)
