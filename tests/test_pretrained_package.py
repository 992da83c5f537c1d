"""The shipped network's package names no machine's folders: grutrack.training.pretrained writes the paths of a
training's data record (model.pt's ``data_source``, training.yaml's ``# data`` line, provenance.json) relative to
the workflow's folder."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")


def _absolute_paths(record: dict) -> list[str]:
    from grutrack.training.pretrained import PATH_KEYS

    return [f"{k}={record[k]}" for k in PATH_KEYS if k in record and Path(record[k]).is_absolute()]


def test_portable_source_writes_paths_relative_to_the_workflow_folder():
    from grutrack.training.pretrained import portable_source

    root = Path("/home/me/grutrack")
    src = {
        "dataset": "nuscenes",
        "dataroot": "/home/me/shared/data/nuscenes",
        "detections": "/home/me/grutrack/detections/x.json",
        "split": "mini_train",
    }
    got = portable_source(src, root)
    assert got == {**src, "dataroot": "../shared/data/nuscenes", "detections": "detections/x.json"}
    assert portable_source({"dataroot": "data/nuscenes"}, root) == {"dataroot": "data/nuscenes"}
    assert portable_source(None, root) is None


def test_the_shipped_package_names_no_absolute_path():
    from grutrack.documents import Checkpoint
    from grutrack.training.pretrained import pretrained_dir

    folder = pretrained_dir("grukf_default")
    prov = json.loads((folder / "provenance.json").read_text())
    data = next(ln for ln in (folder / "training.yaml").read_text().splitlines() if ln.startswith("# data "))
    records = {
        "provenance.json": prov["data_source"],
        "training.yaml": json.loads(data[len("# data ") :]),
        "model.pt": Checkpoint.read(folder / "model.pt").data_source,
    }
    found = {name: _absolute_paths(rec) for name, rec in records.items() if _absolute_paths(rec)}
    assert not found, f"absolute paths in the shipped package: {found}"
    assert records["provenance.json"] == records["model.pt"]


def test_package_rewrites_the_data_record_and_keeps_the_network(tmp_path):
    """A training folder whose records hold absolute paths is packaged with them relative to ``root``; the
    weights, the training.yaml settings and the log are the training's."""
    from dataclasses import replace

    from grutrack.documents import Checkpoint
    from grutrack.training.pretrained import FILES, package, pretrained_dir

    shipped = pretrained_dir("grukf_default")
    root = tmp_path / "work"
    src = root / "checkpoints" / "t"
    src.mkdir(parents=True)
    absolute = {"dataroot": str(tmp_path / "shared/data/nuscenes"), "detections": str(root / "detections/d.json")}
    ck = Checkpoint.read(shipped / "model.pt")
    replace(ck, data_source={**ck.data_source, **absolute}).write(src / "model.pt")
    yaml_text = (shipped / "training.yaml").read_text()
    lines = yaml_text.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith("# data "))
    lines[i] = "# data " + json.dumps({**json.loads(lines[i][7:]), **absolute}, sort_keys=True)
    (src / "training.yaml").write_text("\n".join(lines) + "\n")
    for name in FILES[2:]:
        (src / name).write_bytes((shipped / name).read_bytes())
    det = root / "detections/d.json"
    det.parent.mkdir()
    det.write_text("{}")

    out = root / "pretrained" / "t"
    prov = package(src, det, out, "cmd", root=root)
    want = {"dataroot": "../shared/data/nuscenes", "detections": "detections/d.json"}
    assert {k: prov["data_source"][k] for k in want} == want
    got = Checkpoint.read(out / "model.pt")
    assert {k: got.data_source[k] for k in want} == want
    assert all(torch.equal(got.weights[k], ck.weights[k]) for k in ck.weights)
    text = (out / "training.yaml").read_text()
    assert '"dataroot": "../shared/data/nuscenes"' in text and str(tmp_path) not in text
    assert text.count("\n") == yaml_text.count("\n")  # the rest kept, line for line
    assert (out / "train_log.csv").read_bytes() == (shipped / "train_log.csv").read_bytes()
