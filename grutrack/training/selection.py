"""Which validated step ``model.pt`` holds (``select_checkpoint`` of the training config).

- ``best_val_amota``: the validated step of highest validation AMOTA (step 0, the untrained network, included; the
  earliest of equals).
- ``best_val_amota_1se``: the one-standard-error rule (Hastie, Tibshirani, Friedman, *The Elements of Statistical
  Learning*, 2nd ed., sec. 7.10) on the same curve: the latest validated step whose AMOTA is within one standard
  error of the best's. The standard error is that of the paired difference between the two steps over the
  validation's detection sets, ``s.e. = std(a_i - b_i, ddof=1) / sqrt(n)`` (both steps are scored on the same
  sets), so a step is passed over only for a loss the sets agree on. Validation scores a few held-out scenes; a
  higher AMOTA at a mid-training step is often noise of those scenes, and the later steps have seen more data at
  the annealed learning rate (docs/results/grukf_eval/README.md, "Selecting the checkpoint"). With fewer than
  two sets the standard error is 0 and the rule takes the latest of the steps of equal best AMOTA.

Both rules are decided step by step as validation runs (the chosen network is saved when chosen), and a resumed
run replays its log through :func:`next_selection` to the same state.
"""

from __future__ import annotations

import numpy as np

from grutrack.documents import TrainingStep


def one_se(row: TrainingStep, best: TrainingStep) -> float:
    """Standard error of the paired difference of validation AMOTA between ``row`` and ``best`` over the
    detection sets (``val_amota_sets``, AMOTA in [0, 1]); 0.0 with fewer than two sets or sets missing."""
    a, b = row.val_amota_sets, best.val_amota_sets
    if a is None or b is None or len(a) != len(b) or len(a) < 2:
        return 0.0
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return float(d.std(ddof=1) / np.sqrt(d.size))


def next_selection(
    rule: str, best: TrainingStep | None, chosen: TrainingStep | None, row: TrainingStep
) -> tuple[TrainingStep, TrainingStep | None]:
    """(best, chosen) after ``row`` has been validated: ``best`` the validated step of highest AMOTA so far (the
    earliest of equals), ``chosen`` the step ``model.pt`` holds under ``rule`` ("best_val_amota" or
    "best_val_amota_1se"). ``row`` is chosen when it is the new best, or under the 1-s.e. rule when its AMOTA is
    at least the best's minus :func:`one_se`; every later step is then measured against the same best, so the
    last chosen step is the latest within one standard error of the best of the whole run."""
    if best is None or row.val_amota > best.val_amota:
        return row, row
    if rule == "best_val_amota_1se" and row.val_amota >= best.val_amota - one_se(row, best):
        return best, row
    return best, chosen
