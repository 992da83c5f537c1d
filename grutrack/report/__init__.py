"""Reports: the paper's tables (``workflow/config/paper.yaml``) beside reproduced numbers read from metrics
JSONs (never recomputed), figures as PNG, and the paper-vs-reproduced check. One module per report kind.

Adding a report: its module (``build(inputs) -> str``) and one :data:`KINDS` line saying what the workflow gives
it; the workflow config accepts the kind and the report rule gathers its inputs from that line.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ReportKind:
    """One report kind. ``module``: the module with ``build(inputs) -> str``; ``datasets``: the workflow dataset
    kinds its experiment may use (empty: the report has no experiment); ``reads``: what the report rule gives it,
    of ``runs`` (each run's metrics JSON and manifest: the experiment must be evaluated), ``trainings`` (the
    training logs of the experiment's GRU-KF runs, or of the report's own ``trainings`` map when it has no
    experiment, or its own ``trainings`` map when it has ``training_roles``), ``renders`` (each run's
    worst-scene frames) and ``zips`` (the leaderboard zips: the experiment must name its ``leaderboard_run``);
    ``training_roles``: the keys its ``trainings`` map must hold;
    ``no_renders``: why a report that does not read renders has none (for the error when one is given);
    ``optional_experiment``: the experiment may be left out (null)."""

    module: str
    datasets: tuple[str, ...]
    reads: tuple[str, ...]
    training_roles: tuple[str, ...] = ()
    no_renders: str = "it has no tracking run"
    optional_experiment: bool = False


#: report kind -> what it is
KINDS: dict[str, ReportKind] = {
    "demo": ReportKind("grutrack.report.demo", ("demo",), ("runs", "trainings", "renders")),
    "nusc_val": ReportKind("grutrack.report.nusc_val", ("nuscenes", "demo"), ("runs", "trainings", "renders")),
    "nusc_test": ReportKind(
        "grutrack.report.nusc_test",
        ("nuscenes", "demo"),
        ("zips",),
        no_renders="nuScenes test has no public ground truth",
    ),
    "av2_val": ReportKind("grutrack.report.av2_val", ("av2",), ("runs", "trainings", "renders")),
    # its experiment, when given, runs trackers without training on the validation split: reference lines
    "semi_supervised": ReportKind(
        "grutrack.report.semi_supervised",
        ("demo", "nuscenes"),
        ("trainings", "runs"),
        training_roles=("semi_supervised", "supervised"),
        optional_experiment=True,
    ),
}
