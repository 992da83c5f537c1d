"""Official Argoverse 2 tracking evaluation (``av2.evaluation.tracking.eval.evaluate``: HOTA objective, TrackEval
HOTA + CLEAR, 50 m range, drivable-area ROI when every log has its map) and the metrics JSON.

What the wrapper adds around the official function, without changing its numbers:

- the labels are built from the split's ``annotations.feather`` at the evaluated rate (all 26 competition
  categories, city frame) and the submission is checked first to hold exactly those frames, so the evaluator's
  frame-equality assertion cannot fire; logs are given in the order the evaluator regroups them;
- its score-threshold tuning pool follows ``workers`` (default: the cores this process may run on,
  ``os.sched_getaffinity``) instead of ``multiprocessing.cpu_count()``; one worker runs in-process;
- TrackEval's side outputs (per-class summary / detailed files, PDF/PNG curves, console tables) are switched
  off, or written under ``trackeval_dir`` when given; nothing is written to the working directory;
- the drivable-area filter is given only frames that hold boxes (the official one fails on an empty frame,
  e.g. a log without tracks; an empty frame has nothing to filter);
- the map / pose loader is remembered for the second of its two identical calls (labels, then tracks);
- IDF1 (TrackEval's Identity metric) is computed on exactly the labels and score-filtered tracks that the
  official final evaluation scores (the official function computes HOTA and CLEAR only);
- on request (``keep_inputs``), those labels and score-filtered tracks and the tuned per-class score thresholds
  are handed back, so that the final CLEAR matching can be replayed frame by frame
  (:mod:`grutrack.evaluation.clear_frames`).

Metrics JSON (same top level as the nuScenes one): ``{"dataset": "av2", "version", "split", "evaluator",
"submission", "overall", "per_class", ...}``. ``per_class[category]`` holds ``hota``, ``mota``, ``idf1`` (final
evaluation at the tuned per-class score threshold), ``hota_tuned`` / ``hota_mean`` (the official function's
tuned and recall-averaged values), the final CLEAR counts ``tp`` / ``fp`` / ``fn`` / ``ids`` (CLR_TP, CLR_FP,
CLR_FN, IDSW; ``idsw`` repeats ``ids``), ``gt_boxes`` and ``present``. ``overall`` holds the Table I average over the
7 classes of Table I (absent classes count as 0, as the official evaluator scores them), never over 26, and the
average over the Table I classes present in the ground truth.
"""

from __future__ import annotations

import contextlib
import copy
import io
import multiprocessing
import os
import tempfile
import time
import types
from pathlib import Path
from unittest import mock

import numpy as np

from grutrack.data.av2 import COMPETITION_CATEGORIES, TABLE_I_CLASSES, load_scenes, split_dir, vocabulary
from grutrack.errors import DatasetError
from grutrack.export.av2_tracks import expected_frames, gt_sequences, read_tracks_pickle, validate_sequences
from grutrack.documents import MetricsDocument

EVALUATOR = "av2.evaluation.tracking.eval.evaluate (HOTA objective)"
DEFAULT_RANGE_M = 50


def default_workers() -> int:
    """The number of cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


class _SerialPool:
    """A stand-in for ``multiprocessing.Pool`` that runs ``imap`` in this process (one worker)."""

    def __init__(self, *args, **kwargs):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def imap(self, fn, iterable):
        return map(fn, iterable)


def has_maps(dataset_dir: Path, log_ids: list[str]) -> bool:
    """Whether every log has the vector map and raster files the drivable-area ROI needs."""
    def ok(log: str) -> bool:
        m = dataset_dir / log / "map"
        return (any(m.glob("log_map_archive_*.json")) and any(m.glob("*img_Sim2_city.json"))
                and any(m.glob("*ground_height_surface*.npy")))
    return all(ok(lg) for lg in log_ids)


def _identity_tap(original, idf1_out: dict, inputs_out: dict | None = None):
    """``evaluate_tracking`` that also computes TrackEval's Identity metric (IDF1) on the same inputs, and keeps
    those inputs (labels, score-filtered tracks) in ``inputs_out`` when given."""
    import trackeval

    from av2.evaluation.tracking.eval import TrackEvalDataset

    def tapped(labels, track_predictions, classes, tracker_name, output_dir, iou_threshold=0.5):
        if inputs_out is not None:
            inputs_out.update(labels=labels, predictions=track_predictions, classes=list(classes),
                              similarity_threshold=float(iou_threshold))
        res = original(labels, track_predictions, classes, tracker_name, output_dir, iou_threshold)
        cfg = {**TrackEvalDataset.get_default_dataset_config(), "GT_TRACKS": {tracker_name: labels},
               "PREDICTED_TRACKS": {tracker_name: track_predictions}, "SEQ_IDS_TO_EVAL": list(labels.keys()),
               "CLASSES_TO_EVAL": classes, "TRACKERS_TO_EVAL": [tracker_name], "OUTPUT_FOLDER": output_dir}
        ev = trackeval.Evaluator({**_quiet_eval_config(), "TIME_PROGRESS": False})
        with contextlib.redirect_stdout(io.StringIO()):
            ident, _ = ev.evaluate([TrackEvalDataset(cfg)],
                                   [trackeval.metrics.Identity({"THRESHOLD": iou_threshold, "PRINT_CONFIG": False})])
        combined = ident["TrackEvalDataset"][tracker_name]["COMBINED_SEQ"]
        idf1_out.update({c: float(combined[c]["Identity"]["IDF1"]) for c in classes})
        return res

    return tapped


def _quiet_eval_config() -> dict:
    """TrackEval evaluator settings with every file and console output off (numbers unaffected)."""
    import trackeval

    return {**trackeval.Evaluator.get_default_eval_config(), "PRINT_RESULTS": False, "PRINT_CONFIG": False,
            "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False}


def _memoised(load):
    """The official map / pose loader, remembered per (logs, folder): it is called once for the labels and once
    for the tracks with the same logs (the maps are read-only there)."""
    cache: dict = {}

    def cached(log_ids, dataset_dir):
        key = (tuple(log_ids), str(dataset_dir))
        if key not in cache:
            cache[key] = load(log_ids, dataset_dir)
        return cache[key]

    return cached


def _skip_empty_frames(filter_roi):
    """The official drivable-area filter, given only frames that hold boxes: it cannot build the box array of
    an empty frame (a (0,) quaternion array), and an empty frame has nothing to filter, so the result is the
    same. Frames are filtered in place, as the official function does."""
    def filtered(tracks, dataset_dir):
        if dataset_dir is None:
            return tracks
        held = {lg: [f for f in frames if len(f["translation_m"])] for lg, frames in tracks.items()}
        held = {lg: frames for lg, frames in held.items() if frames}
        if held:
            filter_roi(held, dataset_dir)
        return tracks

    return filtered


def _threshold_tap(original, inputs_out: dict):
    """The official score-threshold tuning, its per-class thresholds kept in ``inputs_out["thresholds"]``."""
    def tapped(*args, **kwargs):
        out = original(*args, **kwargs)
        inputs_out["thresholds"] = {c: float(t) for c, t in out[0].items()}
        return out

    return tapped


@contextlib.contextmanager
def _official_settings(workers: int, quiet: bool, idf1_out: dict, inputs_out: dict | None = None):
    """Patches scoped to one call: worker count, TrackEval side outputs, the IDF1 tap, the input taps."""
    import trackeval

    import av2.evaluation.tracking.eval as official

    pool = _SerialPool if workers == 1 else multiprocessing.Pool
    shim = types.SimpleNamespace(cpu_count=lambda: workers, Pool=pool)
    with contextlib.ExitStack() as stack:
        stack.enter_context(mock.patch.object(official, "mp", shim))
        stack.enter_context(mock.patch.object(official, "evaluate_tracking",
                                              _identity_tap(official.evaluate_tracking, idf1_out, inputs_out)))
        if inputs_out is not None:
            stack.enter_context(mock.patch.object(official, "_tune_score_thresholds",
                                                  _threshold_tap(official._tune_score_thresholds, inputs_out)))
        stack.enter_context(mock.patch.object(official, "load_mapped_avm_and_egoposes",
                                              _memoised(official.load_mapped_avm_and_egoposes)))
        stack.enter_context(mock.patch.object(official, "filter_drivable_area",
                                              _skip_empty_frames(official.filter_drivable_area)))
        if quiet:
            cfg = _quiet_eval_config()
            stack.enter_context(mock.patch.object(trackeval.Evaluator, "get_default_eval_config",
                                                  staticmethod(lambda: dict(cfg))))
        yield official


def evaluate_sequences(predictions: dict, labels: dict, dataset_dir: str | Path | None, *,
                       max_range_m: int = DEFAULT_RANGE_M, workers: int | None = None,
                       trackeval_dir: str | Path | None = None, verbose: bool = False,
                       keep_inputs: bool = False) -> dict:
    """Run the official evaluation on in-memory sequences.

    predictions / labels: ``{log_id: [frame, ...]}`` (the pickle layout), same frames. dataset_dir: the split
    folder (enables the ROI filter) or None. Returns ``{"result": TrackEval's result tree, "tuned": {class: HOTA},
    "mean": {class: HOTA}, "idf1": {class: IDF1}}``; with ``keep_inputs`` also ``"final"``: ``{"labels",
    "predictions"}`` (what the final HOTA / CLEAR evaluation scored: range- and ROI-filtered labels, tracks also
    filtered by the tuned thresholds), ``"classes"``, ``"similarity_threshold"`` and ``"thresholds"``
    ({class: tuned score threshold}).
    """
    # the official function regroups the labels by first timestamp (a stable sort) and then pairs prediction and
    # label frames by position: give both in that order
    order = sorted(labels, key=lambda lg: labels[lg][0]["timestamp_ns"] if labels[lg] else 0)
    labels = copy.deepcopy({lg: labels[lg] for lg in order})
    predictions = copy.deepcopy({lg: predictions[lg] for lg in order})
    workers = max(1, int(workers or default_workers()))
    if dataset_dir is not None:
        dataset_dir = Path(dataset_dir).resolve()      # the evaluation runs in another working directory
    idf1: dict = {}
    final: dict | None = {} if keep_inputs else None
    with tempfile.TemporaryDirectory(prefix="grutrack-av2-eval-") as tmp:
        out_root = Path(trackeval_dir).resolve() if trackeval_dir else Path(tmp)
        out_root.mkdir(parents=True, exist_ok=True)
        sink = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
        errsink = contextlib.nullcontext() if verbose else contextlib.redirect_stderr(io.StringIO())
        with _official_settings(workers, quiet=trackeval_dir is None, idf1_out=idf1, inputs_out=final) as official, \
                contextlib.chdir(out_root), sink, errsink:
            # the official function writes under ".".join(out.split("/")[:-1]), relative to the working dir
            res, tuned, mean = official.evaluate(predictions, labels, "HOTA", int(max_range_m),
                                                 None if dataset_dir is None else str(dataset_dir),
                                                 "trackeval/metrics.json")
    out = {"result": res, "tuned": tuned, "mean": mean, "idf1": idf1}
    if final is not None:
        out["final"] = final
    return out


def metrics_from_result(out: dict) -> tuple[dict, dict]:
    """(overall, per_class) from :func:`evaluate_sequences` output; see the module docstring."""
    combined = out["result"]["TrackEvalDataset"]["TRACKER"]["COMBINED_SEQ"]
    per_class = {}
    for c in COMPETITION_CATEGORIES:
        m = combined[c]
        gt = int(m["CLEAR"]["CLR_TP"] + m["CLEAR"]["CLR_FN"])
        per_class[c] = {"hota": float(np.mean(m["HOTA"]["HOTA"])), "mota": float(m["CLEAR"]["MOTA"]),
                        "idf1": float(out["idf1"].get(c, 0.0)), "hota_tuned": float(out["tuned"][c]),
                        "hota_mean": float(out["mean"][c]), "detA": float(np.mean(m["HOTA"]["DetA"])),
                        "assA": float(np.mean(m["HOTA"]["AssA"])), "idsw": int(m["CLEAR"]["IDSW"]),
                        "tp": int(m["CLEAR"]["CLR_TP"]), "fp": int(m["CLEAR"]["CLR_FP"]),
                        "fn": int(m["CLEAR"]["CLR_FN"]), "ids": int(m["CLEAR"]["IDSW"]),
                        "gt_boxes": gt, "present": gt > 0}
    present = [c for c in TABLE_I_CLASSES if per_class[c]["present"]]
    overall = {f"{k}": float(np.mean([per_class[c][k] for c in TABLE_I_CLASSES])) for k in ("hota", "mota", "idf1")}
    overall.update({f"{k}_present": (float(np.mean([per_class[c][k] for c in present])) if present else None)
                    for k in ("hota", "mota", "idf1")})
    overall.update({"classes": list(TABLE_I_CLASSES), "present_classes": present})
    return overall, per_class


def metrics_document(out: dict, *, split: str, submission: str, rate_hz: float | None, max_range_m: int,
                     roi: bool, workers: int) -> MetricsDocument:
    """The AV2 metrics document."""
    overall, per_class = metrics_from_result(out)
    return MetricsDocument(
        dataset="av2", version="sensor", split=split, evaluator=EVALUATOR, submission=str(submission),
        overall=overall, per_class=per_class,
        settings={"rate_hz": rate_hz, "max_range_m": int(max_range_m), "drivable_area_roi": bool(roi),
                  "objective": "HOTA", "workers": int(workers),
                  "average": "Table I: mean over the 7 Table I classes (absent classes score 0)"})


def load_submission(root: str | Path, split: str, submission: str | Path, *, rate_hz: float | None = 2.0,
                    roi: bool | None = None) -> tuple[list, dict, dict, Path, bool]:
    """What the evaluation of a tracking pickle reads: (scenes with ground truth of all 26 categories, labels,
    the checked submission, split folder, whether the drivable-area ROI applies).

    ``roi`` None: on when every log has its map. Raises :class:`InputFormatError` when the pickle does not hold
    exactly the label frames of the split at ``rate_hz``.
    """
    scenes = load_scenes(root, split, rate_hz=rate_hz, with_gt=True, all_categories=True)
    labels = gt_sequences(scenes, vocabulary(all_categories=True))
    preds = read_tracks_pickle(submission)
    validate_sequences(preds, expected_frames(scenes), where=str(submission))
    ddir = split_dir(root, split)
    use_roi = has_maps(ddir, list(labels)) if roi is None else bool(roi)
    if use_roi and not has_maps(ddir, list(labels)):
        raise DatasetError(f"{ddir}: the drivable-area ROI needs every log's map/ folder")
    return scenes, labels, preds, ddir, use_roi


def evaluate_submission(root: str | Path, split: str, submission: str | Path, *, rate_hz: float | None = 2.0,
                        max_range_m: int = DEFAULT_RANGE_M, workers: int | None = None, roi: bool | None = None,
                        trackeval_dir: str | Path | None = None, verbose: bool = False) -> MetricsDocument:
    """Evaluate a tracking pickle against the split's labels; returns the metrics document.

    ``roi`` None: on when every log has its map. Raises :class:`InputFormatError` when the pickle does not hold
    exactly the label frames of the split at ``rate_hz``.
    """
    t0 = time.perf_counter()
    _, labels, preds, ddir, use_roi = load_submission(root, split, submission, rate_hz=rate_hz, roi=roi)
    workers = max(1, int(workers or default_workers()))
    out = evaluate_sequences(preds, labels, ddir if use_roi else None, max_range_m=max_range_m, workers=workers,
                             trackeval_dir=trackeval_dir, verbose=verbose)
    doc = metrics_document(out, split=split, submission=str(submission), rate_hz=rate_hz, max_range_m=max_range_m,
                           roi=use_roi, workers=workers)
    doc.logs, doc.frames = len(labels), sum(len(v) for v in labels.values())
    doc.seconds = round(time.perf_counter() - t0, 3)
    return doc


def format_summary(doc: MetricsDocument) -> str:
    """A table of HOTA / MOTA / IDF1 for the Table I classes and their average."""
    lines = [f"{'class':<16}{'HOTA':>8}{'MOTA':>8}{'IDF1':>8}{'GT':>7}"]
    for c in TABLE_I_CLASSES:
        m = doc.per_class[c]
        lines.append(f"{c:<16}{m['hota']:>8.3f}{m['mota']:>8.3f}{m['idf1']:>8.3f}{m['gt_boxes']:>7d}")
    o = doc.overall
    lines.append(f"{'AVERAGE (7)':<16}{o['hota']:>8.3f}{o['mota']:>8.3f}{o['idf1']:>8.3f}")
    return "\n".join(lines)
