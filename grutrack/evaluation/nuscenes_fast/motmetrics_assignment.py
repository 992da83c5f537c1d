"""motmetrics' ``linear_sum_assignment`` (scipy solver), the contested boxes' matching, without importing either.

The devkit's tracking evaluation matches the contested boxes of a frame with
``motmetrics.lap.linear_sum_assignment`` (motmetrics 1.4.0, its default solver: scipy). Importing motmetrics
pulls pandas and ``scipy.optimize`` (0.3 s and more), most of the fast evaluator's command time on a mini split.
This module reproduces that call, ties included:

* motmetrics' ``add_expensive_edges``: NaN / inf entries (no edge) cost ``2 r c + 1`` with ``r = min(shape)``
  and ``c = max |finite cost| + 1`` (so an optimum uses as many real edges as possible); an all-missing matrix
  costs 0 everywhere; ``_exclude_missing_edges`` drops the pairs on a missing edge afterwards;
* scipy's ``linear_sum_assignment``: :func:`grutrack.lsap.scipy_lsa`, its plain-Python form (the matrices are
  small, the contested boxes of one class in one frame, and the command need not load a compiler).
"""

from __future__ import annotations

import numpy as np

from grutrack.lsap import scipy_lsa

__all__ = ["motmetrics_lsa"]


def motmetrics_lsa(costs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``motmetrics.lap.linear_sum_assignment(costs)`` with the scipy solver: ``costs`` (nr, nc) float64, NaN /
    inf for a missing edge -> ``(rows, cols)`` (K,) int64 of the pairs on real edges."""
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
