"""Render a nuScenes tracking submission: load the split, run the fast exact evaluator's matching, pick scenes,
draw them and write ``counts.json``.

``counts.json``: ``{"dataset", "version", "split", "submission", "detections", "thresholds": {class: float|None},
"scenes": [{"name", "token", "animation", "errors", "frames": [{"index" (from 0), "frame" (from 1, as drawn),
"sample_token", "timestamp", "png", "ego": {"xy", "yaw"}, "totals": {tp, fp, fn, ids},
"per_class": {class: {tp, fp, fn, ids}}, "false_positives": [...], "missed": [...], "id_switches": [...]}]}],
"per_class": {class: {tp, fp, fn, ids}}}``. ``per_class`` sums the rendered frames; as in the metrics JSON, FP
and IDS are null for a class without an achieved threshold and every count is null for a class without ground
truth in the split.
"""

from __future__ import annotations

import time
from pathlib import Path

from grutrack.errors import InputFormatError
from grutrack.io import read_json, write_json_atomic
from grutrack.render.records import scene_record
from grutrack.render.views import COUNT_KEYS, FrameView, build_views, choose_scenes, scene_errors


def load_evaluation(dataroot: str, version: str, split: str, submission: str | Path):
    """(nusc, scenes with GT, submission results, MatchDecisions) of a split and a tracking submission.

    Raises InputFormatError / DatasetError (exit 2) for a missing or malformed submission, one of another
    split, or an unknown split.
    """
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.evaluation.nuscenes_fast import load_tracks, match_decisions

    nusc = open_nuscenes(dataroot, version)
    scenes = load_scenes(nusc, split, with_gt=True)
    doc = read_json(submission, "tracking submission")
    from grutrack.export.nuscenes_json import check_document

    check_document(doc, str(submission))  # the format's description, box by box (one line naming the field)
    results = doc["results"]
    tokens = {f.token for s in scenes for f in s.frames}
    missing, extra = tokens - set(results), set(results) - tokens
    if missing or extra:
        raise InputFormatError(
            f"{submission}: 'results' must hold exactly the {len(tokens)} samples of split "
            f"'{split}' ({len(missing)} missing, {len(extra)} from other splits)"
        )
    try:
        tracks_gt, tracks_pred, _ = load_tracks(nusc, doc, split)
        decisions, _ = match_decisions(tracks_gt, tracks_pred)
    except (AssertionError, KeyError, ValueError) as exc:
        why = str(exc) or type(exc).__name__
        raise InputFormatError(f"{submission}: the tracking evaluation rejects it ({why})") from exc
    return nusc, scenes, results, decisions


def select_scenes(scenes: list, decisions, names: list[str] | None, worst: int | None) -> list:
    """The scenes named (in the given order), or the ``worst`` scenes by id switches + FP + FN (ties: split
    order)."""
    return choose_scenes(scenes, names, worst, lambda: scene_errors(decisions), lambda s: s.token, "scene")


def sum_counts(views: list[FrameView], thresholds: dict, gt_classes: set) -> dict:
    """{class: {tp, fp, fn, ids}} summed over frames; None where the metrics JSON has no value."""
    out = {}
    for c, thr in thresholds.items():
        if c not in gt_classes:
            out[c] = dict.fromkeys(COUNT_KEYS)
            continue
        tot = {k: 0 for k in COUNT_KEYS}
        for v in views:
            for k in COUNT_KEYS:
                tot[k] += v.counts.get(c, {}).get(k) or 0
        if thr is None:
            tot["fp"] = tot["ids"] = None
        out[c] = tot
    return out


def render_nuscenes(
    dataroot: str,
    version: str,
    split: str,
    submission: str,
    out: str | Path,
    scene_names: list[str] | None = None,
    worst: int | None = None,
    detections: str | None = None,
    animation: bool = True,
    rerun: bool = False,
) -> dict:
    """Render the chosen scenes into ``out`` and write ``out/counts.json``; returns that document."""
    from grutrack.render.draw import TRAIL_FRAMES, BevCanvas, render_scene

    t_start = time.perf_counter()
    nusc, scenes, results, decisions = load_evaluation(dataroot, version, split, submission)
    chosen = select_scenes(scenes, decisions, scene_names, worst)
    det = None
    if detections:
        from grutrack.data.nusc_detections import load_detections

        det = load_detections(detections, [f.token for s in chosen for f in s.frames])
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    from grutrack.data.demo_defaults import is_demo_tables

    synthetic = is_demo_tables(nusc)
    banner = "SYNTHETIC: grutrack's demo dataset" if synthetic else ""
    canvas = BevCanvas(thresholds=decisions.thresholds, banner=banner)
    errors = scene_errors(decisions)
    all_views, scene_docs = [], []
    for scene in chosen:
        views = build_views(scene, results, decisions, det, trail_frames=TRAIL_FRAMES)
        pngs, gif = render_scene(views, out, decisions.thresholds, canvas, animation=animation)
        all_views += views
        scene_docs.append(scene_record(scene, errors.get(scene.token, 0), views, pngs, gif, out, rerun))
    gt_classes = {decisions.class_names[c] for c in set(decisions.g_cls.tolist())}
    doc = {
        "dataset": "nuscenes",
        "version": version,
        "synthetic": synthetic,  # the grutrack demo's scenes: every frame says SYNTHETIC under its title
        "split": split,
        "submission": str(submission),
        "detections": str(detections) if detections else None,
        "thresholds": decisions.thresholds,
        "matching": "fast exact nuScenes evaluator (tracking_nips_2019): per class at its best-MOTA "
        "threshold, 2 m centre distance",
        "scenes": scene_docs,
        "per_class": sum_counts(all_views, decisions.thresholds, gt_classes),
        "seconds": round(time.perf_counter() - t_start, 3),
    }
    write_json_atomic(out / "counts.json", doc, indent=1)
    return doc


def render_dataset(dataset, split: str, submission: str | Path, out: str | Path, **options) -> dict:
    """:func:`render_nuscenes` for a :class:`grutrack.datasets.nuscenes.NuScenesDataset` (evaluator settings
    of other datasets, e.g. ``workers``, do not apply and are ignored)."""
    keep = ("scene_names", "worst", "detections", "animation", "rerun")
    return render_nuscenes(
        dataset.options.dataroot,
        dataset.options.version,
        split,
        submission,
        out,
        **{k: v for k, v in options.items() if k in keep},
    )
