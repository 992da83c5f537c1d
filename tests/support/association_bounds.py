"""The association's pruning bound (``grutrack.tracking.association._similarity_bound``, inlined into its compiled
cost kernel) evaluated on aligned box pairs, so that tests can check it against the exact similarities."""

from __future__ import annotations

import numpy as np
from numba import njit

from grutrack import geometry
from grutrack.tracking.association import _centre_distance, _similarity_bound


@njit
def _bound_kernel(ta, tb, code, out) -> None:
    for k in range(out.shape[0]):
        out[k] = _similarity_bound(ta, k, tb, k, _centre_distance(ta, k, tb, k), code)


def similarity_upper_bound(a: np.ndarray, b: np.ndarray, metric: str) -> np.ndarray:
    """Upper bounds ``(K,)`` of the similarity ``metric`` of aligned pairs of boxes ``a, b (K, >=7)``: the bound
    below which the association skips a pair without computing its polygon geometry."""
    a, b = geometry._check_boxes(a, "a"), geometry._check_boxes(b, "b")
    out = np.empty(a.shape[0])
    _bound_kernel(geometry._box_terms(a), geometry._box_terms(b), geometry.SIMILARITIES.index(metric), out)
    return out
