"""Reproduced vs paper numbers under per-metric tolerances (``grutrack check``)."""

from __future__ import annotations

from dataclasses import dataclass

from grutrack.documents import ABSENT_TEXT, MetricsDocument
from grutrack.report.paper import absent_columns, get_row, reproduced


@dataclass(frozen=True)
class Comparison:
    """One metric of one row. ``absent``: the metric is a per-class value of a class without ground truth in the
    evaluated data (no number to compare; it neither passes nor fails)."""

    metric: str
    paper: float
    reproduced: float | None
    tolerance: float
    absent: bool = False

    @property
    def diff(self) -> float | None:
        return None if self.reproduced is None else self.reproduced - self.paper

    @property
    def ok(self) -> bool:
        return self.diff is not None and abs(self.diff) <= self.tolerance + 1e-9

    @property
    def failed(self) -> bool:
        """Out of tolerance or missing; an absent class is not a failure."""
        return not (self.ok or self.absent)

    @property
    def status(self) -> str:
        if self.absent:
            return ABSENT_TEXT
        return "ok" if self.ok else ("MISSING" if self.reproduced is None else "OUT OF TOLERANCE")


def compare(table: dict, doc: MetricsDocument, row: str | None = None) -> tuple[str, list[Comparison]]:
    """(row name, one comparison per column the paper reports for that row)."""
    name, numbers = get_row(table, row)
    values = reproduced(table, doc)
    absent = absent_columns(table, doc)
    return name, [
        Comparison(col, float(numbers[col]), values[col], float(table["columns"][col]["tolerance"]), col in absent)
        for col in table["columns"]
        if col in numbers
    ]


def _num(v: float | None, integer: bool, signed: bool = False) -> str:
    if v is None:
        return "n/a"
    if integer:
        return f"{v:+.0f}" if signed else f"{v:.0f}"
    return f"{v:+.2f}" if signed else f"{v:.2f}"


def format_comparisons(table: dict, comps: list[Comparison]) -> str:
    """A plain-text table: metric, paper, reproduced, difference, tolerance, status."""
    head = f"{'metric':<16}{'paper':>10}{'reproduced':>12}{'diff':>10}{'tolerance':>11}  status"
    lines = [head, "-" * len(head)]
    for c in comps:
        integer = table["columns"][c.metric]["scale"] == 1
        repro = "absent" if c.absent else _num(c.reproduced, integer)
        lines.append(
            f"{c.metric:<16}{_num(c.paper, integer):>10}{repro:>12}"
            f"{_num(c.diff, integer, True):>10}{'±' + _num(c.tolerance, integer):>11}  {c.status}"
        )
    return "\n".join(lines)
