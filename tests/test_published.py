"""Known detection files (``grutrack check-published``, docs/known_files.md): the shipped figures CANMOT published
for Poly-MOT on the CenterPoint flip val file, and the comparison of a run with published figures: integers
exactly, other figures at their printed precision.

The CenterPoint flip file is not among the test data, so the comparison is exercised on the real PointPillars
mini_val file: a published-results file made here gives its SHA-256 and, as the published figures, those of
Poly-MOT's own code on it (the stock devkit metrics in ../shared/data/nuscenes/reference), and the run is
``grutrack track --config polymot`` on that file scored by ``grutrack evaluate``."""

from __future__ import annotations

import copy
import hashlib
import json
import math
from pathlib import Path

import pytest
import yaml

from grutrack.cli import main
from grutrack.errors import ConfigError
from grutrack.evaluation.published import Figure, load_published, results_for

CANMOT_VAL = "4186f748f91e071c1276287244e23a01da5908a373af85ee2dfb08ea935b903e"
CANMOT_TRAIN = "547fdb7dd6c401749f619a504fa37ee70dbad676d3f400b28c5176bff3327145"
PERCENT = ("amota", "amotp", "recall", "motar", "mota", "motp")
COUNTS = ("mt", "ml", "tp", "fp", "fn", "ids", "frag")


def test_the_shipped_canmot_figures():
    from grutrack.data.registry import load_registry

    (r,) = results_for(load_published(), CANMOT_VAL)
    assert (r.name, r.tracker, r.dataset, r.version, r.split) == (
        "Poly-MOT",
        "polymot",
        "nuscenes",
        "v1.0-trainval",
        "val",
    )
    assert (r.repository, r.commit, r.path) == (
        "rst-tu-dortmund/CANMOT",
        "afe1113f2cd5e73d703a695a1de5fe0522d04f74",
        "reproducibility/reference/poly_mot.json",
    )
    assert r.license == "BSD-3-Clause" and r.filename == "infos_val_10sweeps_withvelo_filter_True.json"
    printed = {f.path: f.printed for f in r.figures}
    assert {k: printed[f"overall.{k}"] for k in ("amota", "amotp", "ids", "frag", "tp", "fp")} == {
        "amota": "72.85",
        "amotp": "51.67",
        "ids": "235",
        "frag": "295",
        "tp": "84094",
        "fp": "13062",
    }
    # the reference JSON's unrounded values give the printed figures
    assert r.figure("overall.amota").equal(0.7284656571534474) and r.figure("overall.amotp").equal(0.5167405821553189)
    assert not r.figure("overall.amota").equal(0.7286)
    classes = {p.split(".")[1] for p in printed if p.startswith("per_class.")}
    assert classes == {"bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck"}
    assert sum(int(printed[f"per_class.{c}.ids"]) for c in classes) == 235
    assert sum(int(printed[f"per_class.{c}.tp"]) for c in classes) == 84094
    assert sum(int(printed[f"per_class.{c}.fp"]) for c in classes) == 13062
    reg = load_registry()
    assert reg["centerpoint_flip_val"].sha256 == CANMOT_VAL == r.sha256 and r.registry == "centerpoint_flip_val"
    assert reg["centerpoint_flip_train"].sha256 == CANMOT_TRAIN and reg["centerpoint_flip_train"].split == "train"


def test_figures_integers_exact_others_at_their_printed_precision():
    ids = Figure("overall.ids", "235")
    assert ids.equal(235.0) and not ids.equal(235.4) and not ids.equal(234.0) and not ids.equal(None)
    assert ids.ours(235.4) == "235.4"  # a value that is not whole never reads as the integer
    amota = Figure("overall.amota", "72.80", 100.0)
    assert amota.equal(0.728) and amota.equal(0.72804) and not amota.equal(0.7286)
    assert amota.ours(0.72804) == "72.80" and amota.decimals == 2
    assert Figure("overall.faf", "46.29").equal(46.2910726614445)


# -- a run on a real file against published figures made for it ------------------------------------------


@pytest.fixture(scope="module")
def run(tmp_path_factory, nusc_root, pointpillars_mini_val, nusc_reference):
    """(metrics JSON of ``--config polymot`` on the PointPillars mini_val file, the published-results mapping
    for that file with Poly-MOT's own figures, the folder)."""
    out = tmp_path_factory.mktemp("published")
    base = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    sub = out / "tracks.json"
    track = ["track", *base, "--detections", str(pointpillars_mini_val), "--tracker", "ekf", "--config", "polymot"]
    assert main([*track, "--out", str(sub)]) == 0
    metrics = out / "metrics.json"
    assert main(["evaluate", *base, "--submission", str(sub), "--out", str(metrics), "--evaluator", "fast"]) == 0
    ref = json.loads((nusc_reference / "polymot_pointpillars_mini_val.metrics_summary.json").read_text())

    def printed(metric, value):
        return f"{value * 100:.2f}" if metric in PERCENT else str(int(value))

    per_class = {}
    for cls in ref["label_metrics"]["amota"]:
        values = {m: ref["label_metrics"][m][cls] for m in PERCENT + COUNTS}
        if all(v is not None and math.isfinite(v) for v in values.values()):  # classes with ground truth
            per_class[cls] = {m: printed(m, v) for m, v in values.items()}
    published = {
        "publication": "Poly-MOT's own code on the real PointPillars mini_val file",
        "source": {
            "repository": "lixiaoyu2000/Poly-MOT",
            "commit": "5fead68f88ec41af71c789da0f52a6f11a290891",
            "license": "MIT",
        },
        "results": [
            {
                "name": "Poly-MOT",
                "detections": {
                    "filename": pointpillars_mini_val.name,
                    "sha256": hashlib.sha256(pointpillars_mini_val.read_bytes()).hexdigest(),
                    "registry": None,
                    "dataset": "nuscenes",
                    "version": "v1.0-mini",
                    "split": "mini_val",
                },
                "tracker": "polymot",
                "tracker_code": "lixiaoyu2000/Poly-MOT @ 5fead68, config/nusc_config.yaml",
                "evaluator": "nuscenes-devkit 1.2.0 TrackingEval (tracking_nips_2019)",
                "path": "polymot_pointpillars_mini_val.metrics_summary.json",
                "scale": {m: 100 for m in PERCENT},
                "overall": {m: printed(m, ref[m]) for m in PERCENT + COUNTS},
                "per_class": per_class,
                "note": None,
            }
        ],
    }
    assert {"car", "bus", "truck"} <= set(per_class)
    return metrics, published, out


def _check(tmp_path, published, metrics, detections, *extra) -> int:
    path = tmp_path / "published.yaml"
    path.write_text(yaml.safe_dump(published, sort_keys=False))
    return main(["check-published", str(metrics), "--detections", str(detections), "--published", str(path), *extra])


def test_a_run_on_the_published_file_gives_every_figure(run, pointpillars_mini_val, tmp_path, capsys):
    metrics, published, _ = run
    assert _check(tmp_path, published, metrics, pointpillars_mini_val, "--tracker", "polymot") == 0
    out = capsys.readouterr().out
    n = len(published["results"][0]["overall"]) + sum(len(v) for v in published["results"][0]["per_class"].values())
    assert f"{n} of {n} figures equal" in out and "every figure equal" in out
    assert "overall.amota" in out and "16.76" in out  # Poly-MOT's AMOTA 0.1676 on this file


@pytest.mark.parametrize(
    "path, value", [(("overall", "ids"), "9"), (("overall", "amota"), "16.77"), (("per_class", "car", "tp"), "1034")]
)
def test_a_figure_that_differs_is_named(run, pointpillars_mini_val, tmp_path, capsys, path, value):
    metrics, published, _ = run
    changed = copy.deepcopy(published)
    node = changed["results"][0]
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    assert _check(tmp_path, changed, metrics, pointpillars_mini_val) == 1
    out = capsys.readouterr().out
    name = ".".join(path)
    assert f"differ: {name}" in out and "SHA-256 equal" in out and "not from the file" in out
    assert [line.split()[-1] for line in out.splitlines() if line.startswith(name + " ")] == ["NO"]


def test_an_unknown_file_is_said_to_be_one(run, pointpillars_mini_val, tmp_path, capsys):
    metrics, published, _ = run
    other = tmp_path / "other.json"
    other.write_bytes(pointpillars_mini_val.read_bytes() + b"\n")  # one byte more: another file
    assert _check(tmp_path, published, metrics, other) == 0
    out = capsys.readouterr().out
    assert "this file is not a known published file" in out and "pointpillars_mini_val.json" in out
    assert hashlib.sha256(other.read_bytes()).hexdigest() in out


def test_metrics_of_another_split_or_version_are_not_comparable(run, pointpillars_mini_val, tmp_path, capsys):
    metrics, published, _ = run
    changed = copy.deepcopy(published)
    changed["results"][0]["detections"].update(split="mini_train", version="v1.0-trainval")
    assert _check(tmp_path, changed, metrics, pointpillars_mini_val) == 1
    out = capsys.readouterr().out
    assert "split: published mini_train, the metrics JSON's mini_val" in out
    assert "version: published v1.0-trainval, the metrics JSON's v1.0-mini" in out
    assert "cannot be compared" in out


def test_bad_input_is_one_line_naming_the_file_or_field(run, pointpillars_mini_val, tmp_path, capsys):
    metrics, published, _ = run
    assert _check(tmp_path, published, metrics, tmp_path / "missing.json") == 2
    err = capsys.readouterr().err.strip()
    assert "missing.json: detection file not found" in err and len(err.splitlines()) == 1

    bad = tmp_path / "bad_metrics.json"
    bad.write_text(json.dumps({"overall": {"amota": 0.5}}))
    assert _check(tmp_path, published, bad, pointpillars_mini_val) == 2
    err = capsys.readouterr().err.strip()
    assert "bad_metrics.json" in err and "per_class" in err and len(err.splitlines()) == 1

    wrong_tracker = _check(tmp_path, published, metrics, pointpillars_mini_val, "--tracker", "fastpoly")
    assert wrong_tracker == 2
    assert "--tracker fastpoly: no figures of that tracker are published on this file (published: polymot)" in (
        capsys.readouterr().err
    )

    unquoted = copy.deepcopy(published)
    unquoted["results"][0]["overall"]["amota"] = 16.76  # a number loses its printed precision: quoted only
    assert _check(tmp_path, unquoted, metrics, pointpillars_mini_val) == 2
    err = capsys.readouterr().err
    assert "published.yaml" in err and "results.0.overall.amota" in err and "in quotes" in err


def test_a_registry_source_must_agree_with_the_published_file(tmp_path):
    raw = yaml.safe_load((Path(__file__).parents[1] / "grutrack/configs/published/canmot.yaml").read_text())
    raw["results"][0]["detections"]["sha256"] = "0" * 64
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match=r"results\[0\]\.detections\.sha256 is 0+, the registry's source "):
        load_published(path)
    raw["results"][0]["detections"]["sha256"] = CANMOT_VAL
    raw["results"][0]["tracker"] = "polymott"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(ConfigError, match="tracker 'polymott' is not a tracker preset"):
        load_published(path)
