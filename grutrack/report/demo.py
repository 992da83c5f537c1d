"""Report of the embedded demo (``reports/demo_val.md``): the EKF and GRU-KF runs on the SYNTHETIC demo
dataset, with the paper's Table III shown separately, for reference only (real nuScenes; no comparison)."""

from __future__ import annotations

import json
from pathlib import Path

from grutrack.documents import SELECTION_RULES, TrainingLog, ValidationRecord
from grutrack.report import figures
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import (
    evaluator_line,
    header,
    image,
    num,
    per_class_table,
    provenance,
    runs_table,
    table,
    training_provenance,
    training_synthetic,
    worst_scene_strips,
)
from grutrack.report.paper import get_table

BANNER = (
    "> **SYNTHETIC DATA.** Every reproduced number in this report is measured on grutrack's synthetic demo "
    "dataset ({version}, split {split}) with simulated, detector-like detections ({detector}). The paper's "
    "numbers further down are for the real nuScenes val split with real CenterPoint detections; they are "
    "shown for reference only. **No comparison between the two is implied**, and no difference is computed."
)

#: what a difference between the runs above means on a split of a few SYNTHETIC scenes
NOISE = (
    "The split is small: one track moves a class's AMOTA by points and the overall AMOTA by tenths of a point, so "
    "differences of that size between runs are within the spread from one detection draw to another (the GRU-KF "
    "against the EKF over thirty draws: `docs/results/main_job.md` in the repository)."
)


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    docs = inp.docs()
    exp = inp.experiment or {}
    version = (next(iter(docs.values())).version or "v1.0-demo") if docs else "v1.0-demo"
    parts = [
        header(
            f"Demo report: GRU-KF and EKF on the SYNTHETIC demo ({exp.get('split', '')})",
            [BANNER.format(version=version, split=exp.get("split", "?"), detector=exp.get("detector", "?"))],
        )
    ]
    parts += [
        "",
        "## Reproduced on the synthetic demo",
        "",
        evaluator_line(docs, *reversed(inp.cross_check_doc())),
        "",
        "Overall (rates ×100, AMOTP in cm):",
        "",
        runs_table(docs),
        "",
        NOISE,
        "",
        "AMOTA per class (×100):",
        "",
        per_class_table(docs, "amota"),
    ]
    parts += ["", _amota_figure(inp, docs)]
    strips = worst_scene_strips(inp)
    parts += ["", strips] if strips else []
    parts += _checkpoints_section(inp)
    parts += _training_sections(inp)
    parts += ["", "## Paper numbers (real nuScenes val; reference only, not comparable)", "", _paper_table(inp)]
    parts += ["", "## Provenance", "", provenance(inp.runs, docs)]
    if inp.train_logs:
        parts += ["", training_provenance(inp.train_logs)]
    return "\n".join(parts) + "\n"


def _amota_figure(inp: ReportInputs, docs: dict) -> str:
    classes = next(iter(docs.values())).classes if docs else []
    series = {
        run: [None if d.per_class[c].get("amota") is None else 100 * d.per_class[c]["amota"] for c in classes]
        for run, d in docs.items()
    }
    path = figures.grouped_bars(
        inp.figures / "amota_per_class.png", classes, series, "AMOTA per class on the SYNTHETIC demo", "AMOTA ×100"
    )
    return image(path, inp.out.parent, "AMOTA per class on the synthetic demo")


def _checkpoints_section(inp: ReportInputs) -> list[str]:
    """Which network each GRU-KF run tracked with: a pretrained one shipped in the package (its provenance.json:
    how, when and from which commit it was trained) or one trained by this workflow."""
    if not inp.run_trainings:
        return []
    rows = []
    for run, label in inp.run_trainings.items():
        folder = Path(inp.train_logs[label]).parent
        steps = TrainingLog.read(inp.train_logs[label]).steps
        length = f"{steps[-1].step} steps, {steps[-1].epoch + 1} epochs" if steps else "no step"
        prov = folder / "provenance.json"
        if prov.is_file():
            p = json.loads(prov.read_text())
            what = (
                f"shipped pretrained network `{folder.name}` (`{p['command']}`, commit {p['git_commit'][:10]}, "
                f"written {p['written']}); not trained by this workflow"
            )
        else:
            what = f"trained by this workflow (`{folder}`)"
        rows.append([run, label, what, length])
    return [
        "",
        "## GRU-KF checkpoints",
        "",
        "Which network each GRU-KF run tracked with (training data and hashes: Provenance below).",
        "",
        table(["run", "training", "checkpoint", "length"], rows, "llll"),
    ]


def _training_sections(inp: ReportInputs) -> list[str]:
    """Loss (and validation AMOTA when logged) against step for each training."""
    out = []
    for label, log in inp.train_logs.items():
        tl = TrainingLog.read(log)
        if not tl.steps:
            out += ["", f"## Training '{label}'", "", _no_step(Path(log).parent / "training.yaml")]
            continue
        path = figures.lines(
            inp.figures / f"training_{label}.png",
            {"loss": ([s.step for s in tl.steps], [s.loss for s in tl.steps])},
            f"GRU-KF training '{label}'" + _synthetic_tag(Path(log).parent),
            "step",
            "loss per scene",
        )
        last, val = tl.steps[-1], tl.validated()
        out += [
            "",
            f"## Training '{label}'",
            "",
            f"{last.step} steps over {last.epoch + 1} epoch(s); last scene loss {last.loss:.4g}"
            + (f"; last validation AMOTA {val[-1].val_amota:.3f}{_synthetic_tag(Path(log).parent)}" if val else "")
            + ".",
            "",
            image(path, inp.out.parent, f"training loss of {label}"),
        ]
        out += _learning_curve(inp, label, tl, Path(log).parent / "validation.json")
    return out


def _learning_curve(inp: ReportInputs, label: str, tl: TrainingLog, record_path: Path) -> list[str]:
    """Validation AMOTA against step (step 0: the network before training) with the reference tracker's AMOTA on
    the same scenes as a line, and which step model.pt holds; nothing when the training was not validated."""
    val = tl.validated()
    if not val or not record_path.is_file():
        return []
    rec = ValidationRecord.read(record_path)
    ref = (
        {f"{rec.reference}: {rec.reference_amota:.3f}": rec.reference_amota}
        if rec.reference_amota is not None
        else None
    )
    path = figures.lines(
        inp.figures / f"learning_curve_{label}.png",
        {"GRU-KF": ([r.step for r in val], [r.val_amota for r in val])},
        f"Validation AMOTA of '{label}'" + _synthetic_tag(record_path.parent),
        "step",
        "AMOTA",
        hlines=ref,
        min_span=0.02,
    )
    n = len(rec.scenes)
    where = f"{n} scene{'s' if n != 1 else ''} held out of {rec.split}" if rec.held_out else f"the {rec.split} split"
    chosen = SELECTION_RULES[rec.rule]
    amota = "n/a" if rec.selected_amota is None else f"{rec.selected_amota:.3f}"
    sets = (
        f" with {len(rec.detection_sets)} detection sets ({', '.join(rec.detection_sets)}; AMOTA their mean)"
        if len(rec.detection_sets) > 1
        else ""
    )
    text = (
        f"Validated on {where} ({', '.join(rec.scenes)}){sets}, not trained on; step 0 is the network before "
        f"training. model.pt holds step {rec.selected_step} ({chosen}, AMOTA {amota})"
        + (f"; {rec.reference} on the same scenes: {rec.reference_amota:.3f}." if ref else ".")
    )
    return ["", text, "", image(path, inp.out.parent, f"validation AMOTA of {label}")]


def _synthetic_tag(folder: Path) -> str:
    """`` (SYNTHETIC data)`` for a figure title when the training's data was partly synthetic, else empty."""
    return " (SYNTHETIC data)" if training_synthetic(folder / "training.yaml") else ""


def _no_step(cfg_path: Path) -> str:
    """What a training without a step gives: the initialised network (one constant gain without a gap table)."""
    import yaml

    cfg = yaml.safe_load(cfg_path.read_text()) if cfg_path.is_file() else {}
    net = {**cfg, **(cfg.get("network") or {})}  # the network's options: nested, or flat in older configs
    if net.get("gap_bins") == 0 and net.get("gain_prior", "constant") == "constant":
        return (
            "No training step: the network as initialised, whose gain is one constant, the EKF's mean gain "
            "on the training data (the constant-gain ablation)."
        )
    return "No training step: the network as initialised (its gain prior)."


def _paper_table(inp: ReportInputs) -> str:
    """Table III as printed in the paper (PAPER numbers)."""
    tbl = get_table(inp.paper, "III")
    cols = list(tbl["columns"])
    rows = [
        [_paper_row(row)] + [num(v.get(c), integer=tbl["columns"][c]["scale"] == 1) for c in cols]
        for row, v in tbl["rows"].items()
    ]
    heads = [c.upper() + (" (cm)" if c == "amotp" else "") for c in cols]
    return f"**Paper numbers**, {tbl['title']}:\n\n" + table(["method"] + heads, rows)


def _paper_row(row: str) -> str:
    """The paper's row label with its own method named: "Ours" -> "Ours (GRUTrack)", "Ours (X)" ->
    "Ours (GRUTrack, X)"."""
    if row == "Ours":
        return "Ours (GRUTrack)"
    return row.replace("Ours (", "Ours (GRUTrack, ", 1) if row.startswith("Ours (") else row
