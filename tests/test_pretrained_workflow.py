"""The shipped pretrained GRU-KF as a workflow training (``{pretrained: grukf_default}``) and as the default of
``grutrack track --tracker grukf``: its checkpoint path comes from the package, no training job builds it, an
unknown name is refused naming the config key, and the report is told which run tracked with which network."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import yaml

from grutrack.cli import main
from grutrack.errors import ConfigError
from grutrack.pipeline import spec
from grutrack.training.pretrained import pretrained_dir

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def shipped():
    from grutrack.data.registry import load_registry
    from grutrack.report.paper import load_paper

    cfg = yaml.safe_load((REPO / "workflow/config/config.yaml").read_text())
    return cfg, load_paper(REPO / cfg["paper"]), load_registry()


def test_the_demo_tracks_its_gru_kf_row_with_the_shipped_network(shipped):
    cfg, paper, registry = shipped
    spec.check_config(cfg, paper, registry)
    runs = cfg["experiments"]["demo_val"]["runs"]
    assert spec.is_pretrained(cfg, runs["grukf"]["training"])
    assert spec.checkpoint_file(cfg, runs["grukf"]["training"]) == str(pretrained_dir("grukf_default") / "model.pt")
    # the demo's own training is a workflow training, the shipped network is not
    assert "demo_grukf" in spec.trained_names(cfg) and runs["grukf"]["training"] not in spec.trained_names(cfg)
    assert spec.checkpoint_file(cfg, "demo_grukf") == "checkpoints/demo_grukf/model.pt"


def test_an_unknown_pretrained_network_is_refused_naming_the_key(shipped):
    cfg, paper, registry = shipped
    c = copy.deepcopy(cfg)
    c["trainings"]["mine"] = {"pretrained": "grukf_huge"}
    with pytest.raises(ConfigError, match=r"trainings\.mine\.pretrained: 'grukf_huge' is not a shipped pretrained"):
        spec.check_config(c, paper, registry)


def test_track_without_checkpoint_uses_the_shipped_network(nusc_root, tmp_path, capsys):
    out = tmp_path / "t.json"
    args = ["track", "--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    args += ["--detections", str(nusc_root / "detections/pointpillars_mini_val.json"), "--tracker", "grukf"]
    assert main([*args, "--out", str(out), "--no-progress", "--device", "cpu"]) == 0
    assert "no --checkpoint: the shipped pretrained network" in capsys.readouterr().err
    explicit = tmp_path / "e.json"
    ck = str(pretrained_dir("grukf_default") / "model.pt")
    assert main([*args, "--checkpoint", ck, "--out", str(explicit), "--no-progress", "--device", "cpu"]) == 0
    assert json.loads(out.read_text())["results"] == json.loads(explicit.read_text())["results"]


def test_report_refuses_a_run_training_without_its_log(tmp_path, capsys):
    code = main(["report", "demo", "--out", str(tmp_path / "r.md"), "--run-training", "grukf=nowhere"])
    assert code == 2
    assert "--run-training: training 'nowhere' has no --train-log" in capsys.readouterr().err
