"""Malformed input files, one format at a time, through the commands that read them: exit status 2 and one line on
stderr naming the file and the field path, no traceback (docs/bad_inputs.md, "Input formats", tables each row).

Every format has one description (grutrack/configs/schemas/formats/*.schema.yaml, the paper's numbers
grutrack/configs/schemas/paper.schema.yaml); the readers check a file against it array by array and let the schema
name the first failing field. The last tests check that the array-level check and the whole schema give the same
verdict on every malformed nuScenes layout here and on the real files."""

from __future__ import annotations

import copy
import json
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from grutrack import formats
from grutrack.cli import main

LOG = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


def fails(capsys, argv: list, path, *fragments: str) -> str:
    """Run ``grutrack argv``; assert exit 2, one stderr line without a traceback that names ``path`` and holds every
    fragment (the field path and the expectation); return the line."""
    assert main([str(a) for a in argv]) == 2
    err = [ln for ln in capsys.readouterr().err.strip().splitlines() if ": warning: " not in ln]
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert f"{path}: " in err[0], (str(path), err[0])
    for f in fragments:
        assert f in err[0], (f, err[0])
    return err[0]


# ----- nuScenes detection JSON ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pp(pointpillars_mini_val) -> dict:
    return json.loads(pointpillars_mini_val.read_text())


def _first(doc: dict) -> str:
    return sorted(doc["results"])[0]


def _box0(doc: dict) -> dict:
    return doc["results"][_first(doc)][0]


def _set(key, value):
    return lambda d: _box0(d).__setitem__(key, value)


def _pop(key):
    return lambda d: _box0(d).pop(key)


#: case -> (mutation of the parsed PointPillars file, or the file's text; the field path in the message with
#: ``{t}`` for the first sample token; a fragment of the expectation)
DETECTION_CASES = {
    "top_level_list": ("[1, 2]", "the document must be a JSON object", "(the official nuScenes detection format)"),
    "top_level_null": ("null", "the document must be a JSON object", "got None"),
    "empty_file": ("", "not valid JSON", "Expecting value"),
    "truncated": (lambda text: text[:2000], "not valid JSON", "line 1 column"),
    "no_results": (lambda d: d.pop("results"), "field 'results' is missing", "an object {sample_token"),
    "results_a_list": (lambda d: d.__setitem__("results", []), "field 'results' must be an object", "got []"),
    "sample_an_object": (
        lambda d: d["results"].__setitem__(_first(d), {}),
        "field 'results['{t}']' must be a list of at most 500 boxes",
        "got {}",
    ),
    "box_a_number": (
        lambda d: d["results"][_first(d)].__setitem__(0, 5),
        "field 'results['{t}'][0]' must be a box object",
        "got 5",
    ),
    "box_missing_size": (_pop("size"), "field 'results['{t}'][0].size' is missing", "3 positive finite numbers"),
    "size_two_numbers": (_set("size", [1.0, 2.0]), "field 'results['{t}'][0].size' must be a list of 3", "[1.0, 2.0]"),
    "size_negative": (_set("size", [1.0, -2.0, 1.5]), "[0].size' must be a list of 3 positive", "[1.0, -2.0, 1.5]"),
    "size_nested": (_set("size", [[1.0], 2.0, 3.0]), "[0].size' must be a list of 3 positive", "[[1.0], 2.0, 3.0]"),
    "size_and_rotation_lengths_swapped": (
        lambda d: _box0(d).update(size=[1.0, 2.0], rotation=[1.0, 0.0, 0.0, 0.0, 0.0]),
        "[0].size' must be a list of 3 positive",
        "[1.0, 2.0]",
    ),
    "translation_nan": (_set("translation", [float("nan"), 0.0, 0.0]), "[0].translation' must be", "[nan, 0.0"),
    "translation_infinity": (_set("translation", [0.0, float("inf"), 0.0]), "[0].translation' must be", "inf"),
    "translation_integer_beyond_a_float": (
        _set("translation", [10**400, 0.0, 0.0]),
        "[0].translation' must be a list of 3 finite numbers",
        "got [1000",
    ),
    "nested_too_deeply": ("[" * 100_000 + "]" * 100_000, "not a JSON document grutrack reads", "nested too deeply"),
    "translation_strings": (
        _set("translation", ["1", "2", "3"]),
        "[0].translation' must be a list of 3 finite numbers",
        "(a number written as a string)",
    ),
    "rotation_three_numbers": (_set("rotation", [1.0, 0.0, 0.0]), "[0].rotation' must be a unit quaternion", "got"),
    "rotation_not_unit": (_set("rotation", [2.0, 0.0, 0.0, 0.0]), "[0].rotation' must be a unit quaternion", "norm 2"),
    "velocity_null": (_set("velocity", None), "[0].velocity' must be a list of 2 finite numbers", "got None"),
    "velocity_one_number": (_set("velocity", [1.0]), "[0].velocity' must be a list of 2", "got [1.0]"),
    "score_a_string": (_set("detection_score", "0.5"), "[0].detection_score' must be a number in [0, 1]", "'0.5'"),
    "score_out_of_range": (_set("detection_score", 1.5), "[0].detection_score' must be a number in [0, 1]", "1.5"),
    "score_a_boolean": (_set("detection_score", True), "[0].detection_score' must be a number in [0, 1]", "True"),
    "rotation_a_boolean": (
        _set("rotation", [True, 0.0, 0.0, 0.0]),
        "[0].rotation' must be a unit quaternion",
        "[True, 0.0",
    ),
    "name_not_a_class": (_set("detection_name", "van"), "[0].detection_name' must be one of car, truck", "'van'"),
    "name_a_list": (_set("detection_name", ["car"]), "[0].detection_name' must be one of", "['car']"),
    "sample_token_a_number": (_set("sample_token", 5), "[0].sample_token' must be the token of the sample", "5"),
    "sample_token_of_another_sample": (
        _set("sample_token", "another"),
        "[0].sample_token' is 'another', expected the sample it is listed under",
        "",
    ),
    "sample_missing": (
        lambda d: d["results"].pop(_first(d)),
        "1 of 81 sample tokens of the split are missing from 'results'",
        "",
    ),
    "meta_missing": (lambda d: d.pop("meta"), "field 'meta' is missing", "use_camera, use_lidar"),
    "meta_boolean_a_string": (
        lambda d: d["meta"].__setitem__("use_lidar", "yes"),
        "field 'meta.use_lidar' must be true or false",
        "'yes'",
    ),
}


def _detection_file(tmp_path: Path, pp: dict, source: Path, make) -> tuple[Path, str]:
    path = tmp_path / "d.json"
    if isinstance(make, str):
        path.write_text(make)
    elif not _takes_doc(make):
        path.write_text(make(source.read_text()))
    else:
        doc = copy.deepcopy(pp)
        make(doc)
        path.write_text(json.dumps(doc))
    return path, _first(pp)


#: detection cases in the slow tier only: each is a second case of a kind a quick one has (top_level_list,
#: size_negative, translation_nan, rotation_not_unit, velocity_null, score_a_string, name_not_a_class); every
#: layout stays checked against the schema in the quick tier (test_the_schema_alone_rejects_...)
SLOW_DETECTION_CASES = {
    "top_level_null",
    "size_two_numbers",
    "size_nested",
    "translation_infinity",
    "rotation_three_numbers",
    "velocity_one_number",
    "score_out_of_range",
    "name_a_list",
}


def _tiered(cases, slow) -> list:
    return [pytest.param(c, marks=pytest.mark.slow) if c in slow else c for c in sorted(cases)]


@pytest.mark.parametrize("case", _tiered(DETECTION_CASES, SLOW_DETECTION_CASES))
def test_malformed_detection_json(nusc_root, pointpillars_mini_val, pp, tmp_path, capsys, case):
    make, field, expect = DETECTION_CASES[case]
    path, token = _detection_file(tmp_path, pp, pointpillars_mini_val, make)
    mini_val = ["--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val"]
    field = field.replace("{t}", token)
    track = ["track", *mini_val, "--detections", path, "--out", tmp_path / "o.json", "--no-progress"]
    fails(capsys, track, path, field, expect)
    convert = ["convert-detections", "--format", "nuscenes_json", "--raw", path, *mini_val, "--out", tmp_path / "c"]
    fails(capsys, convert, path, field, expect)
    assert not (tmp_path / "o.json").exists() and not (tmp_path / "c").exists()


def test_detection_file_that_is_a_folder(nusc_root, tmp_path, capsys):
    mini_val = ["--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val"]
    argv = ["track", *mini_val, "--detections", tmp_path, "--out", tmp_path / "o.json", "--no-progress"]
    fails(capsys, argv, tmp_path, "detection file is a folder; expected a JSON file")


# ----- nuScenes tracking JSON (submissions) ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def submission(nusc_root) -> dict:
    from grutrack.data.nuscenes import load_scenes, open_nuscenes

    tokens = [f.token for s in load_scenes(open_nuscenes(nusc_root, "v1.0-mini"), "mini_val") for f in s.frames]
    box = {
        "translation": [600.0, 1600.0, 1.0],
        "size": [1.9, 4.5, 1.6],
        "rotation": [1.0, 0.0, 0.0, 0.0],
        "velocity": [0.0, 0.0],
        "tracking_id": "1",
        "tracking_name": "car",
        "tracking_score": 0.5,
    }
    return {
        "meta": {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False},
        "results": {t: [{"sample_token": t, **box}] for t in tokens},
    }


def _tbox(doc: dict) -> dict:
    return doc["results"][_first(doc)][0]


def _tset(key, value):
    return lambda d: _tbox(d).__setitem__(key, value)


#: case -> (mutation, the commands that read it, field path with ``{t}``, a fragment of the expectation)
TRACKING_CASES = {
    "top_level_list": (lambda d: [d], ("evaluate", "compare-tracks"), "the document must be a JSON object", "got"),
    "no_meta": (lambda d: d.pop("meta"), ("evaluate", "render"), "field 'meta' is missing", "use_camera"),
    "extra_top_level_key": (
        lambda d: d.__setitem__("version", 1),
        ("evaluate", "submit"),
        "the document has the unknown field 'version'",
        "'meta' and 'results'",
    ),
    "results_a_list": (
        lambda d: d.__setitem__("results", []),
        ("evaluate", "compare-tracks"),
        "field 'results' must be an object",
        "got []",
    ),
    "sample_a_string": (
        lambda d: d["results"].__setitem__(_first(d), "x"),
        ("evaluate", "submit", "render"),
        "field 'results['{t}']' must be a list",
        "got 'x'",
    ),
    "box_a_number": (
        lambda d: d["results"][_first(d)].__setitem__(0, 5),
        ("evaluate", "submit", "compare-tracks", "render", "leaderboard-zip"),
        "field 'results['{t}'][0]' must be a box object with exactly",
        "got 5",
    ),
    "tracking_id_missing": (
        lambda d: _tbox(d).pop("tracking_id"),
        ("evaluate", "compare-tracks", "cross-check"),
        "field 'results['{t}'][0].tracking_id' is missing",
        "a string",
    ),
    "tracking_id_a_number": (
        _tset("tracking_id", 7),
        ("evaluate", "compare-tracks", "render", "submit"),
        "[0].tracking_id' must be a string",
        "got 7",
    ),
    "tracking_name_not_a_class": (
        _tset("tracking_name", "barrier"),
        ("evaluate", "render"),
        "[0].tracking_name' must be one of bicycle, bus, car",
        "'barrier'",
    ),
    "tracking_name_a_list": (
        _tset("tracking_name", ["car"]),
        ("evaluate", "submit", "leaderboard-zip"),
        "[0].tracking_name' must be one of",
        "['car']",
    ),
    "score_nan": (_tset("tracking_score", float("nan")), ("evaluate", "compare-tracks"), "[0].tracking_score'", "nan"),
    "size_two_numbers": (_tset("size", [1.0, 2.0]), ("evaluate", "compare-tracks"), "[0].size' must be", "[1.0, 2.0]"),
    "rotation_not_unit": (
        _tset("rotation", [1.0, 0.1, 0.0, 0.0]),
        ("evaluate", "compare-tracks"),
        "[0].rotation' must be a unit quaternion",
        "norm 1.0050",
    ),
    "unknown_box_field": (
        _tset("detection_name", "car"),
        ("evaluate", "render"),
        "field 'results['{t}'][0]' has the unknown field 'detection_name'",
        "exactly sample_token",
    ),
    "sample_not_in_the_dataset": (
        lambda d: d["results"].__setitem__("not-a-sample", []),
        ("evaluate", "render", "submit"),
        "must hold exactly the 81 samples of",
        "1 ",
    ),
    "meta_without_sensor": (
        lambda d: d["meta"].__setitem__("use_lidar", False),
        ("evaluate", "compare-tracks"),
        "field 'meta' declares no sensor",
        "",
    ),
}


def _tracking_argv(command: str, path: Path, nusc_root: Path, tmp_path: Path) -> list:
    mini_val = ["--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val"]
    return {
        "evaluate": ["evaluate", *mini_val, "--submission", path, "--out", tmp_path / "m.json", "--evaluator", "fast"],
        "cross-check": ["cross-check", *mini_val, "--submission", path, "--out", tmp_path / "x.json"],
        "submit": ["submit", *mini_val, "--tracks", path, "--out", tmp_path / "s.json", "--manifest", "none"],
        "leaderboard-zip": ["leaderboard-zip", *mini_val, "--submission", path, "--out", tmp_path / "s.zip"],
        "compare-tracks": ["compare-tracks", *mini_val, "--reference", path, "--submission", path],
        "render": [*["render", *mini_val, "--submission", path], "--scene", "scene-0103", "--out", tmp_path / "r"],
    }[command]


#: tracking cases in the slow tier only: box fields of a kind the quick detection cases have, read by commands the
#: quick tracking cases run (box_a_number runs all five of tracking_name_a_list's and more)
SLOW_TRACKING_CASES = {"size_two_numbers", "score_nan", "rotation_not_unit", "tracking_name_a_list"}


@pytest.mark.parametrize("case", _tiered(TRACKING_CASES, SLOW_TRACKING_CASES))
def test_malformed_tracking_json(nusc_root, submission, tmp_path, capsys, case):
    make, commands, field, expect = TRACKING_CASES[case]
    doc = copy.deepcopy(submission)
    new = make(doc)
    doc = new if isinstance(new, list) else doc
    path = tmp_path / "sub.json"
    path.write_text(json.dumps(doc))
    field = field.replace("{t}", _first(submission))
    for command in commands:
        fails(capsys, _tracking_argv(command, path, nusc_root, tmp_path), path, field, expect)
    assert not any((tmp_path / n).exists() for n in ("m.json", "x.json", "s.json", "s.zip", "r"))


# ----- the metrics JSON ------------------------------------------------------------------------------------------
def _metrics() -> dict:
    return {
        "dataset": "nuscenes",
        "version": "v1.0-mini",
        "split": "mini_val",
        "evaluator": "fast",
        "submission": "s.json",
        "overall": {"amota": 0.5, "amotp": 1.2, "ids": 3.0},
        "per_class": {"car": {"amota": 0.7, "amotp": None}, "bus": {"amota": float("nan")}},
    }


METRICS_CASES = {
    "a_list": (lambda d: [d], "the document must be a metrics JSON of grutrack evaluate", "got [{"),
    "overall_missing": (lambda d: d.pop("overall"), "field 'overall' is missing", "an object {metric: value}"),
    "per_class_a_list": (lambda d: d.__setitem__("per_class", []), "field 'per_class' must be an object", "got []"),
    "class_a_number": (
        lambda d: d["per_class"].__setitem__("car", 3),
        "field 'per_class.car' must be an object of metric values",
        "got 3",
    ),
    "metric_a_string": (
        lambda d: d["overall"].__setitem__("amota", "0.5"),
        "field 'overall.amota' must be a finite number, null or NaN",
        "(a number written as a string)",
    ),
    "class_metric_a_list": (
        lambda d: d["per_class"]["car"].__setitem__("amota", [0.7]),
        "field 'per_class.car.amota' must be a finite number, null or NaN",
        "got [0.7]",
    ),
    "absent_not_boolean": (
        lambda d: d["per_class"]["car"].__setitem__("absent", 1),
        "field 'per_class.car.absent' must be true or false",
        "got 1",
    ),
    "split_a_number": (lambda d: d.__setitem__("split", 3), "field 'split' must be the split name", "got 3"),
}


def test_a_missing_metrics_json_says_what_writes_it(tmp_path, capsys):
    """check / check-published on a metrics JSON that is not there: one line naming it and what makes it, the
    workflow's target for a path of the workflow's reports/metrics/{experiment}/{detector}/{run}.json layout."""
    wf = tmp_path / "reports/metrics/nusc_val/centerpoint/grukf.json"
    line = fails(capsys, ["check", wf, "--table", "III"], wf, "metrics JSON does not exist")
    assert f"snakemake --cores 2 {wf}" in line and "experiment nusc_val, detections centerpoint, run grukf" in line
    other = tmp_path / "m.json"
    line = fails(capsys, ["check", other, "--table", "III"], other, "does not exist")
    assert f"grutrack evaluate writes it (--out {other})" in line
    dets = tmp_path / "d.json"
    dets.write_text("{}")
    fails(capsys, ["check-published", other, "--detections", dets], other, "grutrack evaluate writes it")


@pytest.mark.parametrize("case", sorted(METRICS_CASES))
def test_malformed_metrics_json(tmp_path, capsys, case):
    make, field, expect = METRICS_CASES[case]
    doc = _metrics()
    new = make(doc)
    doc = new if isinstance(new, list) else doc
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    fails(capsys, ["check", path, "--table", "III"], path, field, expect)
    out = tmp_path / "r.md"
    argv = ["report", "nusc_val", "--out", out, "--run", f"ekf={path}", "--row", "III:Ours=ekf"]
    fails(capsys, argv, path, field, expect)
    assert not out.exists()


# ----- the paper's numbers -----------------------------------------------------------------------------------
PAPER = Path(__file__).resolve().parents[1] / "workflow" / "config" / "paper.yaml"

PAPER_CASES = {
    "misspelt_key": (
        lambda p: p["tables"]["III"].__setitem__("colums", p["tables"]["III"].pop("columns")),
        "unknown key 'tables.III.colums'",
    ),
    "tolerance_a_string": (
        lambda p: p["tables"]["III"]["columns"]["amota"].__setitem__("tolerance", "small"),
        "'tables.III.columns.amota.tolerance' must be",
    ),
    "tables_a_list": (lambda p: p.__setitem__("tables", [1]), "'tables' must be"),
    "row_number_a_string": (
        lambda p: p["tables"]["III"]["rows"]["Ours"].__setitem__("amota", "69.3"),
        "'tables.III.rows.Ours.amota' must be",
    ),
}


@pytest.mark.parametrize("case", sorted(PAPER_CASES))
def test_malformed_paper_numbers(tmp_path, capsys, case):
    make, field = PAPER_CASES[case]
    paper = yaml.safe_load(PAPER.read_text())
    make(paper)
    path = tmp_path / "paper.yaml"
    path.write_text(yaml.safe_dump(paper))
    metrics = tmp_path / "m.json"
    metrics.write_text(json.dumps(_metrics()))
    fails(capsys, ["check", metrics, "--table", "III", "--paper", path], path, field)


# ----- AV2: the LT3D detection table, the annotations and poses, the tracking pickle -------------------------------
@pytest.fixture(scope="module")
def av2_scenes(av2_root):
    from grutrack.data import av2

    return av2.load_scenes(av2_root, "val", with_gt=True)


@pytest.fixture(scope="module")
def lt3d_table(av2_scenes) -> pd.DataFrame:
    from grutrack.data.lt3d_detections import detection_table

    return detection_table(av2_scenes, {f.token: f.gt for s in av2_scenes for f in s.frames})


def _col(name, value, row=3):
    return lambda d: d.__setitem__(name, d[name].astype(object).where(d.index != row, value))


#: case -> (mutation of the table, file suffix, what names the failing row and column, a fragment)
LT3D_CASES = {
    "column_missing": (lambda d: d.drop(columns=["score"], inplace=True), "feather", "missing column(s) ['score']", ""),
    "numbers_as_strings": (
        lambda d: d.__setitem__("tx_m", d["tx_m"].astype(str)),
        "feather",
        "row 0 (log_id ",
        "field 'tx_m' must be a finite number",
    ),
    "nan_size": (_col("height_m", float("nan")), "feather", "row 3 (log_id ", "field 'height_m' must be a positive"),
    "negative_size": (_col("width_m", -1.0), "csv", "row 3 (log_id ", "field 'width_m' must be a positive"),
    "score_out_of_range": (_col("score", 1.5), "pkl", "row 3 (log_id ", "field 'score' must be a number in [0, 1]"),
    "category_unknown": (_col("category", "CAR"), "feather", "row 3 (", "field 'category' must be an AV2 category"),
    "category_a_number": (
        lambda d: d.__setitem__("category", 5),
        "feather",
        "row 0 (",
        "field 'category' must be an AV2 category",
    ),
    "timestamp_not_integer": (
        lambda d: d.__setitem__("timestamp_ns", d["timestamp_ns"].astype(str)),
        "feather",
        "row 0 (",
        "field 'timestamp_ns' must be an integer",
    ),
    "quaternion_not_unit": (_col("qw", 3.0), "feather", "row 3 (", "field 'qw/qx/qy/qz' must be a unit quaternion"),
    "log_id_a_number": (
        lambda d: d.__setitem__("log_id", 7),
        "feather",
        "row 0 (log_id 7",
        "field 'log_id' must be a log id",
    ),
}


def _write_table(df: pd.DataFrame, path: Path) -> None:
    {"feather": df.to_feather, "csv": lambda p: df.to_csv(p, index=False), "pkl": df.to_pickle}[path.suffix[1:]](path)


@pytest.mark.parametrize("case", sorted(LT3D_CASES))
def test_malformed_lt3d_table(av2_root, lt3d_table, tmp_path, capsys, case):
    make, suffix, where, expect = LT3D_CASES[case]
    df = lt3d_table.copy()
    make(df)
    path = tmp_path / f"d.{suffix}"
    _write_table(df, path)
    av2_val = ["--dataset", "av2", "--dataroot", av2_root, "--split", "val"]
    fails(
        capsys,
        ["track", *av2_val, "--detections", path, "--out", tmp_path / "o.pkl", "--no-progress"],
        path,
        where,
        expect,
    )
    convert = ["convert-detections", "--format", "lt3d", "--raw", path, "--dataroot", av2_root, "--split", "val"]
    fails(capsys, [*convert, "--out", tmp_path / "c.feather"], path, where, expect)
    assert not (tmp_path / "o.pkl").exists() and not (tmp_path / "c.feather").exists()


def test_lt3d_pickle_of_another_structure(av2_root, tmp_path, capsys):
    av2_val = ["--dataset", "av2", "--dataroot", av2_root, "--split", "val", "--out", tmp_path / "o.pkl"]
    path = tmp_path / "d.pkl"
    path.write_bytes(pickle.dumps({"boxes": [1, 2]}))
    fails(capsys, ["track", *av2_val, "--detections", path], path, "expected a pandas DataFrame of LT3D detections")


def _log_copy(av2_root: Path, tmp_path: Path, table: str, make) -> Path:
    """An AV2 root whose first log has ``table`` (annotations / city_SE3_egovehicle) rewritten by ``make``; the
    other files are links to the real ones."""
    root = tmp_path / "av2"
    for log in (av2_root / "val").iterdir():
        dest = root / "val" / log.name
        dest.mkdir(parents=True)
        for item in log.iterdir():
            (dest / item.name).symlink_to(item)
    target = root / "val" / LOG / f"{table}.feather"
    df = pd.read_feather(target.resolve())
    target.unlink()
    make(df)
    df.to_feather(target)
    return target


AV2_TABLE_CASES = {
    "annotations_column_missing": (
        "annotations",
        lambda d: d.drop(columns=["category"], inplace=True),
        "missing column(s) ['category']",
    ),
    "annotations_negative_length": ("annotations", _col("length_m", -2.0), "row 3 (timestamp_ns "),
    "poses_quaternion_not_unit": ("city_SE3_egovehicle", _col("qx", 0.5), "field 'qw/qx/qy/qz' must be a unit"),
    "poses_timestamp_strings": (
        "city_SE3_egovehicle",
        lambda d: d.__setitem__("timestamp_ns", d["timestamp_ns"].astype(str)),
        "field 'timestamp_ns' must be an integer",
    ),
}


@pytest.mark.parametrize("case", sorted(AV2_TABLE_CASES))
def test_malformed_av2_log_tables(av2_root, lt3d_table, tmp_path, capsys, case):
    table, make, fragment = AV2_TABLE_CASES[case]
    path = _log_copy(av2_root, tmp_path, table, make)
    dets = tmp_path / "d.feather"
    lt3d_table.to_feather(dets)
    argv = ["track", "--dataset", "av2", "--dataroot", tmp_path / "av2", "--split", "val", "--detections", dets]
    fails(capsys, [*argv, "--out", tmp_path / "o.pkl", "--no-progress"], path, fragment)


@pytest.fixture(scope="module")
def av2_tracks(av2_root) -> dict:
    """A valid tracking pickle object of the val logs at 2 Hz: the labels as tracks."""
    from grutrack.data import av2
    from grutrack.data.scene import BoxSet
    from grutrack.export.av2_tracks import build_sequences

    scenes = av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True)
    res = {
        f.token: BoxSet(f.gt.boxes, np.full(len(f.gt), 0.9), f.gt.labels, np.arange(len(f.gt)))
        for s in scenes
        for f in s.frames
    }
    return build_sequences(scenes, res, av2.vocabulary(all_categories=True))


def _frame(s: dict) -> dict:
    return s[LOG][2]


PICKLE_CASES = {
    "a_list": (lambda s: [s], "the document must be a dict {log_id: [frame, ...]}"),
    "log_an_object": (lambda s: s.__setitem__(LOG, {}), f"field '['{LOG}']' must be a list of frame dicts"),
    "frame_missing_score": (lambda s: _frame(s).pop("score"), f"field '['{LOG}'][2].score' is missing"),
    "size_a_list": (
        lambda s: _frame(s).__setitem__("size", _frame(s)["size"].tolist()),
        f"field '['{LOG}'][2].size' must be a numpy array (N, 3)",
    ),
    "size_two_columns": (
        lambda s: _frame(s).__setitem__("size", _frame(s)["size"][:, :2]),
        "[2].size' must be a numpy array (N, 3) of positive finite numbers",
    ),
    "translation_nan": (
        lambda s: _frame(s)["translation_m"].__setitem__((0, 0), np.nan),
        "[2].translation_m' must be a numpy array (N, 3) of finite numbers",
    ),
    "name_not_a_category": (
        lambda s: _frame(s)["name"].__setitem__(0, "CAR"),
        "[2].name' must be a numpy array (N,) of AV2 competition category names",
    ),
    "score_one_short": (
        lambda s: _frame(s).__setitem__("score", _frame(s)["score"][:-1]),
        "[2].score' must have as many rows as 'track_id'",
    ),
    "track_id_twice": (
        lambda s: _frame(s)["track_id"].__setitem__(1, _frame(s)["track_id"][0]),
        "[2].track_id' must be a numpy array (N,) of track ids, unique within the frame",
    ),
    "frames_missing": (lambda s: s[LOG].pop(), f"log {LOG}: frames must be exactly the 32 label frames"),
}


@pytest.mark.parametrize("case", sorted(PICKLE_CASES))
def test_malformed_av2_tracking_pickle(av2_root, av2_tracks, tmp_path, capsys, case):
    make, fragment = PICKLE_CASES[case]
    seqs = copy.deepcopy(av2_tracks)
    new = make(seqs)
    seqs = new if isinstance(new, list) else seqs
    path = tmp_path / "t.pkl"
    path.write_bytes(pickle.dumps(seqs))
    av2_val = ["--dataset", "av2", "--dataroot", av2_root, "--split", "val"]
    argv = ["evaluate", *av2_val, "--submission", path, "--out", tmp_path / "m.json", "--workers", "1"]
    fails(capsys, argv, path, fragment)
    fails(
        capsys,
        ["submit", *av2_val, "--tracks", path, "--out", tmp_path / "s.pkl", "--manifest", "none"],
        path,
        fragment,
    )
    assert not (tmp_path / "m.json").exists() and not (tmp_path / "s.pkl").exists()


# ----- one description: the array-level check and the whole schema agree ----------------------------------------
def _parsed_cases() -> list[str]:
    """The detection cases that change the parsed document (not its text)."""
    return sorted(k for k, (make, _, _) in DETECTION_CASES.items() if callable(make) and _takes_doc(make))


def _takes_doc(make) -> bool:
    return make.__code__.co_varnames[:1] != ("text",)


@pytest.mark.parametrize("case", _parsed_cases())
def test_the_schema_alone_rejects_every_malformed_detection_layout(pp, case):
    """The whole document against nusc_detections.schema.yaml (jsonschema, no array-level check) rejects the same
    layouts, except what only the reader can tell: a sample of the split missing, a box under another sample, and no
    meta (the schema describes a meta when there is one; the commands that carry it require it)."""
    doc = copy.deepcopy(pp)
    DETECTION_CASES[case][0](doc)
    only_by_the_reader = {"sample_missing", "sample_token_of_another_sample", "meta_missing"}
    assert (formats.first_error("nusc_detections", doc) is None) == (case in only_by_the_reader)


@pytest.mark.parametrize("case", sorted(TRACKING_CASES))
def test_the_schema_alone_rejects_every_malformed_tracking_layout(submission, case):
    doc = copy.deepcopy(submission)
    new = TRACKING_CASES[case][0](doc)
    doc = new if isinstance(new, list) else doc
    only_with_the_split = {"sample_not_in_the_dataset", "meta_without_sensor"}
    assert (formats.first_error("nusc_tracking", doc) is None) == (case in only_with_the_split)


def test_real_files_fit_their_description_whole(pointpillars_mini_val, nusc_reference):
    """The real detection and tracking files fit their schemas checked whole by jsonschema alone, as they pass the
    readers' array-level check."""
    from grutrack.data.nusc_detections import results_boxes
    from grutrack.export.nuscenes_json import check_document

    for det in (pointpillars_mini_val, nusc_reference / "mini_val_centerpoint_sim_s7.json"):
        doc = json.loads(det.read_text())
        assert formats.first_error("nusc_detections", doc) is None
        assert len(results_boxes(det, doc["results"], list(doc["results"]))) == len(doc["results"])
    for name in ("polymot", "fastpoly", "mctrack"):
        doc = json.loads((nusc_reference / f"{name}_pointpillars_mini_val.json").read_text())
        assert formats.first_error("nusc_tracking", doc) is None
        check_document(doc, name)


def test_schema_enums_are_the_class_lists():
    from grutrack.classes import DETECTION_CLASSES, TRACKING_CLASSES
    from grutrack.data.av2 import COMPETITION_CATEGORIES, OTHER_ANNOTATION_CATEGORIES

    det = formats.node("nusc_detections", ("results", "t", 0, "detection_name"))
    trk = formats.node("nusc_tracking", ("results", "t", 0, "tracking_name"))
    assert tuple(det["enum"]) == DETECTION_CLASSES and tuple(trk["enum"]) == TRACKING_CLASSES
    lt3d = formats.node("lt3d_detections", (0, "category"))
    assert set(lt3d["enum"]) == {*COMPETITION_CATEGORIES, *OTHER_ANNOTATION_CATEGORIES, "OTHER"}
    assert tuple(formats.node("av2_tracks", ("log", 0, "name"))["ndarray"]["enum"]) == tuple(COMPETITION_CATEGORIES)


def test_every_format_has_a_description_with_descriptions_on_its_fields():
    for name in formats.FORMATS:
        root = formats.schema(name)
        assert root.get("description") and root.get("title"), name
