"""Checkpoint selection on validation AMOTA (``select_checkpoint``), the untrained network's validation (step 0),
the reference tracker's AMOTA in ``validation.json`` and validation scenes held out of the training split
(``validation_scenes``)."""

from __future__ import annotations

import json

import pytest
import torch

from grutrack.documents import TrainingLog, ValidationRecord
from grutrack.motion.checkpoint import read_checkpoint


@pytest.fixture(scope="module")
def small_training_set(nusc_mini, tmp_path_factory):
    """Two mini_train scenes of 12 frames with SYNTHETIC CenterPoint-like detections (seed 5)."""
    from support.grukf_data import mini_train_scenes_and_dets

    return mini_train_scenes_and_dets(nusc_mini, tmp_path_factory.mktemp("dets"), 2, 12)


class ScriptedValidator:
    """A validator (:class:`grutrack.training.validation.Validator`) of one detection set whose AMOTA is a fixed
    pseudo-random function of the network's weights (so a resumed run sees the values of an uninterrupted one); it
    keeps the weights of every call."""

    metric = "AMOTA"
    detection_sets = ["given"]

    def __init__(self):
        self.seen: list[tuple[float, dict]] = []

    def scores(self, net) -> list[float]:
        s = sum(float(p.detach().double().sum()) for p in net.parameters())
        value = round(0.5 + (abs(s) * 7919.0) % 0.4, 6)
        self.seen.append((value, {k: v.clone() for k, v in net.state_dict().items()}))
        return [value]

    def reference_scores(self) -> list[float]:
        return [0.75]

    def describe(self) -> ValidationRecord:
        return ValidationRecord(
            rule="last",
            selected_step=0,
            split="mini_val",
            scenes=["scene-a", "scene-b"],
            detection_sets=list(self.detection_sets),
            reference="tracker preset 'ekf' (its EKF)",
        )


#: validation AMOTA of three detection sets at validations 0, 1, ... (steps 0, 1, ... with val_every 1): the best
#: mean is validation 3 (0.720); validation 5 (0.718) is within one standard error of the paired differences to it
#: (d = (+0.004, -0.010, 0.000): s.e. 0.0042), validation 4 (0.7173, s.e. 0.0024) and 6 (0.701) are not: the
#: 1-s.e. rule keeps validation 5, the best-AMOTA rule validation 3.
SETS_CURVE = (
    (0.700, 0.705, 0.702),
    (0.705, 0.709, 0.707),
    (0.712, 0.716, 0.714),
    (0.720, 0.722, 0.718),
    (0.716, 0.724, 0.712),
    (0.724, 0.712, 0.718),
    (0.700, 0.701, 0.702),
)


class ScriptedSetsValidator(ScriptedValidator):
    """A :class:`ScriptedValidator` that scores three detection sets (``scores``; the call is their mean) along a
    fixed curve (:data:`SETS_CURVE`): the n-th distinct network it is shown (told apart by its weights, so a
    resumed run that shares ``order`` with an uninterrupted one sees that run's values) gets the n-th row. The
    curve does not depend on what the weights are, so a change of the training recipe cannot make the two
    selection rules agree by chance."""

    detection_sets = ["given", "centerpoint", "pointpillars"]

    def __init__(self, order: dict | None = None):
        super().__init__()
        self.order = {} if order is None else order  # weights' fingerprint -> position on the curve

    def scores(self, net):
        import numpy as np

        key = tuple(float(p.detach().double().sum()) for p in net.parameters())
        n = self.order.setdefault(key, len(self.order))
        values = np.array(SETS_CURVE[min(n, len(SETS_CURVE) - 1)])
        self.seen.append((round(float(values.mean()), 6), {k: v.clone() for k, v in net.state_dict().items()}))
        return values

    def reference_scores(self):
        return [0.7, 0.71, 0.72]


def _trainer(scenes, dets, out, validate=None, **over):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config(
        "grukf",
        {"epochs": 3, "checkpoint_every": 0, "device": "cpu", "lr": 3e-3, "gain_prior": "ekf", "val_every": 1, **over},
    )
    return Trainer(cfg, scenes, dets, out, validate=validate, progress=False)


def _same(a: dict, b: dict) -> bool:
    return set(a) == set(b) and all(torch.equal(a[k], b[k]) for k in a)


def test_model_pt_holds_the_best_validated_step_and_last_pt_the_last(small_training_set, tmp_path):
    from grutrack.training.validation import Validator

    scenes, dets = small_training_set
    v = ScriptedValidator()
    assert isinstance(v, Validator) and isinstance(ScriptedSetsValidator(), Validator)  # the trainer's protocol
    (tmp_path / "validated").mkdir()
    (tmp_path / "validated" / "step_99.pt").write_bytes(b"an earlier run's")  # removed by a run from its start
    t = _trainer(scenes, dets, tmp_path, v, select_checkpoint="best_val_amota")
    final = t.run()
    log = TrainingLog.read(tmp_path / "train_log.csv")
    # the untrained network is validated first (step 0), then every step
    assert [r.step for r in log.validated()] == list(range(0, 7))
    values = [r.val_amota for r in log.validated()]
    assert values == [x for x, _ in v.seen]
    best = values.index(max(values))  # the earliest of equals
    assert len(set(values)) > 1, "the scripted values must differ for the test to mean anything"
    model, last = read_checkpoint(final), read_checkpoint(tmp_path / "last.pt")
    assert _same(model["model"], v.seen[best][1])
    assert _same(last["model"], v.seen[-1][1])
    # every validated network is kept, loadable as a network, with its step and validation AMOTA
    from grutrack.motion.checkpoint import load_network

    kept = sorted(p.name for p in (tmp_path / "validated").iterdir())
    assert kept == sorted(f"step_{i}.pt" for i in range(7))
    for i, (value, weights) in enumerate(v.seen):
        doc = read_checkpoint(tmp_path / "validated" / f"step_{i}.pt")
        assert _same(doc["model"], weights) and doc["selected"] == {"step": i, "val_amota": value}
    load_network(tmp_path / "validated" / f"step_{best}.pt")
    assert model["selected"] == {"rule": "best_val_amota", "step": best, "val_amota": max(values)}
    rec = ValidationRecord.read(tmp_path / "validation.json")
    assert (rec.rule, rec.selected_step, rec.selected_amota) == ("best_val_amota", best, max(values))
    assert (rec.reference_amota, rec.split, rec.scenes) == (0.75, "mini_val", ["scene-a", "scene-b"])
    # the loss of step 0 is not a number (no step was taken); readers keep it
    assert log.steps[0].scene == "(before training)" and log.steps[0].loss != log.steps[0].loss


def test_select_last_writes_the_last_step_and_says_so(small_training_set, tmp_path):
    scenes, dets = small_training_set
    v = ScriptedValidator()
    final = _trainer(scenes, dets, tmp_path, v, select_checkpoint="last").run()
    assert _same(read_checkpoint(final)["model"], v.seen[-1][1])
    assert not (tmp_path / "best.pt").exists()
    rec = json.loads((tmp_path / "validation.json").read_text())
    assert rec["rule"] == "last" and rec["selected_step"] == 6 and rec["selected_amota"] == v.seen[-1][0]


def test_without_validation_the_record_names_the_last_step(small_training_set, tmp_path):
    scenes, dets = small_training_set
    (tmp_path / "validated").mkdir()
    (tmp_path / "validated" / "step_3.pt").write_bytes(b"an earlier run's")
    final = _trainer(scenes, dets, tmp_path, None, select_checkpoint="best_val_amota", epochs=1).run()
    assert not list((tmp_path / "validated").iterdir())  # no network validated, none left from before
    rec = ValidationRecord.read(tmp_path / "validation.json")
    assert (rec.rule, rec.selected_step, rec.reference_amota) == ("last", 2, None)
    assert read_checkpoint(final)["train_state"]["step"] == 2
    assert [r.step for r in TrainingLog.read(tmp_path / "train_log.csv").steps] == [1, 2]


def test_a_resumed_run_selects_what_the_uninterrupted_run_selects(small_training_set, tmp_path):
    scenes, dets = small_training_set
    a = _trainer(scenes, dets, tmp_path / "a", ScriptedValidator(), select_checkpoint="best_val_amota")
    a.run()
    b = _trainer(scenes, dets, tmp_path / "b", ScriptedValidator(), select_checkpoint="best_val_amota")
    b.run(max_steps=4)
    c = _trainer(scenes, dets, tmp_path / "b", ScriptedValidator(), select_checkpoint="best_val_amota")
    c.resume(tmp_path / "b" / "last.pt")
    c.run()
    ma, mb = read_checkpoint(tmp_path / "a" / "model.pt"), read_checkpoint(tmp_path / "b" / "model.pt")
    assert ma["selected"] == mb["selected"] and _same(ma["model"], mb["model"])
    # the resumed run keeps the networks it validated before the interruption, and adds the later ones
    kept = {p.name: read_checkpoint(p)["model"] for p in (tmp_path / "a" / "validated").iterdir()}
    resumed = {p.name: read_checkpoint(p)["model"] for p in (tmp_path / "b" / "validated").iterdir()}
    assert set(kept) == set(resumed) and all(_same(kept[k], resumed[k]) for k in kept)
    assert (tmp_path / "a" / "validation.json").read_text() == (tmp_path / "b" / "validation.json").read_text()


def _step(step: int, sets: list[float] | None, amota: float | None = None):
    from grutrack.documents import TrainingStep

    mean = round(sum(sets) / len(sets), 6) if sets else amota
    return TrainingStep(
        step=step, epoch=0, scene="s", loss=1.0, val_amota=mean, val_amota_sets=None if sets is None else tuple(sets)
    )


def _select(rule: str, rows) -> int:
    from grutrack.training.selection import next_selection

    best = chosen = None
    for r in rows:
        best, chosen = next_selection(rule, best, chosen, r)
    return chosen.step


def test_one_se_rule_takes_the_latest_step_the_sets_do_not_agree_is_worse():
    from grutrack.training.selection import one_se

    best = _step(2, [0.80, 0.60, 0.70, 0.50])
    noisy = _step(4, [0.79, 0.62, 0.66, 0.49])  # mean 0.010 lower; the sets disagree: s.e. 0.0122
    worse = _step(6, [0.78, 0.58, 0.68, 0.48])  # 0.020 lower on every set: s.e. 0
    assert one_se(noisy, best) == pytest.approx(0.012247, abs=1e-6)
    assert one_se(worse, best) == pytest.approx(0.0, abs=1e-12)
    start = _step(0, [0.70, 0.55, 0.65, 0.45])
    assert _select("best_val_amota_1se", [start, best, noisy]) == 4
    assert _select("best_val_amota_1se", [start, best, noisy, worse]) == 4
    assert _select("best_val_amota", [start, best, noisy, worse]) == 2
    # a later new best is chosen by both rules, and later steps are measured against it
    top = _step(8, [0.82, 0.64, 0.72, 0.52])
    assert _select("best_val_amota_1se", [start, best, noisy, top, noisy]) == 8
    # one set (or none recorded): no spread, the latest of the steps of equal best AMOTA
    assert _select("best_val_amota_1se", [_step(0, [0.7]), _step(1, [0.8]), _step(2, [0.8]), _step(3, [0.79])]) == 2
    assert _select("best_val_amota_1se", [_step(0, None, 0.7), _step(1, None, 0.8), _step(2, None, 0.8)]) == 2
    assert _select("best_val_amota", [_step(0, None, 0.7), _step(1, None, 0.8), _step(2, None, 0.8)]) == 1


def test_one_se_rule_in_training_writes_the_chosen_step_with_its_sets(small_training_set, tmp_path):
    import numpy as np

    from grutrack.training.selection import one_se

    scenes, dets = small_training_set
    v = ScriptedSetsValidator()
    final = _trainer(scenes, dets, tmp_path, v, select_checkpoint="best_val_amota_1se").run()
    val = TrainingLog.read(tmp_path / "train_log.csv").validated()
    assert all(len(r.val_amota_sets) == 3 for r in val)
    assert [r.val_amota for r in val] == [mean for mean, _ in v.seen]  # the mean of the sets' unrounded scores
    # the log rounds the mean and each set to 6 decimals: the mean of the rounded sets is within 1e-6 of it
    assert [r.val_amota for r in val] == pytest.approx([float(np.mean(r.val_amota_sets)) for r in val], abs=1e-6)
    # the rule written out over the whole curve: the latest step within one s.e. of the (earliest) best
    best = max(val, key=lambda r: (r.val_amota, -r.step))
    expected = max(r.step for r in val if r.val_amota >= best.val_amota - one_se(r, best))
    assert len(v.order) == len(val) == 7  # every validation a network of its own
    assert (best.step, expected) == (3, 5)  # the scripted curve: the two rules differ
    assert _same(read_checkpoint(final)["model"], v.seen[expected][1])
    rec = ValidationRecord.read(tmp_path / "validation.json")
    assert (rec.rule, rec.selected_step) == ("best_val_amota_1se", expected)
    assert rec.selected_amota_sets == list(val[expected].val_amota_sets)
    assert rec.reference_amota_sets == [0.7, 0.71, 0.72]
    # resumed half way, the same choice
    b = _trainer(scenes, dets, tmp_path / "b", ScriptedSetsValidator(v.order), select_checkpoint="best_val_amota_1se")
    b.run(max_steps=3)
    c = _trainer(scenes, dets, tmp_path / "b", ScriptedSetsValidator(v.order), select_checkpoint="best_val_amota_1se")
    c.resume(tmp_path / "b" / "last.pt")
    c.run()
    assert ValidationRecord.read(tmp_path / "b" / "validation.json") == rec
    assert _same(read_checkpoint(tmp_path / "b" / "model.pt")["model"], v.seen[expected][1])


def test_held_out_scenes_are_evenly_spaced_in_name_order():
    from types import SimpleNamespace

    from grutrack.training.validation import held_out_scenes

    scenes = [SimpleNamespace(name=f"scene-{i:04d}") for i in (7, 3, 1, 9, 5, 8, 2, 4)]
    assert [s.name for s in held_out_scenes(scenes, 2)] == ["scene-0003", "scene-0008"]
    assert [s.name for s in held_out_scenes(scenes, 1)] == ["scene-0005"]
    assert held_out_scenes(scenes, 0) == []
    assert len({s.name for s in held_out_scenes(scenes, 8)}) == 8


@pytest.mark.slow
def test_cli_holds_scenes_out_of_training_and_validates_on_them(
    nusc_mini, nusc_root, tmp_path, capsys, ekf_coasting_keep
):
    import yaml

    from grutrack.cli import main
    from grutrack.config_loader import read_config
    from grutrack.data.detection_sim import simulate_nuscenes

    dets = tmp_path / "d.json"
    dets.write_text(
        json.dumps(simulate_nuscenes(None, "v1.0-mini", "mini_train", "centerpoint", seed=5, nusc=nusc_mini))
    )
    cfg, _ = read_config("training", "grukf")
    cfg.update(
        validation_scenes=2,
        validation_draws=2,
        select_checkpoint="best_val_amota",
        val_every=3,
        lr=3e-3,
        gain_prior="ekf",
        network_classes="ss_model",
        yaw_flip=True,
        motion_config="grutrack_nusc",
        sources=[],
    )
    # the paper's coasting (keep): with the recipe's zero turn rate and acceleration from a track's second missed
    # frame on, the untrained network writes other coasted boxes than the EKF for the classes the preset coasts
    # two frames (bus, trailer, truck)
    cfg["network"] = {**cfg["network"], "coast_yaw_rate": "keep", "coast_acceleration": "keep"}
    # ... and the preset trained with and compared against coasts so too for every class (motion.coast_*: keep)
    cfg["tracker_preset"] = str(ekf_coasting_keep)
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(cfg))
    argv = [
        "train",
        "--dataroot",
        str(nusc_root),
        "--version",
        "v1.0-mini",
        "--split",
        "mini_train",
        "--detections",
        str(dets),
        "--config",
        str(tmp_path / "t.yaml"),
        "--out",
        str(tmp_path / "ck"),
        "--epochs",
        "1",
        "--no-progress",
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    held = ["scene-0655", "scene-1094"]
    assert f"validating on 2 scenes held out of mini_train: {', '.join(held)}" in out
    log = TrainingLog.read(tmp_path / "ck" / "train_log.csv")
    assert len([r for r in log.steps if r.step > 0]) == 6 and not {r.scene for r in log.steps} & set(held)
    rec = ValidationRecord.read(tmp_path / "ck" / "validation.json")
    assert rec.scenes == held and rec.split == "mini_train" and rec.held_out
    # validated with the command's detections and two simulated sets per resampling profile (AMOTA their mean)
    assert rec.detection_sets == [
        "given",
        *(f"{p}{d}" for p in ("centerpoint", "pointpillars", "centerpoint_velfail") for d in ("", "_1")),
    ]
    assert 0.5 < rec.reference_amota < 1.0
    # with gain_prior ekf and the preset's motion config for the network's classes, the untrained GRU-KF is the
    # preset's EKF: its validation AMOTA (step 0) is the reference's up to float32 rounding
    assert log.steps[0].step == 0 and log.steps[0].val_amota == pytest.approx(rec.reference_amota, abs=2e-3)
    best = max(log.validated(), key=lambda r: (r.val_amota, -r.step))
    assert (rec.selected_step, rec.selected_amota) == (best.step, best.val_amota)
    assert f"model.pt holds step {best.step} (" in out
    # every scene held out is refused
    cfg["validation_scenes"] = 8
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(cfg))
    assert main(argv[:-5] + ["--out", str(tmp_path / "ck2"), "--epochs", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "t.yaml: validation_scenes 8 would leave no training scene (split 'mini_train' has 8)" in err


@pytest.mark.parametrize(
    "key, value, message",
    [
        ("validation_scenes", -1, "'validation_scenes' must be an integer from 0 to 1000, got -1"),
        ("validation_scenes", 2.5, "'validation_scenes' must be an integer from 0 to 1000, got 2.5"),
        ("validation_draws", 0, "'validation_draws' must be an integer from 1 to 100, got 0"),
        ("validation_draws", 1.5, "'validation_draws' must be an integer from 1 to 100, got 1.5"),
        (
            "select_checkpoint",
            "best",
            "'select_checkpoint' must be 'last', 'best_val_amota' or 'best_val_amota_1se', got 'best'",
        ),
    ],
)
def test_bad_selection_settings_are_refused_naming_the_key(key, value, message):
    from grutrack.errors import ConfigError
    from grutrack.training.config import load_train_config

    with pytest.raises(ConfigError, match=message):
        load_train_config("grukf", {key: value})
    # the two shipped configs: the default recipe selects on held-out validation, the paper's keeps the last step
    assert (load_train_config("grukf").validation_scenes, load_train_config("grukf").select_checkpoint) == (
        2,
        "best_val_amota_1se",
    )
    assert (load_train_config("paper").validation_scenes, load_train_config("paper").select_checkpoint) == (0, "last")


@pytest.mark.slow  # an AV2 training; test_datasets::test_train_on_av2_then_track_av2_with_the_model is quick
def test_av2_training_validates_on_a_held_out_log_with_the_datasets_hota(av2_root, tmp_path, capsys):
    """Training on AV2 validates as on nuScenes, through the dataset: a log held out of the split, scored with
    AV2's metric (HOTA, the official evaluation, :meth:`AV2Dataset.score_tracks`), the preset's EKF as reference."""
    from grutrack.cli import main
    from grutrack.datasets import DatasetOptions, open_dataset
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes

    common = ["--dataset", "av2", "--dataroot", str(av2_root), "--split", "val"]
    dets = tmp_path / "d.feather"
    assert main(["simulate-detections", *common, "--seed", "4", "--out", str(dets)]) == 0
    over = {"epochs": 1, "device": "cpu", "validation_scenes": 1, "val_every": 1, "select_checkpoint": "best_val_amota"}
    cfg = tmp_path / "t.yaml"
    assert (
        main(["resolve-config", "training", "--base", "paper", "--overrides", json.dumps(over), "--out", str(cfg)]) == 0
    )
    assert (
        main(
            [
                "train",
                *common,
                "--detections",
                str(dets),
                "--config",
                str(cfg),
                "--out",
                str(tmp_path / "ck"),
                "--no-progress",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    ds = open_dataset("av2", DatasetOptions(av2_root))
    scenes = ds.scenes("val")
    logs = sorted(s.name for s in scenes)
    assert f"validating on 1 scenes held out of val: {logs[1]}" in out
    rec = ValidationRecord.read(tmp_path / "ck" / "validation.json")
    assert (rec.split, rec.scenes, rec.held_out, rec.detection_sets) == ("val", [logs[1]], True, ["given"])
    log = TrainingLog.read(tmp_path / "ck" / "train_log.csv")
    assert [r.step for r in log.validated()] == [0, 1] and all(0.0 < r.val_amota <= 1.0 for r in log.validated())
    assert [r.scene for r in log.steps if r.step > 0] == [logs[0]]  # trained on the other log only
    assert f"validation HOTA {rec.selected_amota:.4f}" in out
    # the reference line: the preset's EKF on the held-out log, scored by the dataset
    ekf = build_tracker("ekf", param_classes=ds.vocabulary.param_classes)
    given = ds.load_detections(dets, "val", scenes, ekf.cfg.measured_yaw).boxes
    held = [s for s in scenes if s.name == logs[1]]
    assert rec.reference_amota == round(ds.score_tracks("val", held, track_scenes(ekf, held, given).results, 500), 6)
    # scoring the whole split is the official evaluation of the same tracks written as the challenge pickle
    results = track_scenes(ekf, scenes, given).results
    ds.write_tracks(tmp_path / "t.pkl", scenes, results, 500)
    assert (
        ds.score_tracks("val", scenes, results, 500)
        == ds.evaluate(tmp_path / "t.pkl", "val", workers=1).overall["hota"]
    )


def test_validation_draws_have_their_own_seeds_and_names(monkeypatch):
    """``validation_draws``: per resample profile that many sets, named ``<profile>``, ``<profile>_1``, ...,
    drawn with seeds no training epoch of this or another config seed draws."""
    from grutrack.training import resample, run
    from grutrack.training.config import load_train_config

    seeds = [resample.validation_seed(1, d) for d in range(5)]
    assert seeds[0] == resample.resample_seed(1, 0) and len(set(seeds)) == 5
    trained = {resample.resample_seed(s, e) for s in range(4) for e in range(1, 1000)}
    assert not trained & {resample.validation_seed(s, d) for s in range(4) for d in range(100)}
    with pytest.raises(ValueError):
        resample.validation_seed(1, resample.RESAMPLE_SEED_BASE)

    class Drawn:  # a resampler that returns what it was asked to draw
        def __init__(self, dataset, split, scenes, yaw):
            pass

        def __call__(self, profile, seed):
            return (profile, seed)

    monkeypatch.setattr(resample, "DetectionResampler", Drawn)
    cfg = load_train_config("grukf", {"validation_draws": 3, "resample_profiles": ["centerpoint", "pointpillars"]})
    sets = run._validation_sets(cfg, None, "mini_train", [], {"t": "given"}, "euler_z")
    assert sets == {
        "given": {"t": "given"},
        **{
            f"centerpoint{s}": ("centerpoint", resample.validation_seed(cfg.seed, d))
            for d, s in enumerate(["", "_1", "_2"])
        },
        **{
            f"pointpillars{s}": ("pointpillars", resample.validation_seed(cfg.seed, d))
            for d, s in enumerate(["", "_1", "_2"])
        },
    }
    assert load_train_config("grukf").validation_draws == 5  # the default recipe: 1 + 3 profiles x 5 = 16 sets
    assert load_train_config("paper").validation_draws == 1


def test_a_bad_validation_draws_exits_2_with_one_line(nusc_root, tmp_path, capsys):
    import yaml

    from grutrack.cli import main
    from grutrack.config_loader import read_config

    cfg, _ = read_config("training", "grukf")
    cfg["validation_draws"] = 0
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(cfg))
    argv = ["train", "--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_train"]
    argv += ["--detections", str(tmp_path / "none.json"), "--config", str(tmp_path / "bad.yaml")]
    assert main([*argv, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"grutrack train: error: {tmp_path / 'bad.yaml'}: 'validation_draws' must be an integer from 1 to 100, got 0"
    ]
