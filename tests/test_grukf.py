"""The GRU-Kalman filter: torch SS models, batching, yaw wrap, gain prior, training determinism and resume,
sticky GT association, checkpoints."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from grutrack.data.scene import Scene
from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig
from grutrack.motion.models import CTRA, Bicycle
from grutrack.motion.torch_models import TorchBicycle, TorchCTRA
from grutrack.training.gt_association import StickyGTAssociation


def _states(n, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [
            rng.normal(0, 500, (n, 3)),
            rng.uniform(0.5, 5, (n, 3)),
            rng.normal(0, 8, n),
            rng.normal(0, 1, n),
            rng.uniform(-3, 3, n),
            rng.uniform(-0.4, 0.4, n),
        ]
    )


def test_torch_ss_models_match_numpy():
    x = _states(2000)
    assert np.abs(CTRA().f(x, 0.5) - TorchCTRA().f(torch.tensor(x), 0.5).numpy()).max() < 1e-8
    assert np.abs(CTRA().h(x) - TorchCTRA().h(torch.tensor(x)).numpy()).max() < 1e-12
    beta = np.arctan2(0.5 * np.sin(x[:, 9]), np.cos(x[:, 9]))
    ds = x[:, 6] * 0.5 + 0.125 * x[:, 7]
    ok = np.abs(np.sin(beta) / (0.4 * x[:, 4]) * ds) < 1.0  # turns of less than a radian per frame
    diff = Bicycle().f(x, 0.5) - TorchBicycle().f(torch.tensor(x), 0.5).numpy()
    assert np.abs(diff[ok]).max() < 1e-6 and ok.mean() > 0.5


def test_torch_piecewise_bicycle_matches_numpy_in_both_branches():
    """The piecewise form (Poly-MOT's; the ekf preset's bicycle_form) equals the numpy model, turning (constant
    speed, a reset to 0) and straight (|beta| <= 1e-3: v + a dt, yaw kept)."""
    from grutrack.motion.models import BicyclePiecewise
    from grutrack.motion.torch_models import TorchBicyclePiecewise, make_torch_model

    x = _states(2000, seed=5)
    x[::3, 9] = np.random.default_rng(1).uniform(-1e-3, 1e-3, len(x[::3]))  # straight rows
    ref, tm = BicyclePiecewise(), make_torch_model("bicycle", form="piecewise")
    assert isinstance(tm, TorchBicyclePiecewise)
    got = tm.f(torch.tensor(x), 0.5).numpy()
    beta = np.arctan2(0.5 * np.sin(x[:, 9]), np.cos(x[:, 9]))
    ok = np.abs(np.sin(beta) / (0.4 * x[:, 4]) * x[:, 6] * 0.5) < 1.0  # turns of less than a radian per frame
    assert np.abs(ref.f(x, 0.5) - got)[ok].max() < 1e-6 and ok.mean() > 0.5
    straight = np.abs(beta) <= 1e-3
    assert straight.sum() > 500 and np.all(got[straight, 8] == x[straight, 8])
    assert np.all(got[~straight, 7] == 0.0)
    with pytest.raises(ValueError, match="form"):
        make_torch_model("CTRA", form="piecewise")


@pytest.mark.parametrize("wheelbase_ratio, front_ratio", [(0.8, 0.5), (0.6, 0.3), (0.95, 0.7)])
def test_torch_bicycle_matches_numpy_at_any_parameters(wheelbase_ratio, front_ratio):
    """f, h and the initial state of the torch Bicycle equal the numpy model's at non-default parameters too
    (reference point off the box centre when front_ratio != 0.5)."""
    x = _states(2000, seed=3)
    ref, tm = Bicycle(wheelbase_ratio, front_ratio), TorchBicycle(wheelbase_ratio, front_ratio)
    assert np.abs(ref.h(x) - tm.h(torch.tensor(x)).numpy()).max() < 1e-12
    z = ref.h(x)
    assert np.abs(ref.init_state(z) - tm.init_state(torch.tensor(z)).numpy()).max() < 1e-9
    beta = np.arctan2((1 - front_ratio) * np.sin(x[:, 9]), np.cos(x[:, 9]))
    ds = x[:, 6] * 0.5 + 0.125 * x[:, 7]
    ok = np.abs(np.sin(beta) / ((1 - front_ratio) * wheelbase_ratio * x[:, 4]) * ds) < 1.0
    diff = ref.f(x, 0.5) - tm.f(torch.tensor(x), 0.5).numpy()
    assert np.abs(diff[ok]).max() < 1e-6 and ok.mean() > 0.4


def test_the_network_takes_the_motion_configs_model_parameters(tmp_path):
    """The trained network's SS model is built with the training motion config's parameters, stored in the
    checkpoint's architecture."""
    import yaml

    from grutrack.motion.config import resolve_config_path
    from grutrack.training.config import load_train_config
    from grutrack.training.network import network_config as _arch

    raw = yaml.safe_load(resolve_config_path("polymot_nusc").read_text())
    raw["models"]["Bicycle"]["params"] = {"wheelbase_ratio": 0.6, "front_ratio": 0.3}
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(raw))
    arch = _arch(load_train_config("grukf", {"ss_model": "Bicycle", "motion_config": str(tmp_path / "m.yaml")}))
    net = GRUKalmanNet(arch)
    assert arch.ss_params == {"wheelbase_ratio": 0.6, "front_ratio": 0.3}
    assert (net.ss.wheelbase_ratio, net.ss.front_ratio) == (0.6, 0.3)


def _net(seed=0, **kw):
    torch.manual_seed(seed)
    net = GRUKalmanNet(GRUKFConfig(**kw))
    K0 = torch.zeros(10, 9)
    for i in range(6):
        K0[i, i] = 0.6
    K0[8, 6], K0[6, 7] = 0.5, 0.5
    net.set_gain_prior(K0)
    return net.double()


@pytest.mark.parametrize("kw", [{}, {"four_gru": True, "class_gain": True, "aux_inputs": True}])
def test_initialisation_from_a_generator_is_torchs_default_and_leaves_the_global_one_alone(kw):
    from torch import nn

    cfg = GRUKFConfig(**kw)
    before = torch.get_rng_state()
    net = GRUKalmanNet(cfg, generator=torch.Generator().manual_seed(7))
    assert torch.equal(torch.get_rng_state(), before)  # nothing drawn from the global generator
    # the reference: torch's own reset of every layer, in creation order, after a global seed
    ref = GRUKalmanNet(cfg, generator=torch.Generator().manual_seed(123))
    torch.manual_seed(7)
    for mod in ref.modules():
        if isinstance(mod, (nn.Linear, nn.GRUCell)):
            mod.reset_parameters()
    with torch.no_grad():
        ref.fc_gain[2].weight.zero_()
        ref.fc_gain[2].bias.zero_()
    a, b = net.state_dict(), ref.state_dict()
    assert set(a) == set(b) and all(torch.equal(a[k], b[k]) for k in a)
    assert float(a["fc_gain.2.weight"].abs().sum()) == 0.0 and float(a["gru_q.weight_ih"].std()) > 0
    # the gain prior's small weights come from the same generator
    K0 = torch.zeros(10, 9)
    g1, g2 = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    before = torch.get_rng_state()
    net.set_gain_prior(K0, generator=g1)
    w = net.fc_gain[2].weight
    assert torch.equal(w, torch.randn(w.shape, generator=g2) * 1e-3) and torch.equal(torch.get_rng_state(), before)


def _correct_inputs(n, seed=1):
    rng = np.random.default_rng(seed)
    prior = torch.tensor(_states(n, seed))
    y = TorchCTRA().h(prior) + torch.tensor(rng.normal(0, 0.3, (n, 9)))
    args = [prior, y, y + 0.1, prior - 0.05, prior + 0.02, prior - 0.1]
    return args


def test_batching_equals_one_by_one():
    net = _net()
    args = _correct_inputs(6)
    hidden = net.init_hidden(6)
    hidden = {k: torch.randn_like(v) * 0.1 for k, v in hidden.items()}
    with torch.no_grad():
        x_all, h_all, _ = net.correct(*args, hidden)
        for i in range(6):
            xi, hi, _ = net.correct(*[a[i : i + 1] for a in args], {k: v[i : i + 1] for k, v in hidden.items()})
            assert torch.allclose(xi, x_all[i : i + 1], atol=1e-9)
            assert all(torch.allclose(hi[k], h_all[k][i : i + 1], atol=1e-9) for k in hi)


def test_a_network_used_in_inference_mode_then_trains_with_the_same_values():
    # tracking runs the network under torch.inference_mode; the index tensors it caches then must still serve a
    # training pass (autograd saves them), and the forward values are those of no_grad
    net = _net()
    args = _correct_inputs(4)
    with torch.inference_mode():
        x_inf, _, K_inf = net.correct(*args, net.init_hidden(4))
    x, _, K = net.correct(*args, net.init_hidden(4))
    x.sum().backward()
    assert torch.equal(x.detach(), x_inf) and torch.equal(K.detach(), K_inf)
    assert float(net.fc_gain[2].weight.grad.abs().sum()) > 0 and float(net.gru_q.weight_ih.grad.abs().sum()) > 0


def test_yaw_residual_wrapped():
    net = _net()
    prior = torch.tensor(_states(1))
    prior[0, 8] = -math.pi + 0.01
    y = TorchCTRA().h(prior)
    y[0, 6] = math.pi - 0.01  # 0.02 rad away across the +-pi seam
    with torch.no_grad():
        x, _, _ = net.correct(prior, y, y, prior, prior, prior, net.init_hidden(1))
    step = (x[0, 8] - prior[0, 8] + math.pi) % (2 * math.pi) - math.pi
    assert abs(float(step)) < 0.03 and -math.pi <= float(x[0, 8]) < math.pi


def test_gain_prior_gives_constant_gain_filter_in_heading_frame():
    net = _net()
    with torch.no_grad():
        net.fc_gain[2].weight.zero_()
    prior = torch.tensor(_states(3))
    y = TorchCTRA().h(prior)
    y[:, 0] += 1.0  # 1 m innovation along global x
    with torch.no_grad():
        x, _, _ = net.correct(prior, y, y, prior, prior, prior, net.init_hidden(3))
    # K0 has 0.6 on x and y in the heading frame: the global correction is 0.6 m along x for any heading
    assert torch.allclose(x[:, 0] - prior[:, 0], torch.full((3,), 0.6, dtype=torch.float64), atol=1e-9)
    assert torch.allclose(x[:, 1], prior[:, 1], atol=1e-9)


def test_four_gru_variant_is_separate_and_runs():
    a, b = _net(), _net(four_gru=True)
    assert sum(p.numel() for p in b.parameters()) > sum(p.numel() for p in a.parameters())
    assert not hasattr(a, "gru_r") and hasattr(b, "gru_r")
    with torch.no_grad():
        x, h, _ = b.correct(*_correct_inputs(4), b.init_hidden(4))
    assert x.shape == (4, 10) and set(h) == {"q", "sigma", "s", "r"}


def test_sticky_gt_association_no_index_bug():
    a = StickyGTAssociation(2.0)
    gt_ids = np.array(["g0", "g1", "g2"], dtype=object)
    gt_xy = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    lab = np.zeros(3, dtype=np.int64)
    # frame 1: track 7 takes g1
    assert a.match(np.array([7]), np.array([[10.2, 0.0]]), np.array([0]), gt_ids, gt_xy, lab).tolist() == [1]
    # frame 2: GT order changes and g0 disappears; track 7 keeps g1 (sticky, even 3 m away), the new track 8
    # near g2 gets g2 (the row of the *current* list, not of the free subset)
    ids2 = np.array(["g1", "g2"], dtype=object)
    xy2 = np.array([[10.0, 0.0], [20.0, 0.0]])
    got = a.match(
        np.array([7, 8]), np.array([[13.0, 0.0], [20.5, 0.0]]), np.array([0, 0]), ids2, xy2, np.zeros(2, dtype=np.int64)
    )
    assert got.tolist() == [0, 1]
    # a free track cannot take a held instance, and classes must agree
    got = a.match(np.array([9]), np.array([[10.0, 0.0]]), np.array([0]), ids2, xy2, np.zeros(2, dtype=np.int64))
    assert got.tolist() == [-1]


# ----- training on real mini_train ground truth with simulated detections ------------------------------------
@pytest.fixture(scope="module")
def small_training_set(nusc_mini):
    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes

    scenes = load_scenes(nusc_mini, "mini_train", with_gt=True)[:2]
    scenes = [Scene(s.name, s.token, s.frames[:12]) for s in scenes]
    sub = simulate_nuscenes(None, "v1.0-mini", "mini_train", "centerpoint", seed=5, nusc=nusc_mini)
    import json
    import os
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "dets.json")
        with open(p, "w") as f:
            json.dump(sub, f)
        dets = load_detections(p, [f.token for s in scenes for f in s.frames])
    return scenes, dets


def _trainer(scenes, dets, out, source=None, **over):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config("grukf", {"epochs": 2, "checkpoint_every": 0, "device": "cpu", "lr": 1e-3, **over})
    return Trainer(cfg, scenes, dets, out, progress=False, source=source)


def test_training_is_deterministic_and_resumes_exactly(small_training_set, tmp_path):
    scenes, dets = small_training_set
    a = _trainer(scenes, dets, tmp_path / "a")
    a.run()
    b = _trainer(scenes, dets, tmp_path / "b")
    b.run(max_steps=3)  # stop mid-epoch 2 ...
    c = _trainer(scenes, dets, tmp_path / "b")
    c.resume(tmp_path / "b" / "last.pt")
    c.run()  # ... and continue from the checkpoint
    sa, sc = a.net.state_dict(), c.net.state_dict()
    assert all(torch.equal(sa[k], sc[k]) for k in sa)
    assert [r.loss for r in a.log.steps] == [r.loss for r in c.log.steps]
    assert len(a.log.steps) == 4 and a.log.steps[0].gt_terms > 0 and a.log.steps[0].pseudo_terms > 0
    # training moved the weights away from the gain prior
    init = _trainer(scenes, dets, tmp_path / "d").net.state_dict()
    assert any(not torch.equal(init[k], sa[k]) for k in sa)
    text = (tmp_path / "a" / "train_log.csv").read_text().splitlines()
    assert text[0].startswith("step,epoch,scene,loss") and len(text) == 5


def test_training_uses_its_own_generators(small_training_set, tmp_path):
    import random

    scenes, dets = small_training_set
    np.random.seed(11)
    random.seed(11)
    torch.manual_seed(11)
    before = (torch.get_rng_state(), np.random.get_state()[1].copy(), random.getstate())
    t = _trainer(scenes, dets, tmp_path, epochs=1)
    t.run(max_steps=1)
    after = (torch.get_rng_state(), np.random.get_state()[1], random.getstate())
    assert torch.equal(before[0], after[0]) and np.array_equal(before[1], after[1]) and before[2] == after[2]
    # the initial weights are those of the config seed, whatever the process-wide generators hold
    torch.manual_seed(99)
    again = _trainer(scenes, dets, tmp_path / "again", epochs=1)
    first = GRUKalmanNet(again.net.cfg, generator=torch.Generator().manual_seed(again.cfg.seed)).state_dict()
    assert torch.equal(again.net.state_dict()["gru_q.weight_ih"], first["gru_q.weight_ih"])
    from grutrack.motion.checkpoint import read_checkpoint

    assert set(read_checkpoint(tmp_path / "last.pt")["rng"]) == {"numpy", "torch"}


@pytest.fixture(scope="module")
def uninterrupted_run(small_training_set, tmp_path_factory):
    """A 3-epoch (6-step) run never stopped: weights and log rows."""
    scenes, dets = small_training_set
    a = _trainer(scenes, dets, tmp_path_factory.mktemp("ref"), epochs=3)
    a.run()
    return a.net.state_dict(), a.log.steps


@pytest.mark.parametrize(
    "how,checkpoint_every,stop_at",
    [
        ("crash", 2, 5),  # periodic checkpoint at step 4, the process dies inside step 5 (mid-epoch 3)
        ("crash", 1, 3),  # checkpoint after step 2 (the end of epoch 1), dies inside step 3
        ("crash", 5, 6),  # checkpoint at step 5 (mid-epoch), dies inside the last step
        ("sigint", 0, 1),  # Ctrl-C during step 1, no periodic checkpoints at all
        ("sigint", 2, 4),  # Ctrl-C during the last step of epoch 2
    ],
)
def test_resume_after_interruption_equals_uninterrupted_run(
    small_training_set, uninterrupted_run, tmp_path, monkeypatch, how, checkpoint_every, stop_at
):
    import os
    import signal

    from grutrack.motion.checkpoint import read_checkpoint
    from grutrack.training import trainer as tr

    scenes, dets = small_training_set
    ref_state, ref_log = uninterrupted_run
    real, calls = tr.run_scene, []

    def interrupted(*a, **k):
        calls.append(1)
        if len(calls) == stop_at:
            if how == "crash":
                raise RuntimeError("power cut")
            os.kill(os.getpid(), signal.SIGINT)  # a real SIGINT, as Ctrl-C sends it
        return real(*a, **k)

    monkeypatch.setattr(tr, "run_scene", interrupted)
    before = signal.getsignal(signal.SIGINT)  # Python's handler, or SIG_IGN when started as a background job
    t = _trainer(scenes, dets, tmp_path, epochs=3, checkpoint_every=checkpoint_every)
    if how == "crash":
        with pytest.raises(RuntimeError, match="power cut"):
            t.run()
        saved = (stop_at - 1) // checkpoint_every * checkpoint_every
    else:
        with pytest.raises(tr.TrainingInterrupted, match=f"after step {stop_at}.*last.pt"):
            t.run()
        saved = stop_at  # the step under way completes, then last.pt is written
    assert signal.getsignal(signal.SIGINT) is before  # the trainer's handler is removed again
    assert read_checkpoint(tmp_path / "last.pt")["train_state"]["step"] == saved
    monkeypatch.setattr(tr, "run_scene", real)
    r = _trainer(scenes, dets, tmp_path, epochs=3, checkpoint_every=checkpoint_every)
    r.resume(tmp_path / "last.pt")
    r.run()
    state = r.net.state_dict()
    assert all(torch.equal(ref_state[k], state[k]) for k in ref_state)  # bit for bit
    assert r.state.step == 6 and [x.step for x in r.log.steps] == [1, 2, 3, 4, 5, 6]
    assert [(x.scene, x.loss, x.lr) for x in r.log.steps] == [(x.scene, x.loss, x.lr) for x in ref_log]


def test_resume_on_other_data_or_settings_is_refused(small_training_set, tmp_path):
    from grutrack.errors import ConfigError

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=2, source={"detections": "/d/a.json"})
    t.run(max_steps=1)
    with pytest.raises(ConfigError, match=r"last.pt: cannot resume with other training settings \(epochs 2 -> 3"):
        _trainer(scenes, dets, tmp_path, epochs=3).resume(tmp_path / "last.pt")
    with pytest.raises(ConfigError, match="cannot resume on other training data"):
        _trainer(scenes[:1], dets, tmp_path, epochs=2).resume(tmp_path / "last.pt")
    token = scenes[0].frames[3].token
    fewer = dict(dets, **{token: dets[token].subset(np.arange(len(dets[token]) - 1))})
    with pytest.raises(ConfigError, match=r"other training data .*detections '/d/a.json' -> '/d/b.json'"):
        _trainer(scenes, fewer, tmp_path, epochs=2, source={"detections": "/d/b.json"}).resume(tmp_path / "last.pt")
    # settings that leave the weights alone may change
    ok = _trainer(scenes, dets, tmp_path, epochs=2, val_every=7, checkpoint_every=3)
    ok.resume(tmp_path / "last.pt")
    assert ok.state.step == 1


def test_supervised_mode_has_no_pseudo_labels(small_training_set, tmp_path):
    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, mode="supervised", epochs=1)
    t.run()
    assert all(r.pseudo_terms == 0 for r in t.log.steps) and any(r.gt_terms > 0 for r in t.log.steps)


def test_checkpoint_loads_without_reinitialising(small_training_set, tmp_path):
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=1)
    final = t.run()
    tracker = build_tracker("grukf", checkpoint=final, device="cpu")
    loaded = tracker.groups[0].backend.net.state_dict()
    assert all(torch.equal(loaded[k], t.net.state_dict()[k]) for k in loaded)
    run = track_scenes(tracker, scenes[:1], dets)
    assert sum(len(r) for r in run.results.values()) > 0
    with pytest.raises(Exception, match="needs --checkpoint"):
        build_tracker("grukf")


def test_nan_loss_stops_training_and_keeps_last_good_checkpoint(small_training_set, tmp_path, monkeypatch):
    from grutrack.motion.checkpoint import read_checkpoint
    from grutrack.training import trainer as tr

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=2)
    t.run(max_steps=1)
    good = {k: v.clone() for k, v in t.net.state_dict().items()}
    real = tr.run_scene

    def poisoned(*a, **k):
        loss = real(*a, **k)
        value = loss.value
        loss.value = lambda: value() * float("nan")
        return loss

    monkeypatch.setattr(tr, "run_scene", poisoned)
    with pytest.raises(tr.TrainingDiverged, match="the loss is nan.*last good checkpoint is .*last.pt"):
        t.run()
    ck = read_checkpoint(tmp_path / "last.pt")
    assert all(torch.equal(ck["model"][k], good[k]) for k in good)
    assert ck["train_state"]["step"] == 1


def test_a_non_finite_gradient_stops_training_before_the_step(small_training_set, tmp_path, monkeypatch):
    from grutrack.motion import grukf
    from grutrack.training.trainer import TrainingDiverged

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=2)
    t.run(max_steps=1)
    good = {k: v.clone() for k, v in t.net.state_dict().items()}
    real = grukf.DeferredWeightGrads.backward

    def poisoned(self, loss, params):
        real(self, loss, params)
        params[3].grad[0] = float("inf")

    monkeypatch.setattr(grukf.DeferredWeightGrads, "backward", poisoned)
    with pytest.raises(TrainingDiverged, match="a gradient is NaN or infinite"):
        t.run()
    assert all(torch.equal(t.net.state_dict()[k], good[k]) for k in good)  # the step was not applied


def test_a_singular_innovation_covariance_stops_training_with_the_last_good_checkpoint(
    small_training_set, tmp_path, monkeypatch
):
    # a network that has driven the filter's state far off makes the EKF gain prior's S = H P H^T + R singular
    # (numpy's LinAlgError in the tracking of a scene): a diverged training, not a traceback
    from grutrack.motion.checkpoint import read_checkpoint
    from grutrack.tracking.grukf_backend import GRUKFBackend
    from grutrack.training.trainer import TrainingDiverged

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=2)
    t.run(max_steps=1)

    def singular(self, s, rows, z, *noise):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(GRUKFBackend, "_ekf_gain", singular)
    with pytest.raises(TrainingDiverged, match=r"step 2 .*the filter's state diverged \(Singular matrix.*last.pt"):
        t.run()
    assert read_checkpoint(tmp_path / "last.pt")["train_state"]["step"] == 1


def test_diverging_gain_stops_training(small_training_set, tmp_path):
    from grutrack.training.trainer import TrainingDiverged

    scenes, dets = small_training_set
    t = _trainer(scenes, dets, tmp_path, epochs=1)
    with torch.no_grad():
        t.net.fc_gain[2].bias.fill_(5e3)
    with pytest.raises(TrainingDiverged, match="gain diverged"):
        t.run()


# ----- gain table (class / update count / frames since the last update) --------------------------------------
def _table_net(**kw):
    """A network whose learned part is silent: K = shared prior + table cell."""
    net = _net(**kw)
    with torch.no_grad():
        net.fc_gain[2].weight.zero_()
    return net


def test_gain_table_cells_start_at_given_gains_and_are_looked_up_per_track():
    net = _table_net(class_gain=True, age_bins=2, gap_bins=3)
    assert tuple(net.gain_table.shape) == (7, 2, 3, 90)
    table = torch.full((7, 2, 3, 10, 9), float("nan"), dtype=torch.float64)
    for g in range(3):
        table[2, 1, g] = 0.0
        table[2, 1, g, 0, 0] = table[2, 1, g, 1, 1] = 0.2 * (g + 1)  # position gain grows with the gap
    net.set_gain_prior(torch.zeros(10, 9, dtype=torch.float64), table)
    with torch.no_grad():
        net.fc_gain[2].weight.zero_()
    net.double()
    prior = torch.tensor(_states(4))
    prior[:, 8] = 0.0  # heading along global x
    y = TorchCTRA().h(prior)
    y[:, 0] += 1.0
    labels = np.array([2, 2, 2, 4])
    n_upd = np.array([5, 5, 5, 5])
    gaps = np.array([1, 2, 9, 1])  # 9 -> the last gap bin
    cells = net.table_index(labels, n_upd, gaps)
    assert cells.tolist() == [(2 * 2 + 1) * 3 + 0, (2 * 2 + 1) * 3 + 1, (2 * 2 + 1) * 3 + 2, (4 * 2 + 1) * 3 + 0]
    with torch.no_grad():
        x, _, _ = net.correct(prior, y, y, prior, prior, prior, net.init_hidden(4), torch.as_tensor(cells))
    step = (x[:, 0] - prior[:, 0]).numpy()
    # class 4 had no update in the table (NaN cells): it starts at the shared prior (zero gain here)
    assert np.allclose(step, [0.2, 0.4, 0.6, 0.0], atol=1e-9)
    with pytest.raises(ValueError, match="gain table needs"):
        net.correct(prior, y, y, prior, prior, prior, net.init_hidden(4))


def test_backend_counts_updates_and_frames_since_the_last_update():
    from grutrack.tracking.grukf_backend import GRUKFBackend

    net = _table_net(age_bins=4, gap_bins=4)
    be = GRUKFBackend(net, "cpu")
    z = TorchCTRA().h(torch.tensor(_states(3))).numpy()
    s = be.initiate(z, np.array([0, 1, 2]))
    seen = []
    real = net.table_index
    net.table_index = lambda c, a, g: (seen.append((c.tolist(), a.tolist(), g.tolist())), real(c, a, g))[1]
    s = be.predict(s, 0.5)
    s = be.update(s, np.array([0, 2]), z[[0, 2]])  # first update, after one frame
    s = be.predict(be.predict(be.predict(s, 0.5), 0.5), 0.5)
    s = be.update(s, np.array([1, 2]), z[[1, 2]])  # track 1: first update after 4 frames; 2: second
    assert seen == [([0, 2], [1, 1], [1, 1]), ([1, 2], [1, 2], [4, 3])]
    assert s.n_updates.tolist() == [1, 1, 2] and s.since.tolist() == [3, 0, 0]
    both = be.concat(be.select(s, np.array([2])), be.select(s, np.array([0])))
    assert both.n_updates.tolist() == [2, 1] and both.since.tolist() == [0, 3]


def test_correct_returns_the_gain_and_the_backend_keeps_each_tracks_largest_entry():
    from grutrack.tracking.grukf_backend import GRUKFBackend

    net = _table_net()  # silent network: K = the prior K0 (largest entry 0.6)
    with torch.no_grad():
        _, _, K = net.correct(*_correct_inputs(2), net.init_hidden(2))
    assert K.shape == (2, 10, 9) and float(K.abs().max()) == pytest.approx(0.6)
    assert not hasattr(net, "max_abs_gain")  # no state written during forward passes
    be = GRUKFBackend(net, "cpu")
    z = TorchCTRA().h(torch.tensor(_states(3))).numpy()
    s = be.predict(be.initiate(z, np.array([0, 1, 2])), 0.5)
    assert s.gain_abs_max.tolist() == [0.0, 0.0, 0.0]
    s = be.update(s, np.array([0, 2]), z[[0, 2]])
    assert s.gain_abs_max.tolist() == pytest.approx([0.6, 0.0, 0.6])
    assert be.concat(be.select(s, np.array([1])), s).gain_abs_max.tolist() == pytest.approx([0.0, 0.6, 0.0, 0.6])


def test_backend_maps_dataset_labels_to_tracking_classes():
    from grutrack.tracking.grukf_backend import GRUKFBackend

    net = _table_net(class_gain=True)
    be = GRUKFBackend(net, "cpu", class_index=np.array([2, 2, 4]))  # e.g. three AV2 categories
    s = be.initiate(TorchCTRA().h(torch.tensor(_states(3))).numpy(), np.array([0, 1, 2]))
    cells = be._cells(be.predict(s, 0.5), np.array([0, 1, 2]))
    assert cells.tolist() == [2, 2, 4]  # flat cells of a (class, 1 age bin, 1 gap bin) table: the class


def test_ekf_gain_table_grows_after_missed_frames(small_training_set):
    from grutrack.tracking.config import load_tracker_config
    from grutrack.training.config import load_train_config
    from grutrack.training.gain_prior import mean_ekf_gain

    scenes, dets = small_training_set
    cfg = load_train_config("grukf", {"gap_bins": 3, "age_bins": 0, "class_gain": False})
    shared, table = mean_ekf_gain(scenes, dets, load_tracker_config(cfg.tracker_preset), cfg, np.arange(7))
    assert table.shape == (1, 1, 3, 10, 9) and np.isfinite(table[0, 0, :2]).all()
    # the covariance grows while a track coasts, so the next detection is trusted more
    assert table[0, 0, 1, 0, 0] > table[0, 0, 0, 0, 0]
    # the shared gain is the count-weighted mean of the cells: it lies between them
    assert table[0, 0, 0, 0, 0] <= shared[0, 0] <= table[0, 0, 1, 0, 0]


def test_prediction_terms_are_added_when_weighted(small_training_set, tmp_path):
    scenes, dets = small_training_set
    plain = _trainer(scenes, dets, tmp_path / "a", epochs=1)
    plain.run()
    pred = _trainer(scenes, dets, tmp_path / "b", epochs=1, prediction_weight=1.0)
    pred.run()
    assert all(r.prediction_terms == 0 for r in plain.log.steps)
    assert all(r.prediction_terms > 0 for r in pred.log.steps)
    assert [r.loss for r in plain.log.steps] != [r.loss for r in pred.log.steps]


def test_progress_is_written_from_the_first_step_and_training_yaml_beside_the_checkpoint(
    small_training_set, tmp_path, monkeypatch
):
    import yaml

    from grutrack.cli.train import write_training_yaml
    from grutrack.training import trainer as tr
    from grutrack.training.config import load_train_config

    scenes, dets = small_training_set
    real, calls = tr.run_scene, []

    def dies_in_step_2(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("killed")
        return real(*a, **k)

    monkeypatch.setattr(tr, "run_scene", dies_in_step_2)
    t = _trainer(scenes, dets, tmp_path, epochs=2, checkpoint_every=10)
    with pytest.raises(RuntimeError):
        t.run()
    rows = (tmp_path / "train_log.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("1,0,")
    write_training_yaml(t.cfg, "grukf", tmp_path / "training.yaml", {"split": "mini_train"})
    text = (tmp_path / "training.yaml").read_text()
    assert '# data {"split": "mini_train"}' in text
    assert (
        load_train_config(tmp_path / "training.yaml")
        == t.cfg
        == load_train_config("grukf", {k: v for k, v in yaml.safe_load(text).items()})
    )


@pytest.mark.slow  # a training on mini_train; Ctrl-C through the CLI is quick in test_resume_cli
def test_cli_ctrl_c_saves_and_exits_130_and_resume_elsewhere_is_refused(
    nusc_mini, nusc_root, tmp_path, capsys, monkeypatch
):
    import json
    import os
    import signal

    from grutrack.cli import main
    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.documents import TrainingLog
    from grutrack.motion.checkpoint import read_checkpoint
    from grutrack.training import trainer as tr

    dets = tmp_path / "d.json"
    dets.write_text(
        json.dumps(simulate_nuscenes(None, "v1.0-mini", "mini_train", "centerpoint", seed=5, nusc=nusc_mini))
    )
    real, calls = tr.run_scene, []

    def ctrl_c_in_step_2(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)
        return real(*a, **k)

    monkeypatch.setattr(tr, "run_scene", ctrl_c_in_step_2)
    argv = [
        "train",
        "--dataroot",
        str(nusc_root),
        "--version",
        "v1.0-mini",
        "--split",
        "mini_train",
        "--no-config-sources",
        "--detections",
        str(dets),
        "--out",
        str(tmp_path / "ck"),
        "--epochs",
        "1",
        "--no-progress",
    ]
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert "grutrack train: interrupted after step 2; resumable checkpoint" in err and "Traceback" not in err
    assert read_checkpoint(tmp_path / "ck" / "last.pt")["train_state"]["step"] == 2
    # the default config validates on scenes held out of the split: step 0 (before training), then steps 1, 2
    assert [r.step for r in TrainingLog.read(tmp_path / "ck" / "train_log.csv").steps] == [0, 1, 2]
    assert '"split": "mini_train"' in (tmp_path / "ck" / "training.yaml").read_text()
    monkeypatch.setattr(tr, "run_scene", real)
    assert main([*argv[:-2], "2", "--no-progress", "--resume"]) == 2
    assert "last.pt: cannot resume with other training settings (epochs 1 -> 2)" in capsys.readouterr().err
    assert "\nepochs: 1\n" in (tmp_path / "ck" / "training.yaml").read_text()  # the run's, not the refused settings


def test_heading_frame_rotation_against_the_matrix_form_and_its_inverse():
    """Planar pairs rotated by -yaw (R(-yaw) [a, b]); other columns untouched; from_heading_frame undoes it;
    gradients flow to the input and the yaw."""
    from grutrack.motion.grukf import MEAS_PLANAR, from_heading_frame, to_heading_frame

    g = torch.Generator().manual_seed(3)
    v = torch.randn(50, 9, generator=g, dtype=torch.float64, requires_grad=True)
    yaw = (torch.rand(50, generator=g, dtype=torch.float64) * 6.0 - 3.0).requires_grad_()
    out = to_heading_frame(v, yaw, MEAS_PLANAR)
    c, s = torch.cos(yaw), torch.sin(yaw)
    rot = torch.stack([torch.stack([c, s], 1), torch.stack([-s, c], 1)], 1)  # (N, 2, 2) = R(-yaw)
    for i, j in MEAS_PLANAR:
        want = torch.einsum("nab,nb->na", rot, v[:, [i, j]])
        assert torch.allclose(out[:, [i, j]], want, atol=1e-12)
    others = [k for k in range(9) if k not in (0, 1, 7, 8)]
    assert torch.equal(out[:, others], v[:, others])
    assert torch.allclose(from_heading_frame(out, yaw, MEAS_PLANAR), v, atol=1e-12)
    out.sum().backward()
    assert v.grad is not None and yaw.grad is not None and torch.isfinite(yaw.grad).all()


def test_scene_loss_is_the_mean_of_the_weighted_squared_residuals():
    # a scene's terms are collected per frame and formed at once: the value is the same sum as term by term
    from grutrack.training.config import load_train_config
    from grutrack.training.loss import SceneLoss

    weights = [1.0, 2.0, 1.0, 1.0, 1.0, 1.0, 3.0, 1.0, 1.0]
    loss = SceneLoss(load_train_config("grukf", {"loss_weights": weights}), torch.device("cpu"))
    post = torch.zeros(2, 9, dtype=torch.float64, requires_grad=True)  # a frame's corrected tracks
    prior = torch.zeros(3, 9, dtype=torch.float64, requires_grad=True)  # every track's predicted box
    target = np.zeros((3, 9))
    target[0, 0], target[1, 1], target[2, 6] = 0.5, 0.25, 2 * np.pi - 0.1  # yaw residual wraps to 0.1
    loss._add_rows(post, None, target[:2], 1.0)  # posterior terms, every row
    loss._add_rows(prior, np.array([2]), target[2:], 0.5)  # a prediction term of row 2, weight 0.5
    loss.gt_terms, loss.prediction_terms = 2, 1
    expected = (0.5**2 + 2.0 * 0.25**2 + 0.5 * 3.0 * 0.1**2) / 3
    value = loss.value()
    assert float(value.detach()) == pytest.approx(expected, rel=1e-12)
    value.backward()
    assert float(post.grad[0, 0]) == pytest.approx(2 * (0.0 - 0.5) / 3, rel=1e-12)  # d/dpred of the first term
    assert float(prior.grad[2, 6]) == pytest.approx(0.5 * 3.0 * 2 * 0.1 / 3, rel=1e-9)
    assert float(prior.grad[:2].abs().sum()) == 0.0  # rows without a term


def test_centre_huber_delta_bounds_the_centre_terms_only():
    # x, y residuals beyond the delta cost 2 d |r| - d^2 (gradient 2 d sign r), within it r^2; the other
    # components stay squared; 0 is the squared loss
    from grutrack.training.config import load_train_config
    from grutrack.training.loss import SceneLoss

    target = np.zeros((1, 9))
    target[0, [0, 1, 6, 7]] = [3.0, -0.5, 2.0, 4.0]  # x 3 m off, y 0.5 m, yaw 2 rad, vx 4 m/s
    values = {}
    for d in (0.0, 1.0):
        cfg = load_train_config("grukf", {"centre_huber_delta": d, "yaw_loss": "heading"})  # yaw term: 2^2
        loss = SceneLoss(cfg, torch.device("cpu"))
        post = torch.zeros(1, 9, dtype=torch.float64, requires_grad=True)
        loss._add_rows(post, None, target, 1.0)
        loss.gt_terms = 1
        value = loss.value()
        value.backward()
        values[d] = (float(value.detach()), post.grad[0].tolist())
    assert values[0.0][0] == pytest.approx(9.0 + 0.25 + 4.0 + 16.0, rel=1e-12)
    assert values[1.0][0] == pytest.approx((2 * 3.0 - 1.0) + 0.25 + 4.0 + 16.0, rel=1e-12)
    grad = values[1.0][1]
    assert grad[0] == pytest.approx(-2.0) and grad[1] == pytest.approx(1.0)  # bounded; within d: 2 r
    assert grad[6] == pytest.approx(-4.0) and grad[7] == pytest.approx(-8.0)  # squared as before
    assert values[0.0][1][0] == pytest.approx(-6.0)


def test_yaw_loss_axis_takes_a_reversed_heading_as_no_residual():
    # "axis": yaw residuals wrap to [-pi/2, pi/2) (pi + 0.1 -> 0.1); "heading": to [-pi, pi) (pi + 0.1 -> 0.1 - pi)
    from grutrack.training.config import load_train_config
    from grutrack.training.loss import SceneLoss

    target = np.zeros((2, 9))
    target[:, 6] = [np.pi + 0.1, 0.3]
    got = {}
    for kind in ("heading", "axis"):
        loss = SceneLoss(load_train_config("grukf", {"yaw_loss": kind}), torch.device("cpu"))
        loss._add_rows(torch.zeros(2, 9, dtype=torch.float64), None, target, 1.0)
        loss.gt_terms = 2
        got[kind] = float(loss.value())
    assert got["heading"] == pytest.approx(((np.pi - 0.1) ** 2 + 0.3**2) / 2, rel=1e-12)
    assert got["axis"] == pytest.approx((0.1**2 + 0.3**2) / 2, rel=1e-12)


def test_lr_min_is_the_learning_rate_of_the_last_step(small_training_set, tmp_path):
    # the cosine schedule ends at lr_min (0: at 0); the first step runs at lr
    scenes, dets = small_training_set
    for lr_min in (0.0, 2e-4):
        t = _trainer(scenes, dets, tmp_path / f"lr{lr_min}", epochs=1, lr_min=lr_min, validation_scenes=0)
        t.run()
        assert t.log.steps[0].lr == pytest.approx(1e-3)
        assert t.opt.param_groups[0]["lr"] == pytest.approx(lr_min, abs=1e-12)


def test_grad_clip_norm_bounds_the_applied_gradient_and_logs_the_norm_before_it(
    small_training_set, tmp_path, monkeypatch
):
    # every step logs ||g|| before clipping; with grad_clip_norm c the gradient AdamW sees has norm min(||g||, c)
    scenes, dets = small_training_set
    seen = []
    step = torch.optim.AdamW.step

    def spy(opt, *a, **k):
        seen.append(
            float(
                torch.nn.utils.get_total_norm(
                    [p.grad for g in opt.param_groups for p in g["params"] if p.grad is not None]
                )
            )
        )
        return step(opt, *a, **k)

    monkeypatch.setattr(torch.optim.AdamW, "step", spy)
    free = _trainer(scenes, dets, tmp_path / "free", epochs=1, validation_scenes=0)
    free.run()
    logged = [r.grad_norm for r in free.log.steps]
    assert logged == pytest.approx(seen, rel=1e-5) and min(logged) > 0
    cap = float(np.median(logged))  # half the steps above it
    seen.clear()
    clipped = _trainer(scenes, dets, tmp_path / "clip", epochs=1, validation_scenes=0, grad_clip_norm=cap)
    clipped.run()
    first = clipped.log.steps[0].grad_norm  # the same network and scene: the same gradient
    assert first == pytest.approx(logged[0], rel=1e-9)
    assert seen[0] == pytest.approx(min(first, cap), rel=1e-5)
    assert all(s <= cap * (1 + 1e-5) for s in seen)
    assert any(r.grad_norm > cap * 1.01 for r in clipped.log.steps)  # some step was really clipped


def test_gt_term_gate_drops_held_instances_the_track_has_left():
    # a sticky track whose GT box is farther than the gate gives no GT term in that frame (-1); 0 is no gate
    from grutrack.data.scene import BoxSet
    from grutrack.training.config import load_train_config
    from grutrack.training.loss import SceneLoss

    gt_boxes = np.zeros((3, 9))
    gt_boxes[:, 0] = [0.0, 10.0, 20.0]
    gt = BoxSet(gt_boxes, np.ones(3), np.zeros(3, dtype=np.int64), np.array(["a", "b", "c"], dtype=object))
    rows = np.array([0, 1, -1, 2])
    xy = np.array([[0.5, 0.0], [13.0, 0.0], [50.0, 0.0], [20.0, 1.99]])  # 0.5 m, 3 m, no GT, 1.99 m
    gated = SceneLoss(load_train_config("grukf", {"gt_term_gate": 2.0}), torch.device("cpu"))
    assert gated._gated(rows, xy, gt).tolist() == [0, -1, -1, 2]
    off = SceneLoss(load_train_config("grukf", {"gt_term_gate": 0.0}), torch.device("cpu"))
    assert off._gated(rows, xy, gt).tolist() == rows.tolist()


def test_gt_term_gate_turns_gated_terms_into_pseudo_labels(small_training_set, tmp_path):
    # the first step tracks with the same (untrained) network: the terms are the same in number, a tight gate
    # moves some of them from ground truth to the pseudo-label
    scenes, dets = small_training_set
    runs = {}
    for gate in (0.0, 0.05):
        t = _trainer(scenes, dets, tmp_path / f"g{gate}", epochs=1, gt_term_gate=gate, validation_scenes=0)
        t.run(max_steps=1)
        runs[gate] = t.log.steps[-1]
    plain, tight = runs[0.0], runs[0.05]
    assert plain.gt_terms + plain.pseudo_terms == tight.gt_terms + tight.pseudo_terms
    assert 0 < tight.gt_terms < plain.gt_terms


def test_gt_term_gate_applies_to_the_prediction_terms(small_training_set, tmp_path):
    # the prediction terms of tracks holding an instance are gated by their predicted centre likewise
    scenes, dets = small_training_set
    runs = {}
    for gate in (0.0, 0.05):
        t = _trainer(
            scenes, dets, tmp_path / f"p{gate}", epochs=1, gt_term_gate=gate, validation_scenes=0, prediction_weight=1.0
        )
        t.run(max_steps=1)
        runs[gate] = t.log.steps[-1].prediction_terms
    assert 0 < runs[0.05] < runs[0.0]
