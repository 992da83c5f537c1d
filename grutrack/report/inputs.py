"""What a report reads: the metrics JSONs of its runs, which run reproduces which paper row, training logs
and leaderboard zips (all given on the command line by the workflow's report rule)."""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

from grutrack.errors import InputFormatError
from grutrack.report.paper import load_metrics


@dataclass
class ReportInputs:
    """Everything a report module needs; paths are as given (relative to the working directory)."""

    name: str
    out: Path
    figures: Path
    paper: dict
    paper_path: str
    experiment: dict | None = None                             # name, dataset, split, detector
    runs: dict[str, Path] = field(default_factory=dict)        # run -> metrics JSON
    rows: dict[str, dict[str, str]] = field(default_factory=dict)  # paper table -> paper row -> run
    train_logs: dict[str, Path] = field(default_factory=dict)  # label -> train_log.csv
    zips: dict[str, Path] = field(default_factory=dict)        # detector -> leaderboard zip
    renders: dict[str, Path] = field(default_factory=dict)     # run -> counts.json of its `grutrack render`
    _docs: dict | None = None

    def docs(self) -> dict[str, dict]:
        """Metrics JSON of every run (read once)."""
        if self._docs is None:
            self._docs = {run: load_metrics(p) for run, p in self.runs.items()}
        return self._docs

    def row_docs(self, tid: str) -> dict[str, dict]:
        """Paper row -> metrics JSON of the run that reproduces it."""
        docs = self.docs()
        out = {}
        for row, run in self.rows.get(tid, {}).items():
            if run not in docs:
                raise InputFormatError(f"table {tid} row '{row}' is mapped to run '{run}', which has no --run")
            out[row] = docs[run]
        return out


def read_train_log(path: str | Path) -> list[dict]:
    """Rows of a train_log.csv (numbers as floats, an empty val_amota as None)."""
    path = Path(path)
    try:
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
    except OSError as exc:
        raise InputFormatError(f"{path}: cannot read the training log ({exc})") from exc
    need = ("step", "epoch", "loss", "val_amota")
    if rows and any(k not in rows[0] for k in need):
        raise InputFormatError(f"{path}: a training log needs the columns {', '.join(need)}")
    out = []
    for r in rows:
        out.append({"step": int(r["step"]), "epoch": int(r["epoch"]), "loss": float(r["loss"]),
                    "val_amota": float(r["val_amota"]) if r["val_amota"] not in ("", None) else None,
                    "lr": float(r.get("lr") or "nan"), "seconds": float(r.get("seconds") or "nan")})
    return out
