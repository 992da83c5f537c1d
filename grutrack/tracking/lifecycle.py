"""Track lifecycle of one frame for the tracks of one group (DESIGN section 1, step 4), one compiled pass.

Scores: matched tracks take the detection's score (``detection``) or ``1 - (1 - s_det)(1 - s * decay_rate)``
(``multiply``, Fast-Poly); unmatched tracks decay, ``s <- s * decay_rate``. Matched tracks have their frames since
the last update (``misses``) reset to 0 and their hit count raised by one. A track stays alive while
``misses < max_age`` (and, with ``average_score`` termination, while the mean of its per-frame scores since birth
is at least ``delete_threshold``). A track is written when alive, matched or missed for at most its class's
``punish_num`` frames (or at any miss count while the scene is no older than ``write_first_frames`` frames, MCTrack),
and confirmed: at least ``min_hits`` hits, or the scene no older than ``min_hits`` frames. The score written with
the box is the track's score, discounted for young tracks by ``young_track_discount`` (``Tracker._written``).
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def lifecycle_kernel(
    rows,
    det_scores,
    labels,
    scores,
    misses,
    hits,
    score_total,
    score_count,
    decay_rate,
    max_age,
    min_hits,
    delete_threshold,
    multiply,
    average_score,
    punish_num,
    frame_count,
    write_first_frames,
    matched,
    alive,
    emit,
) -> None:
    """One frame's lifecycle of N tracks, in place.

    rows (K,) int64: the matched tracks, det_scores (K,): their detections' scores; labels (N,) int64;
    scores, score_total (N,) float64 and misses, hits, score_count (N,) int64 are updated; decay_rate, max_age,
    min_hits, delete_threshold (n_labels,) float64 per label; multiply: the ``multiply`` score rule; average_score:
    the ``average_score`` termination; punish_num (n_labels,) float64 per label; frame_count: frames of the scene
    so far, this one included; write_first_frames: every live confirmed track is written while frame_count is at
    most this (0: never). Per-label arrays are sized by the dataset's vocabulary (7 nuScenes tracking
    classes, more for AV2 categories).
    Out: matched, alive, emit (N,) bool.
    """
    n = labels.shape[0]
    for i in range(n):
        matched[i] = False
    for k in range(rows.shape[0]):
        matched[rows[k]] = True
    if multiply:
        for i in range(n):
            scores[i] = scores[i] * decay_rate[labels[i]]
        for k in range(rows.shape[0]):
            scores[rows[k]] = 1.0 - (1.0 - det_scores[k]) * (1.0 - scores[rows[k]])
    else:
        for k in range(rows.shape[0]):
            scores[rows[k]] = det_scores[k]
        for i in range(n):
            if not matched[i]:
                scores[i] *= decay_rate[labels[i]]
    for k in range(rows.shape[0]):
        misses[rows[k]] = 0
        hits[rows[k]] += 1
    for i in range(n):
        lab = labels[i]
        live = misses[i] < max_age[lab]
        if average_score:
            score_total[i] = score_total[i] + scores[i]
            score_count[i] += 1
            live = live and score_total[i] / score_count[i] >= delete_threshold[lab]
        alive[i] = live
        confirmed = hits[i] >= min_hits[lab] or frame_count <= min_hits[lab]
        shown = matched[i] or misses[i] <= punish_num[lab] or frame_count <= write_first_frames
        emit[i] = live and shown and confirmed
