"""The extension points of ARCHITECTURE.md, measured by doing: a dataset added as its own module plus one
registry line reaches the commands and the workflow config (schema, checks, command-line arguments) with no
other edit."""

from __future__ import annotations

import copy
import json
import textwrap
from pathlib import Path

import pytest
import yaml

from grutrack.datasets import DATASETS, config_kinds
from grutrack.errors import ConfigError
from grutrack.pipeline import spec

REPO = Path(__file__).resolve().parents[1]
SCHEMA = REPO / "workflow/schemas/config.schema.yaml"

#: a new dataset module: nuScenes-format data whose workflow entries name a fixed version (the module is all a
#: contributor writes; the test adds the registry line)
MODULE = textwrap.dedent('''
    from grutrack.datasets.base import config_entry
    from grutrack.datasets.nuscenes import NuScenesDataset


    class KeyframeSet(NuScenesDataset):
        """nuScenes-format keyframes under another name and config kind."""

        name = "keyframes"
        config_kinds = {"keyframes": config_entry("keyframes", dataroot={"type": "string"},
                                                  version={"type": "string"})}

        @staticmethod
        def config_version(entry, split):
            return entry["version"]
''')


@pytest.fixture()
def new_dataset(tmp_path, monkeypatch):
    """The module written to a folder on sys.path and its one line in the registry."""
    (tmp_path / "keyframe_set.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(DATASETS, "keyframes", "keyframe_set:KeyframeSet")
    return "keyframes"


def test_config_kinds_come_from_the_dataset_classes():
    kinds = config_kinds()
    assert {k: name for k, (name, _) in kinds.items()} == {"nuscenes": "nuscenes", "demo": "nuscenes", "av2": "av2"}
    assert all(schema["properties"]["kind"] == {"const": k} for k, (_, schema) in kinds.items())


def test_a_new_dataset_reaches_the_commands(new_dataset, nusc_root, tmp_path, capsys):
    """simulate-detections, track, submit and evaluate with --dataset keyframes; the metrics equal those of the
    same files evaluated as nuScenes."""
    from grutrack.cli import main
    from grutrack.documents import MetricsDocument

    common = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    dets, tracks, sub = (tmp_path / n for n in ("dets.json", "tracks.json", "sub.json"))
    assert (
        main(
            [
                "simulate-detections",
                "--dataset",
                new_dataset,
                *common,
                "--profile",
                "centerpoint",
                "--seed",
                "3",
                "--out",
                str(dets),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "track",
                "--dataset",
                new_dataset,
                *common,
                "--detections",
                str(dets),
                "--out",
                str(tracks),
                "--no-progress",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "submit",
                "--dataset",
                new_dataset,
                *common,
                "--tracks",
                str(tracks),
                "--out",
                str(sub),
                "--manifest",
                "none",
            ]
        )
        == 0
    )
    for ds in (new_dataset, "nuscenes"):
        assert (
            main(
                [
                    "evaluate",
                    "--dataset",
                    ds,
                    *common,
                    "--submission",
                    str(sub),
                    "--evaluator",
                    "fast",
                    "--out",
                    str(tmp_path / f"{ds}.json"),
                ]
            )
            == 0
        )
    new, ref = (MetricsDocument.read(tmp_path / f"{ds}.json") for ds in (new_dataset, "nuscenes"))
    assert new.dataset == "keyframes" and 0.3 < new.overall["amota"] <= 1.0
    assert json.dumps(new.overall) == json.dumps(ref.overall)
    assert json.dumps(new.per_class) == json.dumps(ref.per_class)
    capsys.readouterr()


def test_a_new_dataset_reaches_the_workflow_config(new_dataset, tmp_path):
    """Its config kind is accepted (and its entry checked against its own schema), the checks ask its class, and
    the rules' command-line arguments come from it."""
    cfg = yaml.safe_load((REPO / "workflow/config/config.yaml").read_text())
    paper = yaml.safe_load((REPO / "workflow/config/paper.yaml").read_text())
    from grutrack.data.registry import load_registry

    (tmp_path / "v2.0").mkdir()
    cfg["datasets"]["kf"] = {"kind": "keyframes", "dataroot": str(tmp_path), "version": "v2.0"}
    exp = copy.deepcopy(cfg["experiments"]["demo_val"])
    exp["dataset"] = "kf"
    cfg["experiments"]["kf_val"] = exp
    spec.validate_config(cfg, SCHEMA, files=[])
    spec.check_config(cfg, paper, load_registry())
    assert (
        spec.dataset_args(cfg, "kf", "val") == f"--dataset keyframes --dataroot {tmp_path} --split val --version v2.0"
    )
    assert spec.require_dataroot(cfg, "kf", "val") == str(tmp_path)
    bad = copy.deepcopy(cfg)
    bad["datasets"]["kf"]["rate_hz"] = 10
    with pytest.raises(ConfigError, match=r"config key datasets\.kf\.rate_hz .*: Additional properties"):
        spec.validate_config(bad, SCHEMA, files=[])
    bad["datasets"]["kf"] = {"kind": "kitti", "dataroot": "x"}
    with pytest.raises(
        ConfigError,
        match=r"datasets\.kf\.kind .*'kitti' is not one of \['av2', 'demo', "
        r"'keyframes', 'nuscenes'\]",
    ):
        spec.validate_config(bad, SCHEMA, files=[])


def test_shipped_dataset_entries_are_still_checked_field_by_field():
    cfg = yaml.safe_load((REPO / "workflow/config/config.yaml").read_text())
    spec.validate_config(cfg, SCHEMA, files=[])
    for dataset, key, value, message in (
        ("av2", "rate_hz", 0, "less than or equal to the minimum of 0"),
        ("demo", "scenes", 1, "less than the minimum of 2"),
        ("nuscenes", "test_version", 3, "is not of type 'string', 'null'"),
    ):
        bad = copy.deepcopy(cfg)
        if dataset not in bad["datasets"]:
            continue
        bad["datasets"][dataset][key] = value
        with pytest.raises(ConfigError, match=rf"datasets\.{dataset}\.{key} .*{message}"):
            spec.validate_config(bad, SCHEMA, files=[])
    assert json.dumps(yaml.safe_load(SCHEMA.read_text())["properties"]["datasets"]).count("av2") == 0


def test_a_new_motion_model_is_its_class_and_one_models_line(monkeypatch, nusc_root, tmp_path, capsys):
    """A model registered in MODELS is accepted by the motion config (its defaults under ``models``) and by a
    tracker preset's ``model_override``, and the tracker runs it: here a constant-velocity twin, whose tracks
    equal those of CV itself."""
    from grutrack.cli import main
    from grutrack.motion import models

    made = []

    class TwinCV(models.CV):
        """CV under another name (records its construction)."""

        name = "TwinCV"

        def __init__(self, **params):
            made.append(params)
            super().__init__(**params)

    monkeypatch.setitem(models.MODELS, "TwinCV", TwinCV)  # the one registry line
    motion = yaml.safe_load((REPO / "grutrack/configs/motion/polymot_nusc.yaml").read_text())
    motion["models"]["TwinCV"] = motion["models"]["CV"]
    (tmp_path / "motion.yaml").write_text(yaml.safe_dump(motion))
    preset = yaml.safe_load((REPO / "grutrack/configs/trackers/polymot.yaml").read_text())
    preset["motion"]["config"] = str(tmp_path / "motion.yaml")
    common = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    dets = tmp_path / "dets.json"
    assert main(["simulate-detections", *common, "--profile", "centerpoint", "--seed", "5", "--out", str(dets)]) == 0
    out = {}
    for model in ("TwinCV", "CV"):
        preset["motion"]["model_override"] = {"car": model, "truck": model}
        (tmp_path / f"{model}.yaml").write_text(yaml.safe_dump(preset))
        assert (
            main(
                [
                    "track",
                    *common,
                    "--config",
                    str(tmp_path / f"{model}.yaml"),
                    "--detections",
                    str(dets),
                    "--out",
                    str(tmp_path / f"{model}.json"),
                    "--no-progress",
                ]
            )
            == 0
        )
        out[model] = json.loads((tmp_path / f"{model}.json").read_text())["results"]
    assert made, "the new model was never built"
    cars = [b for boxes in out["TwinCV"].values() for b in boxes if b["tracking_name"] == "car"]
    assert len(cars) > 500
    assert out["TwinCV"] == out["CV"]
    preset["motion"]["model_override"] = {"car": "TwinCVX"}
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(preset))
    assert (
        main(
            [
                "track",
                *common,
                "--config",
                str(tmp_path / "bad.yaml"),
                "--detections",
                str(dets),
                "--out",
                str(tmp_path / "bad.json"),
            ]
        )
        == 2
    )
    assert "'motion.model_override.car' must be one of BICYCLE, CA, CTRA, CV, TWINCV" in capsys.readouterr().err


#: a new report module: the overall AMOTA of each run, one line each
REPORT_MODULE = textwrap.dedent('''
    def build(inp):
        lines = [f"# {inp.name}", ""]
        for run, doc in sorted(inp.docs().items()):
            lines.append(f"- {run}: AMOTA {doc.overall['amota']:.4f}")
        return "\\n".join(lines) + "\\n"
''')


def test_a_new_report_is_its_module_and_one_kinds_line(monkeypatch, tmp_path, capsys):
    """The workflow config accepts the new kind and checks its experiment as the line says; the command
    builds it."""
    from grutrack.cli import main
    from grutrack.data.registry import load_registry
    from grutrack.documents import MetricsDocument
    from grutrack.report import KINDS, ReportKind

    (tmp_path / "amota_list.py").write_text(REPORT_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(KINDS, "amota_list", ReportKind("amota_list", ("demo", "nuscenes"), ("runs",)))
    cfg = yaml.safe_load((REPO / "workflow/config/config.yaml").read_text())
    paper = yaml.safe_load((REPO / "workflow/config/paper.yaml").read_text())
    cfg["reports"]["short"] = {"kind": "amota_list", "experiment": "demo_val", "tables": {}, "trainings": {}}
    spec.validate_config(cfg, SCHEMA, files=[])
    spec.check_config(cfg, paper, load_registry())
    bad = copy.deepcopy(cfg)
    bad["reports"]["short"]["experiment"] = "av2_val"
    with pytest.raises(
        ConfigError,
        match=r"reports\.short\.experiment: a amota_list report needs a demo or "
        r"nuscenes experiment, 'av2_val' is av2",
    ):
        spec.check_config(bad, paper, load_registry())
    bad["reports"]["short"]["kind"] = "amota_lst"
    with pytest.raises(ConfigError, match=r"reports\.short\.kind .*'amota_lst' is not one of"):
        spec.validate_config(bad, SCHEMA, files=[])
    metrics = tmp_path / "m.json"
    MetricsDocument(
        dataset="nuscenes",
        version="v1.0-mini",
        split="mini_val",
        evaluator="fast",
        submission="sub.json",
        overall={"amota": 0.61234},
        per_class={},
    ).write(metrics)
    out = tmp_path / "short.md"
    assert main(["report", "amota_list", "--out", str(out), "--run", f"ekf={metrics}"]) == 0
    assert out.read_text() == "# short\n\n- ekf: AMOTA 0.6123\n"
    assert (
        main(
            [
                "report",
                "amota_list",
                "--out",
                str(out),
                "--run",
                f"ekf={metrics}",
                "--render",
                f"ekf={tmp_path}/counts.json",
            ]
        )
        == 2
    )
    assert "--render: a amota_list report shows no key frames (it has no tracking run)" in capsys.readouterr().err


@pytest.mark.slow  # two whole AV2 evaluations; AV2 track + evaluate are quick in test_av2
def test_a_new_av2_metric_is_one_line(monkeypatch, av2_root, tmp_path):
    """A column from a TrackEval metric class is one TRACKEVAL_COLUMNS line (a class the official run lacks, as
    Identity for idf1, runs in the same final evaluation; a field of one it has is read from its tree): here
    Count's detections, which land in the metrics JSON; the other columns are unchanged."""
    from grutrack.cli import main
    from grutrack.documents import MetricsDocument
    from grutrack.evaluation import av2_eval

    common = ["--dataset", "av2", "--dataroot", str(av2_root), "--split", "val"]
    dets, tracks, sub = tmp_path / "d.feather", tmp_path / "t.pkl", tmp_path / "s.pkl"
    assert main(["simulate-detections", *common, "--profile", "centerpoint", "--seed", "4", "--out", str(dets)]) == 0
    assert main(["track", *common, "--detections", str(dets), "--out", str(tracks), "--no-progress"]) == 0
    assert main(["submit", *common, "--tracks", str(tracks), "--out", str(sub), "--manifest", "none"]) == 0
    assert (
        main(["evaluate", *common, "--submission", str(sub), "--out", str(tmp_path / "a.json"), "--workers", "1"]) == 0
    )
    monkeypatch.setitem(av2_eval.TRACKEVAL_COLUMNS, "dets", ("Count", "Dets", "int"))  # the one line
    assert (
        main(["evaluate", *common, "--submission", str(sub), "--out", str(tmp_path / "b.json"), "--workers", "1"]) == 0
    )
    before, after = MetricsDocument.read(tmp_path / "a.json"), MetricsDocument.read(tmp_path / "b.json")
    for c, row in after.per_class.items():
        assert row.pop("dets") == row["tp"] + row["fp"], c  # Count's detections: the scored tracks' boxes
        assert row == before.per_class[c]
    assert sum(r["tp"] for r in after.per_class.values()) > 500
