"""Bird's-eye renders of a tracking run with the evaluator's own decisions (true positive, false positive, miss,
id switch) drawn on the scene. :mod:`grutrack.render.views` joins the boxes with the decisions (numpy only);
:mod:`grutrack.render.draw` draws them (matplotlib, imported lazily); :mod:`grutrack.render.records` forms the
counts.json entries and, on request, the Rerun recordings (:mod:`grutrack.render.rerun_log`). Sits at the report
layer: it reads data and evaluation, nothing below imports it."""

from __future__ import annotations

import importlib
from pathlib import Path

#: dataset name (grutrack.datasets) -> its renderer, "module:function"; each replays its own evaluator's matching
RENDERERS: dict[str, str] = {
    "nuscenes": "grutrack.render.nuscenes:render_dataset",
    "av2": "grutrack.render.av2:render_dataset",
}


def render(dataset, split: str, submission: str | Path, out: str | Path, **options) -> dict:
    """Render the chosen scenes of a run on ``dataset`` (a :class:`grutrack.datasets.Dataset`) into ``out`` and
    write ``out/counts.json``; returns that document. ``options``: scene_names, worst, detections, animation,
    rerun, and the evaluator's settings (AV2: max_range_m, workers)."""
    from grutrack.errors import ConfigError

    if dataset.name not in RENDERERS:
        raise ConfigError(f"--dataset {dataset.name}: no renderer (available: {', '.join(RENDERERS)})")
    module, fn = RENDERERS[dataset.name].split(":")
    return getattr(importlib.import_module(module), fn)(dataset, split, submission, out, **options)
