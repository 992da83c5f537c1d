"""The paper-vs-reproduced check (``grutrack check``) and reports built from crafted metrics JSONs."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from grutrack.cli import main
from grutrack.documents import MetricsDocument
from grutrack.report.paper import load_paper, reproduced

REPO = Path(__file__).resolve().parents[1]
PAPER = REPO / "workflow/config/paper.yaml"
CLASSES = ("bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck")


def nusc_metrics(
    path: Path,
    amota: float,
    amotp: float,
    ids: int,
    per_class: dict | None = None,
    submission: str = "submissions/x.json",
) -> Path:
    """A metrics JSON as `grutrack evaluate` writes it (through the same document class)."""
    pc = {c: {"amota": amota, "amotp": amotp, "ids": 1} for c in CLASSES}
    for c, v in (per_class or {}).items():
        pc[c].update(v)
    MetricsDocument(
        dataset="nuscenes",
        version="v1.0-trainval",
        split="val",
        evaluator="devkit",
        submission=submission,
        per_class=pc,
        overall={
            "amota": amota,
            "amotp": amotp,
            "ids": ids,
            "mota": 0.6,
            "recall": 0.7,
            "frag": 10,
            "tp": 100,
            "fp": 5,
            "fn": 7,
        },
    ).write(path)
    return path


def test_paper_numbers_are_the_design_tables():
    paper = load_paper(PAPER)
    t = paper["tables"]
    assert t["III"]["rows"]["Ours"] == {"amota": 73.2, "amotp": 51.1, "ids": 267}
    assert t["II"]["rows"]["Ours (LargeKernel3D)"]["amota"] == 74.4
    assert t["IV"]["rows"]["Bicycle+EKF"]["bicycle_amotp"] == 50.7
    assert t["I"]["rows"]["Ours"]["average"] == 47.3


def test_metric_paths_and_scale(tmp_path):
    doc = MetricsDocument.read(nusc_metrics(tmp_path / "m.json", 0.732, 0.511, 267))
    assert doc.value("overall.amota") == 0.732 and doc.value("per_class.car.nope") is None
    assert doc.class_value("car", "amotp") == 0.511 and doc.classes == list(CLASSES)
    values = reproduced(load_paper(PAPER)["tables"]["III"], doc)
    assert values == pytest.approx({"amota": 73.2, "amotp": 51.1, "ids": 267})


def test_check_within_tolerance_exits_zero(tmp_path, capsys):
    m = nusc_metrics(tmp_path / "m.json", 0.728, 0.52, 290)
    assert main(["check", str(m), "--table", "III", "--paper", str(PAPER)]) == 0
    out = capsys.readouterr().out
    for name in ("amota", "amotp", "ids"):
        assert re.search(rf"^{name}\s+.*\bok$", out, re.M), out
    assert "3 of 3 within tolerance" in out
    assert "note:" not in out


def test_check_on_the_demo_says_synthetic_and_not_comparable(tmp_path, capsys):
    """Metrics of the demo dataset checked against a paper table: the comparison is printed, with a note naming
    the metrics' version and split, SYNTHETIC, not comparable."""
    m = nusc_metrics(tmp_path / "m.json", 0.887, 0.271, 7)
    doc = MetricsDocument.read(m)
    doc.version, doc.split = "v1.0-demo", "demo_val"
    doc.write(m)
    main(["check", str(m), "--table", "III", "--paper", str(PAPER)])
    out = capsys.readouterr().out
    assert (
        "note: the paper's table is nuscenes val; the metrics are of v1.0-demo demo_val (SYNTHETIC: grutrack's "
        "demo dataset), not comparable" in out
    )


def test_check_out_of_tolerance_exits_non_zero(tmp_path, capsys):
    m = nusc_metrics(tmp_path / "m.json", 0.70, 0.511, 267)
    assert main(["check", str(m), "--table", "III", "--paper", str(PAPER)]) == 1
    out = capsys.readouterr().out
    assert re.search(r"^amota\s+73\.20\s+70\.00\s+-3\.20\s+±1\.00\s+OUT OF TOLERANCE$", out, re.M), out
    assert "out: amota" in out


def test_check_other_row_and_per_class_table(tmp_path, capsys):
    m = nusc_metrics(
        tmp_path / "m.json",
        0.73,
        0.5,
        250,
        {"bicycle": {"amota": 0.545, "amotp": 0.507}, "car": {"amota": 0.863, "amotp": 0.342}},
    )
    assert main(["check", str(m), "--table", "IV", "--row", "Bicycle+EKF", "--paper", str(PAPER)]) == 0
    assert main(["check", str(m), "--table", "IV", "--row", "CA+KF", "--paper", str(PAPER)]) == 1
    assert main(["check", str(m), "--table", "IV", "--row", "Nope", "--paper", str(PAPER)]) == 2
    assert "no row 'Nope'" in capsys.readouterr().err


def test_nusc_val_report_has_paper_reproduced_and_difference(tmp_path):
    runs = {
        "grukf": (0.730, 0.515, 270),
        "polymot": (0.725, 0.53, 300),
        "ekf": (0.72, 0.52, 280),
        "fastpoly": (0.737, 0.49, 250),
        "mctrack": (0.741, 0.48, 240),
    }
    args = [
        "report",
        "nusc_val",
        "--out",
        str(tmp_path / "r.md"),
        "--paper",
        str(PAPER),
        "--experiment",
        "nusc_val:nuscenes:val:centerpoint",
        "--row",
        "III:Ours=grukf",
        "--row",
        "III:Poly-MOT=polymot",
        "--row",
        "IV:CTRA+Ours=grukf",
        "--row",
        "IV:CTRA+EKF=ekf",
        "--extra-row",
        "III:Fast-Poly=fastpoly",
        "--extra-row",
        "III:MCTrack=mctrack",
        "--extra-row",
        "IV:MCTrack=mctrack",
    ]
    for run, (a, p, i) in runs.items():
        args += ["--run", f"{run}={nusc_metrics(tmp_path / f'{run}.json', a, p, i)}"]
    assert main(args) == 0
    text = (tmp_path / "r.md").read_text()
    assert "**Paper numbers**" in text and "**Reproduced**" in text and "**Difference**" in text
    assert re.search(r"^\| Ours \| 73\.0 \| 51\.5 \| 270 \|$", text, re.M)  # reproduced row
    assert re.search(r"^\| Ours \| -0\.2 \| \+0\.4 \| \+3 \|$", text, re.M)  # difference row
    # a row that is not in the paper: reproduced, labelled, never among the paper numbers or the differences
    assert len(re.findall(r"^\| Fast-Poly \(not in the paper\) \| 73\.7 \| 49\.0 \| 250 \|$", text, re.M)) == 1
    assert "Fast-Poly" not in text.split("**Reproduced**")[0] and "Fast-Poly" not in text.split("**Difference**")[1]
    assert len(re.findall(r"^\| MCTrack \(not in the paper\) \| 74\.1 \| 48\.0 \| 240 \|$", text, re.M)) == 1
    assert len(re.findall(r"^\| MCTrack \(not in the paper\) \|", text, re.M)) == 2  # Tables III and IV
    for link in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        png = tmp_path / link
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_semi_supervised_report_from_two_logs(tmp_path):
    from grutrack.documents import ValidationRecord

    head = "step,epoch,scene,loss,gt_terms,pseudo_terms,lr,val_amota,seconds\n"
    semi = head + "".join(
        f"{s},{(s - 1) // 4},sc,{1 / s:.4f},10,2,1e-5,{'' if s % 2 else 0.5 + 0.02 * s},1.0\n" for s in range(1, 9)
    )
    sup = head + "".join(
        f"{s},{(s - 1) // 4},sc,{1 / s:.4f},10,0,1e-5,{'' if s % 2 else 0.4 + 0.02 * s},1.0\n" for s in range(1, 9)
    )
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a/train_log.csv").write_text(semi)
    (tmp_path / "b/train_log.csv").write_text(sup)
    # each training's own reference (the preset's EKF on its validation): one line for the equal values
    for d in ("a", "b"):
        ValidationRecord(
            "best_val_amota",
            8,
            "mini_train",
            reference="tracker preset 'ekf' (its EKF)",
            reference_amota=0.55,
            selected_amota=0.66,
        ).write(tmp_path / d / "validation.json")
    out = tmp_path / "s.md"
    assert (
        main(
            [
                "report",
                "semi_supervised",
                "--out",
                str(out),
                "--paper",
                str(PAPER),
                "--train-log",
                f"semi_supervised={tmp_path / 'a/train_log.csv'}",
                "--train-log",
                f"supervised={tmp_path / 'b/train_log.csv'}",
            ]
        )
        == 0
    )
    text = out.read_text()
    assert "| semi_supervised | 8 | 2 | 0.660 | 0.660 (step 8) |" in text
    assert "1,700 steps" in text and (tmp_path / "figures/s/val_amota_vs_step.png").is_file()
    assert "(EKF on the validation of semi_supervised, supervised 0.5500)." in text


def test_semi_supervised_report_over_seeds(tmp_path):
    """Three runs per mode: per-mode mean and spread of the final validation AMOTA and of the first step that
    reaches 99 % of it, a band figure, and every validation point as CSV."""
    import csv

    head = "step,epoch,scene,loss,gt_terms,pseudo_terms,lr,val_amota,seconds\n"
    args = ["report", "semi_supervised", "--out", str(tmp_path / "s.md"), "--paper", str(PAPER)]
    finals = {}
    for mode, base in (("semi_supervised", 0.60), ("supervised", 0.50)):
        for k, label in enumerate((mode, f"{mode}_2", f"{mode}_3")):
            # AMOTA rises by 0.05 per logged step until step 4 (semi) / 8 (supervised), then stays
            top = 4 if mode == "semi_supervised" else 8
            rows = "".join(
                f"{st},0,sc,0.1,1,1,1e-5,{base + 0.01 * k + 0.05 * min(st, top)},1.0\n" for st in range(2, 11, 2)
            )
            (tmp_path / label).mkdir()
            (tmp_path / label / "train_log.csv").write_text(head + rows)
            args += ["--train-log", f"{label}={tmp_path / label / 'train_log.csv'}"]
            finals.setdefault(mode, []).append(base + 0.01 * k + 0.05 * top)
    args += [
        "--experiment",
        "study_val:demo:demo_val:centerpoint_sim:simulated",
        "--run",
        f"ekf={nusc_metrics(tmp_path / 'ekf.json', 0.8765, 0.4, 20)}",
    ]
    assert main(args) == 0
    text = (tmp_path / "s.md").read_text()
    assert "| semi_supervised | 3 | 0.8100 ± 0.0100 (0.8000–0.8200) | 4 ± 0 (4–4) |" in text, text
    assert "| supervised | 3 | 0.9100 ± 0.0100 (0.9000–0.9200) | 8 ± 0 (8–8) |" in text
    assert (tmp_path / "figures/s/val_amota_vs_step_seeds.png").read_bytes()[:4] == b"\x89PNG"
    rows = list(csv.DictReader((tmp_path / "figures/s/val_amota_vs_step.csv").open()))
    assert len(rows) == 30 and {r["mode"] for r in rows} == {"semi_supervised", "supervised"}
    assert "[val_amota_vs_step.csv](figures/s/val_amota_vs_step.csv)" in text
    assert (
        "Reference lines: AMOTA of trackers without training on the same validation scenes and detections "
        "(ekf 0.8765)." in text
    )


def test_reports_name_their_sources_training_data_and_scored_logs(tmp_path, monkeypatch):
    from grutrack.cli.train import write_training_yaml
    from grutrack.report import figures
    from grutrack.training.config import load_train_config

    # a training folder as `grutrack train` leaves it inside the workflow: training.yaml resolved first
    ck = tmp_path / "checkpoints/nusc_grukf"
    ck.mkdir(parents=True)
    (ck / "train_log.csv").write_text(
        "step,epoch,scene,loss,gt_terms,pseudo_terms,lr,val_amota,seconds\n"
        "1,0,s,0.5,3,1,1e-5,,1.0\n2,0,s,0.4,3,1,1e-5,,1.0\n3,1,s,0.3,3,1,1e-5,,1.0\n"
    )
    assert (
        main(["resolve-config", "training", "--base", "grukf", "--overrides", "{}", "--out", str(ck / "training.yaml")])
        == 0
    )
    before = (ck / "training.yaml").read_text()
    src = {
        "dataroot": "/data/nuscenes",
        "version": "v1.0-trainval",
        "split": "train",
        "detections": "/d/centerpoint_train.json",
    }
    write_training_yaml(load_train_config(ck / "training.yaml"), str(ck / "training.yaml"), ck / "training.yaml", src)
    after = (ck / "training.yaml").read_text()
    assert after.replace('# data ' + json.dumps(src, sort_keys=True) + "\n", "") == before  # header and body kept
    args = [
        "report",
        "nusc_val",
        "--out",
        str(tmp_path / "r.md"),
        "--paper",
        str(PAPER),
        "--experiment",
        "nusc_val:nuscenes:val:centerpoint",
        "--row",
        "III:Ours=grukf",
        "--run",
        f"grukf={nusc_metrics(tmp_path / 'g.json', 0.73, 0.5, 270)}",
        "--train-log",
        f"nusc_grukf={ck / 'train_log.csv'}",
    ]
    assert main(args) == 0
    text = (tmp_path / "r.md").read_text()
    assert "## How the GRU-KF was trained" in text
    assert (
        "split train of v1.0-trainval at `/data/nuscenes`; detections `/d/centerpoint_train.json` | "
        "none | 3 steps, 2 epochs |"
    ) in text  # no synthetic data listed: none
    assert "SYNTHETIC TRAINING DATA" not in text
    # the semi-supervised report says it reads training logs, and names where the data is said
    out = tmp_path / "s.md"
    assert (
        main(
            [
                "report",
                "semi_supervised",
                "--out",
                str(out),
                "--paper",
                str(PAPER),
                "--train-log",
                f"semi_supervised={ck / 'train_log.csv'}",
            ]
        )
        == 0
    )
    text = out.read_text()
    assert "from the training logs (train_log.csv) written by `grutrack train`" in text
    assert "metrics JSON" not in text and '"trained on" column under Provenance' in text
    assert "| split train of v1.0-trainval" in text

    # figures: a flat AMOTA curve is drawn flat; legends sit beside the bars, never on them
    captured = []
    monkeypatch.setattr(figures, "_save", lambda fig, path: captured.append(fig) or Path(path))
    figures.lines(tmp_path / "l.png", {"a": ([1, 2, 3], [0.50001, 0.50004, 0.50006])}, "t", "x", "y", min_span=0.1)
    lo, hi = captured[-1].axes[0].get_ylim()
    assert hi - lo == pytest.approx(0.1)
    figures.grouped_bars(
        tmp_path / "b.png",
        ["bicycle", "bus", "car"],
        {
            "paper Ours": [90.0, 95.0, 99.0],
            "reproduced Ours": [89.0, 96.0, 98.0],
            "reproduced Greedy": [80.0, 85.0, 97.0],
        },
        "t",
        "HOTA",
    )
    fig = captured[-1]
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent(r)
    assert ax.patches and not any(legend.overlaps(p.get_window_extent(r)) for p in ax.patches)


def test_av2_report_says_how_many_logs_it_scored(tmp_path):
    from grutrack.report.av2_val import _scored

    def doc(**kw):
        return MetricsDocument(
            dataset="av2",
            version="sensor",
            split="val",
            evaluator="official",
            submission="x",
            overall={},
            per_class={},
            **kw,
        )

    d = doc(logs=150, frames=4700, settings={"rate_hz": 2.0})
    assert _scored({"a": d, "b": d}) == "150 logs, 4700 frames at 2 Hz"
    assert "not in the metrics JSONs" in _scored({"a": doc(settings={})})


@pytest.mark.parametrize(
    "flag, value, message",
    [
        ("--row", "III-Ours=grukf", "--row expects TABLE:ROW=RUN, got 'III-Ours=grukf'"),
        ("--extra-row", "III:Fast-Poly", "--extra-row expects TABLE:ROW=RUN, got 'III:Fast-Poly'"),
        ("--extra-row", "III:Fast-Poly=nope", "row 'Fast-Poly' is mapped to run 'nope', which has no --run"),
    ],
)
def test_bad_row_arguments_exit_2_with_one_line(tmp_path, capsys, flag, value, message):
    args = [
        "report",
        "nusc_val",
        "--out",
        str(tmp_path / "r.md"),
        "--paper",
        str(PAPER),
        "--experiment",
        "nusc_val:nuscenes:val:centerpoint",
        "--row",
        "III:Ours=grukf",
        "--run",
        f"grukf={nusc_metrics(tmp_path / 'g.json', 0.73, 0.5, 270)}",
        flag,
        value,
    ]
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "r.md").exists()


def test_demo_report_draws_the_learning_curve_with_the_reference_line(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from grutrack.documents import TrainingLog, ValidationRecord
    from grutrack.report import demo, figures

    (tmp_path / "log.csv").write_text(
        "step,epoch,scene,loss,gt_terms,pseudo_terms,lr,val_amota,seconds\n"
        "0,0,(before training),nan,0,0,nan,0.80,0\n1,0,s,0.5,3,1,1e-3,,1.0\n"
        "2,0,s,0.4,3,1,1e-3,0.83,1.0\n3,1,s,0.3,3,1,1e-3,0.82,1.0\n"
    )
    rec = ValidationRecord(
        rule="best_val_amota",
        selected_step=2,
        split="demo_train",
        scenes=["a", "b"],
        held_out=True,
        detection_sets=["given", "velfail"],
        reference="tracker preset 'ekf' (its EKF)",
        reference_amota=0.81,
        selected_amota=0.83,
    )
    rec.write(tmp_path / "validation.json")
    drawn = []
    monkeypatch.setattr(figures, "lines", lambda path, series, *a, **k: drawn.append((series, k)) or Path(path))
    inp = SimpleNamespace(figures=tmp_path / "fig", out=tmp_path / "r.md")
    text = "\n".join(
        demo._learning_curve(inp, "g", TrainingLog.read(tmp_path / "log.csv"), tmp_path / "validation.json")
    )
    series, kw = drawn[0]
    assert series == {"GRU-KF": ([0, 2, 3], [0.80, 0.83, 0.82])}
    assert kw["hlines"] == {"tracker preset 'ekf' (its EKF): 0.810": 0.81}
    assert (
        "Validated on 2 scenes held out of demo_train (a, b) with 2 detection sets (given, velfail; AMOTA their "
        "mean), not trained on; step 0 is the network before "
        "training. model.pt holds step 2 (the step of best validation AMOTA, AMOTA 0.830); tracker preset "
        "'ekf' (its EKF) on the same scenes: 0.810."
    ) in text
    # a training without validation draws no curve
    assert demo._learning_curve(inp, "g", TrainingLog.read(tmp_path / "log.csv"), tmp_path / "none.json") == []


def test_semi_supervised_summary_counts_step_0_as_a_step():
    """A log validated before its first step (step 0) that is already within 1 % of its best says step 0."""
    from grutrack.documents import TrainingStep
    from grutrack.report.semi_supervised import _summary, first_step_reaching, first_step_within

    rows = [
        TrainingStep(0, 0, "(before training)", float("nan"), val_amota=0.870),
        TrainingStep(1, 0, "s", 0.5, val_amota=0.860),
        TrainingStep(2, 0, "s", 0.4, val_amota=0.875),
    ]
    assert first_step_within(rows) == 0 and first_step_reaching(rows) == 0
    assert "| a | 2 | 1 | 0.875 | 0.875 (step 2) | 0 |" in _summary({"a": rows})
    rows[0].val_amota = 0.80
    assert first_step_within(rows) == 2


def test_report_paths_are_relative_below_the_working_directory(tmp_path, monkeypatch):
    """A report shows a path below the working directory (the workflow's outputs, the package in a checkout)
    relative to it, so that the same run gives the same report in any checkout; a path elsewhere stays as given."""
    from grutrack.report.markdown import shown_path

    monkeypatch.chdir(tmp_path)
    assert shown_path(tmp_path / "checkpoints" / "m" / "model.pt") == "checkpoints/m/model.pt"
    assert shown_path("checkpoints/m/model.pt") == "checkpoints/m/model.pt"
    assert shown_path("/elsewhere/data/nuscenes") == "/elsewhere/data/nuscenes"
    assert shown_path("../shared/data/nuscenes") == "../shared/data/nuscenes"


@pytest.mark.parametrize(
    "scanned, split_scenes, words",
    [
        (1, 1, "on the split's one scene:"),
        (2, 2, "on both scenes of the split:"),
        (150, 150, "on all 150 scenes of the split:"),
        (10, 150, "on 10 of the split's 150 scenes, evenly spaced (400 samples):"),
    ],
)
def test_the_cross_check_line_names_the_scenes_it_compared(tmp_path, scanned, split_scenes, words):
    from grutrack.documents import CrossCheckDocument
    from grutrack.report.markdown import evaluator_line

    cc = CrossCheckDocument(
        dataset="nuscenes",
        version="v1.0-trainval",
        split="val",
        submission="submissions/x.json",
        scenes=[f"scene-{i:04d}" for i in range(scanned)],
        split_scenes=split_scenes,
        samples=400,
        entries=185,
        max_abs_difference=0.0,
        worst_entry="amota",
        tolerance=1e-9,
        equal=True,
    )
    docs = {"grukf": MetricsDocument.read(nusc_metrics(tmp_path / "grukf.json", 0.5, 1.0, 3))}
    assert words in evaluator_line(docs, cc, "grukf")
