"""The workflow's evaluator cross-check: nuscenes-devkit ``TrackingEval`` and the fast exact evaluator on the
same submission, every entry of their ``metrics_summary.json`` compared (equal to :data:`TOLERANCE`).

The devkit takes hours on a nuScenes-val-sized split where the fast evaluator takes seconds
(docs/results/valsize.md), so a cross-check of a large split scores a subset of its scenes: ``scenes`` of
them, evenly spaced over the split in its order (:func:`spread`). The subset is a custom split of a temporary
dataroot whose tables are links to the real ones (the devkit's own custom-split mechanism, ``splits.json``; the
user's dataroot is never written), and the submission is cut to the subset's samples. Both evaluators then run
unchanged, as ``grutrack evaluate`` runs them.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from grutrack.documents import CrossCheckDocument

#: the largest absolute difference of any metric entry the cross-check calls equal
TOLERANCE = 1e-9
#: top-level summary entries that legitimately differ between two evaluations of the same input
IGNORED = ("eval_time",)
#: the custom split the temporary dataroot defines
SUBSET_SPLIT = "grutrack_crosscheck"


def flatten(d: dict, prefix: str = "") -> dict[str, Any]:
    """Nested dicts as one dict with dotted keys (``label_metrics.amota.car``)."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        if isinstance(value, dict):
            out.update(flatten(value, prefix + str(key) + "."))
        else:
            out[prefix + str(key)] = value
    return out


def value_difference(a: Any, b: Any) -> float:
    """Absolute difference of two numbers (0 for NaN/NaN or None/None, inf for NaN/number); 0 or inf by ``==``
    otherwise (strings, booleans, lists)."""
    numbers = (int, float, np.number)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool) and not isinstance(b, bool):
        a, b = float(a), float(b)
        if math.isnan(a) or math.isnan(b):
            return 0.0 if math.isnan(a) and math.isnan(b) else math.inf
        return abs(a - b)
    return 0.0 if a == b else math.inf


def entry_differences(ref: dict, ours: dict) -> dict[str, float]:
    """Difference per flattened entry of two summaries with the same keys (:data:`IGNORED` left out).

    Raises ValueError naming the entries present in only one of them.
    """
    fr, fo = flatten(ref), flatten(ours)
    if set(fr) != set(fo):
        raise ValueError(f"different entries: {sorted(set(fr) ^ set(fo))}")
    return {k: value_difference(fr[k], fo[k]) for k in sorted(fr) if k not in IGNORED}


def spread(names: list[str], n: int | None) -> list[str]:
    """``n`` of ``names`` evenly spaced in their order (the first always in), or all of them for ``n`` None or
    at least ``len(names)``."""
    if n is None or n >= len(names):
        return list(names)
    idx = np.unique(np.floor(np.arange(n) * len(names) / n).astype(int))
    return [names[i] for i in idx]


def subset_dataroot(dataroot: str | Path, version: str, scenes: list[str], into: Path) -> Path:
    """A dataroot at ``into`` whose ``<version>/`` links every table of the real one and whose ``splits.json``
    adds the split :data:`SUBSET_SPLIT` = ``scenes`` to the real custom splits; ``maps`` linked too."""
    src = Path(dataroot) / version
    dst = into / version
    dst.mkdir(parents=True)
    splits = {}
    for f in src.iterdir():
        if f.name == "splits.json":
            splits = json.loads(f.read_text())
        else:
            os.symlink(f.resolve(), dst / f.name)
    splits[SUBSET_SPLIT] = list(scenes)
    (dst / "splits.json").write_text(json.dumps(splits))
    if (Path(dataroot) / "maps").exists():
        os.symlink((Path(dataroot) / "maps").resolve(), into / "maps")
    return into


def cross_check(
    dataroot: str | Path, version: str, split: str, submission: str | Path, scenes: int | None = None
) -> CrossCheckDocument:
    """Score ``submission`` (a tracking JSON of ``split``) with both nuScenes evaluators on ``scenes`` evenly
    spaced scenes of the split (None: all) and compare every summary entry."""
    from grutrack.data.nuscenes import split_scene_names
    from grutrack.datasets.base import DatasetOptions
    from grutrack.datasets.nuscenes import NuScenesDataset
    from grutrack.export.leaderboard import load_valid_submission

    full = NuScenesDataset(DatasetOptions(dataroot=dataroot, version=version))
    names = split_scene_names(full.tables, split)
    chosen = spread(names, scenes)
    sub = load_valid_submission(submission, full.sample_tokens(split))
    with tempfile.TemporaryDirectory(prefix="grutrack-crosscheck-") as tmp:
        root = subset_dataroot(dataroot, version, chosen, Path(tmp) / "root")
        ds = NuScenesDataset(DatasetOptions(dataroot=root, version=version))
        tokens = ds.sample_tokens(SUBSET_SPLIT)
        cut = Path(tmp) / "submission.json"
        cut.write_text(json.dumps({"meta": sub["meta"], "results": {t: sub["results"][t] for t in tokens}}))
        docs = {ev: ds.evaluate(cut, SUBSET_SPLIT, ev, progress=False) for ev in ("devkit", "fast")}
    diffs = entry_differences(docs["devkit"].devkit_summary, docs["fast"].devkit_summary)
    worst = max(diffs, key=diffs.get)
    return CrossCheckDocument(
        dataset="nuscenes",
        version=version,
        split=split,
        submission=str(submission),
        scenes=chosen,
        split_scenes=len(names),
        samples=len(tokens),
        entries=len(diffs),
        max_abs_difference=diffs[worst],
        worst_entry=worst,
        tolerance=TOLERANCE,
        equal=diffs[worst] <= TOLERANCE,
        amota={ev: d.overall.get("amota") for ev, d in docs.items()},
        seconds={ev: d.seconds for ev, d in docs.items()},
    )
