"""Report of the training ablation (``reports/semi_supervised.md``): validation AMOTA against training step for
semi-supervised and supervised runs (their train_log.csv), beside what the paper's figure shows.

Trainings labelled ``<mode>`` and ``<mode>_<n>`` (``semi_supervised``, ``semi_supervised_2``, ...) are runs of one
mode with other seeds: the report gives each run, and per mode the mean and spread over its runs of the final
validation AMOTA and of the first step reaching 99 % of it, a figure of the mean with the min-max band, and the
validation points of every run as CSV."""

from __future__ import annotations

import re
import statistics

from grutrack.documents import TrainingLog, TrainingStep, ValidationRecord
from grutrack.io import write_text_atomic
from grutrack.report import figures
from grutrack.report.inputs import ReportInputs
from grutrack.report.markdown import DASH, header, image, table, training_provenance

#: the y axis of the AMOTA figure spans at least this much, so that a flat curve looks flat
MIN_AMOTA_SPAN = 0.1


def build(inp: ReportInputs) -> str:
    """The markdown text (figures are written into ``inp.figures``)."""
    logs = {label: TrainingLog.read(p).steps for label, p in inp.train_logs.items()}
    paper = inp.paper.get("figures", {}).get("semi_supervised", {})
    parts = [
        header(
            "Semi-supervised vs supervised training of the GRU-KF",
            [
                "Validation AMOTA is the one logged by `grutrack train` (`val_amota` of train_log.csv, "
                "official semantics). The paper's figure is on real nuScenes; the runs here were trained on "
                "the data in the \"trained on\" column under Provenance (the SYNTHETIC demo by default), so "
                "the curves show the method's behaviour, not the paper's values."
            ],
            source="the training logs (train_log.csv) written by `grutrack train`",
        )
    ]
    groups = _groups(logs)
    refs = _references(inp)
    parts += ["", "## Validation AMOTA against step", "", _figure(inp, logs, refs), ""]
    if refs:
        parts += [
            "Reference lines: AMOTA of trackers without training on the same validation scenes and "
            "detections (" + ", ".join(f"{k} {v:.4f}" for k, v in refs.items()) + ").",
            "",
        ]
    if any(len(g) > 1 for g in groups.values()):
        parts += [_band_figure(inp, logs, groups, refs), "", "## Across seeds", "", _across(logs, groups), ""]
    csv_path = _csv(inp, logs, groups)
    parts += [
        f"Every validation point: [{csv_path.name}]({_relative(csv_path, inp.out.parent)}).",
        "",
        "## Summary",
        "",
        _summary(logs),
        "",
        "## What the paper reports (**paper numbers**, nuScenes)",
        "",
        _paper(paper),
        "",
        "## Provenance",
        "",
        training_provenance(inp.train_logs),
    ]
    return "\n".join(parts) + "\n"


def _validated(rows: list[TrainingStep]) -> list[TrainingStep]:
    return [r for r in rows if r.val_amota is not None]


def _references(inp: ReportInputs) -> dict[str, float]:
    """Label -> AMOTA of the report's experiment runs (trackers without training on the validation split), and
    of each training's own reference (``reference_amota`` of the validation.json beside its train_log.csv: the
    tracker preset's EKF on the same validation scenes and detection sets; trainings sharing a value share a
    line)."""
    refs = {run: float(doc.overall["amota"]) for run, doc in inp.docs().items() if doc.overall.get("amota") is not None}
    by_value: dict[float, list[str]] = {}
    for label, log in inp.train_logs.items():
        path = log.parent / "validation.json"
        record = ValidationRecord.read(path) if path.is_file() else None
        if record is not None and record.reference_amota is not None:
            by_value.setdefault(round(float(record.reference_amota), 6), []).append(label)
    for value, labels in by_value.items():
        refs[f"EKF on the validation of {', '.join(labels)}"] = value
    return refs


def _figure(inp: ReportInputs, logs: dict[str, list[TrainingStep]], refs: dict[str, float]) -> str:
    series = {
        label: ([r.step for r in _validated(rows)], [r.val_amota for r in _validated(rows)])
        for label, rows in logs.items()
    }
    path = figures.lines(
        inp.figures / "val_amota_vs_step.png",
        series,
        "Validation AMOTA against training step",
        "step (one optimizer step per scene)",
        "validation AMOTA",
        hlines=refs,
        min_span=MIN_AMOTA_SPAN,
    )
    return image(path, inp.out.parent, "validation AMOTA against step")


def _groups(logs: dict[str, list[TrainingStep]]) -> dict[str, list[str]]:
    """Mode -> its trainings (``semi_supervised`` and ``semi_supervised_2`` are one mode, other seeds)."""
    out: dict[str, list[str]] = {}
    for label in logs:
        out.setdefault(re.sub(r"_\d+$", "", label), []).append(label)
    return out


def _csv(inp: ReportInputs, logs: dict[str, list[TrainingStep]], groups: dict[str, list[str]]):
    """``val_amota_vs_step.csv`` beside the figures: training, mode, step, epoch, val_amota."""
    path = inp.figures / "val_amota_vs_step.csv"
    mode_of = {label: mode for mode, labels in groups.items() for label in labels}
    lines = ["training,mode,step,epoch,val_amota"]
    lines += [
        f"{label},{mode_of[label]},{r.step},{r.epoch},{r.val_amota}"
        for label, rows in logs.items()
        for r in _validated(rows)
    ]
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


def _relative(path, base) -> str:
    """``path`` relative to ``base`` when below it, else as given (a link in the markdown)."""
    from pathlib import Path

    try:
        return Path(path).resolve().relative_to(Path(base).resolve()).as_posix()
    except ValueError:
        return Path(path).as_posix()


def _band_figure(
    inp: ReportInputs, logs: dict[str, list[TrainingStep]], groups: dict[str, list[str]], refs: dict[str, float]
) -> str:
    """Mean validation AMOTA of each mode's runs with their min-max band, at the steps every run logged."""
    data = {}
    for mode, labels in groups.items():
        per = [{r.step: r.val_amota for r in _validated(logs[label])} for label in labels]
        steps = sorted(set.intersection(*(set(p) for p in per))) if per else []
        if not steps:
            continue
        vals = [[p[s] for p in per] for s in steps]
        data[f"{mode} ({len(labels)} runs)"] = (
            steps,
            [statistics.fmean(v) for v in vals],
            [min(v) for v in vals],
            [max(v) for v in vals],
        )
    path = figures.bands(
        inp.figures / "val_amota_vs_step_seeds.png",
        data,
        "Validation AMOTA against step: mean and min-max over seeds",
        "step",
        "validation AMOTA",
        min_span=MIN_AMOTA_SPAN,
        hlines=refs,
    )
    return image(path, inp.out.parent, "validation AMOTA against step, mean and spread over seeds")


def first_step_reaching(rows: list[TrainingStep], fraction: float = 0.99) -> int | None:
    """First logged step whose validation AMOTA reaches ``fraction`` of the final (last logged) one."""
    val = _validated(rows)
    if not val:
        return None
    final = val[-1].val_amota
    return next(r.step for r in val if r.val_amota >= fraction * final)


def _mean_spread(values: list[float], fmt: str) -> str:
    if not values:
        return DASH
    if len(values) == 1:
        return fmt.format(values[0])
    return (
        f"{fmt.format(statistics.fmean(values))} ± {fmt.format(statistics.stdev(values))} "
        f"({fmt.format(min(values))}–{fmt.format(max(values))})"
    )


def _across(logs: dict[str, list[TrainingStep]], groups: dict[str, list[str]]) -> str:
    """Per mode: runs, final validation AMOTA and first step reaching 99 % of it, mean ± standard deviation
    (min–max) over the runs."""
    rows = []
    for mode, labels in groups.items():
        finals = [_validated(logs[lb])[-1].val_amota for lb in labels if _validated(logs[lb])]
        steps = [float(s) for s in (first_step_reaching(logs[lb]) for lb in labels) if s is not None]
        rows.append([mode, str(len(labels)), _mean_spread(finals, "{:.4f}"), _mean_spread(steps, "{:.0f}")])
    return table(["mode", "runs", "final val AMOTA: mean ± sd (min–max)", "first step ≥ 99 % of final"], rows)


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
        rows.append(
            [
                label,
                str(log[-1].step) if log else DASH,
                str(log[-1].epoch + 1) if log else DASH,
                f"{val[-1].val_amota:.3f}" if val else DASH,
                f"{best.val_amota:.3f} (step {best.step})" if best else DASH,
                _step_text(first_step_within(log)),
            ]
        )
    return table(["training", "steps", "epochs", "last val AMOTA", "best val AMOTA", "first step ≥ 99 % of best"], rows)


def _step_text(step: int | None) -> str:
    """A step number (0: the network before training, validated first), or a dash when there is none."""
    return DASH if step is None else str(step)


def _paper(paper: dict) -> str:
    rows = []
    for label in ("semi_supervised", "supervised"):
        p = paper.get(label) or {}
        rows.append(
            [
                label,
                str(p.get("converged_step") or DASH),
                str(p.get("converged_epochs") or DASH),
                str(p.get("amota") or DASH),
                p.get("text", DASH),
            ]
        )
    return table(["training", "converged at step", "epochs", "AMOTA", "paper says"], rows, "lrrrl")
