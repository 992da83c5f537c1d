"""TrackEval's CLEAR matching replayed frame by frame, with the decision about every box kept.

TrackEval's ``CLEAR.eval_sequence`` only returns sums (CLR_TP, CLR_FP, CLR_FN, IDSW). :func:`clear_decisions`
runs the same loop on the same per-class sequence data (what TrackEval's dataset class hands the metric: ids per
timestep and the similarity matrices) and records, per timestep, which ground truth was matched to which track,
which match is an id switch and against which earlier track. Its sums are CLEAR's by construction of the loop
(``trackeval/metrics/clear.py``, v1.0):

- score ``S = 1000 * [track continues the GT's match of the previous timestep] + similarity``, and ``S = 0``
  where ``similarity < threshold - eps``;
- Hungarian assignment maximising ``S`` (``scipy.optimize.linear_sum_assignment(-S)``); a pair is a match when
  ``S > eps``;
- a match is an id switch when the GT was matched before (at any earlier timestep) to another track;
- TP = matches (id switches included), FN = GT - matches, FP = tracks - matches, per timestep.

:func:`official_sequence_data` builds that per-class data with the AV2 evaluator's own dataset class
(``av2.evaluation.tracking.eval.TrackEvalDataset``: centre-distance similarity ``max(0, 1 - d / 2 m)``), so that the
replay sees exactly what the official CLEAR metric sees.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

_EPS = np.finfo("float").eps


@dataclass
class StepDecisions:
    """CLEAR's decisions of one timestep of one class (indices into that timestep's boxes of the class).

    gt_track: (G,) int64, the matched track's index in the timestep, -1 for a miss (FN).
    gt_switch: (G,) bool, the match is an id switch.
    gt_previous: (G,) int64, for a switch the (mapped) id of the track the GT was last matched to, else -1.
    track_matched: (T,) bool; an unmatched track is a false positive (FP).
    """

    gt_track: np.ndarray
    gt_switch: np.ndarray
    gt_previous: np.ndarray
    track_matched: np.ndarray

    def counts(self) -> dict:
        """``{tp, fp, fn, ids}`` of the timestep (CLEAR: tp includes the id-switch matches)."""
        tp = int((self.gt_track >= 0).sum())
        return {
            "tp": tp,
            "fp": int(len(self.track_matched) - tp),
            "fn": int(len(self.gt_track) - tp),
            "ids": int(self.gt_switch.sum()),
        }


def clear_decisions(
    gt_ids: list, tracker_ids: list, similarity: list, num_gt_ids: int, threshold: float = 0.5
) -> list[StepDecisions]:
    """Replay CLEAR over one sequence of one class: one :class:`StepDecisions` per timestep.

    Per timestep: gt_ids (G_t,) int ids in ``0..num_gt_ids-1`` (TrackEval's mapped ids), tracker_ids (T_t,) int
    ids (mapped), similarity (G_t, T_t) float (1 = same place). threshold: CLEAR's similarity threshold (AV2:
    0.5, i.e. centre distance <= 1 m).
    """
    prev_tracker_id = np.full(num_gt_ids, np.nan)  # last match, any timestep before: id switches
    prev_timestep_tracker_id = np.full(num_gt_ids, np.nan)  # match of the previous timestep: matching bonus
    out = []
    for gt_t, tr_t, sim in zip(gt_ids, tracker_ids, similarity):
        gt_t = np.asarray(gt_t, dtype=np.int64)
        tr_t = np.asarray(tr_t, dtype=np.int64)
        g, n = len(gt_t), len(tr_t)
        step = StepDecisions(
            np.full(g, -1, dtype=np.int64),
            np.zeros(g, dtype=bool),
            np.full(g, -1, dtype=np.int64),
            np.zeros(n, dtype=bool),
        )
        out.append(step)
        if g == 0 or n == 0:  # CLEAR leaves the previous-timestep record as it is on such a timestep
            continue
        score = tr_t[np.newaxis, :] == prev_timestep_tracker_id[gt_t[:, np.newaxis]]
        score = 1000 * score + sim
        score[sim < threshold - _EPS] = 0
        rows, cols = linear_sum_assignment(-score)
        ok = score[rows, cols] > 0 + _EPS
        rows, cols = rows[ok], cols[ok]
        matched_gt, matched_tr = gt_t[rows], tr_t[cols]
        prev = prev_tracker_id[matched_gt]
        switch = ~np.isnan(prev) & (matched_tr != prev)
        step.gt_track[rows] = cols
        step.gt_switch[rows] = switch
        step.gt_previous[rows[switch]] = prev[switch].astype(np.int64)
        step.track_matched[cols] = True
        prev_tracker_id[matched_gt] = matched_tr
        prev_timestep_tracker_id[:] = np.nan
        prev_timestep_tracker_id[matched_gt] = matched_tr
    return out


@dataclass
class ClassSequence:
    """One class of one sequence as the official metric sees it, with the way back to the frames' boxes.

    gt_rows / tracker_rows: per timestep, the (G_t,) / (T_t,) row of each box of the class in the frame dict it
    came from; gt_ids / tracker_ids: the mapped ids; gt_names / tracker_names: mapped id -> original track id;
    similarity: per timestep, (G_t, T_t).
    """

    gt_rows: list
    tracker_rows: list
    gt_ids: list
    tracker_ids: list
    similarity: list
    gt_names: list
    tracker_names: list

    def decisions(self, threshold: float) -> list[StepDecisions]:
        return clear_decisions(self.gt_ids, self.tracker_ids, self.similarity, len(self.gt_names), threshold)


def official_sequence_data(labels: dict, predictions: dict, classes: list[str]) -> dict:
    """Per log and class, the data the AV2 evaluator's CLEAR metric is given: ``{log_id: {class: ClassSequence}}``.

    labels / predictions: ``{log_id: [frame dict, ...]}`` as the final official evaluation scores them
    (:func:`grutrack.evaluation.av2_eval.evaluate_sequences` with ``keep_inputs``).
    """
    from grutrack.evaluation.av2_eval import official_module

    TrackEvalDataset = official_module().TrackEvalDataset
    cfg = {
        **TrackEvalDataset.get_default_dataset_config(),
        "GT_TRACKS": {"t": labels},
        "PREDICTED_TRACKS": {"t": predictions},
        "SEQ_IDS_TO_EVAL": list(labels),
        "CLASSES_TO_EVAL": classes,
        "TRACKERS_TO_EVAL": ["t"],
        "OUTPUT_FOLDER": None,
    }
    with contextlib.redirect_stdout(io.StringIO()):  # the dataset class prints its zero distance
        ds = TrackEvalDataset(cfg)
    out: dict = {}
    for log in labels:
        raw = ds.get_raw_seq_data("t", log)
        out[log] = {}
        for cls in classes:
            data = ds.get_preprocessed_seq_data(raw, cls)
            k = classes.index(cls)
            g_rows = [np.flatnonzero(c == k) for c in raw["gt_classes"]]
            t_rows = [np.flatnonzero(c == k) for c in raw["tracker_classes"]]
            g_names = _names(data["gt_ids"], raw["gt_ids"], g_rows)
            t_names = _names(data["tracker_ids"], raw["tracker_ids"], t_rows)
            out[log][cls] = ClassSequence(
                g_rows, t_rows, data["gt_ids"], data["tracker_ids"], data["similarity_scores"], g_names, t_names
            )
    return out


def _names(mapped: list, original: list, rows: list) -> list:
    """mapped id -> original id, from the boxes of each timestep."""
    n = max((int(m.max()) + 1 for m in mapped if len(m)), default=0)
    names: list = [None] * n
    for m, orig, r in zip(mapped, original, rows):
        for i, j in zip(m.tolist(), r.tolist()):
            names[i] = orig[j]
    return names
