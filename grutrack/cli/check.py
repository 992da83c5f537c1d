"""``grutrack check METRICS.json --table III``: reproduced vs paper numbers under the tolerances of paper.yaml;
exits 1 when a number is out of tolerance or missing. A per-class number of a class without ground truth in the
evaluated data (marked absent in the metrics JSON) is shown absent and not checked."""

from __future__ import annotations

import argparse


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


def run(args: argparse.Namespace) -> int:
    """Print the comparison; 0 when every metric is within tolerance, else 1."""
    from grutrack.documents import MetricsDocument
    from grutrack.report.check import compare, format_comparisons
    from grutrack.report.paper import get_table, load_paper

    table = get_table(load_paper(args.paper), args.table)
    doc = MetricsDocument.read(args.metrics)
    row, comps = compare(table, doc, args.row)
    print(f"{table['title']}; paper row '{row}'")
    print(
        f"reproduced: {args.metrics} ({doc.dataset or '?'} {doc.version or ''} {doc.split or '?'})".replace("  ", " ")
    )
    if (doc.dataset, doc.split) != (table.get("dataset"), table.get("split")):
        print(f"note: the paper's table is {table.get('dataset')} {table.get('split')}; the metrics are not")
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
