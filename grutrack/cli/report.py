"""``grutrack report KIND``: a markdown report with PNG figures from metrics JSONs, training logs and
leaderboard zips, the paper's numbers (paper.yaml) beside the reproduced ones."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from grutrack.errors import ConfigError
from grutrack.io import write_text_atomic
from grutrack.report import KINDS


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``report``."""
    p = sub.add_parser(
        "report",
        help="write a report (paper tables beside reproduced numbers, PNG figures)",
        description="Write a markdown report and its PNG figures. Reproduced numbers are read from "
        "metrics JSONs (grutrack evaluate) and training logs, never recomputed; paper "
        "numbers come from paper.yaml and are labelled as such. Kinds: demo (synthetic "
        "demo; paper numbers for reference only), nusc_val (Tables III and IV), "
        "nusc_test (Table II and the leaderboard zips), av2_val (Table I), "
        "semi_supervised (training figure).",
    )
    p.add_argument("kind", choices=tuple(KINDS), help="report kind")
    p.add_argument("--out", required=True, help="markdown file to write")
    p.add_argument("--figures", default=None, help="folder for the PNG figures (default: <out dir>/figures/<name>)")
    p.add_argument("--paper", default=None, help="paper numbers (default: workflow/config/paper.yaml)")
    p.add_argument("--name", default=None, help="report name (default: the --out file name without suffix)")
    p.add_argument(
        "--experiment",
        default=None,
        help="NAME:DATASET:SPLIT:DETECTOR[:simulated] the runs belong to (simulated: the "
        "detections are SYNTHETIC, simulated from the ground truth; the report says so)",
    )
    p.add_argument("--run", action="append", default=[], metavar="RUN=METRICS_JSON", help="a run's metrics JSON")
    p.add_argument(
        "--row",
        action="append",
        default=[],
        metavar="TABLE:ROW=RUN",
        help="paper row reproduced by a run, e.g. III:Ours=grukf",
    )
    p.add_argument(
        "--extra-row",
        action="append",
        default=[],
        metavar="TABLE:ROW=RUN",
        help="a row that is not in the paper's table, shown reproduced only (e.g. Fast-Poly)",
    )
    p.add_argument("--train-log", action="append", default=[], metavar="LABEL=CSV", help="a train_log.csv")
    p.add_argument(
        "--run-training",
        action="append",
        default=[],
        metavar="RUN=LABEL",
        help="the training (a --train-log label) whose model.pt a GRU-KF run tracked with",
    )
    p.add_argument("--zip", action="append", default=[], metavar="DETECTOR=ZIP", help="a leaderboard zip")
    p.add_argument(
        "--render",
        action="append",
        default=[],
        metavar="RUN=COUNTS_JSON",
        help="a run's `grutrack render` folder (its counts.json): the report shows key frames of its worst scene",
    )
    p.add_argument(
        "--cross-check",
        default=None,
        metavar="RUN=CROSSCHECK_JSON",
        help="a run's `grutrack cross-check` JSON (devkit vs fast evaluator): the report states it",
    )
    p.set_defaults(func=run)


def _pairs(values: list[str], option: str) -> dict[str, str]:
    """``A=B`` arguments as a dict."""
    out = {}
    for v in values:
        key, sep, val = v.partition("=")
        if not sep or not key or not val:
            raise ConfigError(f"{option} expects KEY=VALUE, got '{v}'")
        out[key] = val
    return out


def _rows(values: list[str], option: str = "--row") -> dict[str, dict[str, str]]:
    """``TABLE:ROW=RUN`` arguments as {table: {row: run}}."""
    out: dict[str, dict[str, str]] = {}
    for v in values:
        left, sep, run_ = v.rpartition("=")
        tid, colon, row = left.partition(":")
        if not sep or not colon or not (tid and row and run_):
            raise ConfigError(f"{option} expects TABLE:ROW=RUN, got '{v}'")
        out.setdefault(tid, {})[row] = run_
    return out


def _experiment(value: str | None) -> dict | None:
    if value is None:
        return None
    parts = value.split(":")
    if len(parts) not in (4, 5) or (len(parts) == 5 and parts[4] != "simulated"):
        raise ConfigError(f"--experiment expects NAME:DATASET:SPLIT:DETECTOR[:simulated], got '{value}'")
    exp = dict(zip(("name", "dataset", "split", "detector"), parts))
    exp["simulated"] = len(parts) == 5
    return exp


def run(args: argparse.Namespace) -> int:
    """Build the report of the given kind and write it atomically."""
    from grutrack.report.inputs import ReportInputs
    from grutrack.report.paper import default_paper_path, load_paper

    out = Path(args.out)
    name = args.name or out.stem
    paper_path = args.paper or str(default_paper_path())
    inp = ReportInputs(
        name=name,
        out=out,
        figures=Path(args.figures or out.parent / "figures" / name),
        paper=load_paper(paper_path),
        paper_path=paper_path,
        experiment=_experiment(args.experiment),
        runs={k: Path(v) for k, v in _pairs(args.run, "--run").items()},
        rows=_rows(args.row),
        extra_rows=_rows(args.extra_row, "--extra-row"),
        train_logs={k: Path(v) for k, v in _pairs(args.train_log, "--train-log").items()},
        run_trainings=_pairs(args.run_training, "--run-training"),
        zips={k: Path(v) for k, v in _pairs(args.zip, "--zip").items()},
        renders={k: Path(v) for k, v in _pairs(args.render, "--render").items()},
        cross_check=next(
            ((k, Path(v)) for k, v in _pairs([args.cross_check] if args.cross_check else [], "--cross-check").items()),
            None,
        ),
    )
    unknown = sorted(set(inp.run_trainings.values()) - set(inp.train_logs))
    if unknown:
        raise ConfigError(f"--run-training: training '{unknown[0]}' has no --train-log")
    if inp.renders and "renders" not in KINDS[args.kind].reads:
        raise ConfigError(f"--render: a {args.kind} report shows no key frames ({KINDS[args.kind].no_renders})")
    inp.figures.mkdir(parents=True, exist_ok=True)
    text = importlib.import_module(KINDS[args.kind].module).build(inp)
    write_text_atomic(out, text)
    print(f"wrote {out} and its figures in {inp.figures}")
    return 0
