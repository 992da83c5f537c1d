"""Markdown building blocks shared by the reports: tables, number formatting, the paper-table mirrors and
the provenance section (from the manifests beside the submissions)."""

from __future__ import annotations

from pathlib import Path

from grutrack import __version__
from grutrack.documents import ABSENT_TEXT, CrossCheckDocument, FileRecord, Manifest, MetricsDocument, TrainingLog
from grutrack.provenance import SHORT
from grutrack.report.paper import absent_columns, reproduced

DASH = "—"


def table(header: list[str], rows: list[list[str]], align: str | None = None) -> str:
    """A GitHub-flavoured markdown table; ``align`` is one char per column (l/r), default: first left."""
    align = align or "l" + "r" * (len(header) - 1)
    sep = ["---:" if a == "r" else ":---" for a in align]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(sep) + " |"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def num(v: float | None, integer: bool = False, signed: bool = False) -> str:
    """A number in the paper's style: one decimal, or an integer for counts; a dash when missing."""
    if v is None:
        return DASH
    if integer:
        return f"{v:+.0f}" if signed else f"{v:.0f}"
    return f"{v:+.1f}" if signed else f"{v:.1f}"


def column_is_count(tbl: dict, col: str) -> bool:
    """Counts (IDS) are scaled by 1 and shown as integers."""
    return tbl["columns"][col]["scale"] == 1


def mirror_tables(tbl: dict, docs: dict[str, dict | None], extra: dict[str, dict] | None = None) -> str:
    """The paper table as printed (PAPER numbers), the same layout with the reproduced numbers, and the
    difference reproduced - paper; ``docs`` maps a paper row to the metrics JSON that reproduces it, ``extra``
    a row that is not in the paper (reproduced only, labelled "not in the paper") to its metrics JSON. A per-class
    column of a class without ground truth in the evaluated data reads "absent (no ground truth)", not a number."""
    cols = list(tbl["columns"])
    paper_rows, repro_rows, diff_rows = [], [], []

    def cells(values: dict, absent: set, diff_to: dict | None = None) -> list[str]:
        out = []
        for c in cols:
            if c in absent:
                out.append(ABSENT_TEXT)
            elif diff_to is None:
                out.append(num(values[c], column_is_count(tbl, c)))
            else:
                out.append(
                    num(
                        None if values[c] is None or c not in diff_to else values[c] - diff_to[c],
                        column_is_count(tbl, c),
                        signed=True,
                    )
                )
        return out

    for row, numbers in tbl["rows"].items():
        values, absent = reproduced(tbl, docs.get(row)), absent_columns(tbl, docs.get(row))
        paper_rows.append([row] + [num(numbers.get(c), column_is_count(tbl, c)) for c in cols])
        if row in docs:
            repro_rows.append([row] + cells(values, absent))
            diff_rows.append([row] + cells(values, absent, numbers))
    for row, doc in (extra or {}).items():
        repro_rows.append([f"{row} (not in the paper)"] + cells(reproduced(tbl, doc), absent_columns(tbl, doc)))
    out = [f"**Paper numbers** ({tbl['title']}; as printed in the paper):", "", table(["method"] + cols, paper_rows)]
    if repro_rows:
        out += [
            "",
            "**Reproduced** (same layout; read from the metrics JSONs listed under Provenance):",
            "",
            table(["method"] + cols, repro_rows),
            "",
            "**Difference** (reproduced − paper, in the paper's unit):",
            "",
            table(["method"] + cols, diff_rows),
        ]
    return "\n".join(out)


def setting_note(tbl: dict, experiment: dict | None, detections: str | None = None) -> str:
    """A warning when the reproduced setting (dataset, split, detector) is not the paper table's."""
    if not experiment:
        return ""
    paper = (tbl.get("dataset"), tbl.get("split"))
    ours = (experiment.get("dataset"), experiment.get("split"))
    same_det = detections is None or detections.lower().replace("_", "") in tbl.get("detections", "").lower()
    if paper == ours and same_det:
        return ""
    return (
        f"> **Different setting.** The paper's numbers are on {paper[0]} {paper[1]} with {tbl.get('detections')} "
        f"detections; the reproduced ones on {ours[0]} {ours[1]} with {detections or '?'} detections, so the "
        f"differences below mostly measure that, not the method."
    )


def detections_line(experiment: dict | None) -> str:
    """What the runs tracked: the detector, and SYNTHETIC banners when the dataset is the demo or the detections
    were simulated."""
    exp = experiment or {}
    line = f"Detections: {exp.get('detector', '?')}."
    if exp.get("dataset") == "demo":
        line = (
            f"> **SYNTHETIC DATA.** The scenes and ground truth are grutrack's SYNTHETIC demo dataset (split "
            f"{exp.get('split', '?')}), and so are detections made from it: the reproduced numbers measure the "
            f"trackers on synthetic data, not on nuScenes.\n\n{line}"
        )
    if exp.get("simulated"):
        line = (
            f"> **SYNTHETIC DETECTIONS.** The detections ({exp.get('detector')}) were simulated from the ground "
            f"truth by `grutrack simulate-detections` (a detector model, not a real detector): the reproduced "
            f"numbers measure the trackers on them, not on a real detector's output.\n\n{line}"
        )
    return line


def short(h: str | None) -> str:
    return h[:SHORT] if h else DASH


def shown_path(path) -> str:
    """A path as a report shows it: relative to the working directory when it lies below it (the workflow's
    outputs, the package in a checkout), else as given (an installed package, data elsewhere)."""
    import os

    text = str(path)
    if os.path.isabs(text):
        rel = os.path.relpath(text)
        if not rel.startswith(".."):
            return rel
    return text


def file_cell(rec: FileRecord | None) -> str:
    """``path`` (sha256 abbreviated) of a file record, a dash for none."""
    if rec is None:
        return DASH
    return f"`{shown_path(rec.path)}` (sha256 {short(rec.sha256)})"


def provenance(runs: dict[str, str], docs: dict[str, MetricsDocument]) -> str:
    """Which detections, checkpoint, tracker config (hash) and package version made each run's numbers."""
    rows = []
    for run, path in runs.items():
        m = Manifest.read(Manifest.path_for(docs[run].submission))
        if m is None:
            rows.append([run, f"`{path}`"] + [DASH] * 5)
            continue
        cfg = m.tracker_config
        config = f"`{cfg.path}` (config hash {cfg.config_hash or DASH})"
        rows.append(
            [
                run,
                f"`{path}`",
                m.tracker or DASH,
                file_cell(m.detections),
                file_cell(m.checkpoint),
                config,
                f"{m.grutrack_version or DASH} (code {m.code_version or DASH})",
            ]
        )
    return table(
        ["run", "metrics JSON", "tracker", "detections", "checkpoint", "tracker config", "grutrack"], rows, "l" * 7
    )


def header(title: str, lines: list[str], source: str = "metrics JSONs written by `grutrack evaluate`") -> str:
    """Title, generator line (naming what the report reads) and notes."""
    return "\n".join(
        [
            f"# {title}",
            "",
            f"Generated by grutrack {__version__} (`grutrack report`) from {source}; no metric is recomputed here.",
            "",
            *lines,
        ]
    )


def image(path: Path, md_dir: Path, alt: str) -> str:
    """A markdown image link relative to the report."""
    rel = Path(path).resolve().relative_to(md_dir.resolve()) if _inside(path, md_dir) else Path(path)
    return f"![{alt}]({rel.as_posix()})"


def _inside(path: Path, folder: Path) -> bool:
    try:
        Path(path).resolve().relative_to(folder.resolve())
        return True
    except ValueError:
        return False


#: overall columns of a nuScenes metrics JSON shown in run tables: (key, header, scale)
NUSC_OVERALL = (
    ("amota", "AMOTA", 100),
    ("amotp", "AMOTP", 100),
    ("mota", "MOTA", 100),
    ("recall", "recall", 100),
    ("ids", "IDS", 1),
    ("frag", "FRAG", 1),
    ("tp", "TP", 1),
    ("fp", "FP", 1),
    ("fn", "FN", 1),
)
#: overall columns of an AV2 metrics JSON (Table I average over its classes with ground truth)
AV2_OVERALL = (("hota", "HOTA", 100), ("mota", "MOTA", 100), ("idf1", "IDF1", 100))


def runs_table(docs: dict[str, MetricsDocument], columns=NUSC_OVERALL) -> str:
    """One row per run with its overall metrics (×100 for rates, as in the paper; counts as integers)."""
    rows = []
    for run, doc in docs.items():
        o = doc.overall
        rows.append([run] + [num(None if o.get(k) is None else o[k] * s, integer=(s == 1)) for k, _, s in columns])
    return table(["run"] + [h for _, h, _ in columns], rows)


def per_class_table(docs: dict[str, MetricsDocument], key: str = "amota", scale: float = 100) -> str:
    """One row per class, one column per run, of one per-class metric (a class without ground truth: absent)."""
    classes = next(iter(docs.values())).classes if docs else []
    rows = [
        [c]
        + [
            ABSENT_TEXT
            if d.is_absent(c)
            else num(None if d.per_class.get(c, {}).get(key) is None else d.per_class[c][key] * scale)
            for d in docs.values()
        ]
        for c in classes
    ]
    return table(["class"] + list(docs), rows)


def check_section(tid: str, tbl: dict, row_docs: dict[str, MetricsDocument]) -> str:
    """For each reproduced row: paper, reproduced, difference and tolerance per metric, and whether it passes
    (the same test as ``grutrack check``; a class without ground truth is absent, not checked)."""
    from grutrack.report.check import compare

    rows = []
    for row, doc in row_docs.items():
        _, comps = compare(tbl, doc, row)
        for c in comps:
            integer = column_is_count(tbl, c.metric)
            rows.append(
                [
                    f"{tid}: {row}",
                    c.metric,
                    num(c.paper, integer),
                    ABSENT_TEXT if c.absent else num(c.reproduced, integer),
                    num(c.diff, integer, signed=True),
                    "±" + num(c.tolerance, integer),
                    "absent, not checked" if c.absent else "within" if c.ok else "**OUT**",
                ]
            )
    if not rows:
        return "_No reproduced row._"
    return table(["paper row", "metric", "paper", "reproduced", "difference", "tolerance", "status"], rows, "llrrrrl")


def training_provenance(train_logs: dict[str, Path]) -> str:
    """Per training: the data it was trained on (dataset, version, split, detections, from the ``# data`` line
    ``grutrack train`` writes into training.yaml), its steps and epochs (train_log.csv), its log, resolved
    training config (hash) and model (sha256), from the checkpoint folder."""
    import yaml

    from grutrack.provenance import config_hash, sha256_file

    rows = []
    for label, log in train_logs.items():
        folder = Path(log).parent
        cfg_path, model = folder / "training.yaml", folder / "model.pt"
        cfg_hash = config_hash(yaml.safe_load(cfg_path.read_text())) if cfg_path.is_file() else DASH
        model_txt = f"`{shown_path(model)}` (sha256 {short(sha256_file(model))})" if model.is_file() else DASH
        steps = TrainingLog.read(log).steps if Path(log).is_file() else None
        done = (
            f"{steps[-1].step} steps, {steps[-1].epoch + 1} epochs"
            if steps
            else "no step (the initialised network)"
            if steps is not None
            else DASH
        )
        synthetic = training_synthetic(cfg_path)
        rows.append(
            [
                label,
                training_data(cfg_path),
                "SYNTHETIC: " + ", ".join(synthetic) if synthetic else "none",
                done,
                f"`{shown_path(log)}`",
                f"`{shown_path(cfg_path)}` (config hash {cfg_hash})",
                model_txt,
            ]
        )
    return table(
        ["training", "trained on", "synthetic data", "length", "log", "training config", "checkpoint"], rows, "lllllll"
    )


def training_synthetic(cfg_path: Path) -> list[str]:
    """What of a training's data was SYNTHETIC (the ``synthetic`` list of training.yaml's ``# data`` line,
    written by ``grutrack train``); empty when none was, or the line predates the list."""
    import json

    if not Path(cfg_path).is_file():
        return []
    for line in Path(cfg_path).read_text().splitlines():
        if line.startswith("# data "):
            try:
                found = json.loads(line[len("# data ") :]).get("synthetic", [])
            except (ValueError, AttributeError):
                return []
            return [str(x) for x in found] if isinstance(found, list) else []
    return []


def synthetic_training_banner(train_logs: dict[str, Path]) -> str | None:
    """A SYNTHETIC banner naming each training whose data was partly synthetic and what was, or None."""
    items = [(label, training_synthetic(Path(log).parent / "training.yaml")) for label, log in train_logs.items()]
    items = [(label, what) for label, what in items if what]
    if not items:
        return None
    return (
        "> **SYNTHETIC TRAINING DATA.** The GRU-KF rows depend on trainings that used synthetic data: "
        + "; ".join(f"`{label}`: {', '.join(what)}" for label, what in items)
        + ". Their numbers measure the method trained so, not trained on a real detector's output alone."
    )


def _whole_split(n: int) -> str:
    """'the split's one scene', 'both scenes of the split', 'all N scenes of the split'."""
    if n == 1:
        return "the split's one scene"
    return "both scenes of the split" if n == 2 else f"all {n} scenes of the split"


def evaluator_line(
    docs: dict[str, MetricsDocument], cross_check: CrossCheckDocument | None = None, run: str | None = None
) -> str:
    """Which evaluator made the numbers and, with a cross-check, how the devkit and the fast evaluator compared
    on ``run``."""
    used = sorted({d.evaluator for d in docs.values()})
    names = {
        "devkit": "nuscenes-devkit `TrackingEval` (`tracking_nips_2019`)",
        "fast": "grutrack's fast exact evaluator (nuscenes-devkit `TrackingEval`'s metrics, re-implemented; "
        "`grutrack evaluate --evaluator fast`)",
        "official": "the official AV2 tracking evaluation (`av2.evaluation.tracking.eval`, HOTA via TrackEval)",
    }
    line = "Evaluated with " + " and ".join(names.get(e, e) for e in used) + "."
    if cross_check is None:
        return line
    cc = cross_check
    where = (
        f"{len(cc.scenes)} of the split's {cc.split_scenes} scenes, evenly spaced ({cc.samples} samples)"
        if cc.subset
        else _whole_split(cc.split_scenes)
    )
    diff = "an entry differing in kind" if cc.max_abs_difference is None else f"{cc.max_abs_difference:.2g}"
    verdict = (
        f"**equal** to {cc.tolerance:g}" if cc.equal else f"**NOT EQUAL** (largest difference in `{cc.worst_entry}`)"
    )
    return (
        f"{line} Cross-check: run `{run or '?'}` scored by both nuscenes-devkit `TrackingEval` and the fast "
        f"evaluator on {where}: all {cc.entries} entries of the metrics summary compared, largest absolute "
        f"difference {diff}: {verdict} (devkit {cc.seconds.get('devkit') or 0:.0f} s, fast "
        f"{cc.seconds.get('fast') or 0:.1f} s; `grutrack cross-check`)."
    )


def training_data(cfg_path: Path) -> str:
    """``split of version at dataroot, detections file`` from a training.yaml's ``# data {...}`` line."""
    import json

    if not Path(cfg_path).is_file():
        return DASH
    for line in Path(cfg_path).read_text().splitlines():
        if line.startswith("# data "):
            try:
                d = json.loads(line[len("# data ") :])
            except ValueError:
                return DASH
            return (
                f"split {d.get('split', '?')} of {d.get('version', '?')} at `{shown_path(d.get('dataroot', '?'))}`; "
                f"detections `{shown_path(d.get('detections', '?'))}`"
            )
    return DASH


WORST_SCENE_TITLE = "## Worst scene per run (key frames)"


def worst_scene_strips(inp, scene_word: str = "scene") -> str:
    """A section with, per rendered run, a strip of key frames of its worst scene (AV2: log; id-switch moments
    first), from the run's ``grutrack render`` folder; empty when the report has no renders."""
    if not inp.renders:
        return ""
    from grutrack.render.draw import strip_from_counts

    matching = (
        "the official AV2 evaluator's own CLEAR matching (an id-switch match is also a TP)"
        if scene_word == "log"
        else "the evaluator's own matching"
    )
    parts = [
        WORST_SCENE_TITLE.replace("scene", scene_word),
        "",
        f"Bird's-eye frames of each run's {scene_word} with the most id switches + false positives + misses "
        "(`grutrack render --worst 1`): tracks coloured by id, false-positive tracks red, missed ground truth "
        f"orange dashed, id switches ringed in magenta (old \u2192 new track); {matching}.",
    ]
    for run, counts in inp.renders.items():
        info = strip_from_counts(counts, inp.figures / f"worst_scene_{run}.png")
        t = info["totals"]
        sw = ", ".join(f"{a}\u2192{b}" for a, b in info["id_switches"]) or "none"
        parts += [
            "",
            f"**{run}**: {info['scene']}, frames {', '.join(map(str, info['frames']))} "
            f"(id switches shown: {sw}; FP {t['fp']}, FN {t['fn']} in these frames)",
            "",
            image(inp.figures / f"worst_scene_{run}.png", inp.out.parent, f"{run}: key frames of {info['scene']}"),
        ]
    return "\n".join(parts)
