"""benchmarks/densify_detections.py: clutter of every detection class, rounded scores, exact duplicates, labelled
SYNTHETIC (docs/mctrack.md's densified rows are made with it)."""

import importlib.util
import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from grutrack.classes import DETECTION_CLASSES

_SPEC = importlib.util.spec_from_file_location(
    "densify_detections", Path(__file__).parents[1] / "benchmarks/densify_detections.py"
)
densify = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(densify)


def _box(token: str, x: float, score: float) -> dict:
    return {
        "sample_token": token,
        "translation": [x, 2.0, 1.0],
        "size": [2.0, 4.5, 1.6],
        "rotation": [1.0, 0.0, 0.0, 0.0],
        "velocity": [1.0, 0.0],
        "detection_name": "car",
        "detection_score": score,
        "attribute_name": "vehicle.moving",
    }


def _submission() -> dict:
    results = {"a": [_box("a", 0.0, 0.91234), _box("a", 10.0, 0.45678)], "b": [_box("b", 1.0, 0.5)], "c": []}
    return {"meta": {"use_lidar": True}, "results": results}


def test_clutter_rounding_and_duplicates(tmp_path):
    src, out = tmp_path / "in.json", tmp_path / "out.json"
    src.write_text(json.dumps(_submission()))
    assert densify.main([str(src), str(out), "--clutter", "200", "--decimals", "2", "--duplicates", "1"]) == 0
    sub = json.loads(out.read_text())
    res = sub["results"]
    assert len(res["a"]) == 2 * 2 + 200 and len(res["b"]) == 2 + 200 and res["c"] == []
    scores = [b["detection_score"] for boxes in res.values() for b in boxes]
    assert all(s == round(s, 2) for s in scores)
    assert 0.91 in scores and 0.46 in scores  # the input's boxes, rounded
    clutter = [b for b in res["a"] if b["translation"][1] != 2.0]
    assert len(clutter) >= 199  # moved in y (a draw of exactly 0 m aside)
    assert all(0.01 <= b["detection_score"] <= 0.3 for b in clutter)
    assert set(Counter(b["detection_name"] for b in clutter)) == set(DETECTION_CLASSES)
    originals = [b for b in res["a"] if b["translation"][1] == 2.0 and b["detection_score"] in (0.91, 0.46)]
    assert len(originals) == 4  # each box twice, exactly
    assert "SYNTHETIC" in sub["synthetic"]["note"] and sub["meta"] == {"use_lidar": True}


def test_the_input_is_not_changed_and_the_draws_follow_the_seed():
    sub = _submission()
    before = json.dumps(sub)
    one = densify.densify(sub, 5, 2, 0.5, np.random.default_rng(3))
    two = densify.densify(sub, 5, 2, 0.5, np.random.default_rng(3))
    assert json.dumps(sub) == before and one == two


def test_a_file_that_is_not_a_submission_is_one_line_with_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"results": {"a": [{"translation": [0, 0, 0]}]}}))
    assert densify.main([str(bad), str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(bad) in err[0] and not (tmp_path / "o.json").exists()


@pytest.mark.parametrize("flag, value", [("--clutter", "-1"), ("--decimals", "-2"), ("--duplicates", "1.5")])
def test_a_bad_flag_value_is_one_line_naming_it_with_exit_2(tmp_path, capsys, flag, value):
    src = tmp_path / "in.json"
    src.write_text(json.dumps(_submission()))
    assert densify.main([str(src), str(tmp_path / "o.json"), flag, value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"{flag}: expected") and value in err[0]
    assert not (tmp_path / "o.json").exists()
