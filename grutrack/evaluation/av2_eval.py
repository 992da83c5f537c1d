"""Argoverse 2 tracking evaluation composed of the official evaluator's own building blocks, and the metrics JSON.

The reference is ``av2.evaluation.tracking.eval.evaluate`` (HOTA objective, TrackEval HOTA + CLEAR, 50 m range,
drivable-area ROI when every log has its map). :func:`evaluate_sequences` performs its steps in its order, each with
the official module's function for it; nothing in ``av2`` or ``trackeval`` is replaced, patched or reassigned:

1. range: ``filter_max_dist`` on the labels, ``utils.annotate_frame_metadata`` (each label frame's
   ``ego_translation_m`` onto the prediction frame at the same position), ``filter_max_dist`` on the tracks;
2. ROI (with ``dataset_dir``): ``filter_drivable_area``, labels and tracks;
3. score-threshold tuning, the body of ``_tune_score_thresholds`` (HOTA objective, 10 recall levels, 2 m match
   distance): per class ``_filter_by_class`` and ``_calculate_score_thresholds`` with ``_xy_center_similarity``;
   per threshold index ``_evaluate_single_threshold``; then the official choice (threshold at the argmax of the
   recall-level HOTA values, tuned HOTA ``max(0, best)``, mean ``nanmean`` of the values clipped at 0);
4. ``utils.filter_by_class_thresholds`` with the tuned thresholds;
5. the final evaluation as ``evaluate_tracking`` configures it (its frame-set check, ``TrackEvalDataset``, tracker
   ``"TRACKER"``, HOTA + CLEAR at similarity 0.5), run by ``trackeval.Evaluator`` with an explicit evaluation
   config.

Private helpers of the official module that are called because it has no public equivalent: ``_filter_by_class``,
``_calculate_score_thresholds``, ``_xy_center_similarity`` and ``_evaluate_single_threshold`` (step 3).
``tests/test_av2.py`` checks the composition against the unmodified official ``evaluate`` on the real val logs
(result tree, tuned and mean HOTA, tuned thresholds: all 26 categories, exactly).

What the composition adds, none of which changes a number:

- the labels are built from the split's ``annotations.feather`` at the evaluated rate (all 26 competition
  categories, city frame) and the submission is checked first to hold exactly those frames, so the official
  frame-equality assertions cannot fire; logs are given in the order the official function regroups them
  (``utils.group_frames``: by timestamp), because step 1 pairs prediction and label frames by position;
- the tuning runs its 10 threshold evaluations in this process for one worker and on a ``multiprocessing.Pool`` of
  ``min(10, workers)`` processes otherwise (``workers`` default: the cores this process may run on,
  ``os.sched_getaffinity``; the official function takes ``multiprocessing.cpu_count()``);
- TrackEval's side outputs (console tables and configs, per-class summary / detailed files, PDF/PNG curves) are
  off, or, with ``trackeval_dir``, the files are written under ``trackeval_dir/trackeval/`` (with the Identity
  columns besides HOTA and CLEAR); its error log inside the trackeval package is never written, and nothing is
  written to the working directory;
- step 2 is one call of ``filter_drivable_area`` given the frames of labels and tracks together (the map and poses
  of each log are read once, not twice) and only frames that hold boxes: the official filter cannot build the box
  array of an empty frame (a (0,) quaternion array), and an empty frame has nothing to filter. Every frame is
  filtered on its own and in place, as in the official function, so the result is the same;
- TrackEval's Identity metric (IDF1), and any other metric class of ``TRACKEVAL_COLUMNS``, is computed in the same
  final TrackEval run, on exactly the labels and score-filtered tracks that HOTA and CLEAR score (the official
  function computes HOTA and CLEAR only); its entries are taken out of the result tree, which then holds what the
  official function returns;
- on request (``keep_inputs``), those labels and score-filtered tracks and the tuned per-class score thresholds
  are handed back, so that the final CLEAR matching can be replayed frame by frame
  (:mod:`grutrack.evaluation.clear_frames`).

Metrics JSON (same top level as the nuScenes one): ``{"dataset": "av2", "version", "split", "evaluator",
"submission", "overall", "per_class", ...}``. ``per_class[category]`` holds ``hota``, ``mota``, ``idf1`` (final
evaluation at the tuned per-class score threshold), ``hota_tuned`` / ``hota_mean`` (the official function's
tuned and recall-averaged values), the final CLEAR counts ``tp`` / ``fp`` / ``fn`` / ``ids`` (CLR_TP, CLR_FP,
CLR_FN, IDSW; ``idsw`` repeats ``ids``), ``gt_boxes`` (the ground-truth boxes the final evaluation scored, after the
range and ROI filters), ``present`` and ``absent`` (``gt_boxes == 0``). ``overall`` holds the Table I average
(``hota``, ``mota``, ``idf1``) over the Table I classes with ground truth, ``classes`` (the 7), ``present_classes``
and ``absent_classes``; an absent class keeps the numbers the official evaluator gives it in ``per_class`` but is
in no average (:func:`class_average` says why). Metrics documents written before absent classes were left out
(their ``overall`` has ``hota_present``) are read with that rule (``MetricsDocument.from_dict``).
"""

from __future__ import annotations

import contextlib
import functools
import io
import multiprocessing
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

from grutrack.data.av2 import COMPETITION_CATEGORIES, TABLE_I_CLASSES, load_scenes, split_dir, vocabulary
from grutrack.documents import ABSENT_TEXT, MetricsDocument
from grutrack.errors import DatasetError, InputFormatError
from grutrack.export.av2_tracks import expected_frames, gt_sequences, read_tracks_pickle, validate_sequences

EVALUATOR = "av2.evaluation.tracking.eval.evaluate (HOTA objective)"
DEFAULT_RANGE_M = 50
OBJECTIVE = "HOTA"  # the official evaluate's objective_metric as the challenge runs it
NUM_THRESHOLDS = 10  # evaluate -> _tune_score_thresholds(num_thresholds=10, match_distance_m=2)
MATCH_DISTANCE_M = 2
SIMILARITY_THRESHOLD = 0.5  # iou_threshold default of _tune_score_thresholds and evaluate_tracking
TRACKER_NAME = "TRACKER"  # evaluate -> evaluate_tracking(tracker_name="TRACKER")


def default_workers() -> int:
    """The number of cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def has_maps(dataset_dir: Path, log_ids: list[str]) -> bool:
    """Whether every log has the vector map and raster files the drivable-area ROI needs."""

    def ok(log: str) -> bool:
        m = dataset_dir / log / "map"
        return (
            any(m.glob("log_map_archive_*.json"))
            and any(m.glob("*img_Sim2_city.json"))
            and any(m.glob("*ground_height_surface*.npy"))
        )

    return all(ok(lg) for lg in log_ids)


def official_module():
    """The official tracking evaluation module ``av2.evaluation.tracking.eval`` (it imports TrackEval with the
    numpy aliases TrackEval needs). Its alias shim probes ``hasattr(np, "bool")`` and the like, which numpy 1.2x
    answers with one FutureWarning per alias on every first import; those warnings, and only those (filtered by
    the shim's module name), are not shown."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=FutureWarning, module=r"av2\.evaluation\.tracking\._numpy_compat")
        import av2.evaluation.tracking.eval as official
    return official


def eval_config(quiet: bool) -> dict:
    """TrackEval ``Evaluator`` config of the final evaluation: the official one (defaults, no timing) without the
    error log in the trackeval package; ``quiet``: no console tables or configs, no summary / detailed / curve
    files. Numbers are unaffected."""
    import trackeval

    cfg = {**trackeval.Evaluator.get_default_eval_config(), "TIME_PROGRESS": False, "LOG_ON_ERROR": None}
    if quiet:
        cfg.update(
            PRINT_RESULTS=False, PRINT_CONFIG=False, OUTPUT_SUMMARY=False, OUTPUT_DETAILED=False, PLOT_CURVES=False
        )
    return cfg


def _frame_keys(seqs: dict) -> dict:
    """{log: [timestamp_ns, ...]} of a ``{log: [frame, ...]}`` sequence dict."""
    return {lg: [int(f["timestamp_ns"]) for f in frames] for lg, frames in seqs.items()}


def range_filter(predictions: dict, labels: dict, max_range_m: int) -> tuple[dict, dict]:
    """Step 1: (tracks, labels) within ``max_range_m`` (metres, xy) of the ego vehicle, as the official
    ``evaluate`` does it. The prediction frames get their label frame's ``ego_translation_m`` (in place)."""
    from av2.evaluation.tracking import utils

    official = official_module()
    labels = official.filter_max_dist(labels, max_range_m)
    utils.annotate_frame_metadata(
        utils.ungroup_frames(predictions), utils.ungroup_frames(labels), ["ego_translation_m"]
    )
    return official.filter_max_dist(predictions, max_range_m), labels


def drivable_area_filter(predictions: dict, labels: dict, dataset_dir: Path) -> None:
    """Step 2, in place: the official ``filter_drivable_area`` on the frames of labels and tracks that hold boxes,
    in one call (each log's map and poses read once)."""
    held: dict[str, list] = {}
    for seqs in (labels, predictions):
        for lg, frames in seqs.items():
            held.setdefault(lg, []).extend(f for f in frames if len(f["translation_m"]))
    held = {lg: frames for lg, frames in held.items() if frames}
    if held:
        official_module().filter_drivable_area(held, str(dataset_dir))


def tune_score_thresholds(
    labels: dict, predictions: dict, classes: list[str], workers: int, output_dir: str
) -> tuple[dict, dict, dict]:
    """Step 3, the body of the official ``_tune_score_thresholds`` (HOTA objective, 10 thresholds, 2 m) with
    this module's pool: (threshold, tuned HOTA, recall-averaged HOTA), each ``{class: float}``."""
    official = official_module()
    metric_class = official.SUBMETRIC_TO_METRIC_CLASS_NAME[OBJECTIVE]
    metrics_config = {"METRICS": [metric_class], "THRESHOLD": SIMILARITY_THRESHOLD, "PRINT_CONFIG": False}
    dataset_config = {
        **official.TrackEvalDataset.get_default_dataset_config(),
        "GT_TRACKS": {"tracker": labels},
        "PREDICTED_TRACKS": {"tracker": predictions},
        "SEQ_IDS_TO_EVAL": list(labels.keys()),
        "CLASSES_TO_EVAL": classes,
        "TRACKERS_TO_EVAL": ["tracker"],
        "OUTPUT_FOLDER": output_dir,
    }
    sim_func = functools.partial(official._xy_center_similarity, zero_distance=MATCH_DISTANCE_M)
    candidates = {
        c: official._calculate_score_thresholds(
            official._filter_by_class(labels, c),
            official._filter_by_class(predictions, c),
            sim_func,
            num_thresholds=NUM_THRESHOLDS,
        )
        for c in classes
    }
    jobs = [(i, candidates, classes, predictions, dataset_config, metrics_config) for i in range(NUM_THRESHOLDS)]
    if workers == 1:
        results = [official._evaluate_single_threshold(job) for job in jobs]
    else:
        with multiprocessing.Pool(min(NUM_THRESHOLDS, workers)) as pool:
            results = list(pool.imap(official._evaluate_single_threshold, jobs))
    thresholds, tuned, mean = {}, {}, {}
    for c in classes:
        values = [r[c][metric_class][OBJECTIVE] for r in results]
        values = [np.mean(v) if isinstance(v, np.ndarray) else v for v in values]
        thresholds[c] = candidates[c][np.argmax(values)]
        tuned[c] = max(0, np.max(values))
        mean[c] = np.nanmean(np.array(values).clip(min=0))
    return thresholds, tuned, mean


#: TrackEval metric classes the official ``evaluate_tracking`` runs (its result tree holds these and Count,
#: which TrackEval's evaluator adds to every run)
OFFICIAL_METRICS = ("HOTA", "CLEAR")
_IN_TREE = (*OFFICIAL_METRICS, "Count")

#: metrics-JSON column -> (TrackEval metric class, its field, how it is reduced: "mean" over the similarity
#: thresholds (HOTA's alphas), "float" or "int" of a scalar), read from the final TrackEval run. A column from
#: another TrackEval metric class (``trackeval.metrics``) is one more line here: that class then runs in the same
#: final evaluation, on the same labels and score-filtered tracks.
TRACKEVAL_COLUMNS: dict[str, tuple[str, str, str]] = {
    "hota": ("HOTA", "HOTA", "mean"),
    "detA": ("HOTA", "DetA", "mean"),
    "assA": ("HOTA", "AssA", "mean"),
    "mota": ("CLEAR", "MOTA", "float"),
    "idsw": ("CLEAR", "IDSW", "int"),
    "tp": ("CLEAR", "CLR_TP", "int"),
    "fp": ("CLEAR", "CLR_FP", "int"),
    "fn": ("CLEAR", "CLR_FN", "int"),
    "ids": ("CLEAR", "IDSW", "int"),
    "idf1": ("Identity", "IDF1", "float"),
}


def _reduced(value, how: str):
    """A TrackEval field reduced as :data:`TRACKEVAL_COLUMNS` says."""
    if how == "mean":
        return float(np.mean(value))
    return int(value) if how == "int" else float(value)


def final_evaluation(
    labels: dict, predictions: dict, classes: list[str], config: dict, output_dir: str
) -> tuple[dict, dict]:
    """Step 5: TrackEval HOTA + CLEAR configured as the official ``evaluate_tracking`` does, with the other metric
    classes of :data:`TRACKEVAL_COLUMNS` (Identity) in the same run. Returns (the result tree with the official
    metrics only, ``{class: {metric class: {field: value}}}`` of the other classes, combined over sequences)."""
    import trackeval
    from av2.evaluation.tracking import utils

    official = official_module()

    def frames(seqs):
        return {(f["seq_id"], f["timestamp_ns"]) for f in utils.ungroup_frames(seqs)}

    if frames(labels) != frames(predictions):  # evaluate_tracking's check; the input check makes it a bug
        raise RuntimeError("sequences ids and timestamp_ns in labels and predictions don't match")
    extra = sorted({m for m, _, _ in TRACKEVAL_COLUMNS.values()} - set(_IN_TREE))
    metrics_config = {
        "METRICS": [*OFFICIAL_METRICS, *extra],
        "THRESHOLD": SIMILARITY_THRESHOLD,
        "PRINT_CONFIG": bool(config["PRINT_CONFIG"]),
    }
    metrics = [getattr(trackeval.metrics, m)(metrics_config) for m in metrics_config["METRICS"]]
    dataset_config = {
        **official.TrackEvalDataset.get_default_dataset_config(),
        "GT_TRACKS": {TRACKER_NAME: labels},
        "PREDICTED_TRACKS": {TRACKER_NAME: predictions},
        "SEQ_IDS_TO_EVAL": list(labels.keys()),
        "CLASSES_TO_EVAL": classes,
        "TRACKERS_TO_EVAL": [TRACKER_NAME],
        "OUTPUT_FOLDER": output_dir,
    }
    result, _ = trackeval.Evaluator(config).evaluate([official.TrackEvalDataset(dataset_config)], metrics)
    tree = result["TrackEvalDataset"][TRACKER_NAME]
    others = {c: {m: tree["COMBINED_SEQ"][c][m] for m in extra} for c in classes}
    for by_class in tree.values():
        for by_metric in by_class.values():
            for m in extra:
                by_metric.pop(m, None)
    return result, others


def evaluate_sequences(
    predictions: dict,
    labels: dict,
    dataset_dir: str | Path | None,
    *,
    max_range_m: int = DEFAULT_RANGE_M,
    workers: int | None = None,
    trackeval_dir: str | Path | None = None,
    verbose: bool = False,
    keep_inputs: bool = False,
) -> dict:
    """Run the official evaluation on in-memory sequences (steps 1-5 of the module docstring).

    predictions / labels: ``{log_id: [frame, ...]}`` (the pickle layout), same frames (else InputFormatError);
    neither is modified. dataset_dir: the split folder (enables the ROI filter) or None. Returns ``{"result":
    TrackEval's result tree, "tuned": {class: HOTA}, "mean": {class: HOTA}, "others": {class: {metric class:
    {field: value}}} (the non-official metric classes of TRACKEVAL_COLUMNS, e.g. Identity)}``; with
    ``keep_inputs`` also ``"final"``: ``{"labels", "predictions"}`` (what the final HOTA / CLEAR evaluation scored:
    range- and ROI-filtered labels, tracks also filtered by the tuned thresholds), ``"classes"``,
    ``"similarity_threshold"`` and ``"thresholds"`` ({class: tuned score threshold}).
    """
    if _frame_keys(predictions) != _frame_keys(labels):
        raise InputFormatError("predictions: logs and frames (timestamp_ns) must be exactly those of the labels")
    # the official function regroups the labels by timestamp (a stable sort) and then pairs prediction and label
    # frames by position: give both in that order. Frames are copied (step 1 adds a key to the prediction frames;
    # later steps build new frames)
    order = sorted(labels, key=lambda lg: labels[lg][0]["timestamp_ns"] if labels[lg] else 0)
    labels = {lg: [dict(f) for f in labels[lg]] for lg in order}
    predictions = {lg: [dict(f) for f in predictions[lg]] for lg in order}
    from av2.evaluation.tracking import utils

    workers = max(1, int(workers or default_workers()))
    classes = list(official_module().constants.AV2_CATEGORIES)
    sink = contextlib.nullcontext() if verbose else contextlib.redirect_stdout(io.StringIO())
    errsink = contextlib.nullcontext() if verbose else contextlib.redirect_stderr(io.StringIO())
    with tempfile.TemporaryDirectory(prefix="grutrack-av2-eval-") as tmp, sink, errsink:
        out_dir = str(Path(trackeval_dir).resolve() / "trackeval" if trackeval_dir else Path(tmp))
        predictions, labels = range_filter(predictions, labels, int(max_range_m))
        if dataset_dir is not None:
            drivable_area_filter(predictions, labels, Path(dataset_dir).resolve())
        thresholds, tuned, mean = tune_score_thresholds(labels, predictions, classes, workers, tmp)
        scored = utils.filter_by_class_thresholds(predictions, thresholds)
        res, others = final_evaluation(labels, scored, classes, eval_config(quiet=trackeval_dir is None), out_dir)
    out = {"result": res, "tuned": tuned, "mean": mean, "others": others}
    if keep_inputs:
        out["final"] = {
            "labels": labels,
            "predictions": scored,
            "classes": classes,
            "similarity_threshold": float(SIMILARITY_THRESHOLD),
            "thresholds": {c: float(t) for c, t in thresholds.items()},
        }
    return out


#: the per-class columns ``overall`` averages
AVERAGED_COLUMNS = ("hota", "mota", "idf1")
AVERAGE_RULE = "Table I: mean over the Table I classes with ground truth (absent classes are left out)"


def class_average(per_class: dict, classes=TABLE_I_CLASSES, columns=AVERAGED_COLUMNS) -> dict:
    """The class average of each column over those of ``classes`` that have ground truth (``per_class[c]["absent"]``
    false): ``{column: mean or None (no class has ground truth)}``, with ``classes``, ``present_classes`` and
    ``absent_classes``. Every average of AV2 metrics in grutrack is this one.

    Why absent classes are left out, from the official code (av2 0.3.6, ``av2/evaluation/tracking/eval.py``):

    - the official tracking evaluation takes no average over classes. ``evaluate`` (eval.py:615-669) scores every
      one of the 26 ``constants.AV2_CATEGORIES`` (eval.py:636) and returns per-class values; its command line
      writes the per-class ``mean_metric_values`` as they are (eval.py:695-702). The class-averaged entries
      TrackEval leaves in the result tree (``cls_comb_cls_av``, over all 26 classes) are TrackEval's generic
      output, which the AV2 code never reads;
    - for a class without ground truth the official numbers are not measurements but the denominators' floors:
      ``_calculate_score_thresholds`` returns all-zero thresholds when no prediction can match (eval.py:450-453),
      HOTA is 0 (DetA = TP / max(1, TP + FN + FP) with TP = 0, ``trackeval/metrics/hota.py:172``) and MOTA is
      (TP - FP - IDSW) / max(1, TP + FN) = -FP (``trackeval/metrics/clear.py:178``), and the tuned HOTA is
      clipped to ``max(0, ...)`` (eval.py:423). So
      an absent class scores 0.0 (not NaN) with no prediction and -FP MOTA with false positives, and a mean over
      it measures the class list, not the tracker (on the val fixture, 12 BUS false positives in a log without a
      bus give BUS MOTA -12);
    - where av2's evaluators do average over classes, a class without ground truth has no value: the forecasting
      evaluator returns NaN for it (``av2/evaluation/forecasting/eval.py:293-294``) and averages with
      ``np.nanmean`` (forecasting/eval.py:498-517), and the detection evaluator skips it ("Cannot evaluate
      without ground truth information", ``av2/evaluation/detection/eval.py:266-268``). (Its summary row,
      detection/eval.py:212, then takes a plain mean of the per-class defaults; the tracking evaluator, the one
      grutrack runs, has no such row.)

    So grutrack reads "absent" as "not evaluable" and averages over the classes present, as the av2 forecasting
    evaluator does. "Ground truth" is what the final evaluation scores (``CLR_TP + CLR_FN``: label boxes within
    the range and, with the maps, the drivable-area ROI), so a class whose labels all lie outside them is absent too.
    TrackEval's own class average has the narrower ``ignore_empty_classes`` (no ground truth and no prediction),
    which would still count a class of pure false positives; it is not used.
    """
    present = [c for c in classes if not per_class[c]["absent"]]
    out = {k: (float(np.mean([per_class[c][k] for c in present])) if present else None) for k in columns}
    out.update(
        {
            "classes": list(classes),
            "present_classes": present,
            "absent_classes": [c for c in classes if c not in present],
        }
    )
    return out


def metrics_from_result(out: dict) -> tuple[dict, dict]:
    """(overall, per_class) from :func:`evaluate_sequences` output; see the module docstring and
    :func:`class_average`."""
    combined = out["result"]["TrackEvalDataset"]["TRACKER"]["COMBINED_SEQ"]
    per_class = {}
    for c in COMPETITION_CATEGORIES:
        m = {**combined[c], **out["others"].get(c, {})}
        gt = int(m["CLEAR"]["CLR_TP"] + m["CLEAR"]["CLR_FN"])
        per_class[c] = {col: _reduced(m[metric][field], how) for col, (metric, field, how) in TRACKEVAL_COLUMNS.items()}
        per_class[c].update(
            {
                "hota_tuned": float(out["tuned"][c]),
                "hota_mean": float(out["mean"][c]),
                "gt_boxes": gt,
                "present": gt > 0,
                "absent": gt == 0,
            }
        )
    return class_average(per_class), per_class


def metrics_document(
    out: dict, *, split: str, submission: str, rate_hz: float | None, max_range_m: int, roi: bool, workers: int
) -> MetricsDocument:
    """The AV2 metrics document."""
    overall, per_class = metrics_from_result(out)
    return MetricsDocument(
        dataset="av2",
        version="sensor",
        split=split,
        evaluator=EVALUATOR,
        submission=str(submission),
        overall=overall,
        per_class=per_class,
        settings={
            "rate_hz": rate_hz,
            "max_range_m": int(max_range_m),
            "drivable_area_roi": bool(roi),
            "objective": "HOTA",
            "workers": int(workers),
            "average": AVERAGE_RULE,
        },
    )


def load_submission(
    root: str | Path, split: str, submission: str | Path, *, rate_hz: float | None = 2.0, roi: bool | None = None
) -> tuple[list, dict, dict, Path, bool]:
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


def evaluate_submission(
    root: str | Path,
    split: str,
    submission: str | Path,
    *,
    rate_hz: float | None = 2.0,
    max_range_m: int = DEFAULT_RANGE_M,
    workers: int | None = None,
    roi: bool | None = None,
    trackeval_dir: str | Path | None = None,
    verbose: bool = False,
) -> MetricsDocument:
    """Evaluate a tracking pickle against the split's labels; returns the metrics document.

    ``roi`` None: on when every log has its map. Raises :class:`InputFormatError` when the pickle does not hold
    exactly the label frames of the split at ``rate_hz``.
    """
    t0 = time.perf_counter()
    _, labels, preds, ddir, use_roi = load_submission(root, split, submission, rate_hz=rate_hz, roi=roi)
    workers = max(1, int(workers or default_workers()))
    out = evaluate_sequences(
        preds,
        labels,
        ddir if use_roi else None,
        max_range_m=max_range_m,
        workers=workers,
        trackeval_dir=trackeval_dir,
        verbose=verbose,
    )
    doc = metrics_document(
        out,
        split=split,
        submission=str(submission),
        rate_hz=rate_hz,
        max_range_m=max_range_m,
        roi=use_roi,
        workers=workers,
    )
    doc.logs, doc.frames = len(labels), sum(len(v) for v in labels.values())
    doc.seconds = round(time.perf_counter() - t0, 3)
    return doc


def format_summary(doc: MetricsDocument) -> str:
    """A table of HOTA / MOTA / IDF1 for the Table I classes and their average over the classes with ground truth
    (a class without is shown absent)."""
    lines = [f"{'class':<16}{'HOTA':>8}{'MOTA':>8}{'IDF1':>8}{'GT':>7}"]
    for c in TABLE_I_CLASSES:
        m = doc.per_class[c]
        if doc.is_absent(c):
            lines.append(f"{c:<16}{ABSENT_TEXT:>24}{m.get('gt_boxes', 0):>7d}")
        else:
            lines.append(f"{c:<16}{m['hota']:>8.3f}{m['mota']:>8.3f}{m['idf1']:>8.3f}{m['gt_boxes']:>7d}")
    o = doc.overall
    n = len([c for c in TABLE_I_CLASSES if not doc.is_absent(c)])
    label = f"AVERAGE ({n}/{len(TABLE_I_CLASSES)})"
    if o.get("hota") is None:
        lines.append(f"{label:<16}{'no class with ground truth':>24}")
    else:
        lines.append(f"{label:<16}{o['hota']:>8.3f}{o['mota']:>8.3f}{o['idf1']:>8.3f}")
    return "\n".join(lines)
