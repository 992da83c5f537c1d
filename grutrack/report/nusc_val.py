"""Report of nuScenes val (``reports/nusc_val.md``): Table III (overall AMOTA / AMOTP / IDS) and Table IV (the
motion-module ablation, bicycle and car), paper numbers beside the reproduced ones."""

from __future__ import annotations

from grutrack.report import figures
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import (
    check_section,
    detections_line,
    evaluator_line,
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


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    docs = inp.docs()
    exp = inp.experiment or {}
    banner = synthetic_training_banner(inp.train_logs)
    parts = [
        header(
            f"nuScenes {exp.get('split', 'val')}: Tables III and IV",
            [
                f"{detections_line(exp)} Paper numbers are labelled **Paper numbers**; "
                "reproduced numbers come from the metrics JSONs under Provenance.",
                *(["", banner] if banner else []),
                "",
                evaluator_line(docs, *reversed(inp.cross_check_doc())),
            ],
        )
    ]
    for tid in ("III", "IV"):
        if tid in inp.rows:
            tbl = get_table(inp.paper, tid)
            note = setting_note(tbl, exp, exp.get("detector"))
            parts += [
                "",
                f"## {tbl['title']}",
                "",
                *([note, ""] if note else []),
                mirror_tables(tbl, inp.row_docs(tid), inp.row_docs(tid, extra=True)),
                "",
                _figure(inp, tid, tbl),
            ]
    parts += ["", "## Every run", "", runs_table(docs)]
    strips = worst_scene_strips(inp)
    parts += ["", strips] if strips else []
    parts += ["", "## Check against the tolerances of paper.yaml", ""]
    parts += ["\n\n".join(check_section(tid, get_table(inp.paper, tid), inp.row_docs(tid)) for tid in inp.rows)]
    parts += ["", "## Provenance", "", provenance(inp.runs, docs)]
    if inp.train_logs:
        parts += ["", "## How the GRU-KF was trained", "", training_provenance(inp.train_logs)]
    return "\n".join(parts) + "\n"


def _figure(inp: ReportInputs, tid: str, tbl: dict) -> str:
    """Paper vs reproduced bars of the table's AMOTA columns."""
    row_docs = inp.row_docs(tid)
    rows = list(row_docs)
    cols = [c for c in tbl["columns"] if c.endswith("amota")]
    series = {}
    for col in cols:
        series[f"paper {col}"] = [tbl["rows"][r].get(col) for r in rows]
        series[f"reproduced {col}"] = [reproduced(tbl, row_docs[r])[col] for r in rows]
    path = figures.grouped_bars(
        inp.figures / f"table_{tid}_amota.png", rows, series, f"Table {tid}: paper vs reproduced", "AMOTA ×100"
    )
    return image(path, inp.out.parent, f"Table {tid}: paper vs reproduced AMOTA")
