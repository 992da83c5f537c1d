"""SYNTHETIC flags wherever a number depends on synthetic data, training included: ``grutrack train`` lists in
training.yaml what of its data was synthetic, and the reports name each such training in a banner."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

from grutrack.report.markdown import detections_line, synthetic_training_banner, training_synthetic
from grutrack.training.run import synthetic_inputs


def _ds(descriptions, name="nuscenes"):
    """A dataset whose scene descriptions are these (the demo's start with its SYNTHETIC marker)."""
    from grutrack.data.demo import MARKER

    return SimpleNamespace(name=name, is_synthetic=lambda: any(d.startswith(MARKER) for d in descriptions))


def _cfg(profiles=(), epochs=3):
    return SimpleNamespace(resample_profiles=tuple(profiles), epochs=epochs)


def test_real_data_and_detector_output_is_not_synthetic():
    real = _ds(["Wait at intersection, peds on sidewalk"])
    assert synthetic_inputs(real, SimpleNamespace(synthetic=None), _cfg(), []) == []
    # resampling needs a second epoch to draw simulated detections
    assert synthetic_inputs(real, SimpleNamespace(synthetic=None), _cfg(["centerpoint"], epochs=1), []) == []


def test_each_synthetic_input_is_named():
    demo = _ds(["SYNTHETIC grutrack demo dataset: straight road"])
    sim = SimpleNamespace(synthetic={"generator": "grutrack simulate-detections", "profile": "centerpoint", "seed": 4})
    got = synthetic_inputs(
        demo,
        sim,
        _cfg(["centerpoint", "pointpillars"]),
        [{"dataset": "demo", "scenes": 700}, {"dataset": "nuscenes", "detections": "x.json"}],
    )
    assert got == [
        "scenes of the SYNTHETIC grutrack demo dataset",
        "simulated detections (centerpoint profile, seed 4)",
        "detections simulated afresh every epoch after the first (centerpoint, pointpillars)",
        "1 SYNTHETIC training source(s) (700 demo scenes)",
    ]
    # AV2 has no demo tables: only its detections can be synthetic
    assert synthetic_inputs(_ds([], name="av2"), sim, _cfg(), []) == [
        "simulated detections (centerpoint profile, seed 4)"
    ]


def _training(folder: Path, synthetic: list[str] | None) -> Path:
    folder.mkdir()
    data = {"dataset": "nuscenes", "split": "train"}
    if synthetic is not None:
        data["synthetic"] = synthetic
    (folder / "training.yaml").write_text(f"# Resolved training config\n# data {json.dumps(data)}\nepochs: 3\n")
    return folder / "train_log.csv"


def test_report_banner_names_each_synthetic_training(tmp_path):
    real = _training(tmp_path / "real", [])
    old = _training(tmp_path / "old", None)  # a training.yaml written before the list existed
    sim = _training(tmp_path / "sim", ["simulated detections (centerpoint profile, seed 1)"])
    assert training_synthetic(real.parent / "training.yaml") == []
    assert synthetic_training_banner({"a": real, "b": old}) is None
    banner = synthetic_training_banner({"a": real, "nusc_grukf": sim})
    assert banner.startswith("> **SYNTHETIC TRAINING DATA.**")
    assert "`nusc_grukf`: simulated detections (centerpoint profile, seed 1)" in banner and "`a`" not in banner


def test_demo_dataset_experiments_are_flagged_whatever_the_detector():
    line = detections_line({"dataset": "demo", "split": "demo_val", "detector": "dense", "simulated": False})
    assert "SYNTHETIC DATA" in line and "SYNTHETIC DETECTIONS" not in line
    line = detections_line({"dataset": "nuscenes", "split": "val", "detector": "centerpoint", "simulated": False})
    assert "SYNTHETIC" not in line
