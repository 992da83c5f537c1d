"""The paper's numbers (``workflow/config/paper.yaml``) and reading the matching numbers from a metrics JSON.

A table has ``columns`` (name -> metric path in a metrics JSON, scale to the paper's unit, tolerance) and
``rows`` (method -> column -> number). See the header of paper.yaml.
"""

from __future__ import annotations

from pathlib import Path

from grutrack.documents import MetricsDocument
from grutrack.errors import ConfigError

PACKAGE_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_PAPER = Path("workflow/config/paper.yaml")
ROW_INFO_KEYS = ("detector",)  # non-numeric keys a paper row may carry


def default_paper_path() -> Path:
    """workflow/config/paper.yaml of the working directory, else of the repository the package lives in."""
    for cand in (DEFAULT_PAPER, PACKAGE_ROOT / DEFAULT_PAPER):
        if cand.is_file():
            return cand
    raise ConfigError(f"no paper numbers found at {DEFAULT_PAPER} (run from the repository root or give --paper)")


def load_paper(path: str | Path | None = None) -> dict:
    """Read paper.yaml and check it against ``grutrack/configs/schemas/paper.schema.yaml`` (the one config
    loader), then that every row's numbers are columns of its table."""
    from grutrack.config_loader import load_config

    paper, source = load_config("paper", Path(path) if path else default_paper_path())
    for tid, table in paper["tables"].items():
        _check_table(source, tid, table)
    return paper


def _check_table(path: str, tid: str, table: dict) -> None:
    """Every column a row gives is a column of the table (what the schema cannot state)."""
    for row, values in table["rows"].items():
        for col in values:
            if col not in table["columns"] and col not in ROW_INFO_KEYS:
                raise ConfigError(
                    f"{path}: tables.{tid}.rows.{row} has column '{col}', not one of {', '.join(table['columns'])}"
                )


def get_table(paper: dict, tid: str) -> dict:
    """A paper table by its id (I, II, III, IV)."""
    if tid not in paper["tables"]:
        raise ConfigError(f"unknown paper table '{tid}' (known: {', '.join(paper['tables'])})")
    return paper["tables"][tid]


def get_row(table: dict, row: str | None) -> tuple[str, dict]:
    """(name, numbers) of a row; the table's default row when ``row`` is None."""
    name = row or table["default_row"]
    if name not in table["rows"]:
        raise ConfigError(f"{table['title']}: no row '{name}' (rows: {', '.join(table['rows'])})")
    return name, {k: v for k, v in table["rows"][name].items() if k not in ROW_INFO_KEYS}


def reproduced(table: dict, doc: MetricsDocument | None) -> dict[str, float | None]:
    """Every column of a table read from a metrics document, in the paper's unit (None: not available, or a
    per-class value of a class without ground truth, see :func:`absent_columns`)."""
    out = {}
    absent = absent_columns(table, doc)
    for col, spec in table["columns"].items():
        v = doc.value(spec["metric"]) if doc is not None and col not in absent else None
        out[col] = None if v is None else v * spec["scale"]
    return out


def absent_columns(table: dict, doc: MetricsDocument | None) -> set[str]:
    """The columns that read a per-class value of a class the document marks absent (no ground truth): shown as
    absent, never as a number, and not checked against the paper."""
    if doc is None:
        return set()
    return {col for col, spec in table["columns"].items() if doc.is_absent_path(spec["metric"])}
