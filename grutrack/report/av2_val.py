"""Report of Argoverse 2 val (``reports/av2_val.md``): Table I, HOTA per class for Greedy, AB3DMOT and the
GRU-KF (trained on nuScenes-format data) on the experiment's detections (LT3D, or SYNTHETIC ones simulated from the
ground truth), paper numbers beside the reproduced ones."""

from __future__ import annotations

from grutrack.documents import MetricsDocument
from grutrack.report import figures
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import (
    AV2_OVERALL,
    check_section,
    detections_line,
    header,
    image,
    mirror_tables,
    provenance,
    runs_table,
    setting_note,
    synthetic_training_banner,
    training_provenance,
    worst_scene_strips,
)
from grutrack.report.paper import get_table, reproduced

AVERAGE_NOTE = (
    "Note: the paper's average for Ours (47.3) is not the mean of its seven per-class values (54.1) "
    "and the paper does not say what it averages over; the reproduced `average` is the mean over the "
    "Table I classes with ground truth in the evaluated logs. A class without any (within the "
    "evaluation range and, with the maps, the drivable area) is shown as \"absent (no ground truth)\" "
    "and left out of every average and of the check: the official evaluator takes no class average and "
    "gives such a class HOTA 0 and MOTA −FP, numbers of the class list rather than of the tracker."
)


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    docs = inp.docs()
    exp = inp.experiment or {}
    tbl = get_table(inp.paper, "I")
    parts = [
        header(
            f"Argoverse 2 {exp.get('split', 'val')}: Table I",
            [
                f"{detections_line(exp)} Official AV2 tracking evaluation (HOTA) of "
                f"{_scored(docs)}. Paper numbers are labelled **Paper numbers**.",
                *([""] + [banner] if (banner := synthetic_training_banner(inp.train_logs)) else []),
            ],
        )
    ]
    note = setting_note(tbl, exp, exp.get("detector"))
    parts += [
        "",
        f"## {tbl['title']}",
        "",
        *([note, ""] if note else []),
        mirror_tables(tbl, inp.row_docs("I"), inp.row_docs("I", extra=True)),
        "",
        AVERAGE_NOTE,
        "",
        _figure(inp, tbl),
    ]
    parts += [
        "",
        "## Every run (Table I average over the classes with ground truth, ×100)",
        "",
        runs_table(docs, AV2_OVERALL),
        "",
        _absent_line(docs),
    ]
    strips = worst_scene_strips(inp, scene_word="log")
    parts += ["", strips] if strips else []
    parts += ["", "## Check against the tolerances of paper.yaml", "", check_section("I", tbl, inp.row_docs("I"))]
    parts += ["", "## Provenance", "", provenance(inp.runs, docs)]
    if inp.train_logs:
        parts += ["", "## How the GRU-KF was trained", "", training_provenance(inp.train_logs)]
    return "\n".join(parts) + "\n"


def _absent_line(docs: dict[str, MetricsDocument]) -> str:
    """Which Table I classes each run's evaluated logs have no ground truth of (the same for every run on the same
    logs, else listed per run)."""
    if not docs:
        return ""
    groups: dict[tuple, list[str]] = {}
    for run, d in docs.items():  # overall.classes: the classes the average is taken over (Table I's 7)
        groups.setdefault(tuple(c for c in d.overall.get("classes") or d.classes if d.is_absent(c)), []).append(run)
    if not any(groups):
        return "Every Table I class has ground truth in the evaluated logs."
    if len(groups) == 1:
        classes = next(iter(groups))
        return f"Absent (no ground truth in the evaluated logs, left out of the averages): {', '.join(classes)}."
    return (
        "Absent (no ground truth in the evaluated logs, left out of the averages): "
        + "; ".join(f"{', '.join(runs)}: {', '.join(classes) or 'none'}" for classes, runs in groups.items())
        + "."
    )


def _scored(docs: dict[str, MetricsDocument]) -> str:
    """How many logs and frames the runs were scored on (the same for every run, else each is listed)."""
    seen = {(d.logs, d.frames, (d.settings or {}).get("rate_hz")) for d in docs.values()}
    if not docs or any(s[0] is None for s in seen):
        return "the split's logs (their number is not in the metrics JSONs: re-run `grutrack evaluate`)"
    return "; ".join(f"{n} logs, {f} frames at {r:g} Hz" for n, f, r in sorted(seen))


def _figure(inp: ReportInputs, tbl: dict) -> str:
    """HOTA per class: the paper's Ours and every reproduced row."""
    cols = list(tbl["columns"])
    row_docs = inp.row_docs("I")
    series = {"paper Ours": [tbl["rows"].get("Ours", {}).get(c) for c in cols]}
    for row, doc in row_docs.items():
        series[f"reproduced {row}"] = [reproduced(tbl, doc)[c] for c in cols]
    for row, doc in inp.row_docs("I", extra=True).items():
        series[f"{row} (not in the paper)"] = [reproduced(tbl, doc)[c] for c in cols]
    path = figures.grouped_bars(inp.figures / "table_I_hota.png", cols, series, "Table I: HOTA per class", "HOTA ×100")
    return image(path, inp.out.parent, "Table I: paper vs reproduced HOTA per class")
