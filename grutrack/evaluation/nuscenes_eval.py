"""Official nuScenes tracking evaluation (nuscenes-devkit ``TrackingEval``, ``tracking_nips_2019``) for
standard and custom splits, and the metrics JSON every later stage reads.

The metrics JSON is a :class:`grutrack.documents.MetricsDocument` (``devkit_summary``: the devkit's
metrics_summary.json).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from pathlib import Path

from grutrack.classes import TRACKING_CLASSES
from grutrack.documents import MetricsDocument
from grutrack.errors import InputFormatError

#: metrics reported overall and per class, in the devkit's names
METRIC_KEYS = (
    "amota",
    "amotp",
    "recall",
    "motar",
    "gt",
    "mota",
    "motp",
    "mt",
    "ml",
    "faf",
    "tp",
    "fp",
    "fn",
    "ids",
    "frag",
    "tid",
    "lgd",
)


def devkit_tracking_eval(
    dataroot: str | Path,
    version: str,
    split: str,
    submission: str | Path,
    verbose: bool = False,
    progress: bool = False,
) -> dict:
    """Run the official ``TrackingEval`` and return the devkit's summary dict (metrics_summary.json).

    ``progress``: a bar on stderr through the devkit's stages (loading, filtering, one step per class), read
    from the devkit's own messages; the evaluation itself is the devkit's, unchanged.
    """
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking.evaluate import TrackingEval

    submission = Path(submission)
    if not submission.is_file():
        raise InputFormatError(f"{submission}: submission file does not exist")
    cfg = config_factory("tracking_nips_2019")
    with (
        tempfile.TemporaryDirectory(prefix="grutrack-eval-") as out_dir,
        _DevkitProgress(len(cfg.class_names), enabled=progress and not verbose) as bar,
    ):
        quiet = contextlib.ExitStack()
        if not verbose:  # the devkit prints and draws progress bars (stderr) even with verbose=False
            quiet.enter_context(contextlib.redirect_stdout(bar.sink if progress else io.StringIO()))
            quiet.enter_context(contextlib.redirect_stderr(io.StringIO()))
        with quiet:
            ev = TrackingEval(
                config=cfg,
                result_path=str(submission),
                eval_set=split,
                output_dir=out_dir,
                nusc_version=version,
                nusc_dataroot=str(dataroot),
                verbose=verbose or progress,
            )
            ev.main(render_curves=False)
        return json.loads((Path(out_dir) / "metrics_summary.json").read_text())


class _DevkitProgress:
    """A tqdm bar on the real stderr moved by the devkit's stdout messages (which are swallowed)."""

    #: devkit message prefix -> stage shown on the bar (in the order TrackingEval prints them)
    STAGES = (
        ("Loading NuScenes tables", "loading tables"),
        ("Loading annotations", "loading ground truth"),
        ("Filtering tracks", "filtering predictions"),
        ("Filtering ground truth", "filtering ground truth"),
        ("Accumulating metric data", "accumulating"),
    )

    def __init__(self, n_classes: int, enabled: bool):
        self.enabled, self.n_classes, self.bar = enabled, n_classes, None
        self.sink = _LineSink(self._line)

    def __enter__(self):
        if self.enabled:
            import sys

            from tqdm import tqdm

            self.bar = tqdm(
                total=len(self.STAGES) + self.n_classes, desc="devkit evaluation", unit="step", file=sys.stderr
            )
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.close()

    def _line(self, line: str) -> None:
        if self.bar is None:
            return
        for prefix, stage in self.STAGES:
            if line.startswith(prefix):
                self.bar.set_postfix_str(stage)
                self.bar.update(1)
                return
        if line.startswith("Computing metrics for class"):
            self.bar.set_postfix_str(line.split("class", 1)[1].strip(" .\n"))
            self.bar.update(1)


class _LineSink(io.TextIOBase):
    """A text stream that hands each complete line to ``on_line`` and keeps nothing else."""

    def __init__(self, on_line):
        super().__init__()
        self._on_line, self._buf = on_line, ""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self._buf += text
        *lines, self._buf = self._buf.split("\n")
        for line in lines:
            self._on_line(line)
        return len(text)


def metrics_from_summary(summary: dict) -> tuple[dict, dict]:
    """(overall, per_class) metric dicts from a devkit summary; NaN becomes None (valid JSON)."""
    overall = {k: _clean(summary.get(k)) for k in METRIC_KEYS}
    per_class = {
        c: {k: _clean(summary["label_metrics"].get(k, {}).get(c)) for k in METRIC_KEYS if k in summary["label_metrics"]}
        for c in TRACKING_CLASSES
    }
    return overall, per_class


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _clean_tree(obj):
    """A copy of a nested dict/list with non-finite floats replaced by None."""
    if isinstance(obj, dict):
        return {k: _clean_tree(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean_tree(v) for v in obj]
    return _clean(obj)


def metrics_document(
    summary: dict, *, dataset: str, version: str, split: str, evaluator: str, submission: str
) -> MetricsDocument:
    """The metrics document for a devkit-format summary."""
    overall, per_class = metrics_from_summary(summary)
    return MetricsDocument(
        dataset=dataset,
        version=version,
        split=split,
        evaluator=evaluator,
        submission=str(submission),
        overall=overall,
        per_class=per_class,
        devkit_summary=_clean_tree(summary),
    )


def format_summary(doc: MetricsDocument) -> str:
    """A human-readable table: overall AMOTA/AMOTP/MOTA/IDS/recall and the same per class."""
    counts = {"ids", "frag", "tp", "fp", "fn", "gt", "mt", "ml"}

    def fmt(v, col):
        if v is None:
            return "nan"
        return str(int(round(v))) if col in counts else f"{v:.3f}"  # the devkit gives counts as floats

    cols = ("amota", "amotp", "mota", "recall", "ids", "frag", "tp", "fp", "fn")
    lines = [f"{'class':<12}" + "".join(f"{c:>9}" for c in cols)]
    for name, m in [*doc.per_class.items(), ("OVERALL", doc.overall)]:
        lines.append(f"{name:<12}" + "".join(f"{fmt(m.get(c), c):>9}" for c in cols))
    return "\n".join(lines)
