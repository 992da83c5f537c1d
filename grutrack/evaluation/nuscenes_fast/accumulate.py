"""The devkit's per-threshold accumulation (motmetrics' ``MOTAccumulator``, one per scene) for one class.

``TrackingEvaluation.accumulate`` (nuscenes-devkit 1.2.0) runs a motmetrics 1.4.0 ``MOTAccumulator`` frame by
frame for every one of a class's recall thresholds. :class:`ClassAccumulator` gives the same MATCH / SWITCH
events, for any set of kept predictions (:meth:`ClassAccumulator.run_pass`):

* the centre distances are computed as the devkit's ``sklearn.metrics.pairwise.euclidean_distances`` call does
  (same formula; the BLAS product on a matrix of the devkit's shape, whose last bit depends on that shape), once
  per frame and distinct set of kept predictions, cached across thresholds;
* a candidate pair (distance < ``dist_th_tp``) whose GT and prediction have no other candidate is matched
  whatever motmetrics' state (every optimal assignment contains it), so most pairs of all frames are matched at
  once with array operations, MATCH or SWITCH following from the object's previous partner;
* the rows with competing candidates replay ``MOTAccumulator.update`` in time order: keep the previous pairing
  if still within distance, then motmetrics' ``linear_sum_assignment`` on the very matrix motmetrics builds
  (:mod:`~grutrack.evaluation.nuscenes_fast.motmetrics_assignment`: ties broken as motmetrics breaks them),
  unless what is left is one-to-one.

:meth:`ClassAccumulator.events` stacks the passes of several thresholds into :class:`ThresholdEvents`, what
:func:`~grutrack.evaluation.nuscenes_fast.clear.clear_metrics` reads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grutrack.evaluation.nuscenes_fast import motmetrics_assignment
from grutrack.evaluation.nuscenes_fast.clear import ThresholdEvents
from grutrack.evaluation.nuscenes_fast.flatten import FlatBoxes

__all__ = ["ClassAccumulator", "NeedsDevkit", "PassResult", "exact_center_distances"]


class NeedsDevkit(Exception):
    """Raised for inputs outside the fast path's assumptions (duplicate GT ids in a frame)."""


def exact_center_distances(gt_xy: np.ndarray, pred_xy: np.ndarray) -> np.ndarray:
    """(n, m) float64 BEV centre distances (metres), bit-identical to the devkit's
    ``euclidean_distances(gt_xy, pred_xy)``.

    scikit-learn computes ``sqrt(max(-2 X.Y^T + |X|^2 + |Y|^2, 0))`` with a BLAS product whose last bit depends
    on the matrix shape; the devkit calls it once per frame on the kept predictions, so this must be called on
    the same rows, in the same order. Inputs are fresh C-contiguous (n, 2) and (m, 2) float64 arrays.
    """
    xx = np.einsum("ij,ij->i", gt_xy, gt_xy)[:, None]
    yy = np.einsum("ij,ij->i", pred_xy, pred_xy)[None, :]
    d = -2 * (gt_xy @ pred_xy.T)
    d += xx
    d += yy
    np.maximum(d, 0, out=d)
    return np.sqrt(d, out=d)


def _assign(dm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (rows, cols) motmetrics' step 2 keeps for the masked distance matrix ``dm`` (NaN: no pairing).

    When the finite entries form a one-to-one matching, every optimal assignment contains all of them (the
    solver first maximises the number of finite pairs: motmetrics makes the others expensive enough), so no
    solver is needed; otherwise the same matrix goes to
    :func:`~grutrack.evaluation.nuscenes_fast.motmetrics_assignment.motmetrics_lsa`.
    """
    ii, jj = np.nonzero(~np.isnan(dm))
    if len(ii) == 0 or not ((ii[1:] == ii[:-1]).any() or np.bincount(jj).max() > 1):
        return ii, jj
    return motmetrics_assignment.motmetrics_lsa(dm)


class _Subset:
    """Candidate pairs of one frame for one set of kept predictions (cached across thresholds).

    A pair is *isolated* when its GT row and its prediction column have no other candidate: motmetrics matches
    such a pair whatever its state (every optimal assignment contains it), so only the other ("contested")
    rows need the state machine.
    """

    __slots__ = (
        "g0",
        "g",
        "p",
        "d",
        "iso",
        "simple",
        "n",
        "kept",
        "ph",
        "unique_ids",
        "col_hid",
        "rows",
        "row_cols",
        "pair_d",
        "iso_rows",
        "iso_cols",
        "_dist",
    )

    def __init__(self, g0: int, g: np.ndarray, p: np.ndarray, d: np.ndarray, iso: np.ndarray, simple: bool):
        self.g0 = g0  # class-level index of the frame's first GT
        self.g = g  # class-level GT index of each candidate pair
        self.p = p  # class-level prediction index of each candidate pair
        self.d = d  # exact distance of each pair
        self.iso = iso  # pair is isolated
        self.simple = simple  # every pair isolated

    def contest(
        self, n: int, kept: np.ndarray, ph: np.ndarray, rows: list[int], cols: list[int], unique_ids: bool
    ) -> None:
        """Python-side structures for the state machine of a frame with contested rows (``rows``, ``cols``: the
        local matrix position of each candidate pair; ``unique_ids``: no hypothesis id repeats in the frame)."""
        self.n = n  # rows of motmetrics' matrix (GT of the frame)
        self.kept = kept  # class-level prediction index of each matrix column
        self.ph = ph
        self.unique_ids = unique_ids
        iso = self.iso.tolist()
        self.pair_d = dict(zip(zip(rows, cols), self.d.tolist()))
        self.col_hid = dict(zip(cols, ph[self.p].tolist()))  # hypothesis id of the candidate columns
        self.row_cols: dict[int, list[int]] = {}
        for r, j, i in zip(rows, cols, iso):
            if not i:
                self.row_cols.setdefault(r, []).append(j)
        self.rows = sorted(self.row_cols)  # contested rows, ascending
        self.iso_rows = [r for r, i in zip(rows, iso) if i]
        self.iso_cols = [j for j, i in zip(cols, iso) if i]
        self._dist = None

    @property
    def hids(self) -> list[int]:
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
class PassResult:
    """The events of one pass (one set of kept predictions) of one class, K matches.

    g, p: (K,) int64 class-level index of the matched GT box / prediction (isolated pairs first, then the
    contested ones in time order: :attr:`d`'s sum depends on that order); d: (K,) float64 their centre
    distances, metres; switch: (K,) bool, SWITCH (True) or MATCH (False); n_kept: predictions kept; n_frames:
    frames with an event; frame_id: (F,) int64 devkit frame id of every frame (-1 where it has no event).
    """

    g: np.ndarray
    p: np.ndarray
    d: np.ndarray
    switch: np.ndarray
    n_kept: int
    n_frames: int
    frame_id: np.ndarray


class ClassAccumulator:
    """The accumulation of one class (index ``c`` of the flattened classes) at any threshold.

    Class-level arrays, G GT boxes and P predictions in frame order: gf, go (G,) int64 frame and object;
    gxy (G, 2) float64 metres; pf, ph (P,) int64 frame and hypothesis; pxy (P, 2) float64 metres; ps (P,)
    float64 track score. obj_order (G,): the GT boxes sorted by object, then frame; obj_starts / obj_counts (O,)
    int64: each object's first position in that order and its box count.
    """

    def __init__(self, flat: FlatBoxes, c: int, dist_th: float):
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
        self._cache: dict[tuple[int, int], _Subset] = {}
        self._pass_cache: dict[int, PassResult] = {}
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
        near_g: list[np.ndarray] = []
        near_p: list[np.ndarray] = []
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

    def _compute_subsets(self, missing: list[tuple[int, int]], kept: np.ndarray, ck: np.ndarray) -> None:
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
            idx = kept_idx[ck[p_ptr[f]] : ck[p_ptr[f + 1]]]
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
        col = ck[npp] - ck[p_ptr[fs[sid]]]  # rank of the prediction among the frame's kept ones
        d = -2 * dot_all[offsets[sid] + row * ks[sid] + col]
        d += self.gxx[ng]
        d += self.pyy[npp]
        np.maximum(d, 0, out=d)
        np.sqrt(d, out=d)
        cand = d < self.dist_th  # the devkit sets distances >= dist_th_tp to NaN
        sid, ng, npp, d, row, col = sid[cand], ng[cand], npp[cand], d[cand], row[cand], col[cand]
        row_off = np.r_[0, np.cumsum(ns)]
        col_off = np.r_[0, np.cumsum(ks)]
        rkey = row_off[sid] + row
        ckey = col_off[sid] + col
        iso = (np.bincount(rkey, minlength=int(row_off[-1]))[rkey] == 1) & (
            np.bincount(ckey, minlength=int(col_off[-1]))[ckey] == 1
        )
        n_contested = np.bincount(sid[~iso], minlength=len(missing))
        bounds = np.searchsorted(sid, np.arange(1, len(missing))).tolist()
        parts = zip(np.split(ng, bounds), np.split(npp, bounds), np.split(d, bounds), np.split(iso, bounds))
        cache = self._cache
        for s_, ((f, k), (g_, p_, d_, iso_), nc) in enumerate(zip(missing, parts, n_contested.tolist())):
            g0 = int(g_ptr[f])
            sub = _Subset(g0, g_, p_, d_, iso_, nc == 0)
            if nc:
                lo, hi = (bounds[s_ - 1] if s_ else 0), (bounds[s_] if s_ < len(bounds) else len(sid))
                sub.contest(
                    int(self.n_f[f]),
                    kept_idx[ck[p_ptr[f]] : ck[p_ptr[f + 1]]].copy(),
                    self.ph,
                    row[lo:hi].tolist(),
                    col[lo:hi].tolist(),
                    not self.frame_dup_hyp[f],
                )
            cache[(f, k)] = sub

    # -- one threshold -----------------------------------------------------------------------------------------

    def run_pass(self, kept: np.ndarray) -> PassResult:
        """Replay the devkit's per-frame accumulation with the predictions in ``kept`` ((P,) bool); cached by the
        number kept (the kept sets of the thresholds are nested)."""
        n_kept = int(kept.sum())
        cached = self._pass_cache.get(n_kept)
        if cached is not None:  # kept sets are nested: same count, same set, same result
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

        res = PassResult(g=g, p=p, d=d, switch=sw, n_kept=n_kept, n_frames=int(nonempty.sum()), frame_id=frame_id)
        self._pass_cache[n_kept] = res
        return res

    def _replay_contested(self, hard: list[tuple[int, _Subset]], g_iso: np.ndarray, p_iso: np.ndarray):
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
        last: dict[int, tuple[int, int]] = {}  # object -> (frame, hypothesis) of its last contested match

        def isolated_prev(rows: list[int], g0: int, f: int) -> tuple[list[int], list[int], list[int]]:
            """Objects of the rows, and (frame, hypothesis) of their last isolated match before f (-1: none)."""
            objs = go[g0 + np.asarray(rows, dtype=np.int64)]
            if len(key_sorted) == 0:
                return objs.tolist(), [-1] * len(rows), [-1] * len(rows)
            q = np.searchsorted(key_sorted, objs * nf + f) - 1
            qc = np.maximum(q, 0)
            ok = (q >= 0) & (key_sorted[qc] // nf == objs)
            return (
                objs.tolist(),
                np.where(ok, key_sorted[qc] % nf, -1).tolist(),
                np.where(ok, h_sorted[qc], -1).tolist(),
            )

        def state(rows: list[int], g0: int, f: int) -> tuple[list[int], list[int]]:
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

        out_g: list[int] = []
        out_p: list[int] = []
        out_d: list[float] = []
        at = 0
        for f, sub in hard:
            rows = sub.rows
            nr = len(rows)
            objs = objs_all[at : at + nr]
            prev = hp_all[at : at + nr]
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
        return (
            np.asarray(out_g, dtype=np.int64),
            np.asarray(out_p, dtype=np.int64),
            np.asarray(out_d, dtype=np.float64),
        )

    @staticmethod
    def _update_generic(sub: _Subset, prev: dict[int, int]) -> list[tuple[int, int]]:
        """Full ``MOTAccumulator.update`` of a frame whose hypothesis ids repeat (``prev``: previous partner of
        every row with a candidate, -1 if none); returns the matches of the contested rows."""
        dist = sub.dist
        n, k = dist.shape
        finite = ~np.isnan(dist)
        hids = np.asarray(sub.hids)
        omask = np.zeros(n, dtype=bool)
        hmask = np.zeros(k, dtype=bool)
        pairs: list[tuple[int, int]] = []
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

    # -- what a pass hands on ------------------------------------------------------------------------------------

    def match_scores(self, res: PassResult) -> np.ndarray:
        """(M,) float64 scores the devkit collects without a threshold: every prediction of a frame whose id had a
        MATCH (not SWITCH) event in that frame."""
        mp = res.p[~res.switch]
        keys = self.pf[mp] * (int(self.ph.max()) + 1 if len(self.ph) else 1) + self.ph[mp]
        all_keys = self.pf * (int(self.ph.max()) + 1 if len(self.ph) else 1) + self.ph
        return self.ps[np.isin(all_keys, keys)]

    def events(self, passes: list[PassResult]) -> ThresholdEvents:
        """The passes of T thresholds (in threshold order) as the CLEAR formulas read them: GT boxes sorted by
        object, then frame (:attr:`obj_order`)."""
        matched = np.zeros((len(passes), self.n_gt), dtype=bool)
        for t, res in enumerate(passes):
            matched[t, res.g] = True
        order = self.obj_order
        return ThresholdEvents(
            matched=matched[:, order],
            frame_id=np.stack([res.frame_id for res in passes])[:, self.gf[order]],
            obj_starts=self.obj_starts,
            obj_counts=self.obj_counts,
            switches=np.asarray([int(res.switch.sum()) for res in passes], dtype=np.int64),
            kept=np.asarray([res.n_kept for res in passes], dtype=np.int64),
            frames=np.asarray([res.n_frames for res in passes], dtype=np.int64),
            dist_sum=np.asarray([float(np.sum(res.d)) for res in passes], dtype=np.float64),
        )
