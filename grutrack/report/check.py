"""Reproduced vs paper numbers under per-metric tolerances (``grutrack check``)."""

from __future__ import annotations

from dataclasses import dataclass

from grutrack.documents import MetricsDocument
from grutrack.report.paper import get_row, reproduced


@dataclass(frozen=True)
class Comparison:
    """One metric of one row."""

    metric: str
    paper: float
    reproduced: float | None
    tolerance: float

    @property
    def diff(self) -> float | None:
        return None if self.reproduced is None else self.reproduced - self.paper

    @property
    def ok(self) -> bool:
        return self.diff is not None and abs(self.diff) <= self.tolerance + 1e-9


def compare(table: dict, doc: MetricsDocument, row: str | None = None) -> tuple[str, list[Comparison]]:
    """(row name, one comparison per column the paper reports for that row)."""
    name, numbers = get_row(table, row)
    values = reproduced(table, doc)
    return name, [Comparison(col, float(numbers[col]), values[col], float(table["columns"][col]["tolerance"]))
                  for col in table["columns"] if col in numbers]


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
        status = "ok" if c.ok else ("MISSING" if c.reproduced is None else "OUT OF TOLERANCE")
        lines.append(f"{c.metric:<16}{_num(c.paper, integer):>10}{_num(c.reproduced, integer):>12}"
                     f"{_num(c.diff, integer, True):>10}{'±' + _num(c.tolerance, integer):>11}  {status}")
    return "\n".join(lines)
