"""Fast, exact nuScenes tracking evaluation (AMOTA, AMOTP, MOTA, IDS, ... as ``tracking_nips_2019``).

The official evaluation (``nuscenes.eval.tracking.evaluate.TrackingEval`` in nuscenes-devkit 1.2.0) runs a
motmetrics 1.4.0 ``MOTAccumulator`` frame by frame for every class and every one of its 40 recall thresholds,
builds pandas event tables and computes per-object metrics (FRAG, TID, LGD) with one pandas filter per object.
This module gives the same numbers (every entry of ``metrics_summary.json`` and of ``metrics_details.json``),
much faster:

* loading and filtering: by default :mod:`grutrack.evaluation.fast_loading`, an exact re-implementation of the
  devkit's ``load_prediction`` / ``load_gt`` (or their custom-split variants), ``add_center_dist``,
  ``filter_eval_boxes`` and ``create_tracks`` (track score = mean of the box scores of an id, gaps
  interpolated) that hands over to the devkit's own loaders for any input it does not reproduce;
  ``loader="devkit"`` uses the devkit's loaders directly;
* the accumulation (``TrackingEvaluation.accumulate``) is re-implemented. The centre distances are computed as
  the devkit's ``sklearn.metrics.pairwise.euclidean_distances`` call does (same formula; the BLAS product on
  a matrix of the devkit's shape, whose last bit depends on that shape), once per frame and distinct set of
  kept predictions, cached across thresholds. A candidate pair (distance < ``dist_th_tp``) whose GT and
  prediction have no other candidate is matched whatever motmetrics' state (every optimal assignment contains
  it), so most pairs of all frames are matched at once with array operations, MATCH or SWITCH following from
  the object's previous partner. The rows with competing candidates replay ``MOTAccumulator.update`` in time
  order: keep the previous pairing if still within distance, then motmetrics' ``linear_sum_assignment`` on
  the very matrix motmetrics builds (:mod:`grutrack.evaluation.lsap`, a port of its scipy solver: ties are
  broken as motmetrics breaks them), unless what is left is one-to-one;
* the per-threshold metrics (MOTAR, MOTA, MOTP, FAF, MT, ML, FP, FN, IDS, FRAG, TID, LGD, recall) are array
  reductions over the GT boxes sorted by object, following ``nuscenes.eval.tracking.metrics`` and
  ``motmetrics.metrics`` on the devkit's frame numbering (only frames with a box of the class count); the
  thresholds (from the scores of the MATCH events without threshold), their de-duplication, the padding of
  unachieved recalls, the worst values when none is achieved, the best-MOTA pick and the AMOTA/AMOTP averaging
  follow ``TrackingEvaluation`` and ``TrackingEval.evaluate``; the result is a ``TrackingMetrics`` /
  ``TrackingMetricDataList`` of :mod:`grutrack.evaluation.tracking_classes` (the devkit's classes and config,
  serialised the same way, without importing the devkit package, whose import alone takes 2-3 s).

Public entry points: :func:`fast_tracking_eval` (the ``metrics_summary.json`` dict), :func:`load_tracks`
(loading and filtering), :func:`evaluate_tracks` (accumulation and metrics on loaded tracks) and
:func:`match_decisions` (the decision behind every counted TP, FP, FN and IDS, box by box, at each class's
best-MOTA threshold: what ``grutrack render`` draws).
"""

from __future__ import annotations

import contextlib
import io
import os
import time
from dataclasses import dataclass
from typing import Any, Dict, List, Tuple, Union

import numpy as np

__all__ = ["fast_tracking_eval", "load_tracks", "evaluate_tracks", "exact_center_distances", "match_decisions",
           "MatchDecisions"]

_MOT_METRICS = ("gt", "tp", "motar", "mota", "motp", "faf", "mt", "ml", "fp", "fn", "ids", "frag", "recall",
                "tid", "lgd")


# ----------------------------------------------------------------------------------------------------------------
# Loading (the devkit's own loaders)
# ----------------------------------------------------------------------------------------------------------------

def _default_config():
    """``config_factory('tracking_nips_2019')``'s content, without importing the devkit."""
    from grutrack.evaluation.tracking_classes import load_config

    return load_config("tracking_nips_2019")


def _quiet(verbose: bool):
    """The devkit's GT loaders draw a tqdm bar on stderr even when not verbose; hide it unless verbose."""
    return contextlib.nullcontext() if verbose else contextlib.redirect_stderr(io.StringIO())


def load_tracks(nusc, submission: Union[dict, str, os.PathLike], eval_split: str, config=None,
                verbose: bool = False, loader: str = "fast"):
    """Load, filter and convert ground truth and predictions to tracks exactly as ``TrackingEval.__init__``.

    :param loader: ``"fast"`` (default): :mod:`grutrack.evaluation.fast_loading`, the same tracks with light box
        records, falling back to the devkit's loaders for any input it does not reproduce (the devkit then gives
        its own result or error); ``"devkit"``: the devkit's loaders (``TrackingBox`` objects).
    :return: ``(tracks_gt, tracks_pred, meta)`` as the devkit's ``create_tracks`` gives them.
    """
    cfg = config if config is not None else _default_config()
    if loader == "fast":
        from grutrack.evaluation.fast_loading import NeedsDevkitLoader, fast_load_tracks

        try:
            return fast_load_tracks(nusc, submission, eval_split, cfg)
        except NeedsDevkitLoader as exc:
            if verbose:
                print("fast loader: %s; using the devkit's loaders" % exc)
    elif loader != "devkit":
        raise ValueError("loader must be 'fast' or 'devkit', not %r" % (loader,))
    return _devkit_load_tracks(nusc, submission, eval_split, cfg, verbose)


def _devkit_load_tracks(nusc, submission, eval_split: str, cfg, verbose: bool):
    from grutrack.evaluation.tracking_classes import devkit_config
    from nuscenes.eval.common.data_classes import EvalBoxes
    from nuscenes.eval.common.loaders import (add_center_dist, filter_eval_boxes, get_samples_of_custom_split,
                                              load_gt, load_gt_of_sample_tokens, load_prediction,
                                              load_prediction_of_sample_tokens)
    from nuscenes.eval.tracking.data_classes import TrackingBox
    from nuscenes.eval.tracking.loaders import create_tracks
    from nuscenes.utils.splits import is_predefined_split

    cfg = devkit_config(cfg)  # also sets the devkit's TRACKING_NAMES, which TrackingBox checks
    predefined = is_predefined_split(split_name=eval_split)
    custom_tokens = None if predefined else get_samples_of_custom_split(split_name=eval_split, nusc=nusc)

    if isinstance(submission, (str, os.PathLike)):
        path = os.fspath(submission)
        assert os.path.exists(path), "Error: The result file does not exist!"
        with _quiet(verbose):
            if predefined:
                pred_boxes, meta = load_prediction(path, cfg.max_boxes_per_sample, TrackingBox, verbose=verbose)
            else:
                pred_boxes, meta = load_prediction_of_sample_tokens(
                    path, cfg.max_boxes_per_sample, TrackingBox, sample_tokens=custom_tokens, verbose=verbose)
    else:
        # Same steps as load_prediction / load_prediction_of_sample_tokens, on an in-memory submission.
        data = submission
        assert "results" in data, "Error: No field `results` in result file."
        if predefined:
            results = data["results"]
        else:
            assert isinstance(data["results"], dict), "Error: results must be a dict."
            results = {token: data["results"][token] for token in custom_tokens}
        pred_boxes = EvalBoxes.deserialize(results, TrackingBox)
        meta = data["meta"]
        for sample_token in pred_boxes.sample_tokens:
            assert len(pred_boxes.boxes[sample_token]) <= cfg.max_boxes_per_sample, \
                "Error: Only <= %d boxes per sample allowed!" % cfg.max_boxes_per_sample

    with _quiet(verbose):
        if predefined:
            gt_boxes = load_gt(nusc, eval_split, TrackingBox, verbose=verbose)
        else:
            gt_boxes = load_gt_of_sample_tokens(nusc, custom_tokens, TrackingBox, verbose=verbose)

    assert set(pred_boxes.sample_tokens) == set(gt_boxes.sample_tokens), \
        "Samples in split don't match samples in predicted tracks."

    pred_boxes = add_center_dist(nusc, pred_boxes)
    gt_boxes = add_center_dist(nusc, gt_boxes)
    pred_boxes = filter_eval_boxes(nusc, pred_boxes, cfg.class_range, verbose=verbose)
    gt_boxes = filter_eval_boxes(nusc, gt_boxes, cfg.class_range, verbose=verbose)

    tracks_gt = create_tracks(gt_boxes, nusc, eval_split, gt=True)
    tracks_pred = create_tracks(pred_boxes, nusc, eval_split, gt=False)
    return tracks_gt, tracks_pred, meta


# ----------------------------------------------------------------------------------------------------------------
# Exact distances
# ----------------------------------------------------------------------------------------------------------------

def exact_center_distances(gt_xy: np.ndarray, pred_xy: np.ndarray) -> np.ndarray:
    """BEV centre distances, bit-identical to the devkit's ``euclidean_distances(gt_xy, pred_xy)``.

    scikit-learn computes ``sqrt(max(-2 X.Y^T + |X|^2 + |Y|^2, 0))`` with a BLAS product whose last bit depends
    on the matrix shape; the devkit calls it once per frame on the kept predictions, so this must be called on
    the same rows, in the same order. Inputs are fresh C-contiguous float64 arrays of shape (n, 2) and (m, 2).
    """
    xx = np.einsum("ij,ij->i", gt_xy, gt_xy)[:, None]
    yy = np.einsum("ij,ij->i", pred_xy, pred_xy)[None, :]
    d = -2 * (gt_xy @ pred_xy.T)
    d += xx
    d += yy
    np.maximum(d, 0, out=d)
    return np.sqrt(d, out=d)


# ----------------------------------------------------------------------------------------------------------------
# Flat arrays
# ----------------------------------------------------------------------------------------------------------------

@dataclass
class _Flat:
    """All boxes of all scenes as arrays, frames numbered in the devkit's iteration order."""
    n_frames: int
    g_frame: np.ndarray
    g_cls: np.ndarray
    g_obj: np.ndarray
    g_xy: np.ndarray
    p_frame: np.ndarray
    p_cls: np.ndarray
    p_hyp: np.ndarray
    p_xy: np.ndarray
    p_score: np.ndarray
    obj_raw_id: List[Any]       # tracking_id of each object (objects are per scene)
    frame_keys: List[Tuple[Any, Any]]   # (scene token, timestamp) of every frame
    p_raw_id: List[Any]         # tracking_id of each prediction box


def _evaluated(boxes, cls_index: Dict[str, int], ids: Dict[Any, int], raw_ids: List[Any]):
    """``(class index, dense id, box)`` of each box of an evaluated class; a tracking id not in ``ids`` gets the
    next dense id (its raw id appended to ``raw_ids``)."""
    out = []
    for box in boxes:
        c = cls_index.get(box.tracking_name, -1)
        if c < 0:
            continue
        i = ids.get(box.tracking_id)
        if i is None:
            i = ids[box.tracking_id] = len(raw_ids)
            raw_ids.append(box.tracking_id)
        out.append((c, i, box))
    return out


def _flatten(tracks_gt, tracks_pred, class_names: List[str]) -> _Flat:
    cls_index = {name: i for i, name in enumerate(class_names)}
    g_frame: List[int] = []
    g_cls: List[int] = []
    g_obj: List[int] = []
    g_xy: List[Tuple[float, float]] = []
    p_frame: List[int] = []
    p_cls: List[int] = []
    p_hyp: List[int] = []
    p_xy: List[Tuple[float, float]] = []
    p_score: List[float] = []
    obj_raw_id: List[Any] = []
    frame_keys: List[Tuple[Any, Any]] = []
    p_raw_id: List[Any] = []
    hyp_raw_id: List[Any] = []      # one entry per dense hypothesis id (ids are per scene)
    f = 0
    # The devkit iterates the GT scenes and, within each, the GT timestamps; prediction ids are per scene
    # (each scene has its own accumulator), hence the per-scene id maps.
    for scene_token, scene_gt in tracks_gt.items():
        scene_pred = tracks_pred[scene_token]
        obj_ids: Dict[Any, int] = {}
        hyp_ids: Dict[Any, int] = {}
        for timestamp, frame_gt in scene_gt.items():
            frame_pred = scene_pred[timestamp]
            for c, o, box in _evaluated(frame_gt, cls_index, obj_ids, obj_raw_id):
                g_frame.append(f)
                g_cls.append(c)
                g_obj.append(o)
                g_xy.append((box.translation[0], box.translation[1]))
            for c, h, box in _evaluated(frame_pred, cls_index, hyp_ids, hyp_raw_id):
                p_frame.append(f)
                p_cls.append(c)
                p_hyp.append(h)
                p_xy.append((box.translation[0], box.translation[1]))
                p_score.append(box.tracking_score)
                p_raw_id.append(box.tracking_id)
            frame_keys.append((scene_token, timestamp))
            f += 1
    return _Flat(
        n_frames=f,
        g_frame=np.asarray(g_frame, dtype=np.int64),
        g_cls=np.asarray(g_cls, dtype=np.int64),
        g_obj=np.asarray(g_obj, dtype=np.int64),
        g_xy=np.asarray(g_xy, dtype=np.float64).reshape(-1, 2),
        p_frame=np.asarray(p_frame, dtype=np.int64),
        p_cls=np.asarray(p_cls, dtype=np.int64),
        p_hyp=np.asarray(p_hyp, dtype=np.int64),
        p_xy=np.asarray(p_xy, dtype=np.float64).reshape(-1, 2),
        p_score=np.asarray(p_score, dtype=np.float64),
        obj_raw_id=obj_raw_id,
        frame_keys=frame_keys,
        p_raw_id=p_raw_id,
    )


# ----------------------------------------------------------------------------------------------------------------
# One class
# ----------------------------------------------------------------------------------------------------------------

class _Subset:
    """Candidate pairs of one frame for one set of kept predictions (cached across thresholds).

    A pair is *isolated* when its GT row and its prediction column have no other candidate: motmetrics matches
    such a pair whatever its state (every optimal assignment contains it), so only the other ("contested")
    rows need the state machine.
    """
    __slots__ = ("g0", "g", "p", "d", "iso", "simple", "n", "kept", "ph", "unique_ids", "col_hid", "rows",
                 "row_cols", "pair_d", "iso_rows", "iso_cols", "_dist")

    def __init__(self, g0: int, g: np.ndarray, p: np.ndarray, d: np.ndarray, iso: np.ndarray, simple: bool):
        self.g0 = g0            # class-level index of the frame's first GT
        self.g = g              # class-level GT index of each candidate pair
        self.p = p              # class-level prediction index of each candidate pair
        self.d = d              # exact distance of each pair
        self.iso = iso          # pair is isolated
        self.simple = simple    # every pair isolated

    def contest(self, n: int, kept: np.ndarray, ph: np.ndarray, rows: List[int], cols: List[int],
                unique_ids: bool) -> None:
        """Python-side structures for the state machine of a frame with contested rows (``rows``, ``cols``: the
        local matrix position of each candidate pair; ``unique_ids``: no hypothesis id repeats in the frame)."""
        self.n = n                                  # rows of motmetrics' matrix (GT of the frame)
        self.kept = kept                            # class-level prediction index of each matrix column
        self.ph = ph
        self.unique_ids = unique_ids
        iso = self.iso.tolist()
        self.pair_d = dict(zip(zip(rows, cols), self.d.tolist()))
        self.col_hid = dict(zip(cols, ph[self.p].tolist()))   # hypothesis id of the candidate columns
        self.row_cols: Dict[int, List[int]] = {}
        for r, j, i in zip(rows, cols, iso):
            if not i:
                self.row_cols.setdefault(r, []).append(j)
        self.rows = sorted(self.row_cols)           # contested rows, ascending
        self.iso_rows = [r for r, i in zip(rows, iso) if i]
        self.iso_cols = [j for j, i in zip(cols, iso) if i]
        self._dist = None

    @property
    def hids(self) -> List[int]:
        """Hypothesis id of every column."""
        return self.ph[self.kept].tolist()

    @property
    def dist(self) -> np.ndarray:
        """motmetrics' distance matrix of the frame: exact distances, NaN where >= the threshold."""
        if self._dist is None:
            m = np.full((self.n, len(self.kept)), np.nan)
            for (r, j), v in self.pair_d.items():
                m[r, j] = v
            self._dist = m
        return self._dist


@dataclass
class _PassResult:
    g: np.ndarray           # matched GT indices
    p: np.ndarray           # matched prediction indices
    d: np.ndarray           # distances of the matches
    switch: np.ndarray      # SWITCH (True) or MATCH (False)
    n_kept: int
    n_frames: int
    frame_id: np.ndarray    # devkit frame id of every frame (-1 where the frame has no event)


class _ClassEval:
    """Accumulation for one class, all thresholds."""

    def __init__(self, flat: _Flat, c: int, dist_th: float):
        self.dist_th = float(dist_th)
        gi = np.flatnonzero(flat.g_cls == c)
        pi = np.flatnonzero(flat.p_cls == c)
        self.n_frames = flat.n_frames
        self.gf = flat.g_frame[gi]
        self.go = flat.g_obj[gi]
        self.gxy = np.ascontiguousarray(flat.g_xy[gi])
        self.pf = flat.p_frame[pi]
        self.ph = flat.p_hyp[pi]
        self.pxy = np.ascontiguousarray(flat.p_xy[pi])
        self.ps = flat.p_score[pi]
        self.n_gt = len(gi)
        # Distinct GT tracking ids of the class (the devkit's ML when no threshold is achieved).
        self.n_gt_ids = len({flat.obj_raw_id[o] for o in set(self.go.tolist())})
        # Squared norms as scikit-learn computes them (row-wise einsum: independent of the other rows).
        self.gxx = np.einsum("ij,ij->i", self.gxy, self.gxy)
        self.pyy = np.einsum("ij,ij->i", self.pxy, self.pxy)
        frames = np.arange(flat.n_frames + 1)
        self.g_ptr = np.searchsorted(self.gf, frames)
        self.p_ptr = np.searchsorted(self.pf, frames)
        self.n_f = np.diff(self.g_ptr)
        # Frames where a hypothesis id occurs twice (the devkit's "first unmasked column with that id" matters).
        self.frame_dup_hyp = np.zeros(flat.n_frames, dtype=bool)
        if len(self.ph) > 1:
            order = np.lexsort((self.ph, self.pf))
            dup = (self.pf[order][1:] == self.pf[order][:-1]) & (self.ph[order][1:] == self.ph[order][:-1])
            self.frame_dup_hyp[self.pf[order][1:][dup]] = True
        self._cache: Dict[Tuple[int, int], _Subset] = {}
        self._pass_cache: Dict[int, _PassResult] = {}
        self._objects()
        self._near()

    # -- static structure ------------------------------------------------------------------------------------

    def _objects(self) -> None:
        """GT boxes sorted by object (stable: by frame within an object)."""
        self.obj_order = np.argsort(self.go, kind="stable")
        go_sorted = self.go[self.obj_order]
        starts = np.flatnonzero(np.r_[True, go_sorted[1:] != go_sorted[:-1]]) if self.n_gt else np.zeros(0, int)
        self.obj_starts = starts
        self.obj_counts = np.diff(np.r_[starts, self.n_gt])
        self.obj_of_sorted = np.repeat(np.arange(len(starts)), self.obj_counts)
        # The devkit expects one event per object and frame (true for nuScenes ground truth).
        gf_sorted = self.gf[self.obj_order]
        dup = (go_sorted[1:] == go_sorted[:-1]) & (gf_sorted[1:] == gf_sorted[:-1])
        self.has_duplicate_gt = bool(dup.any())

    def _near(self) -> None:
        """(GT, prediction) pairs of a frame that could be within the distance threshold (conservative margin
        over the rounding of the devkit's formula), row-major per frame; and the predictions in such a pair."""
        self.p_near = np.zeros(len(self.ps), dtype=bool)
        both = np.flatnonzero((self.n_f > 0) & (np.diff(self.p_ptr) > 0))
        th = self.dist_th
        near_g: List[np.ndarray] = []
        near_p: List[np.ndarray] = []
        for f in both.tolist():
            g0, g1 = self.g_ptr[f], self.g_ptr[f + 1]
            p0, p1 = self.p_ptr[f], self.p_ptr[f + 1]
            gxy = self.gxy[g0:g1]
            pxy = self.pxy[p0:p1]
            approx = np.hypot(gxy[:, 0, None] - pxy[None, :, 0], gxy[:, 1, None] - pxy[None, :, 1])
            # |x|^2 - 2xy + |y|^2 loses ~1e-16 |x|^2 to rounding: far below this margin near the threshold.
            scale = max(float(np.abs(gxy).max()), float(np.abs(pxy).max()), 1.0)
            ii, jj = np.nonzero(approx < th + 1e-3 + 1e-12 * scale * scale)
            near_g.append(g0 + ii)
            near_p.append(p0 + jj)
        self.near_g = np.concatenate(near_g) if near_g else np.zeros(0, np.int64)
        self.near_p = np.concatenate(near_p) if near_p else np.zeros(0, np.int64)
        self.p_near[self.near_p] = True
        self.near_ptr = np.searchsorted(self.gf[self.near_g], np.arange(self.n_frames + 1))

    # -- candidate pairs ---------------------------------------------------------------------------------------

    def _compute_subsets(self, missing: List[Tuple[int, int]], kept: np.ndarray, ck: np.ndarray) -> None:
        """Exact distances and candidate pairs of frames with their kept predictions; cached by (frame, number
        kept): the kept sets of a frame are nested, so the count identifies the set.

        The devkit calls ``euclidean_distances(gt_xy, kept_pred_xy)`` per frame: ``-2 X.Y^T + |X|^2 + |Y|^2``,
        clipped at 0, square-rooted. The BLAS product's last bit depends on the matrix shape, so it is made
        per frame on fresh arrays of the devkit's shapes; the rest is elementwise and done for all frames at
        once, on the pairs that can be candidates.
        """
        kept_idx = np.flatnonzero(kept)
        g_ptr, p_ptr = self.g_ptr, self.p_ptr
        gxy, pxy = self.gxy, self.pxy
        dots = []
        for f, _ in missing:
            g0, g1 = g_ptr[f], g_ptr[f + 1]
            idx = kept_idx[ck[p_ptr[f]]:ck[p_ptr[f + 1]]]
            dots.append((gxy[g0:g1].copy() @ pxy[idx].T).ravel())
        fs = np.asarray([f for f, _ in missing], dtype=np.int64)
        ks = np.asarray([k for _, k in missing], dtype=np.int64)
        ns = self.n_f[fs]
        offsets = np.r_[0, np.cumsum(ns * ks)]
        dot_all = np.concatenate(dots)
        # Near pairs of these frames whose prediction is kept.
        starts = self.near_ptr[fs]
        counts = self.near_ptr[fs + 1] - starts
        sid = np.repeat(np.arange(len(missing)), counts)
        pos = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts) + np.repeat(starts, counts)
        ng, npp = self.near_g[pos], self.near_p[pos]
        sel = kept[npp]
        sid, ng, npp = sid[sel], ng[sel], npp[sel]
        row = ng - g_ptr[fs[sid]]
        col = ck[npp] - ck[p_ptr[fs[sid]]]          # rank of the prediction among the frame's kept ones
        d = -2 * dot_all[offsets[sid] + row * ks[sid] + col]
        d += self.gxx[ng]
        d += self.pyy[npp]
        np.maximum(d, 0, out=d)
        np.sqrt(d, out=d)
        cand = d < self.dist_th                     # the devkit sets distances >= dist_th_tp to NaN
        sid, ng, npp, d, row, col = sid[cand], ng[cand], npp[cand], d[cand], row[cand], col[cand]
        row_off = np.r_[0, np.cumsum(ns)]
        col_off = np.r_[0, np.cumsum(ks)]
        rkey = row_off[sid] + row
        ckey = col_off[sid] + col
        iso = (np.bincount(rkey, minlength=int(row_off[-1]))[rkey] == 1) & \
              (np.bincount(ckey, minlength=int(col_off[-1]))[ckey] == 1)
        n_contested = np.bincount(sid[~iso], minlength=len(missing))
        bounds = np.searchsorted(sid, np.arange(1, len(missing))).tolist()
        parts = zip(np.split(ng, bounds), np.split(npp, bounds), np.split(d, bounds), np.split(iso, bounds))
        cache = self._cache
        for s_, ((f, k), (g_, p_, d_, iso_), nc) in enumerate(zip(missing, parts, n_contested.tolist())):
            g0 = int(g_ptr[f])
            sub = _Subset(g0, g_, p_, d_, iso_, nc == 0)
            if nc:
                lo, hi = (bounds[s_ - 1] if s_ else 0), (bounds[s_] if s_ < len(bounds) else len(sid))
                sub.contest(int(self.n_f[f]), kept_idx[ck[p_ptr[f]]:ck[p_ptr[f + 1]]].copy(), self.ph,
                            row[lo:hi].tolist(), col[lo:hi].tolist(), not self.frame_dup_hyp[f])
            cache[(f, k)] = sub

    # -- one threshold -----------------------------------------------------------------------------------------

    def run_pass(self, kept: np.ndarray) -> _PassResult:
        """Replay the devkit's per-frame accumulation with the predictions in ``kept`` (bool mask)."""
        n_kept = int(kept.sum())
        cached = self._pass_cache.get(n_kept)
        if cached is not None:   # kept sets are nested: same count, same set, same result
            return cached
        ck = np.r_[0, np.cumsum(kept)]
        k_f = ck[self.p_ptr[1:]] - ck[self.p_ptr[:-1]]
        cn = np.r_[0, np.cumsum(kept & self.p_near)]
        near_f = cn[self.p_ptr[1:]] - cn[self.p_ptr[:-1]]
        nonempty = (self.n_f > 0) | (k_f > 0)
        frame_id = np.where(nonempty, np.cumsum(nonempty) - 1, -1)

        # Frames with at least one candidate pair; the others only produce misses and false positives.
        active = np.flatnonzero((self.n_f > 0) & (near_f > 0))
        cache = self._cache
        keys = list(zip(active.tolist(), k_f[active].tolist()))
        missing = [key for key in keys if key not in cache]
        if missing:
            self._compute_subsets(missing, kept, ck)
        subs = [cache[key] for key in keys]
        hard = [(f, sub) for (f, _), sub in zip(keys, subs) if not sub.simple]

        # Isolated pairs: matched whatever the state.
        if subs:
            g = np.concatenate([s.g if s.simple else s.g[s.iso] for s in subs])
            p = np.concatenate([s.p if s.simple else s.p[s.iso] for s in subs])
            d = np.concatenate([s.d if s.simple else s.d[s.iso] for s in subs])
        else:
            g = np.zeros(0, np.int64)
            p = np.zeros(0, np.int64)
            d = np.zeros(0, np.float64)
        if hard:
            hg, hp, hd = self._replay_contested(hard, g, p)
            g = np.concatenate([g, hg])
            p = np.concatenate([p, hp])
            d = np.concatenate([d, hd])

        # SWITCH: the object's previous partner (MOTAccumulator.m, last match in an earlier frame) differs.
        o = self.go[g]
        h = self.ph[p]
        order = np.lexsort((self.gf[g], o))
        o_s, h_s = o[order], h[order]
        sw = np.zeros(len(order), dtype=bool)
        if len(order) > 1:
            sw[order[1:]] = (o_s[1:] == o_s[:-1]) & (h_s[1:] != h_s[:-1])

        res = _PassResult(g=g, p=p, d=d, switch=sw, n_kept=n_kept, n_frames=int(nonempty.sum()),
                          frame_id=frame_id)
        self._pass_cache[n_kept] = res
        return res

    def _replay_contested(self, hard: List[Tuple[int, _Subset]], g_iso: np.ndarray, p_iso: np.ndarray):
        """motmetrics' ``MOTAccumulator.update`` for the contested rows, frame by frame in time order.

        1. an object keeps its previous partner (``MOTAccumulator.m``) if that hypothesis (the first unmasked
           column with its id) is within distance; 2. the rest goes to ``motmetrics.lap.linear_sum_assignment``
           on the very matrix motmetrics builds, unless what is left is one-to-one (then all of it matches).
        The previous partner of an object is its last match before the frame: among the isolated pairs (all
        known) or the contested matches replayed before.
        """
        go, ph, gf = self.go, self.ph, self.gf
        nf = self.n_frames + 1
        key_iso = go[g_iso] * nf + gf[g_iso]
        order = np.argsort(key_iso, kind="stable")
        key_sorted = key_iso[order]
        h_sorted = ph[p_iso][order]
        last: Dict[int, Tuple[int, int]] = {}   # object -> (frame, hypothesis) of its last contested match

        def isolated_prev(rows: List[int], g0: int, f: int) -> Tuple[List[int], List[int], List[int]]:
            """Objects of the rows, and (frame, hypothesis) of their last isolated match before f (-1: none)."""
            objs = go[g0 + np.asarray(rows, dtype=np.int64)]
            if len(key_sorted) == 0:
                return objs.tolist(), [-1] * len(rows), [-1] * len(rows)
            q = np.searchsorted(key_sorted, objs * nf + f) - 1
            qc = np.maximum(q, 0)
            ok = (q >= 0) & (key_sorted[qc] // nf == objs)
            return (objs.tolist(), np.where(ok, key_sorted[qc] % nf, -1).tolist(),
                    np.where(ok, h_sorted[qc], -1).tolist())

        def state(rows: List[int], g0: int, f: int) -> Tuple[List[int], List[int]]:
            """Objects of the rows and their previous partner (-1: none) before frame f."""
            objs, pf, hp = isolated_prev(rows, g0, f)
            for t, o in enumerate(objs):
                lc = last.get(o)
                if lc is not None and lc[0] > pf[t]:
                    hp[t] = lc[1]
            return objs, hp

        # Isolated-match state of every contested row of every frame, in one search.
        all_rows = np.concatenate([sub.g0 + np.asarray(sub.rows, dtype=np.int64) for _, sub in hard])
        all_f = np.repeat(np.asarray([f for f, _ in hard], dtype=np.int64), [len(sub.rows) for _, sub in hard])
        all_objs = go[all_rows]
        if len(key_sorted):
            q = np.searchsorted(key_sorted, all_objs * nf + all_f) - 1
            qc = np.maximum(q, 0)
            ok = (q >= 0) & (key_sorted[qc] // nf == all_objs)
            pf_all = np.where(ok, key_sorted[qc] % nf, -1).tolist()
            hp_all = np.where(ok, h_sorted[qc], -1).tolist()
        else:
            pf_all = [-1] * len(all_objs)
            hp_all = [-1] * len(all_objs)
        objs_all = all_objs.tolist()

        out_g: List[int] = []
        out_p: List[int] = []
        out_d: List[float] = []
        at = 0
        for f, sub in hard:
            rows = sub.rows
            nr = len(rows)
            objs = objs_all[at:at + nr]
            prev = hp_all[at:at + nr]
            for t, o in enumerate(objs):
                lc = last.get(o)
                if lc is not None and lc[0] > pf_all[at + t]:
                    prev[t] = lc[1]
            at += nr
            if not sub.unique_ids:
                prev_all = dict(zip(rows, prev))
                prev_all.update(zip(sub.iso_rows, state(sub.iso_rows, sub.g0, f)[1]))
                matched = self._update_generic(sub, prev_all)
            else:
                row_cols, col_hid = sub.row_cols, sub.col_hid
                hmask = set()
                omask = set()
                matched = []
                for r, hp in zip(rows, prev):
                    if hp < 0:
                        continue
                    # Ids are unique: the partner's column, if within distance, is one of the row's candidates.
                    for j in row_cols[r]:
                        if col_hid[j] == hp:
                            if j not in hmask:
                                hmask.add(j)
                                omask.add(r)
                                matched.append((r, j))
                            break
                # What the contested rows have left; isolated pairs never share a row or column with them.
                rest = [(r, j) for r in rows if r not in omask for j in row_cols[r] if j not in hmask]
                rr = {r for r, _ in rest}
                cc = {j for _, j in rest}
                if len(rr) == len(rest) and len(cc) == len(rest):
                    matched.extend(rest)
                else:
                    # Solver needed, on motmetrics' matrix: the isolated rows that kept their previous
                    # partner in step 1 are masked there too.
                    iso_prev = state(sub.iso_rows, sub.g0, f)[1]
                    for r, j, hh in zip(sub.iso_rows, sub.iso_cols, iso_prev):
                        if hh == sub.col_hid[j]:
                            omask.add(r)
                            hmask.add(j)
                    dm = sub.dist.copy()
                    dm[sorted(omask), :] = np.nan
                    dm[:, sorted(hmask)] = np.nan
                    contested = set(rows)
                    r2, c2 = _assign(dm)
                    matched.extend((r, j) for r, j in zip(r2.tolist(), c2.tolist()) if r in contested)
            row_obj = dict(zip(rows, objs))
            kept, col_hid, pair_d, g0 = sub.kept, sub.col_hid, sub.pair_d, sub.g0
            for r, j in matched:
                out_g.append(g0 + r)
                out_p.append(int(kept[j]))
                out_d.append(pair_d[(r, j)])
                last[row_obj[r]] = (f, col_hid[j])
        return (np.asarray(out_g, dtype=np.int64), np.asarray(out_p, dtype=np.int64),
                np.asarray(out_d, dtype=np.float64))

    @staticmethod
    def _update_generic(sub: _Subset, prev: Dict[int, int]) -> List[Tuple[int, int]]:
        """Full ``MOTAccumulator.update`` of a frame whose hypothesis ids repeat (``prev``: previous partner of
        every row with a candidate, -1 if none); returns the matches of the contested rows."""
        dist = sub.dist
        n, k = dist.shape
        finite = ~np.isnan(dist)
        hids = np.asarray(sub.hids)
        omask = np.zeros(n, dtype=bool)
        hmask = np.zeros(k, dtype=bool)
        pairs: List[Tuple[int, int]] = []
        for r in np.flatnonzero(finite.any(axis=1)).tolist():
            hp = prev.get(r, -1)
            if hp < 0:
                continue
            js = np.flatnonzero(~hmask & (hids == hp))
            if len(js) == 0 or not finite[r, js[0]]:
                continue
            omask[r] = True
            hmask[js[0]] = True
            pairs.append((r, int(js[0])))
        dm = dist.copy()
        dm[omask, :] = np.nan
        dm[:, hmask] = np.nan
        r2, c2 = _assign(dm)
        pairs.extend(zip(r2.tolist(), c2.tolist()))
        contested = set(sub.rows)
        return [(r, j) for r, j in pairs if r in contested]

    # -- metrics of one threshold --------------------------------------------------------------------------------

    def pass_metrics(self, res: _PassResult) -> Dict[str, float]:
        n_obj = self.n_gt
        n_det = len(res.g)
        n_sw = int(res.switch.sum())
        n_match = n_det - n_sw
        n_miss = n_obj - n_det
        n_fp = res.n_kept - n_det

        matched = np.zeros(self.n_gt, dtype=bool)
        matched[res.g] = True
        ms = matched[self.obj_order]
        fid = res.frame_id[self.gf[self.obj_order]]
        starts = self.obj_starts
        counts = self.obj_counts
        n_objects = len(starts)
        tracked = np.add.reduceat(ms.astype(np.int64), starts) if n_objects else np.zeros(0, np.int64)
        ratio = tracked / counts
        mt = int(np.count_nonzero(ratio >= 0.8))
        ml = int(np.count_nonzero(ratio < 0.2))

        pos = np.arange(self.n_gt)
        big = self.n_gt + 1
        first_m = np.minimum.reduceat(np.where(ms, pos, big), starts) if n_objects else pos[:0]
        last_m = np.maximum.reduceat(np.where(ms, pos, -1), starts) if n_objects else pos[:0]
        is_tracked = tracked > 0
        first_fid = fid[starts]
        last_fid = fid[starts + counts - 1]
        n_tracked = int(is_tracked.sum())

        # TID: frames from first appearance to first match; LGD: longest run of unmatched frame ids in the span.
        ft = first_m[is_tracked]
        lt = last_m[is_tracked]
        lead = fid[ft] - first_fid[is_tracked]
        trail = last_fid[is_tracked] - fid[lt]
        gaps = np.maximum(lead, trail)
        mpos = np.flatnonzero(ms)
        if len(mpos) > 1:
            same = self.obj_of_sorted[mpos[1:]] == self.obj_of_sorted[mpos[:-1]]
            inner = fid[mpos[1:]] - fid[mpos[:-1]] - 1
            inner_gap = np.zeros(n_objects, dtype=np.int64)
            np.maximum.at(inner_gap, self.obj_of_sorted[mpos[1:]][same], inner[same])
            gaps = np.maximum(gaps, inner_gap[is_tracked])
        # FRAG: matched -> missed transitions inside [first match, last match] of each object.
        frag = 0
        if self.n_gt > 1:
            trans = np.flatnonzero(ms[:-1] & ~ms[1:]) + 1
            if len(trans):
                obj_t = self.obj_of_sorted[trans]
                same = obj_t == self.obj_of_sorted[trans - 1]
                frag = int(np.count_nonzero(same & (trans <= last_m[obj_t])))

        if n_tracked == 0:
            tid = np.nan
            lgd = np.nan
        else:
            tid = float(np.sum(lead * 0.5)) / n_tracked
            lgd = float(np.sum(gaps * 0.5)) / n_tracked

        # motmetrics / devkit formulas, same operation order.
        recall_m = n_match / n_obj
        nominator = (n_miss + n_sw + n_fp) - (1 - recall_m) * n_obj
        denominator = recall_m * n_obj
        motar = np.nan if denominator == 0 else max(0.0, 1 - 1.0 * nominator / denominator)
        mota = max(0.0, 1. - (n_miss + n_sw + n_fp) / n_obj)
        motp = np.nan if n_det == 0 else float(np.sum(res.d)) / n_det
        faf = n_fp / res.n_frames * 100
        recall = n_det / n_obj
        return {"gt": n_obj, "tp": n_match, "motar": motar, "mota": mota, "motp": motp, "faf": faf, "mt": mt,
                "ml": ml, "fp": n_fp, "fn": n_miss, "ids": n_sw, "frag": frag, "recall": recall, "tid": tid,
                "lgd": lgd}

    def match_scores(self, res: _PassResult) -> np.ndarray:
        """Scores the devkit collects without a threshold: every prediction of a frame whose id had a MATCH
        (not SWITCH) event in that frame."""
        mp = res.p[~res.switch]
        keys = self.pf[mp] * (int(self.ph.max()) + 1 if len(self.ph) else 1) + self.ph[mp]
        all_keys = self.pf * (int(self.ph.max()) + 1 if len(self.ph) else 1) + self.ph
        return self.ps[np.isin(all_keys, keys)]


def _assign(dm: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Pairs (rows, cols) motmetrics' step 2 keeps for the masked distance matrix ``dm`` (NaN: no pairing).

    When the finite entries form a one-to-one matching, every optimal assignment contains all of them (the
    solver first maximises the number of finite pairs: motmetrics makes the others expensive enough), so no
    solver is needed; otherwise the same matrix goes to :func:`grutrack.evaluation.lsap.motmetrics_lsa`
    (``motmetrics.lap.linear_sum_assignment`` with its scipy solver, ties included, without their imports).
    """
    ii, jj = np.nonzero(~np.isnan(dm))
    if len(ii) == 0 or not ((ii[1:] == ii[:-1]).any() or np.bincount(jj).max() > 1):
        return ii, jj
    from grutrack.evaluation.lsap import motmetrics_lsa

    return motmetrics_lsa(dm)


class _NeedsDevkit(Exception):
    """Raised for inputs outside the fast path's assumptions (duplicate GT ids in a frame)."""


# ----------------------------------------------------------------------------------------------------------------
# Thresholds and metric data (TrackingEvaluation.accumulate)
# ----------------------------------------------------------------------------------------------------------------

def _compute_thresholds(scores: np.ndarray, gt_box_count: int, min_recall: float, num_thresholds: int):
    if len(scores) == 0:
        return [np.nan] * num_thresholds, [np.nan] * num_thresholds
    scores = np.array(scores)
    scores.sort()
    scores = scores[::-1]
    tps = np.array(range(1, len(scores) + 1))
    rec = tps / gt_box_count
    assert len(scores) / gt_box_count <= 1
    max_recall_achieved = np.max(rec)
    rec_interp = np.linspace(min_recall, 1, num_thresholds).round(12)
    thresholds = np.interp(rec_interp, rec, scores, right=0)
    thresholds[rec_interp > max_recall_achieved] = np.nan
    thresholds = list(thresholds.tolist())
    rec_interp = list(rec_interp.tolist())
    thresholds.reverse()
    rec_interp.reverse()
    return thresholds, rec_interp


def _accumulate_class(ce: _ClassEval, cfg, nelem: int):
    from grutrack.evaluation.tracking_classes import TrackingMetricData

    md = TrackingMetricData()
    if ce.n_gt == 0:
        return md
    if ce.has_duplicate_gt:
        raise _NeedsDevkit()

    all_kept = np.ones(len(ce.ps), dtype=bool)
    scores = ce.match_scores(ce.run_pass(all_kept))
    thresholds, recalls = _compute_thresholds(scores, ce.n_gt, cfg.min_recall, nelem)
    md.confidence = thresholds
    md.recall_hypo = recalls

    thresh_metrics: List[Dict[str, float]] = []
    for t, threshold in enumerate(thresholds):
        if np.isnan(threshold) or threshold in thresholds[:t]:
            continue
        thresh_metrics.append(ce.pass_metrics(ce.run_pass(ce.ps >= threshold)))

    num_unachieved = len([t for t in thresholds if np.isnan(t)])
    valid = [t for t in thresholds if not np.isnan(t)]
    assert valid == sorted(valid)
    assert num_unachieved + len(valid) - len(np.unique(valid)) + len(thresh_metrics) == nelem
    rep_counts = [int(np.sum(np.asarray(thresholds) == t)) for t in np.unique(valid)]

    for name in _MOT_METRICS:
        if not thresh_metrics:
            worst = cfg.metric_worst[name]
            if worst == -1:
                if name == "ml":
                    worst = ce.n_gt_ids
                elif name in ("gt", "fn"):
                    worst = ce.n_gt
                elif name in ("fp", "ids", "frag"):
                    worst = np.nan
                else:
                    raise NotImplementedError
            values = [worst] * nelem
        else:
            per = [m[name] for m in thresh_metrics]
            assert len(rep_counts) == len(per)
            values = [np.nan] * num_unachieved
            for v, r in zip(per, rep_counts):
                values.extend([v] * r)
        md.set_metric(name, values)
    return md


def _devkit_accumulate(tracks_gt, tracks_pred, class_name: str, cfg, nelem: int):
    """Fallback to the devkit's own accumulation for one class (inputs the fast path does not model)."""
    from nuscenes.eval.tracking.algo import TrackingEvaluation

    from grutrack.evaluation.tracking_classes import devkit_config

    cfg = devkit_config(cfg)  # sets the devkit's TrackingMetricData.nelem
    ev = TrackingEvaluation(tracks_gt, tracks_pred, class_name, cfg.dist_fcn_callable, cfg.dist_th_tp,
                            cfg.min_recall, num_thresholds=nelem, metric_worst=cfg.metric_worst, verbose=False)
    return ev.accumulate()


# ----------------------------------------------------------------------------------------------------------------
# Public API
# ----------------------------------------------------------------------------------------------------------------

def evaluate_tracks(tracks_gt, tracks_pred, config=None):
    """The fast equivalent of ``TrackingEval.evaluate`` on tracks from :func:`load_tracks`.

    :return: ``(TrackingMetrics, TrackingMetricDataList)`` (:mod:`grutrack.evaluation.tracking_classes`: the
        devkit's classes without the devkit import, same ``serialize()``), eval_time set to this call's time.
    """
    from grutrack.evaluation.tracking_classes import (AVG_METRIC_MAP, MOT_METRIC_MAP, TrackingMetricData,
                                                      TrackingMetricDataList, TrackingMetrics)

    start = time.time()
    cfg = config if config is not None else _default_config()
    assert cfg.dist_fcn == "center_distance"
    TrackingMetricData.nelem = nelem = cfg.num_thresholds
    metrics = TrackingMetrics(cfg)
    md_list = TrackingMetricDataList()

    flat = _flatten(tracks_gt, tracks_pred, cfg.class_names)
    for c, class_name in enumerate(cfg.class_names):
        ce = _ClassEval(flat, c, cfg.dist_th_tp)
        try:
            md = _accumulate_class(ce, cfg, nelem)
        except _NeedsDevkit:
            md = _devkit_accumulate(tracks_gt, tracks_pred, class_name, cfg, nelem)
        md_list.set(class_name, md)

    for class_name in cfg.class_names:
        md = md_list[class_name]
        best = None if np.all(np.isnan(md.mota)) else np.nanargmax(md.mota)
        if best is not None:
            for metric_name in MOT_METRIC_MAP.values():
                if metric_name == "":
                    continue
                metrics.add_label_metric(metric_name, class_name, md.get_metric(metric_name)[best])
        for metric_name, per_threshold in AVG_METRIC_MAP.items():
            values = np.array(md.get_metric(per_threshold))
            if np.all(np.isnan(values)):
                value = np.nan
            else:
                values[np.isnan(values)] = cfg.metric_worst[metric_name]
                value = float(np.nanmean(values))
            metrics.add_label_metric(metric_name, class_name, value)

    metrics.add_runtime(time.time() - start)
    return metrics, md_list


#: decision codes of :class:`MatchDecisions` (GT and prediction boxes)
MATCH, SWITCH, MISS_OR_FP, BELOW_THRESHOLD, UNSCORED = 0, 1, 2, 3, 4


@dataclass
class MatchDecisions:
    """The evaluator's own decision for every evaluated box, at each class's best-MOTA threshold.

    Boxes are those the metrics read (after the class-range / zero-point filter and, for predictions, the
    track-gap interpolation), in the devkit's frame order. Decision codes: ``MATCH`` (TP), ``SWITCH`` (matched,
    counted as an id switch, not a TP), ``MISS_OR_FP`` (GT: missed, FN; prediction: kept but unmatched, FP),
    ``BELOW_THRESHOLD`` (prediction whose track score is under its class's threshold: not scored) and
    ``UNSCORED`` (every box of a class for which no threshold is achieved: the devkit reports TP 0, FN = GT
    and no FP / IDS; its GT are still counted as misses, code ``MISS_OR_FP``).

    frame_keys: (scene token, timestamp in microseconds) of every frame index.
    g_frame, g_cls, g_status: (G,) int64; g_id: (G,) tracking ids (instance tokens); g_xy: (G, 2) float64,
    global frame, metres. p_frame, p_cls, p_status: (P,) int64; p_id: (P,) track ids; p_xy: (P, 2) float64,
    metres; p_score: (P,) float64 track score (mean box score of the track, as the devkit computes it).
    g_partner: (G,) int64 index of the matched prediction, -1 if none.
    thresholds: {class: best-MOTA threshold, or None when the class has none}.
    """
    frame_keys: List[Tuple[Any, Any]]
    g_frame: np.ndarray
    g_cls: np.ndarray
    g_id: List[Any]
    g_xy: np.ndarray
    g_status: np.ndarray
    g_partner: np.ndarray
    p_frame: np.ndarray
    p_cls: np.ndarray
    p_id: List[Any]
    p_xy: np.ndarray
    p_score: np.ndarray
    p_status: np.ndarray
    thresholds: Dict[str, Any]
    class_names: List[str]


def match_decisions(tracks_gt, tracks_pred, config=None) -> Tuple[MatchDecisions, Any]:
    """Per-box decisions of the tracking evaluation (what :func:`evaluate_tracks` counts at each class's
    best-MOTA threshold): summing them per class gives the summary's TP, FP, FN and IDS exactly.

    :return: ``(MatchDecisions, TrackingMetrics)``; the metrics are those of :func:`evaluate_tracks`.
    :raises ValueError: for ground truth the fast path does not model (duplicate GT ids in a frame).
    """
    cfg = config if config is not None else _default_config()
    assert cfg.dist_fcn == "center_distance"
    nelem = cfg.num_thresholds
    flat = _flatten(tracks_gt, tracks_pred, cfg.class_names)
    g_status = np.full(len(flat.g_frame), MISS_OR_FP, dtype=np.int64)
    g_partner = np.full(len(flat.g_frame), -1, dtype=np.int64)
    p_status = np.full(len(flat.p_frame), UNSCORED, dtype=np.int64)
    thresholds: Dict[str, Any] = {}
    for c, class_name in enumerate(cfg.class_names):
        ce = _ClassEval(flat, c, cfg.dist_th_tp)
        try:
            md = _accumulate_class(ce, cfg, nelem)
        except _NeedsDevkit as exc:
            raise ValueError("ground truth with a repeated id in one frame (class %s): per-box decisions are "
                             "not available" % class_name) from exc
        thresholds[class_name] = None
        if ce.n_gt == 0 or np.all(np.isnan(md.mota)):
            continue
        threshold = md.confidence[int(np.nanargmax(md.mota))]
        if threshold is None or np.isnan(threshold):
            continue
        thresholds[class_name] = float(threshold)
        kept = ce.ps >= threshold
        res = ce.run_pass(kept)
        gi = np.flatnonzero(flat.g_cls == c)
        pi = np.flatnonzero(flat.p_cls == c)
        p_status[pi] = np.where(kept, MISS_OR_FP, BELOW_THRESHOLD)
        g_status[gi[res.g]] = np.where(res.switch, SWITCH, MATCH)
        p_status[pi[res.p]] = np.where(res.switch, SWITCH, MATCH)
        g_partner[gi[res.g]] = pi[res.p]
    metrics, _ = evaluate_tracks(tracks_gt, tracks_pred, cfg)
    decisions = MatchDecisions(
        frame_keys=flat.frame_keys, g_frame=flat.g_frame, g_cls=flat.g_cls,
        g_id=[flat.obj_raw_id[o] for o in flat.g_obj.tolist()], g_xy=flat.g_xy, g_status=g_status,
        g_partner=g_partner, p_frame=flat.p_frame, p_cls=flat.p_cls, p_id=flat.p_raw_id, p_xy=flat.p_xy,
        p_score=flat.p_score, p_status=p_status, thresholds=thresholds, class_names=list(cfg.class_names))
    return decisions, metrics


def fast_tracking_eval(nusc, submission: Union[dict, str, os.PathLike], eval_split: str, config=None,
                       verbose: bool = False, *, loader: str = "fast") -> dict:
    """Evaluate a nuScenes tracking submission; returns what ``TrackingEval.main`` writes as
    ``metrics_summary.json`` (``TrackingMetrics.serialize()`` plus ``meta``), with the same numbers.

    :param nusc: a loaded ``nuscenes.NuScenes``.
    :param submission: the tracking-submission dict (``{"meta": ..., "results": {sample_token: [box, ...]}}``)
        or the path of its JSON file.
    :param eval_split: a predefined split name (``mini_val``, ``val``, ...) or a custom split of
        ``<dataroot>/<version>/splits.json``.
    :param config: a devkit ``TrackingConfig`` (or :class:`grutrack.evaluation.tracking_classes.TrackingConfig`);
        default: the devkit's ``tracking_nips_2019``.
    :param verbose: print the loading messages and the final metrics table.
    :param loader: ``"fast"`` (exact re-implementation of the devkit's loading, devkit fallback) or
        ``"devkit"`` (the devkit's loaders); see :func:`load_tracks`.
    ``eval_time`` is this implementation's accumulation + metrics time (what the devkit times there too).
    """
    cfg = config if config is not None else _default_config()
    tracks_gt, tracks_pred, meta = load_tracks(nusc, submission, eval_split, cfg, verbose=verbose, loader=loader)
    metrics, _ = evaluate_tracks(tracks_gt, tracks_pred, cfg)
    summary = metrics.serialize()
    summary["meta"] = meta.copy()
    if verbose:
        from nuscenes.eval.tracking.utils import print_final_metrics

        print_final_metrics(metrics)
    return summary
