"""`grutrack train` stopped by Ctrl-C at every phase of a run (while it reads its data, during its start-up
validation, mid-epoch, during a validation, in its last step, during the last step's validation, while it writes
its final outputs; once, or twice to abort at once, also between the checkpoint of a chosen step and its
best.pt), then `grutrack train --resume`: the run ends with the
uninterrupted run's weights, training log and selected step, bit for bit, and validates no step twice that it had
saved. A run stopped before it saved a step starts from the beginning and says so; a folder that holds no run at
all is refused in one line."""

from __future__ import annotations

import csv
import json
import signal
from dataclasses import dataclass

import pytest
import torch

from grutrack.cli import main
from grutrack.datasets.nuscenes import NuScenesDataset
from grutrack.documents import Checkpoint
from grutrack.training import trainer as trainer_module
from grutrack.training.validation import DatasetValidator

#: the run: 4 training scenes x 2 epochs = 8 steps; validation before step 1, after steps 3 and 6 (val_every) and
#: after the last step (8); the 1-s.e. rule over three detection sets (the given one and two resampled) chooses
#: step 0, then at each validation the latest step within one standard error of the best: 3, 6, and 8 at the end
STEPS, VALIDATED, SELECTED = 8, [0, 3, 6, 8], 8


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 6-scene SYNTHETIC demo (demo_train: 5 scenes, one held out for validation), simulated detections and a
    training config of the paper's recipe at lr 1e-3 that validates every 3 steps, resamples detections and
    selects model.pt by the 1-s.e. rule; the arguments of `grutrack train` on them."""
    tmp = tmp_path_factory.mktemp("resume")
    assert main(["demo-data", "--out", str(tmp / "demo"), "--scenes", "6", "--frames-per-scene", "8"]) == 0
    common = ["--dataroot", str(tmp / "demo"), "--version", "v1.0-demo", "--split", "demo_train"]
    dets = tmp / "dets.json"
    assert main(["simulate-detections", *common, "--seed", "1", "--out", str(dets)]) == 0
    over = {
        "epochs": 2,
        "lr": 1e-3,
        "device": "cpu",
        "val_every": 3,
        "validation_scenes": 1,
        "select_checkpoint": "best_val_amota_1se",
        "checkpoint_every": 0,
        "resample_profiles": ["centerpoint", "pointpillars"],
    }
    cfg = ["resolve-config", "training", "--base", "paper", "--overrides", json.dumps(over)]
    assert main([*cfg, "--out", str(tmp / "train.yaml")]) == 0
    return tmp, [*common, "--detections", str(dets), "--config", str(tmp / "train.yaml"), "--no-progress"]


@pytest.fixture
def python_sigint():
    """SIGINT raises KeyboardInterrupt outside the trainer's handler (as in a terminal), also where the tests run
    as a background job (SIGINT ignored)."""
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _log_rows(folder) -> list[dict]:
    """train_log.csv's rows as text, all but the wall seconds of a step."""
    with open(folder / "train_log.csv", newline="") as f:
        return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]


def _assert_ends_as(whole, out) -> None:
    """``out`` holds the outputs of the run in ``whole``, bit for bit: the weights of model.pt (and of last.pt), the
    selected step, train_log.csv but its wall seconds, validation.json with every score."""
    for name in ("model.pt", "last.pt"):
        a, b = Checkpoint.read(whole / name), Checkpoint.read(out / name)
        assert a.weights.keys() == b.weights.keys() and all(torch.equal(a.weights[k], b.weights[k]) for k in a.weights)
    assert Checkpoint.read(out / "model.pt").selected == Checkpoint.read(whole / "model.pt").selected
    assert _log_rows(out) == _log_rows(whole)
    assert (out / "validation.json").read_text() == (whole / "validation.json").read_text()


def _saved_step(folder) -> int | None:
    last = folder / "last.pt"
    return Checkpoint.read(last).training.position.step if last.is_file() else None


@pytest.fixture(scope="module")
def whole(small):
    """The uninterrupted run: its folder."""
    tmp, args = small
    assert main(["train", *args, "--out", str(tmp / "whole")]) == 0
    assert [int(r["step"]) for r in _log_rows(tmp / "whole")] == list(range(STEPS + 1))
    assert [int(r["step"]) for r in _log_rows(tmp / "whole") if r["val_amota"]] == VALIDATED
    assert Checkpoint.read(tmp / "whole" / "model.pt").selected.step == SELECTED
    return tmp / "whole"


class Calls:
    """Counts the calls of the functions the test watches; at the ``at``-th call of ``target`` it sends the
    process ``times`` real SIGINTs (what Ctrl-C does), each handled before the next, then makes the call."""

    def __init__(self, monkeypatch, target: str | None = None, at: int = 0, times: int = 1):
        self.n = {"load_detections": 0, "run_scene": 0, "scores": 0, "_write_best": 0, "reference_scores": 0}
        for owner, name in (
            (NuScenesDataset, "load_detections"),
            (trainer_module, "run_scene"),
            (DatasetValidator, "scores"),
            (trainer_module.Trainer, "_write_best"),
            (DatasetValidator, "reference_scores"),
        ):
            monkeypatch.setattr(owner, name, self._watch(name, getattr(owner, name), target, at, times))

    def _watch(self, name, real, target, at, times):
        def call(*a, **k):
            self.n[name] += 1
            if name == target and self.n[name] == at:
                for _ in range(times):
                    signal.raise_signal(signal.SIGINT)  # its handler runs before raise_signal returns
            return real(*a, **k)

        return call


@dataclass
class Phase:
    target: str  # the function during whose ``at``-th call Ctrl-C is pressed
    at: int
    times: int  # 1: Ctrl-C; 2: Ctrl-C twice (abort at once)
    exit: int  # of the interrupted run
    says: str  # on its stderr
    saved: int | None  # the step its last.pt holds (None: no last.pt)


PHASES = {
    "reading_the_data": Phase("load_detections", 1, 1, 130, "grutrack train: interrupted; --resume continues", None),
    "start_up_validation": Phase(
        "scores", 1, 1, 130, "interrupted after the validation before the first step; resumable checkpoint", 0
    ),
    "start_up_validation_twice": Phase("scores", 1, 2, 130, "grutrack train: interrupted; --resume continues", None),
    "mid_epoch": Phase("run_scene", 2, 1, 130, "interrupted after step 2; resumable checkpoint", 2),
    "a_validation": Phase("scores", 2, 1, 130, "interrupted after step 3; resumable checkpoint", 3),
    "a_validation_twice": Phase("scores", 3, 2, 130, "grutrack train: interrupted; --resume continues", 3),
    # step 3 is chosen (the 1-s.e. rule keeps it to the end): aborted after its last.pt, before its best.pt
    "saving_a_chosen_step_twice": Phase("_write_best", 2, 2, 130, "grutrack train: interrupted; --resume continues", 3),
    "the_last_step": Phase("run_scene", STEPS, 1, 130, f"interrupted after step {STEPS}; resumable checkpoint", STEPS),
    "the_last_steps_validation": Phase(
        "scores", len(VALIDATED), 1, 130, f"interrupted after step {STEPS}; resumable checkpoint", STEPS
    ),
    "the_final_outputs": Phase(
        "reference_scores", 1, 1, 0, "interrupt: the last step is saved; finishing model.pt and validation.json", STEPS
    ),
    "the_final_outputs_twice": Phase(
        "reference_scores", 1, 2, 130, "grutrack train: interrupted; --resume continues", STEPS
    ),
}


#: phases in the slow tier only: the quick tier keeps one of each kind (Ctrl-C in the data, during a validation
#: (start-up, last step's), in a step, twice (abort at once), while the final outputs are written)
SLOW_PHASES = {
    "start_up_validation_twice",
    "a_validation",
    "a_validation_twice",
    "the_last_step",
    "the_final_outputs_twice",
}


@pytest.mark.parametrize(
    "phase", [pytest.param(p, id=k, marks=[pytest.mark.slow] if k in SLOW_PHASES else []) for k, p in PHASES.items()]
)
def test_ctrl_c_at_any_phase_then_resume_ends_as_the_uninterrupted_run(
    small, whole, phase, tmp_path, monkeypatch, capsys, python_sigint
):
    _, args = small
    out = tmp_path / "run"
    first = Calls(monkeypatch, phase.target, phase.at, phase.times)
    capsys.readouterr()
    assert main(["train", *args, "--out", str(out)]) == phase.exit
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # the trainer's handler is removed again
    err = capsys.readouterr().err
    assert phase.says in err and "Traceback" not in err
    assert first.n[phase.target] == phase.at  # stopped in that call (or, the final outputs, ran to the end)
    assert _saved_step(out) == phase.saved
    assert (out / "model.pt").is_file() == (phase.exit == 0)
    if phase.exit == 0:  # the run ended: its outputs are already the uninterrupted run's
        _assert_ends_as(whole, out)
    rows = _log_rows(out) if phase.saved is not None else []
    if phase.saved is not None:  # the saved log ends at the saved step, with every validation up to it
        ref = _log_rows(whole)[: phase.saved + 1]
        if phase.target == "run_scene" and phase.at == STEPS:  # the last step's validation is still to come
            ref[-1] = {**ref[-1], "val_amota": "", "val_amota_sets": ""}
        assert rows == ref
    monkeypatch.undo()  # the real functions again, counted
    again = Calls(monkeypatch)
    assert main(["train", *args, "--out", str(out), "--resume"]) == 0
    err = capsys.readouterr().err
    assert ("starting from the beginning" in err) == (phase.saved is None) and "Traceback" not in err
    _assert_ends_as(whole, out)
    # the resumed run takes the steps and runs the validations the interrupted one had not saved, no more
    assert again.n["run_scene"] == STEPS - (phase.saved or 0)
    assert again.n["scores"] == len(VALIDATED) - sum(bool(r["val_amota"]) for r in rows)


def test_resume_of_a_folder_without_a_run_is_refused(small, tmp_path, capsys):
    _, args = small
    assert main(["train", *args, "--out", str(tmp_path / "typo"), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume: nothing to resume in" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "typo").exists()  # refused before anything is read or written
