"""`grutrack train --resume` after a run that saved nothing (stopped during its start-up validation, before the
first step): it starts from the beginning, says so, and ends with the uninterrupted run's weights; a folder that
holds no run at all is refused in one line."""

from __future__ import annotations

import shutil

import pytest
import torch

from grutrack.cli import main
from grutrack.documents import Checkpoint


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 4-scene SYNTHETIC demo with simulated detections of demo_train."""
    tmp = tmp_path_factory.mktemp("resume")
    assert main(["demo-data", "--out", str(tmp / "demo"), "--scenes", "4", "--frames-per-scene", "8"]) == 0
    common = ["--dataroot", str(tmp / "demo"), "--version", "v1.0-demo", "--split", "demo_train"]
    dets = tmp / "dets.json"
    assert main(["simulate-detections", *common, "--seed", "1", "--out", str(dets)]) == 0
    return tmp, [*common, "--detections", str(dets), "--config", "paper", "--epochs", "2", "--no-progress"]


def test_resume_with_nothing_saved_starts_over_and_equals_the_uninterrupted_run(small, capsys):
    tmp, args = small
    assert main(["train", *args, "--out", str(tmp / "whole")]) == 0
    # a run stopped before its first step: its folder holds training.yaml and no last.pt
    (tmp / "stopped").mkdir()
    shutil.copy(tmp / "whole" / "training.yaml", tmp / "stopped" / "training.yaml")
    capsys.readouterr()
    assert main(["train", *args, "--out", str(tmp / "stopped"), "--resume"]) == 0
    err = capsys.readouterr().err
    assert (
        "--resume: " in err and "(the run stopped before its first step was saved); starting from the beginning" in err
    )
    a = Checkpoint.read(tmp / "whole" / "model.pt").weights
    b = Checkpoint.read(tmp / "stopped" / "model.pt").weights
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_resume_of_a_folder_without_a_run_is_refused(small, tmp_path, capsys):
    _, args = small
    assert main(["train", *args, "--out", str(tmp_path / "typo"), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume: nothing to resume in" in err[0] and "Traceback" not in err[0]
