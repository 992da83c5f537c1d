"""The evaluator cross-check (``grutrack cross-check``, the workflow's rule cross_check): nuscenes-devkit
TrackingEval and the fast evaluator on the same submission, on all or evenly spaced scenes of the split, every
summary entry compared; a difference is reported and fails the command; the user's dataroot is never written."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from grutrack.documents import CrossCheckDocument
from grutrack.evaluation import crosscheck
from grutrack.evaluation.crosscheck import cross_check, spread


def test_spread_keeps_the_first_and_spaces_the_rest():
    names = [f"s{i}" for i in range(10)]
    assert spread(names, 3) == ["s0", "s3", "s6"]
    assert spread(names, 1) == ["s0"]
    assert spread(names, None) == names and spread(names, 10) == names and spread(names, 99) == names
    assert len(spread(names, 7)) == 7


def _mini_val(command: str, nusc_root: Path, *args: str) -> subprocess.CompletedProcess:
    """``grutrack COMMAND`` on nuScenes mini_val with ``args``."""
    common = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    return subprocess.run([sys.executable, "-m", "grutrack", command, *common, *args], capture_output=True, text=True)


@pytest.fixture(scope="module")
def tracks(tmp_path_factory, nusc_root, pointpillars_mini_val) -> Path:
    """The EKF's tracks of mini_val on the real PointPillars detections."""
    out = tmp_path_factory.mktemp("cc") / "tracks.json"
    proc = _mini_val("track", nusc_root, "--detections", str(pointpillars_mini_val), "--out", str(out), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    return out


def _listing(root: Path) -> dict[str, float]:
    return {str(p): p.stat().st_mtime for p in root.rglob("*")}


@pytest.mark.slow
def test_devkit_and_fast_agree_on_all_and_on_a_subset(tracks, nusc_root, tmp_path):
    before = _listing(nusc_root)
    full_out, sub_out = tmp_path / "full.json", tmp_path / "sub.json"
    proc = _mini_val("cross-check", nusc_root, "--submission", str(tracks), "--out", str(full_out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "EQUAL at 1e-09" in proc.stdout
    full = CrossCheckDocument.read(full_out)
    assert full.equal and full.max_abs_difference <= 1e-9 and not full.subset
    assert full.scenes == ["scene-0103", "scene-0916"] and full.samples == 81 and full.entries > 150
    # the same AMOTA as `grutrack evaluate --evaluator fast` on the whole split
    ev = tmp_path / "metrics.json"
    proc = _mini_val("evaluate", nusc_root, "--submission", str(tracks), "--evaluator", "fast", "--out", str(ev))
    assert proc.returncode == 0, proc.stderr
    assert full.amota["fast"] == full.amota["devkit"] == json.loads(ev.read_text())["overall"]["amota"]
    # one scene of two: the submission is cut to its samples and both evaluators score it
    proc = _mini_val("cross-check", nusc_root, "--submission", str(tracks), "--scenes", "1", "--out", str(sub_out))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    sub = CrossCheckDocument.read(sub_out)
    assert sub.subset and sub.scenes == ["scene-0103"] and sub.samples == 40 and sub.equal
    assert sub.amota["devkit"] == sub.amota["fast"] != full.amota["fast"]
    assert _listing(nusc_root) == before  # no splits.json or anything else written into the dataroot


def test_a_difference_is_reported_and_not_called_equal(tracks, nusc_root, monkeypatch):
    """A fast evaluator that drifted by 1e-6 in one entry: the cross-check names the entry and says not equal."""
    from grutrack.evaluation import nuscenes_fast as fast_amota

    real = fast_amota.fast_tracking_eval

    def drifted(*a, **k):
        summary = real(*a, **k)
        summary["label_metrics"]["motar"]["car"] += 1e-6
        return summary

    monkeypatch.setattr(fast_amota, "fast_tracking_eval", drifted)
    doc = cross_check(nusc_root, "v1.0-mini", "mini_val", tracks, scenes=1)
    assert not doc.equal
    assert doc.worst_entry == "label_metrics.motar.car"
    assert doc.max_abs_difference == pytest.approx(1e-6, rel=1e-3)


def test_bad_scene_count_exits_2_naming_the_flag(tracks, nusc_root, tmp_path):
    out = tmp_path / "x.json"
    proc = _mini_val("cross-check", nusc_root, "--submission", str(tracks), "--scenes", "0", "--out", str(out))
    assert proc.returncode == 2 and "--scenes 0" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()


def test_a_missing_submission_exits_2_naming_it(nusc_root, tmp_path):
    missing = tmp_path / "nope.json"
    proc = _mini_val("cross-check", nusc_root, "--submission", str(missing), "--out", str(tmp_path / "x.json"))
    assert proc.returncode == 2 and str(missing) in proc.stderr and "Traceback" not in proc.stderr


def test_subset_dataroot_merges_the_custom_splits(tmp_path):
    src = tmp_path / "root" / "v1.0-x"
    src.mkdir(parents=True)
    (src / "scene.json").write_text("[]")
    (src / "splits.json").write_text(json.dumps({"mine": ["a", "b"]}))
    root = crosscheck.subset_dataroot(tmp_path / "root", "v1.0-x", ["b"], tmp_path / "tmp")
    splits = json.loads((root / "v1.0-x" / "splits.json").read_text())
    assert splits == {"mine": ["a", "b"], crosscheck.SUBSET_SPLIT: ["b"]}
    assert (root / "v1.0-x" / "scene.json").is_symlink()
    assert json.loads((src / "splits.json").read_text()) == {"mine": ["a", "b"]}
