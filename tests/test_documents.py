"""The stage documents: metrics JSON, submission manifest and training log round-trip through their classes,
keep the layout other tools read, and name the file and field when a file is not what it should be."""

from __future__ import annotations

import json
import math

import pytest

from grutrack.documents import FileRecord, Manifest, MetricsDocument, TrainingLog, TrainingStep
from grutrack.errors import InputFormatError


def _metrics(**kw) -> MetricsDocument:
    base = dict(dataset="nuscenes", version="v1.0-mini", split="mini_val", evaluator="fast", submission="s.json",
                overall={"amota": 0.5, "ids": 3.0}, per_class={"car": {"amota": 0.7, "amotp": float("nan")},
                                                               "bus": {"amota": None}})
    base.update(kw)
    return MetricsDocument(**base)


def test_metrics_layout_is_the_one_other_tools_read(tmp_path):
    doc = _metrics(seconds=1.5, devkit_summary={"amota": 0.5})
    doc.write(tmp_path / "m.json")
    raw = json.loads((tmp_path / "m.json").read_text())
    assert list(raw)[:7] == ["dataset", "version", "split", "evaluator", "submission", "overall", "per_class"]
    assert raw["seconds"] == 1.5 and raw["devkit_summary"] == {"amota": 0.5}
    assert "settings" not in raw and "logs" not in raw          # unset optional fields are left out
    back = MetricsDocument.read(tmp_path / "m.json")
    assert back.overall == doc.overall and back.seconds == 1.5 and back.settings is None


def test_metrics_values_by_path_skip_nan_and_missing():
    doc = _metrics()
    assert doc.value("overall.amota") == 0.5 and doc.class_value("car", "amota") == 0.7
    assert doc.class_value("car", "amotp") is None           # NaN (no ground truth) reads as not available
    assert doc.class_value("bus", "amota") is None and doc.value("per_class.truck.amota") is None
    assert doc.value("overall") is None and doc.classes == ["car", "bus"]


@pytest.mark.parametrize("text,expect", [
    ("[1, 2]", "expected a JSON object"),
    ('{"per_class": {}}', "no 'overall' object"),
    ('{"overall": {}, "per_class": {"car": 3}}', "per_class.car must be an object"),
    ("{not json", "not valid JSON"),
])
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
    m = Manifest(dataset="nuscenes", split="mini_val", submission=FileRecord.of(sub), tracker="ekf",
                 tracker_config=FileRecord.of(cfg, "abc123"), version="v1.0-mini", counts={"samples": 81, "boxes": 9})
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
    log = TrainingLog([TrainingStep(1, 0, "scene-0061", 0.5, 3, 1, 0, 1e-5, None, 0.2, grad_norm=1.25),
                       TrainingStep(2, 0, "scene-0103", 0.4, 2, 2, 0, 1e-5, 0.8123, 0.3, (0.9, 0.7246), 1274.95)])
    log.write(tmp_path / "train_log.csv")
    text = (tmp_path / "train_log.csv").read_text().splitlines()
    assert text[0] == ("step,epoch,scene,loss,gt_terms,pseudo_terms,prediction_terms,lr,val_amota,seconds,"
                       "val_amota_sets,grad_norm")
    assert text[1].split(",")[8] == ""                       # no validation after step 1: empty cell
    assert text[2].split(",")[10] == "0.9;0.7246"             # the AMOTA of each validation detection set
    back = TrainingLog.read(tmp_path / "train_log.csv")
    assert back == log and [s.step for s in back.validated()] == [2]


def test_training_log_of_an_older_version_reads_with_defaults(tmp_path):
    p = tmp_path / "train_log.csv"
    p.write_text("step,epoch,loss,val_amota\n1,0,0.5,\n")
    (s,) = TrainingLog.read(p).steps
    assert s.scene == "" and s.prediction_terms == 0 and math.isnan(s.lr) and s.val_amota is None
    assert math.isnan(s.grad_norm)


@pytest.mark.parametrize("text,expect", [
    ("step,epoch,loss\n1,0,0.5\n", "needs the columns step, epoch, loss, val_amota"),
    ("step,epoch,loss,val_amota\n1,0,abc,\n", "step '1': not a number"),
    ("step,epoch,loss,val_amota,val_amota_sets\n2,0,0.5,0.7,0.6;x\n", "step '2': not a number"),
])
def test_bad_training_logs(tmp_path, text, expect):
    p = tmp_path / "train_log.csv"
    p.write_text(text)
    with pytest.raises(InputFormatError, match=expect):
        TrainingLog.read(p)


@pytest.mark.parametrize("text, message", [
    ('{"selected_step": 3}', "needs the fields 'rule' and 'selected_step'"),
    ('{"rule": "best", "selected_step": 3}', "'rule' must be one of 'last', 'best_val_amota', 'best_val_amota_1se'"),
    ('{"rule": "last", "selected_step": "3"}', "'selected_step' an integer, got 'last' and '3'"),
    ('{"rule": "last", "selected_step": 3, "reference_amota": "0.8"}', "'reference_amota' must be a number or null"),
    ('{"rule": "last", "selected_step": 3, "selected_amota_sets": [0.8, "x"]}',
     "'selected_amota_sets' must be a list of numbers or null"),
    ('{"rule": "last", "selected_step": 3, "reference_amota_sets": 0.8}',
     "'reference_amota_sets' must be a list of numbers or null"),
])
def test_a_bad_validation_record_names_the_file_and_field(tmp_path, text, message):
    from grutrack.documents import ValidationRecord

    (tmp_path / "validation.json").write_text(text)
    with pytest.raises(InputFormatError, match=message):
        ValidationRecord.read(tmp_path / "validation.json")
    rec = ValidationRecord(rule="best_val_amota_1se", selected_step=4, reference_amota=0.8,
                           reference_amota_sets=[0.7, 0.9], selected_amota_sets=[0.75, 0.95])
    rec.write(tmp_path / "ok.json")
    assert ValidationRecord.read(tmp_path / "ok.json") == rec
