"""Rectangular linear sum assignment exactly as ``scipy.optimize.linear_sum_assignment`` solves it, in two forms
of one algorithm: plain Python over lists (:func:`scipy_lsa`; small matrices, no compiler) and compiled with numba
(:func:`scipy_lsa_compiled`; the tracker's association, every frame).

The algorithm is scipy's (``scipy/optimize/rectangular_lsap/rectangular_lsap.cpp``, the shortest augmenting path
method of Crouse, IEEE TAES 2016): rows are added one at a time, each by a Dijkstra-like search over the reduced
costs ``c_ij - u_i - v_j``, the columns visited from the highest index down, ties of the shortest path cost broken
in favour of a free column; a tall matrix is solved transposed and its pairs returned by row. Same pairs as scipy,
ties included (tests/test_lsap.py), so the results do not depend on which form ran.

Importing ``scipy.optimize`` costs about 0.2 s, a sixth of a whole ``grutrack track`` command on a mini split;
this module imports numpy only (numba when the compiled form is first asked for).
"""

from __future__ import annotations

import functools
import math

import numpy as np


def _solve(c, nr, nc, u, v, spc, path, col4row, row4col, SR, SC, remaining) -> bool:
    """Assign every row of ``c`` (nr x nc, nr <= nc, finite; a list of lists or a 2-D array) in place.

    Work vectors (lists or arrays, preset by the caller): duals ``u (nr)``, ``v (nc)`` = 0; ``col4row (nr)``,
    ``row4col (nc)`` = -1 (the result); ``spc (nc)``, ``path (nc)``, ``SR (nr)``, ``SC (nc)``, ``remaining (nc)``:
    scratch. Returns False when the matrix is infeasible.
    """
    for cur in range(nr):
        # shortest augmenting path from free row ``cur``
        n_rem = nc
        for it in range(nc):
            remaining[it] = nc - 1 - it  # reverse order: a constant matrix gives the identity
        for k in range(nr):
            SR[k] = False
        for j in range(nc):
            SC[j] = False
            spc[j] = math.inf
        min_val = 0.0
        sink = -1
        i = cur
        while sink == -1:
            index, lowest = -1, math.inf
            SR[i] = True
            row, ui = c[i], u[i]
            for it in range(n_rem):
                j = remaining[it]
                r = min_val + row[j] - ui - v[j]
                sj = spc[j]
                if r < sj:
                    path[j] = i
                    spc[j] = r
                    sj = r
                if sj < lowest or (sj == lowest and row4col[j] == -1):
                    lowest = sj
                    index = it
            min_val = lowest
            if min_val == math.inf:
                return False
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            SC[j] = True
            n_rem -= 1
            remaining[index] = remaining[n_rem]
        # dual update: u_cur += minVal; u_i += minVal - spc[col4row[i]] for the other visited rows
        u[cur] += min_val
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
    return True


@functools.cache
def _compiled():
    """The numba form of :func:`_solve` (compiled on first use, cached on disk)."""
    from numba import njit

    return njit(cache=True)(_solve)


def _pairs(col4row, transpose: bool) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) int64 sorted by row from the solved ``col4row`` of the (possibly transposed) matrix."""
    col4row = np.asarray(col4row, dtype=np.int64)
    if transpose:
        order = np.argsort(col4row, kind="stable")
        return col4row[order], order.astype(np.int64)
    return np.arange(len(col4row), dtype=np.int64), col4row


def _oriented(cost) -> tuple[np.ndarray, bool]:
    """``cost (nr, nc)`` as float64 with at least as many columns as rows, and whether it was transposed."""
    cost = np.asarray(cost, dtype=np.float64)
    if cost.ndim != 2:
        raise ValueError(f"cost matrix must be 2-D, got shape {cost.shape}")
    transpose = cost.shape[1] < cost.shape[0]
    return (cost.T if transpose else cost), transpose


def scipy_lsa(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.optimize.linear_sum_assignment(cost)`` (minimise) for a finite ``cost (nr, nc)`` float64:
    ``(rows, cols)`` int64, sorted by row, ``min(nr, nc)`` pairs. Plain Python: for small matrices."""
    c, transpose = _oriented(cost)
    nr, nc = c.shape
    if nr == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    col4row = [-1] * nr
    if not _solve(
        c.tolist(),
        nr,
        nc,
        [0.0] * nr,
        [0.0] * nc,
        [math.inf] * nc,
        [-1] * nc,
        col4row,
        [-1] * nc,
        [False] * nr,
        [False] * nc,
        [0] * nc,
    ):
        raise ValueError("cost matrix is infeasible")
    return _pairs(col4row, transpose)


def scipy_lsa_compiled(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`scipy_lsa` compiled: the same pairs, for the matrices of every tracking frame."""
    c, transpose = _oriented(cost)
    nr, nc = c.shape
    if nr == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if not np.isfinite(c).all():
        raise ValueError("cost matrix contains NaN or inf")
    col4row = np.full(nr, -1, dtype=np.int64)
    ok = _compiled()(
        np.ascontiguousarray(c),
        nr,
        nc,
        np.zeros(nr),
        np.zeros(nc),
        np.full(nc, math.inf),
        np.full(nc, -1, dtype=np.int64),
        col4row,
        np.full(nc, -1, dtype=np.int64),
        np.zeros(nr, dtype=np.bool_),
        np.zeros(nc, dtype=np.bool_),
        np.zeros(nc, dtype=np.int64),
    )
    if not ok:
        raise ValueError("cost matrix is infeasible")
    return _pairs(col4row, transpose)
