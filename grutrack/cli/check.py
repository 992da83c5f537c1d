"""``grutrack check METRICS.json --table III``: reproduced vs paper numbers under the tolerances of paper.yaml;
exits 1 when a number is out of tolerance or missing. A per-class number of a class without ground truth in the
evaluated data (marked absent in the metrics JSON) is shown absent and not checked.

``grutrack check-published METRICS.json --detections FILE``: a run on a detection file whose results others
published (known by its SHA-256, grutrack/configs/published/) against those figures, exactly: integers equal,
other figures at their printed precision; exits 1 when one differs, 0 when all are equal or the file is not a known
one (said so)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``check``."""
    p = sub.add_parser(
        "check",
        help="compare a metrics JSON with the paper's numbers (non-zero exit when off)",
        description="Compare the numbers of a metrics JSON (grutrack evaluate) with one row of a "
        "paper table (workflow/config/paper.yaml) under that table's per-metric "
        "tolerances (|reproduced - paper| <= tolerance, in the paper's unit). Prints a "
        "table naming each metric; exit status 0 when all are within tolerance, 1 when "
        "any is out of tolerance or missing. A class without ground truth in the "
        "evaluated data (absent in the metrics JSON) is marked absent, not checked.",
    )
    p.add_argument("metrics", help="metrics JSON written by grutrack evaluate")
    p.add_argument("--table", required=True, help="paper table: I, II, III or IV")
    p.add_argument("--row", default=None, help="paper row (default: the table's default_row, e.g. Ours)")
    p.add_argument("--paper", default=None, help="paper numbers (default: workflow/config/paper.yaml)")
    p.set_defaults(func=run)
    p = sub.add_parser(
        "check-published",
        help="compare a run on a known detection file with the figures published for it (exact)",
        description="Hash the detection file a run tracked (SHA-256) and, when others published results on "
        "that file (grutrack/configs/published/), compare the metrics JSON of the run (grutrack evaluate) "
        "with those figures exactly: an integer figure (IDS 235) must be equal, another (AMOTA 72.85) equal "
        "at its printed precision. Prints a table of the figures; exit status 0 when all are equal, 1 when "
        "any differs or the metrics are of another dataset, version or split. With the file's SHA-256 equal "
        "to the published one, a difference comes from the code or its configuration, not from the file. A "
        "file that is not a known one is said to be so (exit status 0).",
    )
    p.add_argument("metrics", help="metrics JSON written by grutrack evaluate")
    p.add_argument("--detections", required=True, help="the detection file the run tracked (it is hashed)")
    p.add_argument(
        "--tracker",
        default=None,
        help="tracker preset the run used, e.g. polymot (needed only when figures of several trackers are "
        "published on the file)",
    )
    p.add_argument(
        "--published",
        default=None,
        help="published-results YAML file or folder (default: the shipped grutrack/configs/published/)",
    )
    p.add_argument("--registry", default=None, help="detection registry YAML (default: the shipped one)")
    p.set_defaults(func=run_published)


def run(args: argparse.Namespace) -> int:
    """Print the comparison; 0 when every metric is within tolerance, else 1."""
    from grutrack.report.check import compare, format_comparisons
    from grutrack.report.paper import get_table, load_paper

    table = get_table(load_paper(args.paper), args.table)
    doc = _read_metrics(args.metrics)
    row, comps = compare(table, doc, args.row)
    print(f"{table['title']}; paper row '{row}'")
    print(
        f"reproduced: {args.metrics} ({doc.dataset or '?'} {doc.version or ''} {doc.split or '?'})".replace("  ", " ")
    )
    if (doc.dataset, doc.split) != (table.get("dataset"), table.get("split")):
        demo = " (SYNTHETIC: grutrack's demo dataset)" if "demo" in (doc.version or "") else ""
        print(
            f"note: the paper's table is {table.get('dataset')} {table.get('split')}; the metrics are of "
            f"{doc.version or doc.dataset} {doc.split}{demo}, not comparable"
        )
    print(format_comparisons(table, comps))
    bad = [c.metric for c in comps if c.failed]
    absent = [c.metric for c in comps if c.absent]
    checked = len(comps) - len(absent)
    print(
        f"{checked - len(bad)} of {checked} within tolerance"
        + (f"; out: {', '.join(bad)}" if bad else "")
        + (f"; absent (no ground truth, not checked): {', '.join(absent)}" if absent else "")
    )
    return 1 if bad else 0


def run_published(args: argparse.Namespace) -> int:
    """Print the comparison with each published result on the file; 0 when all are equal (or none is known),
    else 1."""
    from grutrack.evaluation.published import (
        compare,
        detection_sha256,
        format_checks,
        load_published,
        results_for,
        setup_differences,
    )

    published = load_published(args.published, args.registry)
    doc = _read_metrics(args.metrics)
    digest = detection_sha256(args.detections)
    chosen = results_for(published, digest, args.tracker)
    print(f"detections: {args.detections} (sha256 {digest})")
    if not chosen:
        known = sorted({f"{r.filename} ({r.dataset} {r.split})" for r in published})
        print(
            "this file is not a known published file: no published figures to compare with"
            + (f" (known: {', '.join(known)})" if known else "")
        )
        return 0
    failed = False
    for r in chosen:
        checks = compare(r, doc)
        differ = [c.path for c in checks if not c.equal]
        setup = setup_differences(r, doc)
        print()
        print(f"published: {r.publication}: {r.name}")
        print(f"  source: {r.url} ({r.license})")
        print(f"  code: {r.tracker_code} (grutrack preset {r.tracker})")
        print(f"  evaluator: {r.evaluator}")
        print(f"  detections: {r.filename} ({_where(r.dataset, r.version, r.split)})")
        print(f"ours: {args.metrics} ({_where(doc.dataset, doc.version, doc.split)}; evaluator {doc.evaluator or '?'})")
        if r.note:
            print(f"note: {r.note}")
        print(format_checks(checks))
        print(
            f"{len(checks) - len(differ)} of {len(checks)} figures equal"
            + (f"; differ: {', '.join(differ)}" if differ else "")
        )
        for line in setup:
            print(f"not the published setting: {line}")
        if setup:
            print("the metrics are not of the published run's data: the figures cannot be compared")
        elif differ:
            print(
                "the detection file is the published one (SHA-256 equal): the differences come from the code or its "
                "configuration, not from the file"
            )
        else:
            print("every figure equal: the file and the code reproduce the published run")
        failed = failed or bool(differ or setup)
    return 1 if failed else 0


def _where(dataset: str | None, version: str | None, split: str | None) -> str:
    """``nuscenes v1.0-trainval val``; what is not known is left out (a question mark when nothing is)."""
    return " ".join(x for x in (dataset, version, split) if x) or "?"


def _read_metrics(path: str):
    """The metrics document at ``path``; a missing file is an InputFormatError that says what writes it."""
    from grutrack.documents import MetricsDocument
    from grutrack.errors import InputFormatError

    if not Path(path).exists():
        raise InputFormatError(f"{path}: metrics JSON does not exist; {_who_writes(Path(path))}")
    return MetricsDocument.read(path)


def _who_writes(path: Path) -> str:
    """How the metrics JSON ``path`` is made: the workflow's target when the path is one of its
    ``reports/metrics/{experiment}/{detector}/{run}.json``, else ``grutrack evaluate``."""
    parts = path.parts
    if path.suffix == ".json" and len(parts) >= 5 and parts[-5:-3] == ("reports", "metrics"):
        exp, det, run = parts[-3], parts[-2], path.stem
        return (
            f"the workflow makes it: snakemake --cores 2 {path} (experiment {exp}, detections {det}, run {run}; "
            f"a real dataset's experiment needs its dataroot: README, The workflow)"
        )
    return f"grutrack evaluate writes it (--out {path})"
