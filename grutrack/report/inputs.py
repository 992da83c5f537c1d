"""What a report reads: the metrics JSONs of its runs, which run reproduces which paper row, training logs
and leaderboard zips (all given on the command line by the workflow's report rule)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from grutrack.documents import CrossCheckDocument, MetricsDocument
from grutrack.errors import InputFormatError


@dataclass
class ReportInputs:
    """Everything a report module needs; paths are as given (relative to the working directory)."""

    name: str
    out: Path
    figures: Path
    paper: dict
    paper_path: str
    experiment: dict | None = None  # name, dataset, split, detector
    runs: dict[str, Path] = field(default_factory=dict)  # run -> metrics JSON
    rows: dict[str, dict[str, str]] = field(default_factory=dict)  # paper table -> paper row -> run
    extra_rows: dict[str, dict[str, str]] = field(default_factory=dict)  # paper table -> row not in it -> run
    train_logs: dict[str, Path] = field(default_factory=dict)  # label -> train_log.csv
    run_trainings: dict[str, str] = field(default_factory=dict)  # GRU-KF run -> the train_logs label of its model
    zips: dict[str, Path] = field(default_factory=dict)  # detector -> leaderboard zip
    renders: dict[str, Path] = field(default_factory=dict)  # run -> counts.json of its `grutrack render`
    cross_check: tuple[str, Path] | None = None  # (run, its `grutrack cross-check` JSON)
    _docs: dict | None = None

    def cross_check_doc(self) -> tuple[str | None, CrossCheckDocument | None]:
        """(run, cross-check document) when the report was given one, else (None, None)."""
        if self.cross_check is None:
            return None, None
        run, path = self.cross_check
        return run, CrossCheckDocument.read(path)

    def docs(self) -> dict[str, MetricsDocument]:
        """Metrics document of every run (read once)."""
        if self._docs is None:
            self._docs = {run: MetricsDocument.read(p) for run, p in self.runs.items()}
        return self._docs

    def row_docs(self, tid: str, extra: bool = False) -> dict[str, MetricsDocument]:
        """Paper row -> metrics JSON of the run that reproduces it (``extra``: the rows not in the paper)."""
        docs = self.docs()
        out = {}
        for row, run in (self.extra_rows if extra else self.rows).get(tid, {}).items():
            if run not in docs:
                raise InputFormatError(f"table {tid} row '{row}' is mapped to run '{run}', which has no --run")
            out[row] = docs[run]
        return out
