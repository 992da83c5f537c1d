"""The paper-vs-reproduced check (``grutrack check``) and reports built from crafted metrics JSONs."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from grutrack.cli import main
from grutrack.report.paper import load_paper, metric, reproduced

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "workflow/config/paper.yaml"
CLASSES = ("bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck")


def nusc_metrics(path: Path, amota: float, amotp: float, ids: int, per_class: dict | None = None,
                 submission: str = "submissions/x.json") -> Path:
    """A metrics JSON shaped like `grutrack evaluate` writes it."""
    pc = {c: {"amota": amota, "amotp": amotp, "ids": 1} for c in CLASSES}
    for c, v in (per_class or {}).items():
        pc[c].update(v)
    doc = {"dataset": "nuscenes", "version": "v1.0-trainval", "split": "val", "evaluator": "devkit",
           "submission": submission, "overall": {"amota": amota, "amotp": amotp, "ids": ids, "mota": 0.6,
                                                 "recall": 0.7, "frag": 10, "tp": 100, "fp": 5, "fn": 7},
           "per_class": pc}
    path.write_text(json.dumps(doc))
    return path


def test_paper_numbers_are_the_design_tables():
    paper = load_paper(PAPER)
    t = paper["tables"]
    assert t["III"]["rows"]["Ours"] == {"amota": 73.2, "amotp": 51.1, "ids": 267}
    assert t["II"]["rows"]["Ours (LargeKernel3D)"]["amota"] == 74.4
    assert t["IV"]["rows"]["Bicycle+EKF"]["bicycle_amotp"] == 50.7
    assert t["I"]["rows"]["Ours"]["average"] == 47.3


def test_metric_paths_and_scale(tmp_path):
    doc = json.loads(nusc_metrics(tmp_path / "m.json", 0.732, 0.511, 267).read_text())
    assert metric(doc, "overall.amota") == 0.732 and metric(doc, "per_class.car.nope") is None
    values = reproduced(load_paper(PAPER)["tables"]["III"], doc)
    assert values == pytest.approx({"amota": 73.2, "amotp": 51.1, "ids": 267})


def test_check_within_tolerance_exits_zero(tmp_path, capsys):
    m = nusc_metrics(tmp_path / "m.json", 0.728, 0.52, 290)
    assert main(["check", str(m), "--table", "III", "--paper", str(PAPER)]) == 0
    out = capsys.readouterr().out
    for name in ("amota", "amotp", "ids"):
        assert re.search(rf"^{name}\s+.*\bok$", out, re.M), out
    assert "3 of 3 within tolerance" in out


def test_check_out_of_tolerance_exits_non_zero(tmp_path, capsys):
    m = nusc_metrics(tmp_path / "m.json", 0.70, 0.511, 267)
    assert main(["check", str(m), "--table", "III", "--paper", str(PAPER)]) == 1
    out = capsys.readouterr().out
    assert re.search(r"^amota\s+73\.20\s+70\.00\s+-3\.20\s+±1\.00\s+OUT OF TOLERANCE$", out, re.M), out
    assert "out: amota" in out


def test_check_other_row_and_per_class_table(tmp_path, capsys):
    m = nusc_metrics(tmp_path / "m.json", 0.73, 0.5, 250,
                     {"bicycle": {"amota": 0.545, "amotp": 0.507}, "car": {"amota": 0.863, "amotp": 0.342}})
    assert main(["check", str(m), "--table", "IV", "--row", "Bicycle+EKF", "--paper", str(PAPER)]) == 0
    assert main(["check", str(m), "--table", "IV", "--row", "CA+KF", "--paper", str(PAPER)]) == 1
    assert main(["check", str(m), "--table", "IV", "--row", "Nope", "--paper", str(PAPER)]) == 2
    assert "no row 'Nope'" in capsys.readouterr().err


def test_nusc_val_report_has_paper_reproduced_and_difference(tmp_path):
    runs = {"grukf": (0.730, 0.515, 270), "polymot": (0.725, 0.53, 300), "ekf": (0.72, 0.52, 280)}
    args = ["report", "nusc_val", "--out", str(tmp_path / "r.md"), "--paper", str(PAPER),
            "--experiment", "nusc_val:nuscenes:val:centerpoint", "--row", "III:Ours=grukf",
            "--row", "III:Poly-MOT=polymot", "--row", "IV:CTRA+Ours=grukf", "--row", "IV:CTRA+EKF=ekf"]
    for run, (a, p, i) in runs.items():
        args += ["--run", f"{run}={nusc_metrics(tmp_path / f'{run}.json', a, p, i)}"]
    assert main(args) == 0
    text = (tmp_path / "r.md").read_text()
    assert "**Paper numbers**" in text and "**Reproduced**" in text and "**Difference**" in text
    assert re.search(r"^\| Ours \| 73\.0 \| 51\.5 \| 270 \|$", text, re.M)   # reproduced row
    assert re.search(r"^\| Ours \| -0\.2 \| \+0\.4 \| \+3 \|$", text, re.M)   # difference row
    for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        png = (tmp_path / link)
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_semi_supervised_report_from_two_logs(tmp_path):
    head = "step,epoch,scene,loss,gt_terms,pseudo_terms,lr,val_amota,seconds\n"
    semi = head + "".join(f"{s},{(s - 1) // 4},sc,{1 / s:.4f},10,2,1e-5,{'' if s % 2 else 0.5 + 0.02 * s},1.0\n"
                          for s in range(1, 9))
    sup = head + "".join(f"{s},{(s - 1) // 4},sc,{1 / s:.4f},10,0,1e-5,{'' if s % 2 else 0.4 + 0.02 * s},1.0\n"
                         for s in range(1, 9))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a/train_log.csv").write_text(semi)
    (tmp_path / "b/train_log.csv").write_text(sup)
    out = tmp_path / "s.md"
    assert main(["report", "semi_supervised", "--out", str(out), "--paper", str(PAPER),
                 "--train-log", f"semi_supervised={tmp_path / 'a/train_log.csv'}",
                 "--train-log", f"supervised={tmp_path / 'b/train_log.csv'}"]) == 0
    text = out.read_text()
    assert "| semi_supervised | 8 | 2 | 0.660 | 0.660 (step 8) |" in text
    assert "1,700 steps" in text and (tmp_path / "figures/s/val_amota_vs_step.png").is_file()
