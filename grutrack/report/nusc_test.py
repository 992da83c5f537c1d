"""Report of nuScenes test (``reports/nusc_test.md``): Table II's paper numbers and the leaderboard zips built
for it (the test split has no public ground truth; the leaderboard scores the zips)."""

from __future__ import annotations

import zipfile

from grutrack.documents import Manifest
from grutrack.provenance import sha256_file
from grutrack.report import figures
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import DASH, WORST_SCENE_TITLE, file_cell, header, image, mirror_tables, short, table
from grutrack.report.paper import get_table

INSTRUCTIONS = (
    "Upload each zip to the nuScenes tracking leaderboard (EvalAI, lidar track). The test split has "
    "no public ground truth, so this report has no reproduced numbers; once the leaderboard has scored "
    "a zip, write its overall AMOTA / AMOTP / IDS into a metrics JSON (`{\"overall\": {\"amota\": ..., "
    "\"amotp\": ..., \"ids\": ...}}`) and run `grutrack check that.json --table II --row "
    "\"Ours (CenterPoint)\"`."
)

NO_GT_FRAMES = (
    "None: nuScenes test has no public ground truth, so no frame can show false positives, misses or "
    "id switches (the other reports embed key frames of each run's worst scene; `grutrack render` "
    "needs a split with ground truth)."
)


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    tbl = get_table(inp.paper, "II")
    parts = [header("nuScenes test: Table II and the leaderboard zips", [INSTRUCTIONS])]
    parts += ["", f"## {tbl['title']}", "", mirror_tables(tbl, {}), "", _figure(inp, tbl)]
    parts += ["", "## Leaderboard zips (validated against the official format before zipping)", "", _zips(inp)]
    parts += ["", WORST_SCENE_TITLE, "", NO_GT_FRAMES]
    return "\n".join(parts) + "\n"


def _zips(inp: ReportInputs) -> str:
    """One row per detector: the zip, its member, counts and what produced it."""
    rows = []
    run = next(iter(inp.rows.get("II", {}).values()), None)
    for det, zp in inp.zips.items():
        with zipfile.ZipFile(zp) as zf:
            member = zf.namelist()[0]
        sub = _submission_of(inp, det, run)
        m = Manifest.read(Manifest.path_for(sub)) if sub else None
        rows.append(
            [det, f"`{zp}`", f"sha256 {short(sha256_file(zp))}", member]
            + (
                [
                    str(m.counts.get("samples", DASH)),
                    str(m.counts.get("boxes", DASH)),
                    file_cell(m.detections),
                    file_cell(m.checkpoint),
                    f"config hash {m.tracker_config.config_hash or DASH}",
                    m.grutrack_version or DASH,
                ]
                if m
                else [DASH] * 6
            )
        )
    return table(
        [
            "detector",
            "zip",
            "zip hash",
            "member",
            "samples",
            "boxes",
            "detections",
            "checkpoint",
            "tracker config",
            "grutrack",
        ],
        rows,
        "l" * 10,
    )


def _submission_of(inp: ReportInputs, det: str, run: str | None) -> str | None:
    """The submission JSON a zip was built from (submissions/<experiment>/<detector>/<run>.json)."""
    exp = (inp.experiment or {}).get("name")
    if not exp or not run:
        return None
    return f"submissions/{exp}/{det}/{run}.json"


def _figure(inp: ReportInputs, tbl: dict) -> str:
    rows = [r for r, v in tbl["rows"].items() if "amota" in v]
    path = figures.grouped_bars(
        inp.figures / "table_II_amota.png",
        rows,
        {"paper": [tbl["rows"][r]["amota"] for r in rows]},
        "Table II (paper numbers): nuScenes test AMOTA",
        "AMOTA ×100",
    )
    return image(path, inp.out.parent, "Table II paper AMOTA")
