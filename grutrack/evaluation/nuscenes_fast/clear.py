"""The per-threshold tracking metrics of one class (MOTAR, MOTA, MOTP, FAF, MT, ML, FP, FN, IDS, FRAG, TID, LGD,
recall, GT, TP), all thresholds at once.

Array reductions over the GT boxes sorted by object, thresholds on the first axis, following
``nuscenes.eval.tracking.metrics`` and ``motmetrics.metrics`` (1.4.0) on the devkit's frame numbering (only
frames with a box of the class count), with the same operation order, so every value is the devkit's to the bit.
The input is :class:`ThresholdEvents` (what :meth:`ClassAccumulator.events
<grutrack.evaluation.nuscenes_fast.accumulate.ClassAccumulator.events>` builds); the output one (T,) array per
metric.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CLEAR_METRICS", "ThresholdEvents", "clear_metrics"]

#: the metrics :func:`clear_metrics` computes, in the order ``TrackingEvaluation`` stores them
CLEAR_METRICS = (
    "gt",
    "tp",
    "motar",
    "mota",
    "motp",
    "faf",
    "mt",
    "ml",
    "fp",
    "fn",
    "ids",
    "frag",
    "recall",
    "tid",
    "lgd",
)


@dataclass
class ThresholdEvents:
    """One class's accumulation at T thresholds; G > 0 GT boxes sorted by object, then frame; O objects.

    matched: (T, G) bool, the box is matched (MATCH or SWITCH). frame_id: (T, G) int64, the devkit's frame
    number of the box's frame (frames with an event at that threshold, counted over all scenes).
    obj_starts, obj_counts: (O,) int64, each object's first position and its box count. switches, kept,
    frames: (T,) int64 SWITCH events, predictions kept, frames with an event. dist_sum: (T,) float64 sum of the
    matches' centre distances in metres, summed in the accumulation's order (that order fixes its last bit).
    """

    matched: np.ndarray
    frame_id: np.ndarray
    obj_starts: np.ndarray
    obj_counts: np.ndarray
    switches: np.ndarray
    kept: np.ndarray
    frames: np.ndarray
    dist_sum: np.ndarray


def clear_metrics(ev: ThresholdEvents) -> dict[str, np.ndarray]:
    """``{metric: (T,) array}`` for :data:`CLEAR_METRICS`: int64 counts (gt, tp, mt, ml, fp, fn, ids, frag),
    float64 ratios (NaN where the devkit gives NaN); motp in metres, faf in false alarms per 100 frames."""
    ms = ev.matched
    n_thresholds, n_gt = ms.shape
    starts, counts = ev.obj_starts, ev.obj_counts
    fid = ev.frame_id
    n_det = np.count_nonzero(ms, axis=1).astype(np.int64)
    n_sw = ev.switches
    n_match = n_det - n_sw
    n_miss = n_gt - n_det
    n_fp = ev.kept - n_det

    # MT / ML: share of an object's boxes matched.
    tracked = np.add.reduceat(ms.astype(np.int64), starts, axis=1)
    ratio = tracked / counts
    mt = np.count_nonzero(ratio >= 0.8, axis=1).astype(np.int64)
    ml = np.count_nonzero(ratio < 0.2, axis=1).astype(np.int64)

    # First and last matched position of each object (sentinels where none), its first and last frame ids.
    pos = np.arange(n_gt)
    first_m = np.minimum.reduceat(np.where(ms, pos, n_gt + 1), starts, axis=1)
    last_m = np.maximum.reduceat(np.where(ms, pos, -1), starts, axis=1)
    is_tracked = tracked > 0
    n_tracked = np.count_nonzero(is_tracked, axis=1)
    first_fid = fid[:, starts]
    last_fid = fid[:, starts + counts - 1]

    # TID: frames from first appearance to first match; LGD: longest run of unmatched frame ids in the span
    # (before the first match, after the last one, or between two matches).
    lead = np.take_along_axis(fid, np.where(is_tracked, first_m, starts), axis=1) - first_fid
    trail = last_fid - np.take_along_axis(fid, np.where(is_tracked, last_m, starts), axis=1)
    gaps = np.maximum(lead, trail)
    obj_of = np.repeat(np.arange(len(starts)), counts)
    prev = np.maximum.accumulate(np.where(ms, pos, -1), axis=1)
    prev = np.concatenate([np.full((n_thresholds, 1), -1), prev[:, :-1]], axis=1)  # last match before
    prev0 = np.maximum(prev, 0)
    inner_ok = ms & (prev >= 0) & (obj_of[prev0] == obj_of)
    inner = fid - np.take_along_axis(fid, prev0, axis=1) - 1
    gaps = np.maximum(gaps, np.maximum.reduceat(np.where(inner_ok, inner, 0), starts, axis=1))
    lead_sum = np.sum(np.where(is_tracked, lead, 0) * 0.5, axis=1)  # halves of small integers: exact sums
    gap_sum = np.sum(np.where(is_tracked, gaps, 0) * 0.5, axis=1)

    # FRAG: matched -> missed transitions inside [first match, last match] of each object.
    trans = ms[:, :-1] & ~ms[:, 1:] & (obj_of[1:] == obj_of[:-1]) & (pos[1:] <= last_m[:, obj_of[1:]])
    frag = np.count_nonzero(trans, axis=1).astype(np.int64)

    # motmetrics / devkit formulas, same operation order.
    with np.errstate(divide="ignore", invalid="ignore"):
        tid = np.where(n_tracked == 0, np.nan, lead_sum / n_tracked)
        lgd = np.where(n_tracked == 0, np.nan, gap_sum / n_tracked)
        recall_m = n_match / n_gt
        nominator = (n_miss + n_sw + n_fp) - (1 - recall_m) * n_gt
        denominator = recall_m * n_gt
        motar = np.where(denominator == 0, np.nan, np.maximum(0.0, 1 - 1.0 * nominator / denominator))
        mota = np.maximum(0.0, 1.0 - (n_miss + n_sw + n_fp) / n_gt)
        motp = np.where(n_det == 0, np.nan, ev.dist_sum / n_det)
    faf = n_fp / ev.frames * 100
    recall = n_det / n_gt
    return {
        "gt": np.full(n_thresholds, n_gt, dtype=np.int64),
        "tp": n_match,
        "motar": motar,
        "mota": mota,
        "motp": motp,
        "faf": faf,
        "mt": mt,
        "ml": ml,
        "fp": n_fp,
        "fn": n_miss,
        "ids": n_sw,
        "frag": frag,
        "recall": recall,
        "tid": tid,
        "lgd": lgd,
    }
