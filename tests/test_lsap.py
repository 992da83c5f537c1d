"""The assignment solver of the fast evaluator against motmetrics' ``linear_sum_assignment`` (scipy solver) and
scipy's ``linear_sum_assignment`` themselves: the same pairs on random matrices with ties and missing edges."""

from __future__ import annotations

import numpy as np
import pytest

from grutrack.evaluation.nuscenes_fast.motmetrics_assignment import motmetrics_lsa
from grutrack.lsap import scipy_lsa, scipy_lsa_compiled


def _matrices(n: int, seed: int):
    """Random (nr, nc) matrices, 1..8 each side: continuous, small integers (ties), one decimal, constant."""
    rng = np.random.default_rng(seed)
    for t in range(n):
        nr, nc = rng.integers(1, 9, 2)
        c = [
            rng.random((nr, nc)),
            rng.integers(0, 3, (nr, nc)).astype(float),
            np.round(rng.random((nr, nc)), 1),
            np.full((nr, nc), 0.5),
        ][t % 4]
        yield c, rng.random((nr, nc)) < (0.4 if t % 3 else 0.0)


def test_same_pairs_as_motmetrics_with_scipy():
    lap = pytest.importorskip("motmetrics.lap")
    assert lap.default_solver == "scipy"  # the solver the devkit's evaluation uses in this environment
    n_pairs = 0
    for c, missing in _matrices(3000, 0):
        c = c.copy()
        c[missing] = np.nan
        want, got = lap.linear_sum_assignment(c), motmetrics_lsa(c)
        assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), c
        n_pairs += len(got[0])
    assert n_pairs > 5000


def test_same_pairs_as_scipy():
    from scipy.optimize import linear_sum_assignment

    for c, _ in _matrices(3000, 1):
        want, got = linear_sum_assignment(c), scipy_lsa(c)
        assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), c
    assert scipy_lsa(np.full((3, 3), 0.5))[1].tolist() == [0, 1, 2]  # scipy's identity on a constant matrix
    assert [x.tolist() for x in scipy_lsa(np.array([[1.0], [0.0], [2.0]]))] == [[1], [0]]  # tall: transposed


def test_missing_edges():
    assert [x.tolist() for x in motmetrics_lsa(np.full((2, 2), np.nan))] == [[], []]
    c = np.array([[0.1, np.nan], [np.nan, np.nan]])
    assert [x.tolist() for x in motmetrics_lsa(c)] == [[0], [0]]
    assert [x.tolist() for x in motmetrics_lsa(np.zeros((0, 3)))] == [[], []]


def test_compiled_form_same_pairs_as_scipy_on_tracker_sized_matrices():
    """The tracker's solver (compiled) against scipy on matrices the association builds: up to 120 x 120, wide
    and tall, ties, and forbidden pairs at the association's large constant."""
    from scipy.optimize import linear_sum_assignment

    from grutrack.tracking.association import _INVALID

    rng = np.random.default_rng(2)
    for t in range(400):
        nr, nc = rng.integers(0, 121, 2) if t % 5 else rng.integers(1, 9, 2)
        c = rng.integers(0, 4, (nr, nc)).astype(float) / 4 if t % 2 else rng.random((nr, nc))
        c[rng.random((nr, nc)) < 0.7] = _INVALID
        want, got = linear_sum_assignment(c), scipy_lsa_compiled(c)
        assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), (t, c.shape)
        assert got[0].dtype == got[1].dtype == np.int64
    for c, _ in _matrices(500, 3):
        want, got = linear_sum_assignment(c), scipy_lsa_compiled(c)
        assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1]), c


def test_compiled_form_refuses_non_finite_costs():
    with pytest.raises(ValueError, match="NaN or inf"):
        scipy_lsa_compiled(np.array([[0.0, np.nan]]))
