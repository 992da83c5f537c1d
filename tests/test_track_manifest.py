"""By hand, with no ``resolve-config`` step: ``grutrack track`` writes the tracker config it ran beside its output
(``<out stem>.tracker.yaml``), and ``submit`` / ``manifest`` find it there; the manifest's config hash is the one
``resolve-config`` gives the same preset, so by-hand and workflow manifests agree."""

from __future__ import annotations

import json

import pytest

from grutrack.cli import main
from grutrack.io import read_yaml
from grutrack.provenance import config_hash


@pytest.fixture()
def by_hand(nusc_root, pointpillars_mini_val, tmp_path):
    """Dataset and provenance arguments of a by-hand run on mini_val with the real PointPillars detections."""
    data = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    return data, ["--detections", str(pointpillars_mini_val), "--tracker", "ekf"]


def _track(data, detections, out, *extra):
    assert main(["track", *data, "--detections", detections, "--out", str(out), "--no-progress", *extra]) == 0


def _resolved_hash(tmp_path, base: str) -> str:
    out = tmp_path / f"resolved_{base}.yaml"
    assert main(["resolve-config", "tracker", "--base", base, "--out", str(out)]) == 0
    return config_hash(read_yaml(out))


def test_track_then_manifest_needs_no_resolve_step(by_hand, tmp_path, capsys):
    data, prov = by_hand
    sub = tmp_path / "sub.json"
    _track(data, prov[1], sub)
    used = tmp_path / "sub.tracker.yaml"
    assert used.is_file() and f"tracker config {used}" in capsys.readouterr().out
    assert main(["manifest", *data, "--submission", str(sub), *prov]) == 0
    m = json.loads((tmp_path / "sub.manifest.json").read_text())
    assert m["tracker_config"]["path"] == str(used) and m["tracker"] == "ekf" and m["samples"] == 81
    assert m["tracker_config"]["config_hash"] == _resolved_hash(tmp_path, "ekf")
    assert not list(tmp_path.glob(".*.tmp"))  # written atomically: no temp file left


def test_track_then_submit_writes_the_manifest(by_hand, tmp_path):
    data, prov = by_hand
    tracks, sub = tmp_path / "run" / "tracks.json", tmp_path / "sub" / "x.json"
    _track(data, prov[1], tracks, "--config", "polymot")
    assert main(["submit", *data, "--tracks", str(tracks), "--out", str(sub), *prov]) == 0
    m = json.loads((tmp_path / "sub" / "x.manifest.json").read_text())
    assert m["tracker_config"]["path"] == str(tmp_path / "run" / "tracks.tracker.yaml")
    assert m["tracker_config"]["config_hash"] == _resolved_hash(tmp_path, "polymot")


def test_without_a_tracker_config_the_error_says_where_it_looked(by_hand, tmp_path, capsys):
    data, prov = by_hand
    sub, elsewhere = tmp_path / "sub.json", tmp_path / "cfg" / "used.yaml"
    _track(data, prov[1], sub, "--config-out", str(elsewhere))
    assert elsewhere.is_file() and not (tmp_path / "sub.tracker.yaml").exists()
    capsys.readouterr()
    assert main(["manifest", *data, "--submission", str(sub), *prov]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--tracker-config: not given, and no {tmp_path / 'sub.tracker.yaml'}" in err[0]
    assert main(["manifest", *data, "--submission", str(sub), *prov, "--tracker-config", str(elsewhere)]) == 0
    _track(data, prov[1], tmp_path / "none.json", "--config-out", "none")
    assert not (tmp_path / "none.tracker.yaml").exists()


def test_grukf_records_the_matched_box_of_its_checkpoint(by_hand, tmp_path):
    """The GRU-KF without --config writes the box its checkpoint was trained to give: the recorded config says
    so, not the EKF preset it starts from."""
    from grutrack.motion.checkpoint import save_checkpoint
    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

    data, prov = by_hand
    ck = tmp_path / "m.pt"
    save_checkpoint(ck, GRUKalmanNet(GRUKFConfig()))  # no training config: matched_box "detection"
    _track(data, prov[1], tmp_path / "g.json", "--tracker", "grukf", "--checkpoint", str(ck), "--device", "cpu")
    used = read_yaml(tmp_path / "g.tracker.yaml")
    assert used["output"]["matched_box"] == "detection"
    ekf = tmp_path / "ekf.yaml"
    assert (
        main(
            [
                "resolve-config",
                "tracker",
                "--base",
                "ekf",
                "--overrides",
                '{"output": {"matched_box": "detection"}}',
                "--out",
                str(ekf),
            ]
        )
        == 0
    )
    assert config_hash(used) == config_hash(read_yaml(ekf))
