"""Linear sum assignment exactly as motmetrics 1.4.0 solves it with scipy, without importing either.

The devkit's tracking evaluation matches the contested boxes of a frame with
``motmetrics.lap.linear_sum_assignment`` (its default solver: scipy). Importing motmetrics pulls pandas and
``scipy.optimize`` (0.3 s and more), most of the fast evaluator's command time on a mini split. This module
reproduces that call, ties included:

* motmetrics' ``add_expensive_edges``: NaN / inf entries (no edge) cost ``2 r c + 1`` with ``r = min(shape)``
  and ``c = max |finite cost| + 1`` (so an optimum uses as many real edges as possible); an all-missing matrix
  costs 0 everywhere; ``_exclude_missing_edges`` drops the pairs on a missing edge afterwards;
* scipy's ``linear_sum_assignment`` (``scipy/optimize/rectangular_lsap/rectangular_lsap.cpp``, the shortest
  augmenting path method of Crouse, IEEE TAES 2016): rows are added one at a time, each by a Dijkstra-like
  search over the reduced costs ``c_ij - u_i - v_j``, the columns visited from the highest index down, ties of
  the shortest path cost broken in favour of a free column; a tall matrix is solved transposed and its pairs
  returned by row.

The matrices it sees are small (the contested boxes of one class in one frame), so plain Python serves.
"""

from __future__ import annotations

import math
from typing import List, Tuple

import numpy as np


def _augmenting_path(cost: List[List[float]], u: List[float], v: List[float], path: List[int],
                     row4col: List[int], spc: List[float], i: int, SR: List[bool], SC: List[bool]):
    """Shortest augmenting path from free row ``i`` over ``cost (nr x nc)``, dual variables ``u (nr)``,
    ``v (nc)``; fills ``path``, ``spc`` (shortest path cost per column), the visited rows ``SR`` and columns
    ``SC``. Returns ``(sink column, path length)``; sink -1 when infeasible."""
    nc = len(v)
    remaining = list(range(nc - 1, -1, -1))  # reverse order: a constant matrix gives the identity
    SR[:] = [False] * len(SR)
    SC[:] = [False] * nc
    spc[:] = [math.inf] * nc
    min_val = 0.0
    sink = -1
    while sink == -1:
        index, lowest = -1, math.inf
        SR[i] = True
        row, ui = cost[i], u[i]
        for it, j in enumerate(remaining):
            r = min_val + row[j] - ui - v[j]
            sj = spc[j]
            if r < sj:
                path[j] = i
                spc[j] = sj = r
            if sj < lowest or (sj == lowest and row4col[j] == -1):
                lowest = sj
                index = it
        min_val = lowest
        if min_val == math.inf:
            return -1, min_val
        j = remaining[index]
        if row4col[j] == -1:
            sink = j
        else:
            i = row4col[j]
        SC[j] = True
        remaining[index] = remaining[-1]
        remaining.pop()
    return sink, min_val


def scipy_lsa(cost: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``scipy.optimize.linear_sum_assignment(cost)`` (minimise) for a finite ``cost (nr, nc)`` float64:
    ``(rows, cols)`` int64, sorted by row, ``min(nr, nc)`` pairs."""
    cost = np.asarray(cost, dtype=np.float64)
    nr, nc = cost.shape
    if nr == 0 or nc == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    transpose = nc < nr
    c = (cost.T if transpose else cost).tolist()
    if transpose:
        nr, nc = nc, nr
    u, v = [0.0] * nr, [0.0] * nc
    spc, path = [math.inf] * nc, [-1] * nc
    col4row, row4col = [-1] * nr, [-1] * nc
    SR, SC = [False] * nr, [False] * nc
    for cur in range(nr):
        sink, min_val = _augmenting_path(c, u, v, path, row4col, spc, cur, SR, SC)
        if sink < 0:
            raise ValueError("cost matrix is infeasible")
        u[cur] += min_val  # dual update: u_i += minVal - spc[col4row[i]] for the other visited rows
        for i in range(nr):
            if SR[i] and i != cur:
                u[i] += min_val - spc[col4row[i]]
        for j in range(nc):
            if SC[j]:
                v[j] -= min_val - spc[j]
        j = sink
        while True:  # augment along the path
            i = path[j]
            row4col[j] = i
            col4row[i], j = j, col4row[i]
            if i == cur:
                break
    if transpose:
        order = sorted(range(nr), key=lambda k: col4row[k])
        return (np.array([col4row[k] for k in order], dtype=np.int64), np.array(order, dtype=np.int64))
    return np.arange(nr, dtype=np.int64), np.array(col4row, dtype=np.int64)


def motmetrics_lsa(costs: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``motmetrics.lap.linear_sum_assignment(costs)`` with the scipy solver: ``costs (nr, nc)`` float64 with
    NaN / inf for missing edges -> ``(rows, cols)`` int64 of the pairs on real edges."""
    costs = np.asarray(costs, dtype=np.float64)
    if not costs.size:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    valid = np.isfinite(costs)
    if valid.all():
        finite = costs
    elif not valid.any():
        finite = np.zeros_like(costs)
    else:
        big = 2 * min(costs.shape) * (np.abs(costs[valid]).max() + 1) + 1
        finite = np.where(valid, costs, big)
    rows, cols = scipy_lsa(finite)
    keep = valid[rows, cols]
    return rows[keep], cols[keep]
