"""Report of the training ablation (``reports/semi_supervised.md``): validation AMOTA against training step for
a semi-supervised and a supervised run (their train_log.csv), beside what the paper's figure shows."""

from __future__ import annotations

from grutrack.report import figures
from grutrack.documents import TrainingLog, TrainingStep
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import DASH, header, image, table, training_provenance


#: the y axis of the AMOTA figure spans at least this much, so that a flat curve looks flat
MIN_AMOTA_SPAN = 0.1


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    logs = {label: TrainingLog.read(p).steps for label, p in inp.train_logs.items()}
    paper = inp.paper.get("figures", {}).get("semi_supervised", {})
    parts = [header("Semi-supervised vs supervised training of the GRU-KF",
                    ["Validation AMOTA is the one logged by `grutrack train` (`val_amota` of train_log.csv, "
                     "official semantics). The paper's figure is on real nuScenes; the runs here were trained on "
                     "the data in the \"trained on\" column under Provenance (the SYNTHETIC demo by default), so "
                     "the curves show the method's behaviour, not the paper's values."],
                    source="the training logs (train_log.csv) written by `grutrack train`")]
    parts += ["", "## Validation AMOTA against step", "", _figure(inp, logs), "",
              "## Summary", "", _summary(logs), "",
              "## What the paper reports (**paper numbers**, nuScenes)", "", _paper(paper),
              "", "## Provenance", "", training_provenance(inp.train_logs)]
    return "\n".join(parts) + "\n"


def _validated(rows: list[TrainingStep]) -> list[TrainingStep]:
    return [r for r in rows if r.val_amota is not None]


def _figure(inp: ReportInputs, logs: dict[str, list[TrainingStep]]) -> str:
    series = {label: ([r.step for r in _validated(rows)], [r.val_amota for r in _validated(rows)])
              for label, rows in logs.items()}
    path = figures.lines(inp.figures / "val_amota_vs_step.png", series, "Validation AMOTA against training step",
                         "step (one optimizer step per scene)", "validation AMOTA", min_span=MIN_AMOTA_SPAN)
    return image(path, inp.out.parent, "validation AMOTA against step")


def first_step_within(rows: list[TrainingStep], fraction: float = 0.99) -> int | None:
    """First logged step whose validation AMOTA reaches ``fraction`` of the best logged one."""
    val = _validated(rows)
    if not val:
        return None
    best = max(r.val_amota for r in val)
    return next(r.step for r in val if r.val_amota >= fraction * best)


def _summary(logs: dict[str, list[TrainingStep]]) -> str:
    rows = []
    for label, log in logs.items():
        val = _validated(log)
        best = max(val, key=lambda r: r.val_amota) if val else None
        rows.append([label, str(log[-1].step) if log else DASH, str(log[-1].epoch + 1) if log else DASH,
                     f"{val[-1].val_amota:.3f}" if val else DASH,
                     f"{best.val_amota:.3f} (step {best.step})" if best else DASH,
                     str(first_step_within(log) or DASH)])
    return table(["training", "steps", "epochs", "last val AMOTA", "best val AMOTA", "first step ≥ 99 % of best"],
                 rows)


def _paper(paper: dict) -> str:
    rows = []
    for label in ("semi_supervised", "supervised"):
        p = paper.get(label) or {}
        rows.append([label, str(p.get("converged_step") or DASH), str(p.get("converged_epochs") or DASH),
                     str(p.get("amota") or DASH), p.get("text", DASH)])
    return table(["training", "converged at step", "epochs", "AMOTA", "paper says"], rows, "lrrrl")
