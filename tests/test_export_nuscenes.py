"""The official nuScenes tracking JSON: content, the 500-box cap, validation and atomic writing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from grutrack.data.scene import BoxSet
from grutrack.errors import InputFormatError
from grutrack.export.nuscenes_json import build_submission, validate_submission, write_submission


def _tracks(n, seed=0):
    rng = np.random.default_rng(seed)
    boxes = np.column_stack(
        [
            rng.uniform(-50, 50, (n, 3)),
            rng.uniform(0.5, 5, (n, 3)),
            rng.uniform(-np.pi, np.pi, n),
            rng.normal(0, 3, (n, 2)),
        ]
    )
    return BoxSet(boxes, rng.uniform(0, 1, n), rng.integers(0, 7, n), np.arange(n))


def test_submission_fields_and_cap():
    res = {"s1": _tracks(620), "s2": _tracks(3, 1)}
    sub = build_submission(res, ["s1", "s2", "s3"])
    assert sub["meta"]["use_lidar"] is True
    assert len(sub["results"]["s1"]) == 500 and sub["results"]["s3"] == []
    kept = [b["tracking_score"] for b in sub["results"]["s1"]]
    assert kept == sorted(kept, reverse=True) and min(kept) >= np.sort(res["s1"].scores)[-500]
    b = sub["results"]["s2"][0]
    i = int(b["tracking_id"])
    src = res["s2"]
    assert b["translation"] == src.boxes[i, :3].tolist() and b["size"] == src.boxes[i, 3:6].tolist()
    assert b["velocity"] == src.boxes[i, 7:9].tolist()  # [vx, vy], global frame
    w, _, _, z = b["rotation"]
    assert np.isclose(np.arctan2(2 * w * z, 1 - 2 * z * z), src.boxes[i, 6])
    validate_submission(sub, ["s1", "s2", "s3"])


def test_validation_errors(tmp_path):
    sub = build_submission({"s1": _tracks(2)}, ["s1"])
    with pytest.raises(InputFormatError, match="1 missing"):
        validate_submission(sub, ["s1", "s2"])
    bad = json.loads(json.dumps(sub))
    bad["results"]["s1"][0]["tracking_name"] = "van"
    with pytest.raises(
        InputFormatError, match=r"field 'results\['s1'\]\[0\]\.tracking_name' must be one of .*, got 'van'"
    ):
        validate_submission(bad, ["s1"])
    bad = json.loads(json.dumps(sub))
    bad["results"]["s1"][0]["velocity"] = [float("nan"), 0.0]
    with pytest.raises(
        InputFormatError, match=r"field 'results\['s1'\]\[0\]\.velocity' must be a list of 2 finite numbers"
    ):
        validate_submission(bad, ["s1"])
    # an invalid submission is never written, not even partly
    out = tmp_path / "sub.json"
    with pytest.raises(InputFormatError):
        write_submission(out, bad, ["s1"])
    assert not out.exists() and list(tmp_path.iterdir()) == []
    write_submission(out, sub, ["s1"])
    assert json.loads(out.read_text()) == json.loads(json.dumps(sub))
