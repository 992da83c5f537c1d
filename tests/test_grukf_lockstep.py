"""Several scenes per training step (``scenes_per_step``): the scenes tracked side by side with the network run
once per frame over all of them (:mod:`grutrack.training.lockstep`) must give the mean of the one-scene losses and
its gradient, with fewer network calls; a failing scene must stop the step with its own error, not hang it."""

from __future__ import annotations

import threading

import pytest
import torch


@pytest.fixture(scope="module")
def scenes_and_dets(nusc_mini, tmp_path_factory):
    """Three mini_train scenes of 10, 6 and 10 frames (the short one leaves the lockstep early) with simulated
    CenterPoint-like detections (SYNTHETIC, seed 5)."""
    from support.grukf_data import mini_train_scenes_and_dets

    from grutrack.data.scene import Scene

    scenes, dets = mini_train_scenes_and_dets(nusc_mini, tmp_path_factory.mktemp("dets"), 3, 10)
    scenes[1] = Scene(scenes[1].name, scenes[1].token, scenes[1].frames[:6])
    return scenes, dets


def _trainer(scenes, dets, out, **over):
    """A trainer of the default recipe (``grukf``: training_classes own_model, the CTRA and the Bicycle network
    groups) with ``over`` overrides, on the CPU."""
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config("grukf", {"epochs": 1, "checkpoint_every": 0, "device": "cpu", **over})
    t = Trainer(cfg, scenes, dets, out, progress=False)
    with torch.no_grad():  # a trained-looking output layer: gradients reach every layer through K
        g = torch.Generator().manual_seed(3)
        t.net.fc_gain[2].weight.add_(torch.randn(t.net.fc_gain[2].weight.shape, generator=g) * 1e-2)
    return t


def _counting(net):
    """Count the calls of ``net.correct`` (wraps the bound method on the instance) by SS model: {model name:
    calls} (the network's own model when no ``ss`` is passed)."""
    calls: dict[str, int] = {}
    inner = net.correct

    def correct(*a, **k):
        name = (k.get("ss") or net.ss).name.upper()
        calls[name] = calls.get(name, 0) + 1
        return inner(*a, **k)

    net.correct = correct
    return calls


def _loss_and_grads(t, scenes, together: bool):
    from grutrack.training.loss import run_scene, run_scenes

    t.net.zero_grad(set_to_none=True)
    with t.net.deferring_weight_grads() as d:
        if together:
            losses = run_scenes(t.net, [(sc, t.index, t.tracker_cfg) for sc in scenes], t.cfg, t.dets, t.device)
        else:
            losses = [run_scene(t.net, sc, t.dets, t.tracker_cfg, t.cfg, t.device, t.index) for sc in scenes]
        value = torch.stack([lo.value() for lo in losses]).mean()
        d.backward(value, list(t.net.parameters()))
    grads = {k: p.grad.clone() for k, p in t.net.named_parameters() if p.grad is not None}
    return value.detach(), grads, [(lo.gt_terms, lo.pseudo_terms) for lo in losses]


#: every ``training_classes`` value, the default recipe as it ships among them; (overrides, the network's SS models)
SETTINGS = {
    "default_recipe": ({}, ("CTRA", "BICYCLE")),  # training_classes own_model, network_classes own_model, EKF prior
    "own_model-network_classes_ss_model": ({"network_classes": "ss_model"}, ("CTRA", "BICYCLE")),
    "tracked": ({"training_classes": "tracked", "network_classes": "ss_model"}, ("CTRA",)),
    "tracked-all-constant_prior": (
        {"training_classes": "tracked", "network_classes": "all", "gain_prior": "constant"},
        ("CTRA",),
    ),
    "tracked-four_gru-aux": (
        {"training_classes": "tracked", "network_classes": "ss_model", "four_gru": True, "aux_inputs": True},
        ("CTRA",),
    ),
}


def test_the_settings_cover_every_training_classes_value():
    from grutrack.config_loader import schema

    values = schema("training")["properties"]["training_classes"]["enum"]
    assert {over.get("training_classes", "own_model") for over, _ in SETTINGS.values()} == set(values)


@pytest.mark.parametrize("setting", list(SETTINGS))
def test_lockstep_equals_the_mean_of_one_scene_steps(scenes_and_dets, tmp_path, setting):
    over, models = SETTINGS[setting]
    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path, **over)
    calls = _counting(t.net)
    v1, g1, terms1 = _loss_and_grads(t, scenes, together=False)
    separate = dict(calls)
    calls.clear()
    v3, g3, terms3 = _loss_and_grads(t, scenes, together=True)
    lockstep = dict(calls)
    # every network group of the setting corrected tracks (own_model: the Bicycle group's too)
    assert set(separate) == set(lockstep) == set(models)
    assert terms3 == terms1 and sum(a + b for a, b in terms1) > 0
    # the network runs in float32: a batch of other size rounds its matrix products differently (~1e-7)
    torch.testing.assert_close(v3, v1, rtol=1e-6, atol=0.0)
    assert g3.keys() == g1.keys() and {"fc_gain.0.weight", "gru_s.weight_ih"} <= g1.keys()
    for k in g1:
        scale = g1[k].abs().max().item()
        assert scale > 0, k
        torch.testing.assert_close(g3[k], g1[k], rtol=1e-4, atol=1e-5 * scale, msg=k)
    # bit for bit the same gradient when run again (the network calls made by one thread of their own)
    v3b, g3b, _ = _loss_and_grads(t, scenes, together=True)
    assert torch.equal(v3b, v3) and all(torch.equal(g3b[k], g3[k]) for k in g3)
    # per network group, one call per frame for all scenes: at most the longest scene's frames, fewer than the
    # separate calls
    for model in models:
        assert 0 < lockstep[model] <= max(len(s) for s in scenes), model
        assert lockstep[model] < separate[model], model
    assert sum(lockstep.values()) <= max(len(s) for s in scenes) * len(models) < sum(separate.values())


def test_a_failing_scene_stops_the_step_with_its_own_error(scenes_and_dets, tmp_path):
    from grutrack.training.loss import run_scenes

    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path)
    missing = dict(dets)
    del missing[scenes[1].frames[3].token]  # the second scene fails in its 4th frame
    result: dict = {}

    def go():
        try:
            run_scenes(t.net, [(sc, t.index, t.tracker_cfg) for sc in scenes], t.cfg, missing, t.device)
        except BaseException as exc:  # noqa: BLE001
            result["exc"] = exc

    th = threading.Thread(target=go, daemon=True)
    th.start()
    th.join(120)
    assert not th.is_alive(), "the other scenes were left waiting"
    assert isinstance(result.get("exc"), KeyError) and scenes[1].frames[3].token in str(result["exc"])


def test_a_failing_network_call_stops_the_step_with_its_error(scenes_and_dets, tmp_path):
    """The network thread's failure (here its third call) reaches the caller; no scene is left waiting."""
    from grutrack.training.loss import run_scenes

    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path)
    calls = _counting(t.net)
    inner = t.net.correct

    def correct(*a, **k):
        if sum(calls.values()) == 2:
            raise FloatingPointError("the third network call failed")
        return inner(*a, **k)

    t.net.correct = correct
    result: dict = {}

    def go():
        try:
            run_scenes(t.net, [(sc, t.index, t.tracker_cfg) for sc in scenes], t.cfg, t.dets, t.device)
        except BaseException as exc:  # noqa: BLE001
            result["exc"] = exc

    th = threading.Thread(target=go, daemon=True)
    th.start()
    th.join(120)
    assert not th.is_alive(), "the scenes were left waiting"
    assert isinstance(result.get("exc"), FloatingPointError) and sum(calls.values()) == 2


def test_trainer_takes_scenes_per_step(scenes_and_dets, tmp_path):
    """3 scenes, 2 per step: 2 steps an epoch (the last one short), each logged with its scenes' names; the
    resumed run continues at the right scene."""
    scenes, dets = scenes_and_dets
    t = _trainer(scenes, dets, tmp_path / "a", epochs=2, scenes_per_step=2)
    assert t.total_steps == 4
    t.run(max_steps=3)
    names = [r.scene for r in t.log.steps]
    assert [len(n.split("+")) for n in names] == [2, 1, 2]
    assert sorted("+".join(names[:2]).split("+")) == sorted(s.name for s in scenes)
    assert all(r.gt_terms + r.pseudo_terms > 0 for r in t.log.steps)
    t2 = _trainer(scenes, dets, tmp_path / "a", epochs=2, scenes_per_step=2)
    t2.resume(tmp_path / "a" / "last.pt")
    t2.run()
    assert t2.state.step == 4 and len(t2.log.steps[-1].scene.split("+")) == 1
    whole = _trainer(scenes, dets, tmp_path / "b", epochs=2, scenes_per_step=2)
    whole.run()  # the same 4 steps without the interruption: the same weights
    ref = whole.net.state_dict()
    assert all(torch.equal(t2.net.state_dict()[k], ref[k]) for k in ref)


def test_scenes_per_step_is_validated():
    from grutrack.errors import ConfigError
    from grutrack.training.config import load_train_config

    assert load_train_config("grukf").scenes_per_step == 1  # the paper's one step per scene
    with pytest.raises(ConfigError, match="scenes_per_step"):
        load_train_config("grukf", {"scenes_per_step": 0})
    # every training_classes and network_classes setting takes several scenes per step
    for over in ({}, {"network_classes": "own_model"}, {"training_classes": "tracked", "network_classes": "all"}):
        assert load_train_config("grukf", {**over, "scenes_per_step": 8}).scenes_per_step == 8
