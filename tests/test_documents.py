"""The stage documents: metrics JSON, submission manifest and training log round-trip through their classes,
keep the layout other tools read, and name the file and field when a file is not what it should be."""

from __future__ import annotations

import json
import math
import re

import pytest

from grutrack.documents import FileRecord, Manifest, MetricsDocument, TrainingLog, TrainingStep
from grutrack.errors import InputFormatError


def _metrics(**kw) -> MetricsDocument:
    base = dict(
        dataset="nuscenes",
        version="v1.0-mini",
        split="mini_val",
        evaluator="fast",
        submission="s.json",
        overall={"amota": 0.5, "ids": 3.0},
        per_class={"car": {"amota": 0.7, "amotp": float("nan")}, "bus": {"amota": None}},
    )
    base.update(kw)
    return MetricsDocument(**base)


def test_metrics_layout_is_the_one_other_tools_read(tmp_path):
    doc = _metrics(seconds=1.5, devkit_summary={"amota": 0.5})
    doc.write(tmp_path / "m.json")
    raw = json.loads((tmp_path / "m.json").read_text())
    assert list(raw)[:7] == ["dataset", "version", "split", "evaluator", "submission", "overall", "per_class"]
    assert raw["seconds"] == 1.5 and raw["devkit_summary"] == {"amota": 0.5}
    assert "settings" not in raw and "logs" not in raw  # unset optional fields are left out
    back = MetricsDocument.read(tmp_path / "m.json")
    assert back.overall == doc.overall and back.seconds == 1.5 and back.settings is None


def test_metrics_values_by_path_skip_nan_and_missing():
    doc = _metrics()
    assert doc.value("overall.amota") == 0.5 and doc.class_value("car", "amota") == 0.7
    assert doc.class_value("car", "amotp") is None  # NaN (no ground truth) reads as not available
    assert doc.class_value("bus", "amota") is None and doc.value("per_class.truck.amota") is None
    assert doc.value("overall") is None and doc.classes == ["car", "bus"]


@pytest.mark.parametrize(
    "text,expect",
    [
        ("[1, 2]", "the document must be a metrics JSON of grutrack evaluate"),
        ('{"per_class": {}}', "field 'overall' is missing"),
        ('{"overall": {}, "per_class": {"car": 3}}', "field 'per_class.car' must be an object"),
        ("{not json", "not valid JSON"),
    ],
)
def test_bad_metrics_files_name_file_and_field(tmp_path, text, expect):
    p = tmp_path / "m.json"
    p.write_text(text)
    with pytest.raises(InputFormatError, match=expect) as e:
        MetricsDocument.read(p)
    assert str(p) in str(e.value)


def test_manifest_round_trip_and_counts_at_top_level(tmp_path):
    sub, cfg = tmp_path / "x.json", tmp_path / "ekf.yaml"
    sub.write_text("{}")
    cfg.write_text("a: 1\n")
    m = Manifest(
        dataset="nuscenes",
        split="mini_val",
        submission=FileRecord.of(sub),
        tracker="ekf",
        tracker_config=FileRecord.of(cfg, "abc123"),
        version="v1.0-mini",
        counts={"samples": 81, "boxes": 9},
    )
    path = Manifest.path_for(sub)
    assert path.name == "x.manifest.json"
    m.write(path)
    raw = json.loads(path.read_text())
    assert raw["samples"] == 81 and raw["boxes"] == 9 and raw["checkpoint"] is None
    assert raw["submission"]["sha256"] == "44136fa355b3678a1146ad16f7e8649e94fb4fc21fe77e8310c060f61caaff8a"
    assert raw["tracker_config"]["config_hash"] == "abc123" and "config_hash" not in raw["submission"]
    back = Manifest.read(path)
    assert back == m
    assert Manifest.read(tmp_path / "none.manifest.json") is None


def test_manifest_without_its_records_is_refused(tmp_path):
    p = tmp_path / "x.manifest.json"
    p.write_text(json.dumps({"dataset": "nuscenes", "submission": {"path": "x.json"}}))
    with pytest.raises(InputFormatError, match="no 'tracker_config' record"):
        Manifest.read(p)
    p.write_text(json.dumps({"submission": {"sha256": "0"}, "tracker_config": {"path": "c"}}))
    with pytest.raises(InputFormatError, match="submission: expected"):
        Manifest.read(p)


def test_training_log_round_trip(tmp_path):
    log = TrainingLog(
        [
            TrainingStep(1, 0, "scene-0061", 0.5, 3, 1, 0, 1e-5, None, 0.2, grad_norm=1.25),
            TrainingStep(2, 0, "scene-0103", 0.4, 2, 2, 0, 1e-5, 0.8123, 0.3, (0.9, 0.7246), 1274.95),
        ]
    )
    log.write(tmp_path / "train_log.csv")
    text = (tmp_path / "train_log.csv").read_text().splitlines()
    assert text[0] == (
        "step,epoch,scene,loss,gt_terms,pseudo_terms,prediction_terms,lr,val_amota,seconds,val_amota_sets,grad_norm"
    )
    assert text[1].split(",")[8] == ""  # no validation after step 1: empty cell
    assert text[2].split(",")[10] == "0.9;0.7246"  # the AMOTA of each validation detection set
    back = TrainingLog.read(tmp_path / "train_log.csv")
    assert back == log and [s.step for s in back.validated()] == [2]


def test_training_log_of_an_older_version_reads_with_defaults(tmp_path):
    p = tmp_path / "train_log.csv"
    p.write_text("step,epoch,loss,val_amota\n1,0,0.5,\n")
    (s,) = TrainingLog.read(p).steps
    assert s.scene == "" and s.prediction_terms == 0 and math.isnan(s.lr) and s.val_amota is None
    assert math.isnan(s.grad_norm)


@pytest.mark.parametrize(
    "text,expect",
    [
        ("step,epoch,loss\n1,0,0.5\n", "needs the columns step, epoch, loss, val_amota"),
        ("step,epoch,loss,val_amota\n1,0,abc,\n", "step '1': not a number"),
        ("step,epoch,loss,val_amota,val_amota_sets\n2,0,0.5,0.7,0.6;x\n", "step '2': not a number"),
    ],
)
def test_bad_training_logs(tmp_path, text, expect):
    p = tmp_path / "train_log.csv"
    p.write_text(text)
    with pytest.raises(InputFormatError, match=expect):
        TrainingLog.read(p)


@pytest.mark.parametrize(
    "text, message",
    [
        ('{"selected_step": 3}', "needs the fields 'rule' and 'selected_step'"),
        (
            '{"rule": "best", "selected_step": 3}',
            "'rule' must be one of 'last', 'best_val_amota', 'best_val_amota_1se'",
        ),
        ('{"rule": "last", "selected_step": "3"}', "'selected_step' an integer, got 'last' and '3'"),
        (
            '{"rule": "last", "selected_step": 3, "reference_amota": "0.8"}',
            "'reference_amota' must be a number or null",
        ),
        (
            '{"rule": "last", "selected_step": 3, "selected_amota_sets": [0.8, "x"]}',
            "'selected_amota_sets' must be a list of numbers or null",
        ),
        (
            '{"rule": "last", "selected_step": 3, "reference_amota_sets": 0.8}',
            "'reference_amota_sets' must be a list of numbers or null",
        ),
    ],
)
def test_a_bad_validation_record_names_the_file_and_field(tmp_path, text, message):
    from grutrack.documents import ValidationRecord

    (tmp_path / "validation.json").write_text(text)
    with pytest.raises(InputFormatError, match=message):
        ValidationRecord.read(tmp_path / "validation.json")
    rec = ValidationRecord(
        rule="best_val_amota_1se",
        selected_step=4,
        reference_amota=0.8,
        reference_amota_sets=[0.7, 0.9],
        selected_amota_sets=[0.75, 0.95],
    )
    rec.write(tmp_path / "ok.json")
    assert ValidationRecord.read(tmp_path / "ok.json") == rec


# -- GRU-KF checkpoints ------------------------------------------------------------------------------------------
def _legacy_checkpoint(path, **fields):
    """A checkpoint in the layout grutrack wrote before the :class:`Checkpoint` document (``save_checkpoint`` of
    motion/checkpoint.py plus the trainer's fields), written here by hand so that the test does not depend on the
    writer it checks; returns the network."""
    import torch

    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

    net = GRUKalmanNet(GRUKFConfig(gap_bins=2), generator=torch.Generator().manual_seed(0))
    torch.save(
        {
            "format": "grutrack-grukf/1",
            "grutrack_version": "0.1.0",
            "arch": net.config_dict(),
            "model": net.state_dict(),
            **fields,
        },
        path,
    )
    return net


def _resume_fields(net) -> dict:
    import numpy as np
    import torch

    opt = torch.optim.AdamW(net.parameters(), lr=1e-3)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=4)
    row = TrainingStep(1, 0, "scene-0061", 0.5, 3, 1, 0, 1e-3, None, 0.2, grad_norm=1.5).to_row()
    return {
        "optimizer": opt.state_dict(),
        "scheduler": sched.state_dict(),
        "rng": {"numpy": np.random.default_rng(0).bit_generator.state, "torch": torch.Generator().get_state()},
        "train_state": {"step": 1, "epoch": 0, "index": 1, "order": [1, 0]},
        "train_config": {"epochs": 2, "matched_box": "filter"},
        "log": [row],
    }


def test_a_checkpoint_of_the_earlier_layout_reads_with_every_field(tmp_path):
    import torch

    from grutrack.documents import Checkpoint, TrainingPosition
    from grutrack.motion.checkpoint import load_network

    path = tmp_path / "last.pt"
    net = _legacy_checkpoint(
        path, **_resume_fields(torch.nn.Linear(2, 2)), data_fingerprint="ab" * 32, data_source={"split": "mini_train"}
    )
    ck = Checkpoint.read(path)
    state = ck.require_resumable(str(path))
    assert state.position == TrainingPosition(step=1, epoch=0, index=1, order=[1, 0])
    assert state.log == [TrainingStep(1, 0, "scene-0061", 0.5, 3, 1, 0, 1e-3, None, 0.2, grad_norm=1.5)]
    assert ck.matched_box == "filter" and ck.data_source == {"split": "mini_train"} and ck.selected is None
    assert ck.grutrack_version == "0.1.0" and ck.arch["gap_bins"] == 2
    loaded = load_network(path)
    assert all(torch.equal(loaded.state_dict()[k], v) for k, v in net.state_dict().items())
    # the writer keeps the layout: every field of the file comes back under its name
    assert set(ck.to_dict()) == set(torch.load(path, weights_only=False))


def test_a_network_only_checkpoint_loads_but_does_not_resume(tmp_path):
    from grutrack.documents import Checkpoint

    path = tmp_path / "model.pt"
    _legacy_checkpoint(path)  # a checkpoint of an old version: no training config, no state
    ck = Checkpoint.read(path)
    assert ck.train_config is None and ck.training is None and ck.matched_box == "detection"
    with pytest.raises(InputFormatError, match=r"model.pt: not a resumable checkpoint \(no 'train_state'"):
        ck.require_resumable(str(path))


def test_checkpoint_round_trip_through_its_one_writer_and_reader(tmp_path):
    import torch

    from grutrack.documents import Checkpoint, CheckpointSelection, TrainingPosition, TrainingState
    from grutrack.motion.checkpoint import network_checkpoint

    net = torch.nn.Linear(2, 2)
    fields = _resume_fields(net)
    state = TrainingState(
        TrainingPosition(4, 1, 0, None),
        fields["optimizer"],
        fields["scheduler"],
        fields["rng"],
        [TrainingStep(4, 1, "s", 0.25, lr=1e-3, val_amota=0.7, seconds=1.0, val_amota_sets=(0.6, 0.8), grad_norm=2.0)],
    )
    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

    gru = GRUKalmanNet(GRUKFConfig(), generator=torch.Generator().manual_seed(1))
    doc = network_checkpoint(
        gru,
        train_config={"matched_box": "filter"},
        training=state,
        selected=CheckpointSelection(4, 0.7, rule="best_val_amota"),
        data_fingerprint="f",
        data_source={"split": "x"},
    )
    doc.write(tmp_path / "m.pt")
    back = Checkpoint.read(tmp_path / "m.pt")
    assert back.selected == CheckpointSelection(4, 0.7, rule="best_val_amota")
    assert back.training.position == state.position and back.training.log == state.log
    assert back.train_config == {"matched_box": "filter"} and back.data_fingerprint == "f"
    assert all(torch.equal(back.weights[k], v) for k, v in gru.state_dict().items())
    (tmp_path / "elsewhere").mkdir()
    doc.write(tmp_path / "elsewhere" / "other_name.pt")  # the same checkpoint: the same bytes (provenance SHA-256)
    assert (tmp_path / "elsewhere" / "other_name.pt").read_bytes() == (tmp_path / "m.pt").read_bytes()
    raw = torch.load(tmp_path / "m.pt", weights_only=False)
    assert raw["selected"] == {"rule": "best_val_amota", "step": 4, "val_amota": 0.7}
    assert raw["train_state"] == {"step": 4, "epoch": 1, "index": 0, "order": None} and raw["log"][0]["step"] == 4


@pytest.mark.parametrize(
    "content, expect",
    [
        ({"state_dict": {}}, "not a grutrack GRU-KF checkpoint (expected format grutrack-grukf/1; train one with"),
        ({"format": "grutrack-grukf/1", "arch": {}, "model": [1]}, "field 'model' must hold the network's tensors"),
        (
            {
                "format": "grutrack-grukf/1",
                "arch": {},
                "model": {},
                "train_state": {"step": 1, "wings": 2},
                "optimizer": {},
                "scheduler": {},
                "rng": {},
                "log": [],
            },
            "field 'train_state' is not a training position",
        ),
    ],
)
def test_a_foreign_checkpoint_is_one_line_naming_the_file(tmp_path, content, expect):
    import torch

    from grutrack.documents import Checkpoint

    torch.save(content, tmp_path / "x.pt")
    with pytest.raises(InputFormatError, match=re.escape(expect)) as e:
        Checkpoint.read(tmp_path / "x.pt")
    assert str(e.value).startswith(str(tmp_path / "x.pt")) and "\n" not in str(e.value)
    (tmp_path / "y.pt").write_text("not a torch file")
    with pytest.raises(InputFormatError, match="y.pt: not a readable torch checkpoint"):
        Checkpoint.read(tmp_path / "y.pt")
    with pytest.raises(InputFormatError, match="z.pt: checkpoint does not exist"):
        Checkpoint.read(tmp_path / "z.pt")


def test_grutrack_track_reads_its_checkpoint_once_and_refuses_a_foreign_one(
    nusc_root, pointpillars_mini_val, tmp_path, capsys, monkeypatch
):
    import torch

    from grutrack.cli import main
    from grutrack.documents import Checkpoint

    track = [
        "track",
        "--dataroot",
        str(nusc_root),
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--detections",
        str(pointpillars_mini_val),
        "--tracker",
        "grukf",
        "--device",
        "cpu",
        "--no-progress",
    ]
    torch.save({"state_dict": {}}, tmp_path / "foreign.pt")
    assert main([*track, "--checkpoint", str(tmp_path / "foreign.pt"), "--out", str(tmp_path / "a.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "foreign.pt: not a grutrack GRU-KF checkpoint" in err[0]
    _legacy_checkpoint(tmp_path / "old.pt", train_config={"matched_box": "filter"})
    reads, read = [], Checkpoint.read.__func__

    def counted(cls, *a, **k):
        reads.append(a[0])
        return read(cls, *a, **k)

    monkeypatch.setattr(Checkpoint, "read", classmethod(counted))
    assert main([*track, "--checkpoint", str(tmp_path / "old.pt"), "--out", str(tmp_path / "b.json")]) == 0
    assert len(reads) == 1  # the network and its matched box from one read
    assert "matched_box: filter" in (tmp_path / "b.tracker.yaml").read_text()
