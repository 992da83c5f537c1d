"""Entry-by-entry comparison of two metrics summaries (evaluator parity checks: the fast evaluator against the
devkit's ``metrics_summary.json``), shared by the parity tests and the evaluation benchmark: the toolkit's own
(``grutrack cross-check`` uses it)."""

from grutrack.evaluation.crosscheck import IGNORED, entry_differences, flatten, value_difference

__all__ = ["IGNORED", "entry_differences", "flatten", "value_difference"]
