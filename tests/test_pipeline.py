"""Workflow support: resolved presets and training configs, per-stage code versions, the workflow config's
cross-references and dataroot messages."""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from grutrack.cli import main
from grutrack.config_loader import merge
from grutrack.data.registry import load_registry
from grutrack.errors import ConfigError
from grutrack.pipeline import codever, spec
from grutrack.pipeline.presets import resolve_tracker, resolve_training
from grutrack.provenance import config_hash
from grutrack.tracking.config import load_tracker_config

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cfg():
    return yaml.safe_load((REPO / "workflow/config/config.yaml").read_text())


@pytest.fixture(scope="module")
def paper():
    return yaml.safe_load((REPO / "workflow/config/paper.yaml").read_text())


def test_merge_keeps_the_rest():
    base = {"a": {"x": 1, "y": 2}, "b": 3}
    assert merge(base, {"a": {"y": 5}}) == {"a": {"x": 1, "y": 5}, "b": 3}
    assert base == {"a": {"x": 1, "y": 2}, "b": 3}


def test_resolved_tracker_preset_and_its_errors(tmp_path):
    raw = resolve_tracker("ekf", {"association": {"first_threshold": {"car": 1.2}}})
    assert raw["association"]["first_threshold"]["car"] == 1.2
    assert (
        raw["association"]["first_threshold"]["bus"] == 1.34
    )  # the ekf preset takes Poly-MOT HEAD's stage-1 bus threshold
    with pytest.raises(ConfigError, match="association.first_treshold"):
        resolve_tracker("ekf", {"association": {"first_treshold": {"car": 1.2}}})
    with pytest.raises(ConfigError, match="first_threshold.cra"):
        resolve_tracker("ekf", {"association": {"first_threshold": {"cra": 1.2}}})
    out = tmp_path / "t.yaml"
    assert (
        main(
            [
                "resolve-config",
                "tracker",
                "--base",
                "ekf",
                "--overrides",
                '{"motion": {"model_override": {"car": "CA"}}}',
                "--out",
                str(out),
            ]
        )
        == 0
    )
    cfg = load_tracker_config(out)
    assert cfg.model_override == {"car": "CA"}
    assert f"config hash {config_hash(yaml.safe_load(out.read_text()))}" in out.read_text()


def test_resolved_training_config():
    assert resolve_training("grukf", {"ss_model": "BICYCLE", "epochs": 3})["ss_model"] == "BICYCLE"
    with pytest.raises(ConfigError, match="unknown key 'epoch'"):
        resolve_training("grukf", {"epoch": 3})


def _tree(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(text)


def test_code_version_changes_only_for_the_stages_that_run_the_file(tmp_path, monkeypatch):
    monkeypatch.delenv("GRUTRACK_CODE_VERSION", raising=False)
    _tree(tmp_path, {"tracking/tracker.py": "a", "report/demo.py": "b", "data/demo.py": "c", "evaluation/x.py": "d"})
    before = {s: codever.code_version(s, tmp_path) for s in codever.STAGE_SOURCES}
    (tmp_path / "report/demo.py").write_text("b2")
    after = {s: codever.code_version(s, tmp_path) for s in codever.STAGE_SOURCES}
    assert [s for s in before if before[s] != after[s]] == ["report"]
    (tmp_path / "tracking/tracker.py").write_text("a2")
    again = {s: codever.code_version(s, tmp_path) for s in codever.STAGE_SOURCES}
    assert {s for s in after if after[s] != again[s]} == {"train", "track"}
    monkeypatch.setenv("GRUTRACK_CODE_VERSION", "pinned")
    assert codever.code_version("track", tmp_path) == "pinned"
    assert codever.code_version("report").startswith("0.") or codever.code_version("report") == "pinned"


def test_code_version_ignores_docstrings_and_comments_but_not_code(tmp_path, monkeypatch):
    """A corrected docstring or comment re-runs nothing (no re-training for a typo); any change of what runs does,
    and so does an edit that leaves a file unparsable."""
    monkeypatch.delenv("GRUTRACK_CODE_VERSION", raising=False)
    py = '"""Module doc."""\n\n\ndef f(x):\n    """Doc."""\n    return x + 1  # note\n'
    cfg = "# Preset.\nkey: {a: 1, b: 2}  # why\n"
    _tree(tmp_path, {"tracking/tracker.py": py, "configs/trackers/p.yaml": cfg})

    def version(files: dict[str, str]) -> str:
        _tree(tmp_path, files)
        return codever.code_version("track", tmp_path)

    base = version({})
    same = {
        "tracking/tracker.py": '"""Doc 2."""\n\n\ndef f(x):\n    """Other."""\n\n    # comment\n    return x + 1\n',
        "configs/trackers/p.yaml": "# Changed comment.\nkey:\n  a: 1\n  b: 2\n",
    }
    for rel, text in same.items():
        assert version({rel: text}) == base, rel
    changed = {
        "tracking/tracker.py": '"""Doc."""\n\n\ndef f(x):\n    return x + 2\n',
        "configs/trackers/p.yaml": "key: {a: 1, b: 3}\n",
    }
    for rel, text in changed.items():
        assert version({rel: text}) != base, rel
        version(same)
    assert version({"tracking/tracker.py": "def f(x:\n"}) != version({"tracking/tracker.py": "def f(x:\n\n"})


def test_default_config_cross_references(cfg, paper):
    spec.check_config(cfg, paper, load_registry())


@pytest.mark.parametrize(
    "path, value, message",
    [
        (("experiments", "demo_val", "runs", "ekf", "preset"), "ekff", "experiments.demo_val.runs.ekf.preset"),
        (("experiments", "demo_val", "runs", "grukf", "training"), "nope", "experiments.demo_val.runs.grukf.training"),
        (("reports", "nusc_val", "tables", "IV", "CTRA+Ours"), "missing_run", "reports.nusc_val.tables.IV.CTRA+Ours"),
        (
            ("reports", "nusc_val", "extra_rows", "III", "Fast-Poly"),
            "missing_run",
            "reports.nusc_val.extra_rows.III.Fast-Poly",
        ),
        (("detectors", "centerpoint", "sources", "val"), "no_such_source", "detectors.centerpoint.sources.val"),
        (("trainings", "demo_grukf", "split"), "demo_test", "detectors.centerpoint_sim.seeds"),
    ],
)
def test_bad_references_name_the_key(cfg, paper, path, value, message):
    bad = copy.deepcopy(cfg)
    node = bad
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    with pytest.raises(ConfigError, match=message.replace("+", r"\+")):
        spec.check_config(bad, paper, load_registry())


def test_dataroot_messages(cfg, tmp_path):
    with pytest.raises(ConfigError, match=r"datasets\.nuscenes\.dataroot is not set: put there the nuScenes dataroot"):
        spec.require_dataroot(cfg, "nuscenes", "val")
    c = copy.deepcopy(cfg)
    c["datasets"]["nuscenes"]["dataroot"] = str(tmp_path)
    with pytest.raises(ConfigError, match="v1.0-test does not exist"):
        spec.require_dataroot(c, "nuscenes", "test")
    (tmp_path / "v1.0-trainval").mkdir()
    assert spec.require_dataroot(c, "nuscenes", "val") == str(tmp_path)
    with pytest.raises(ConfigError, match=r"datasets\.av2\.dataroot is not set: put there the Argoverse 2"):
        spec.require_dataroot(cfg, "av2", "val")
    assert spec.require_dataroot(cfg, "demo") == "data/demo"


def test_a_new_datasets_modules_version_every_stage_that_goes_through_a_dataset(tmp_path, monkeypatch):
    """A dataset's interface, readers and writers (datasets/, data/, export/) version the stages that run through
    the dataset interface without being listed one by one."""
    monkeypatch.delenv("GRUTRACK_CODE_VERSION", raising=False)
    _tree(tmp_path, {"tracking/tracker.py": "a", "report/demo.py": "b"})
    dataset_stages = {"simulate", "train", "track", "submit", "evaluate", "render"}
    for rel in ("datasets/newset.py", "data/newset.py", "export/newset_tracks.py"):
        before = {s: codever.code_version(s, tmp_path) for s in codever.STAGE_SOURCES}
        _tree(tmp_path, {rel: "x"})
        after = {s: codever.code_version(s, tmp_path) for s in codever.STAGE_SOURCES}
        assert dataset_stages <= {s for s in before if before[s] != after[s]}, rel
        assert before["report"] == after["report"] and before["resolve"] == after["resolve"], rel


def test_core_geometry_and_box_code_re_run_tracking():
    """Geometry, the box layout and the canonical scene form feed every tracker: they version the track stages."""
    from grutrack.pipeline.codever import STAGE_SOURCES

    for stage in ("track", "train"):
        for path in ("geometry.py", "boxes.py", "data/scene.py", "tracking", "motion"):
            assert path in STAGE_SOURCES[stage], (stage, path)
    assert "evaluation" in STAGE_SOURCES["evaluate"]  # every evaluator module, fast_loading.py included


def test_every_listed_code_version_source_exists():
    """A renamed or moved module must be renamed in the stage lists too (a missing path hashes as nothing)."""
    from grutrack.pipeline.codever import _COMMON, PACKAGE, STAGE_SOURCES

    missing = sorted(
        {
            (stage, rel)
            for stage, paths in STAGE_SOURCES.items()
            for rel in (*_COMMON, *paths)
            if not (PACKAGE / rel).exists()
        }
    )
    assert missing == []


def test_extra_row_that_is_a_paper_row_is_refused(cfg, paper):
    bad = copy.deepcopy(cfg)
    bad["reports"]["nusc_val"]["extra_rows"] = {"III": {"Poly-MOT": "polymot"}}
    with pytest.raises(
        ConfigError, match=r"reports.nusc_val.extra_rows.III.Poly-MOT: 'Poly-MOT' is a row of the paper"
    ):
        spec.check_config(bad, paper, load_registry())


def _shipped_workflow_config():
    """The shipped workflow config with the paper numbers and the detection registry it is checked against."""
    from grutrack.report.paper import load_paper

    root = Path(__file__).resolve().parents[1]
    cfg = yaml.safe_load((root / "workflow/config/config.yaml").read_text())
    return cfg, load_paper(root / cfg["paper"]), load_registry()


def test_workflow_checks_ask_the_dataset_what_it_supports(monkeypatch):
    """Evaluators, leaderboard zips, validation during training and dataroot layout come from the dataset
    classes (grutrack.datasets), not from per-dataset branches of the workflow's checks."""
    from grutrack.datasets.av2 import AV2Dataset

    cfg, paper, registry = _shipped_workflow_config()
    spec.check_config(cfg, paper, registry)
    # a GRU-KF training on AV2 logs is accepted, with validation too (AV2 validates by HOTA); a dataset class that
    # does not validate trainings has validation refused
    c = copy.deepcopy(cfg)
    c["detectors"]["av2_sim"] = {"kind": "simulated", "profile": "centerpoint", "seeds": {"train": 1, "val": 2}}
    c["trainings"]["av2_grukf"] = {
        "dataset": "av2",
        "split": "train",
        "detector": "av2_sim",
        "config": "grukf",
        "overrides": {},
        "validation": None,
    }
    spec.check_config(c, paper, registry)
    c["trainings"]["av2_grukf"]["validation"] = {"split": "val", "every": 4}
    spec.check_config(c, paper, registry)
    monkeypatch.setattr(AV2Dataset, "validates_training", False)
    with pytest.raises(ConfigError, match=r"trainings\.av2_grukf\.validation: .* \(av2\); set it to null"):
        spec.check_config(c, paper, registry)
    monkeypatch.undo()
    c = copy.deepcopy(cfg)
    c["experiments"]["av2_val"]["evaluator"] = "fast"
    with pytest.raises(ConfigError, match=r"experiments\.av2_val\.evaluator: 'fast' .* \(choose official, none\)"):
        spec.check_config(c, paper, registry)
    c = copy.deepcopy(cfg)
    c["experiments"]["av2_val"]["leaderboard_run"] = "greedy"
    with pytest.raises(ConfigError, match=r"experiments\.av2_val\.leaderboard_run: .* not av2"):
        spec.check_config(c, paper, registry)
    c = copy.deepcopy(cfg)
    c["experiments"]["demo_val"]["evaluator"] = "official"
    with pytest.raises(ConfigError, match=r"\(choose devkit, fast, none\)"):
        spec.check_config(c, paper, registry)


def test_dataroot_layout_comes_from_the_dataset(tmp_path):
    cfg, _, _ = _shipped_workflow_config()
    cfg["datasets"]["av2"]["dataroot"] = str(tmp_path)
    with pytest.raises(ConfigError, match=r"val does not exist; it must be the Argoverse 2 sensor-dataset root"):
        spec.require_dataroot(cfg, "av2", "val")
    (tmp_path / "val").mkdir()
    assert spec.require_dataroot(cfg, "av2", "val") == str(tmp_path)
    cfg["datasets"]["nuscenes"]["dataroot"] = str(tmp_path)
    with pytest.raises(ConfigError, match=r"v1.0-trainval does not exist; it must be the nuScenes dataroot"):
        spec.require_dataroot(cfg, "nuscenes", "val")


@pytest.mark.parametrize(
    "entry, key, message",
    [
        ({"overides": {"epochs": 12}}, "trainings.demo_grukf.overides", "'overides' was unexpected"),
        ({"split": 3}, "trainings.demo_grukf.split", "3 is not of type 'string'"),
        ({"pretrained": 3}, "trainings.demo_grukf.pretrained", "3 is not of type 'string'"),
    ],
)
def test_a_bad_key_of_a_training_is_named(cfg, entry, key, message):
    """A training entry is one of two shapes (``{pretrained: ...}`` or a training): an error in one is named by
    its key inside the shape it was meant to be, not reported as the whole entry matching neither."""
    bad = copy.deepcopy(cfg)
    if "pretrained" in entry:
        bad["trainings"]["demo_grukf"] = entry
    else:
        bad["trainings"]["demo_grukf"].update(entry)
    with pytest.raises(ConfigError) as exc:
        spec.validate_config(bad, REPO / "workflow/schemas/config.schema.yaml", files=[], cli=None)
    assert str(exc.value).startswith(f"config key {key} (from workflow/config/config.yaml): "), exc.value
    assert message in str(exc.value)
