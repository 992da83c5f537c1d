"""AV2 classes without ground truth: on the real val log 7fab2350 (../shared/data/av2), whose labels hold no BUS,
LARGE_VEHICLE or TRUCK, a submission with BUS false positives is scored by the official evaluator (BUS: HOTA 0,
MOTA -FP), and the Table I average in the metrics document, the av2_val report and ``grutrack check`` is the
average over the classes with ground truth only; the absent classes are marked absent in all three.

The submission is made from the annotations (not a detector): the first 6 labelled frames at 2 Hz of the log as
tracks (score 1), every second REGULAR_VEHICLE box dropped in odd frames and the pedestrians moved 0.8 m (so that
the present classes score different, non-trivial numbers), plus 3 BUS tracks 8 m from the ego vehicle.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from grutrack.cli import main
from grutrack.data import av2
from grutrack.documents import ABSENT_TEXT, MetricsDocument
from grutrack.evaluation.av2_eval import evaluate_sequences, format_summary, metrics_document
from grutrack.export.av2_tracks import gt_sequences

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "workflow/config/paper.yaml"
LOG_A = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"  # no BUS, LARGE_VEHICLE or TRUCK in its annotations
FRAMES = 6
BUS_OFFSETS = np.array([[8.0, 0.0, 0.0], [0.0, 8.0, 0.0], [-8.0, 0.0, 0.0]])
AVERAGED = ("hota", "mota", "idf1")


def _submission(labels: dict) -> dict:
    """Tracks from the labels (see the module docstring), with BUS false positives in every frame."""
    bus = av2.COMPETITION_CATEGORIES.index("BUS")
    n = len(BUS_OFFSETS)
    out = {}
    for lg, frames in labels.items():
        out[lg] = []
        for i, f in enumerate(frames):
            keep = np.ones(len(f["track_id"]), bool)
            if i % 2:
                car = np.flatnonzero(f["name"] == "REGULAR_VEHICLE")
                keep[car[::2]] = False
            xyz = f["translation_m"].copy()
            xyz[f["name"] == "PEDESTRIAN", 0] += 0.8
            out[lg].append(
                {
                    "seq_id": f["seq_id"],
                    "timestamp_ns": f["timestamp_ns"],
                    "track_id": np.concatenate([f["track_id"][keep], [f"fp-bus-{k}" for k in range(n)]]).astype(object),
                    "translation_m": np.vstack([xyz[keep], np.asarray(f["ego_translation_m"]) + BUS_OFFSETS]),
                    "size": np.vstack([f["size"][keep], np.tile([12.0, 2.6, 3.2], (n, 1))]),
                    "yaw": np.concatenate([f["yaw"][keep], np.zeros(n)]),
                    "velocity_m_per_s": np.vstack([f["velocity_m_per_s"][keep], np.zeros((n, 3))]),
                    "label": np.concatenate([f["label"][keep], np.full(n, bus)]),
                    "name": np.concatenate([f["name"][keep], np.full(n, "BUS", dtype=object)]).astype(object),
                    "score": np.ones(int(keep.sum()) + n),
                }
            )
    return out


@pytest.fixture(scope="module")
def evaluated(av2_root, tmp_path_factory):
    """(metrics JSON path, official per-class inputs): the official evaluation (ROI on, one worker) of the
    submission against the log's first frames, written as `grutrack evaluate` writes its document."""
    all_labels = gt_sequences(
        av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True), av2.vocabulary(all_categories=True)
    )
    # the fixture's fact the test rests on: the whole log has no BUS label at all
    assert not any("BUS" in set(f["name"]) for f in all_labels[LOG_A])
    labels = {LOG_A: all_labels[LOG_A][:FRAMES]}
    out = evaluate_sequences(_submission(labels), labels, av2_root / "val", workers=1, keep_inputs=True)
    doc = metrics_document(out, split="val", submission="bus_fp.pkl", rate_hz=2.0, max_range_m=50, roi=True, workers=1)
    path = tmp_path_factory.mktemp("absent") / "metrics.json"
    doc.write(path)
    # ground truth per class as the final evaluation scored it (range + ROI), counted from its inputs
    counts = {
        c: sum(int((f["name"] == c).sum()) for fs in out["final"]["labels"].values() for f in fs)
        for c in av2.TABLE_I_CLASSES
    }
    return path, counts


def _present(counts: dict) -> list[str]:
    return [c for c in av2.TABLE_I_CLASSES if counts[c] > 0]


def test_average_is_over_the_classes_with_ground_truth(evaluated):
    path, counts = evaluated
    raw = json.loads(path.read_text())
    pc, overall = raw["per_class"], raw["overall"]
    present = _present(counts)
    assert {"REGULAR_VEHICLE", "PEDESTRIAN"} <= set(present) and "BUS" not in present
    absent = [c for c in av2.TABLE_I_CLASSES if c not in present]
    assert {"BUS", "LARGE_VEHICLE", "TRUCK"} <= set(absent)
    # the official numbers of the absent BUS are kept: HOTA 0, MOTA = -FP over zero boxes
    bus = pc["BUS"]
    assert bus["fp"] > 0 and bus["gt_boxes"] == 0 and bus["hota"] == 0.0 and bus["mota"] == -bus["fp"]
    # each class records whether it has ground truth
    for c in av2.COMPETITION_CATEGORIES:
        assert pc[c]["absent"] is (pc[c]["gt_boxes"] == 0) and pc[c]["present"] is not pc[c]["absent"]
    for c in av2.TABLE_I_CLASSES:
        assert pc[c]["gt_boxes"] == counts[c], c
    assert overall["present_classes"] == present and overall["absent_classes"] == absent
    assert overall["classes"] == list(av2.TABLE_I_CLASSES)
    # the present classes score real, different numbers (not all 1.0)
    assert len({round(pc[c]["mota"], 6) for c in present}) > 1 and min(pc[c]["hota"] for c in present) < 0.99
    for k in AVERAGED:
        expected = float(np.mean([pc[c][k] for c in present]))
        assert overall[k] == pytest.approx(expected, abs=1e-12), k
        assert overall[k] != pytest.approx(float(np.mean([pc[c][k] for c in av2.TABLE_I_CLASSES])), abs=1e-3), k
    assert overall["mota"] > 0  # the -FP of BUS is in no average
    assert not any(k.endswith("_present") for k in overall)
    assert "classes with ground truth" in raw["settings"]["average"]
    doc = MetricsDocument.read(path)
    assert doc.absent_classes == [c for c in av2.COMPETITION_CATEGORIES if pc[c]["gt_boxes"] == 0]
    assert doc.is_absent("BUS") and not doc.is_absent("REGULAR_VEHICLE")
    assert doc.is_absent_path("per_class.BUS.hota") and not doc.is_absent_path("overall.hota")
    summary = format_summary(doc).splitlines()
    bus_line = next(line for line in summary if line.startswith("BUS "))
    assert ABSENT_TEXT in bus_line and "-" not in bus_line.replace(ABSENT_TEXT, "")
    assert summary[-1].startswith(f"AVERAGE ({len(present)}/7)")
    assert f"{overall['mota']:.3f}" in summary[-1]


def test_an_older_document_is_read_with_the_same_average(evaluated, tmp_path):
    """A metrics JSON written before absent classes were left out (overall: 7-class mean as `hota`, the present
    mean as `hota_present`; per class only `present`) reads as the current layout."""
    path, counts = evaluated
    raw = json.loads(path.read_text())
    pc, new = raw["per_class"], raw["overall"]
    old_pc = {c: {k: v for k, v in m.items() if k != "absent"} for c, m in pc.items()}
    old_overall = {k: float(np.mean([pc[c][k] for c in av2.TABLE_I_CLASSES])) for k in AVERAGED}
    old_overall.update({f"{k}_present": new[k] for k in AVERAGED})
    old_overall.update({"classes": new["classes"], "present_classes": new["present_classes"]})
    old = {
        **raw,
        "overall": old_overall,
        "per_class": old_pc,
        "settings": {**raw["settings"], "average": "Table I: mean over the 7 Table I classes (absent classes score 0)"},
    }
    (tmp_path / "old.json").write_text(json.dumps(old))
    doc = MetricsDocument.read(tmp_path / "old.json")
    for k in AVERAGED:
        assert doc.overall[k] == new[k] and f"{k}_present" not in doc.overall
    assert doc.overall["absent_classes"] == new["absent_classes"]
    assert doc.is_absent("BUS") and doc.per_class["BUS"]["absent"] is True
    assert "classes with ground truth" in doc.settings["average"]
    # documents that are not of that layout are read as they are
    assert MetricsDocument.from_dict(raw).to_dict() == raw


def _paper_matching(path: Path, counts: dict, tmp_path: Path) -> Path:
    """paper.yaml with Table I's Ours row set to the reproduced HOTA of the classes with ground truth and to their
    mean as the average, BUS (absent) kept at the paper's 59.2: only how absent classes are handled decides whether
    the check passes."""
    raw = json.loads(path.read_text())
    paper = yaml.safe_load(PAPER.read_text())
    row = paper["tables"]["I"]["rows"]["Ours"]
    present = _present(counts)
    for c in present:
        row[c] = round(100 * raw["per_class"][c]["hota"], 1)
    row["average"] = round(100 * float(np.mean([raw["per_class"][c]["hota"] for c in present])), 1)
    assert row["BUS"] == 59.2 and "BUS" not in present
    out = tmp_path / "paper.yaml"
    out.write_text(yaml.safe_dump(paper, sort_keys=False))
    return out


def test_check_marks_absent_classes_instead_of_failing(evaluated, tmp_path, capsys):
    path, counts = evaluated
    paper = _paper_matching(path, counts, tmp_path)
    assert main(["check", str(path), "--table", "I", "--paper", str(paper)]) == 0
    out = capsys.readouterr().out
    absent = [c for c in av2.TABLE_I_CLASSES if c not in _present(counts)]
    for c in absent:
        assert re.search(rf"^{c}\s+\S+\s+absent\s+n/a\s+\S+\s+{re.escape(ABSENT_TEXT)}$", out, re.M), out
    for c in _present(counts) + ["average"]:
        assert re.search(rf"^{c}\s+.*\bok$", out, re.M), out
    n = len(_present(counts)) + 1
    assert f"{n} of {n} within tolerance; absent (no ground truth, not checked): {', '.join(absent)}" in out
    # the average is still checked: off by more than its tolerance, the check fails
    raw = json.loads(path.read_text())
    raw["overall"]["hota"] -= 0.05
    (tmp_path / "off.json").write_text(json.dumps(raw))
    assert main(["check", str(tmp_path / "off.json"), "--table", "I", "--paper", str(paper)]) == 1
    assert re.search(r"^average\s+.*OUT OF TOLERANCE$", capsys.readouterr().out, re.M)


def _md_table_after(text: str, marker: str) -> list[dict[str, str]]:
    """The rows (header -> cell) of the first markdown table after ``marker``."""
    lines = text[text.index(marker) :].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip().strip("|").split("|")])
    return [dict(zip(rows[0], r)) for r in rows[2:]]


def _row(rows: list[dict[str, str]], key: str, value: str) -> dict[str, str]:
    return next(r for r in rows if r[key] == value)


def test_report_shows_absent_classes_and_the_present_average(evaluated, tmp_path):
    path, counts = evaluated
    doc = json.loads(path.read_text())
    paper = _paper_matching(path, counts, tmp_path)
    md = tmp_path / "rep" / "av2_val.md"
    assert (
        main(
            [
                "report",
                "av2_val",
                "--out",
                str(md),
                "--paper",
                str(paper),
                "--experiment",
                "oracle_bus_fp:av2:val:annotations",
                "--run",
                f"ours={path}",
                "--row",
                "I:Ours=ours",
            ]
        )
        == 0
    )
    text = md.read_text()
    present = _present(counts)
    absent = [c for c in av2.TABLE_I_CLASSES if c not in present]
    mean = {k: float(np.mean([doc["per_class"][c][k] for c in present])) for k in AVERAGED}
    ours = _row(_md_table_after(text, "**Reproduced**"), "method", "Ours")
    for c in absent:
        assert ours[c] == ABSENT_TEXT, (c, ours)
    for c in present:
        assert ours[c] == f"{100 * doc['per_class'][c]['hota']:.1f}", (c, ours)
    assert ours["average"] == f"{100 * mean['hota']:.1f}"
    diff = _row(_md_table_after(text, "**Difference**"), "method", "Ours")
    assert all(diff[c] == ABSENT_TEXT for c in absent)
    run = _row(_md_table_after(text, "## Every run"), "run", "ours")
    assert all(run[k.upper()] == f"{100 * mean[k]:.1f}" for k in AVERAGED), (run, mean)
    assert float(run["MOTA"]) > 0
    assert f"Absent (no ground truth in the evaluated logs, left out of the averages): {', '.join(absent)}." in text
    checks = {r["metric"]: r for r in _md_table_after(text, "## Check against")}
    for c in absent:
        if c in checks:  # the paper row reports the class
            assert checks[c]["reproduced"] == ABSENT_TEXT and checks[c]["status"] == "absent, not checked"
    assert checks["BUS"]["status"] == "absent, not checked"
    assert all(checks[c]["status"] == "within" for c in present + ["average"])
    assert "**OUT**" not in text
