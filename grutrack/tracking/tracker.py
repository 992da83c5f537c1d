"""The tracking-by-detection loop (ARCHITECTURE.md, "The method"): predict, pre-process, associate, update,
lifecycle, output.

Tracks are kept in a few :class:`TrackGroup` s, one per motion backend (e.g. one per state-space model for
the EKF tracker, one for the GRU-Kalman filter). Within a group every per-track quantity is an array and
each step is a handful of array operations over all its tracks; there is no Python loop over tracks.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from threadpoolctl import threadpool_limits

from grutrack.boxes import empty_boxes
from grutrack.data.scene import BoxSet, Scene
from grutrack.tracking.association import Matches, associate, gated_association, gated_association_needed
from grutrack.tracking.config import TrackerConfig, gate_growth_rules
from grutrack.tracking.lifecycle import lifecycle_kernel
from grutrack.tracking.preprocess import preprocess_frame


class MotionBackend(Protocol):
    """A batched filter over the tracks of one group. ``state`` is backend-defined (arrays indexed by track)."""

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> Any:
        """New state for detections ``z (N, 9)`` of classes ``labels (N,)``."""

    def predict(self, state: Any, dt: float) -> Any:
        """State predicted ``dt`` seconds ahead."""

    def update(self, state: Any, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None) -> Any:
        """State with tracks ``rows (K,)`` corrected by measurements ``z (K, 9)`` scored ``scores`` (K,) (a filter
        with confidence-weighted noise reads them; None: unknown)."""

    def boxes(self, state: Any) -> np.ndarray:
        """Boxes ``(N, 9)`` of the current state (global frame)."""

    def select(self, state: Any, index: np.ndarray) -> Any:
        """The tracks selected by a boolean mask or index array."""

    def concat(self, a: Any, b: Any) -> Any:
        """Tracks of ``a`` followed by those of ``b``."""


@dataclass
class TrackGroup:
    """The tracks handled by one backend; every array has one entry per track."""

    backend: MotionBackend
    classes: np.ndarray  # (n_labels,) bool: which labels this group takes
    #: (n_labels,) m/s: this group also takes the tracks of a label born with a detected speed at least this (the
    #: label's motion-config ``moving`` model); inf for none; None: inf for every label
    moving_speed: np.ndarray | None = None
    state: Any = None
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))
    misses: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  # time since update
    hits: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: sum and number of the per-frame scores since birth (the average-score termination rule)
    score_total: np.ndarray = field(default_factory=lambda: np.zeros(0))
    score_count: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        return len(self.ids)

    def keep(self, mask: np.ndarray) -> None:
        """Drop the tracks where ``mask`` is False."""
        if mask.all():
            return
        self.state = self.backend.select(self.state, mask) if len(self.ids) else self.state
        self.ids, self.labels, self.scores = self.ids[mask], self.labels[mask], self.scores[mask]
        self.misses, self.hits = self.misses[mask], self.hits[mask]
        self.score_total, self.score_count = self.score_total[mask], self.score_count[mask]

    def add(self, z: np.ndarray, labels: np.ndarray, scores: np.ndarray, ids: np.ndarray) -> None:
        """Start tracks from detections ``z (N, 9)``."""
        new = self.backend.initiate(z, labels)
        self.state = new if self.state is None or len(self.ids) == 0 else self.backend.concat(self.state, new)
        self.ids = np.concatenate([self.ids, ids])
        self.labels = np.concatenate([self.labels, labels])
        self.scores = np.concatenate([self.scores, scores])
        self.misses = np.concatenate([self.misses, np.zeros(len(ids), dtype=np.int64)])
        self.hits = np.concatenate([self.hits, np.ones(len(ids), dtype=np.int64)])
        self.score_total = np.concatenate([self.score_total, scores])
        self.score_count = np.concatenate([self.score_count, np.ones(len(ids), dtype=np.int64)])


@dataclass(frozen=True)
class GroupUpdate:
    """The correction of one track group in one frame, as :meth:`Tracker.step_with_updates` reports it.

    Reported for every group that had tracks at this frame's predict, after its matched tracks were corrected
    and before the lifecycle (score, hit and miss counts, deaths) of this frame touched it. N = the group's
    tracks at this frame, K = those matched.
    """

    group: int  # index into ``Tracker.groups``
    rows: np.ndarray  # (K,) int64 matched track rows (possibly none)
    det_rows: np.ndarray  # (K,) int64 their detections' rows in the pre-processed frame
    ids: np.ndarray  # (N,) int64 track ids
    labels: np.ndarray  # (N,) int64 track labels
    hits: np.ndarray  # (N,) int64 matched frames since birth, before this frame's update
    misses: np.ndarray  # (N,) int64 frames since the last update (>= 1 after the predict)
    prior: Any  # the backend state of the N tracks after this frame's predict
    posterior: Any  # the backend state after correcting ``rows`` (``prior`` when K = 0)


@dataclass(frozen=True)
class TrackView:
    """What an association that asks for it (``wants_tracks``) sees of the tracks besides their predicted boxes:
    ids (T,), the boxes before this frame's prediction (T, 9), and hits (T,) int64 (matched frames since birth)
    and misses (T,) int64 (frames since the last match, this one included: 1 for a track matched in the frame
    before), in the order of the predicted boxes."""

    ids: np.ndarray
    last_boxes: np.ndarray
    hits: np.ndarray
    misses: np.ndarray


#: association of one frame: (detections after pre-processing, predicted track boxes (T, 9), track labels (T,),
#: dt seconds since the previous frame) -> :class:`Matches`
AssociateFn = Callable[[BoxSet, np.ndarray, np.ndarray, float], Matches]


def two_stage_association(cfg: TrackerConfig) -> AssociateFn:
    """The default association: per-class similarity, Hungarian, optional second stage (ARCHITECTURE.md, "The
    method"); with Ro_GDIoU as the stage-1 metric of some classes, their stage-1 costs from
    :func:`~grutrack.tracking.ro_gdiou.ro_gdiou_first_stage`; with ``crowded_threshold``, Ro_GDIoU for the
    crowded rows and columns of stage 1 (:func:`~grutrack.tracking.association.crowded_stage_one`); with
    ``lost_newborn_penalty``, the stage-1 costs of lost newborn tracks (:func:`lost_newborns`) raised, and with
    ``crowded_skips_lost_newborns``, those tracks left out of the crowded test; with ``distance_gate_growth``
    missed_frames or a speed for a gated class, its tracks' gates grown with their misses (:func:`gate_scale`; these
    ask for the tracks' hits and misses, ``wants_tracks``)."""
    if gated_association_needed(cfg):
        return gated_association(cfg)
    first_metric, first_override, strict = cfg.first_metric, None, None
    if "ro_gdiou_bev" in cfg.first_metric:
        from grutrack.tracking.ro_gdiou import ro_gdiou_first_stage

        first_metric, first_override = ro_gdiou_first_stage(cfg)
    if np.any(cfg.crowded_threshold > 0):
        from grutrack.tracking.ro_gdiou import predicted_pose_costs

        strict = predicted_pose_costs(cfg.crowded_threshold > 0, cfg)
    penalty, skip_lost = cfg.lost_newborn_penalty, cfg.crowded_skips_lost_newborns and strict is not None
    gated = cfg.distance_gate > 0  # (C,)
    frames, speed = gate_growth_rules(cfg.distance_gate_growth)  # (C,) bool, (C,) m/s
    frames, speed = frames & gated, speed * gated
    widens = frames | (speed > 0)

    def run(
        dets: BoxSet, trk_boxes: np.ndarray, trk_labels: np.ndarray, dt: float, tracks: TrackView | None = None
    ) -> Matches:
        lost = None if tracks is None else lost_newborns(tracks.hits, tracks.misses, dt)  # (T,) bool
        return associate(
            dets.boxes,
            dets.labels,
            trk_boxes,
            trk_labels,
            first_metric,
            cfg.first_threshold,
            cfg.two_stage,
            cfg.second_metric,
            cfg.second_threshold,
            cfg.assignment,
            cfg.distance_gate,
            None if first_override is None else first_override(dets, trk_boxes, trk_labels),
            None
            if strict is None
            else (
                cfg.crowded_threshold,
                lambda r, c, need: strict(dets.boxes[r], dets.labels[r], trk_boxes[c], trk_labels[c], need),
            ),
            None if lost is None else np.where(lost, penalty[trk_labels], 0.0),
            lost if skip_lost else None,
            dets.extra.get("footprint"),
            None
            if tracks is None or not widens.any()
            else gate_scale(frames, speed, cfg.distance_gate, trk_labels, tracks.misses, dt),
            cfg.size_gate,
        )

    run.wants_tracks = bool(np.any(penalty > 0)) or skip_lost or bool(widens.any())
    return run


def gate_scale(
    frames: np.ndarray, speed: np.ndarray, radius: np.ndarray, labels: np.ndarray, misses: np.ndarray, dt: float
) -> np.ndarray:
    """(T,) float64 factor on each track's ``distance_gate`` (``association.distance_gate_growth``).

    frames (C,) bool: classes gated at ``misses`` times their radius (missed_frames); speed (C,) m/s, radius (C,) m:
    classes whose gate grows by ``speed`` times the seconds missed, r' = r + v t with t = (misses - 1) dt; labels (T,)
    the tracks' classes; misses (T,) int64 frames since each track's last match, this one included (1 for a track
    matched in the frame before); dt: this frame's interval in seconds. Other classes: 1."""
    missed_s = (misses - 1) * dt  # (T,) seconds without a detection before this frame
    r = radius[labels]
    grown = 1.0 + speed[labels] * missed_s / np.where(r > 0, r, 1.0)  # r' / r
    return np.where(frames[labels], misses.astype(np.float64), grown)


#: seconds a newborn track must have been missed to count as lost: every missed nuScenes keyframe (2 Hz), the
#: third missed sweep at Argoverse 2's 10 Hz (the rate-independent test of ``motion.velocity_check_window``)
LOST_NEWBORN_MISSED_S = 0.25


def lost_newborns(hits: np.ndarray, misses: np.ndarray, dt: float) -> np.ndarray:
    """(T,) bool: the lost newborns, tracks matched at their birth only (``hits`` (T,) == 1) and missed since for
    at least :data:`LOST_NEWBORN_MISSED_S`: ``misses`` (T,) counts this frame (1 for a track matched in the frame
    before), so ``(misses - 1) * dt`` seconds (``dt``: this frame's interval) have passed without a match."""
    return (hits == 1) & ((misses - 1) * dt >= LOST_NEWBORN_MISSED_S)


class Tracker:
    """Online multi-object tracker over the frames of one scene at a time.

    ``groups``: the track groups; each tracking class must belong to exactly one group.
    ``associate``: the association function (default :func:`two_stage_association` of ``cfg``).
    """

    def __init__(self, cfg: TrackerConfig, groups: list[TrackGroup], associate: AssociateFn | None = None):
        owners = np.sum([g.classes for g in groups], axis=0)
        if not np.all(owners == 1):
            raise ValueError("each tracking class must belong to exactly one track group")
        self.cfg = cfg
        self.groups = groups
        self.group_of_class = np.argmax(np.stack([g.classes for g in groups]), axis=0)
        speeds = np.stack([np.full(len(owners), np.inf) if g.moving_speed is None else g.moving_speed for g in groups])
        if np.any(np.isfinite(speeds).sum(axis=0) > 1):
            raise ValueError("each tracking class may have at most one track group for its moving tracks")
        #: (n_labels,) the group taking a label's tracks born at or above ``moving_speed`` (n_labels,) m/s
        self.moving_group, self.moving_speed = np.argmin(speeds, axis=0), np.min(speeds, axis=0)
        self.next_id = 0
        self.last_timestamp: int | None = None
        self.frame_count = 0  # frames of the current scene, this one included
        self.associate = associate if associate is not None else two_stage_association(cfg)
        #: per-class lifecycle tables of :func:`lifecycle_kernel`: decay_rate, max_age, min_hits, delete_threshold
        self._life = tuple(
            np.ascontiguousarray(a, dtype=np.float64)
            for a in (cfg.decay_rate, cfg.max_age, cfg.min_hits, cfg.delete_threshold)
        )
        self._punish = np.ascontiguousarray(cfg.punish_num, dtype=np.float64)  # (n_labels,) frames a track may coast

    def reset(self) -> None:
        """Forget all tracks (start of a scene); track ids keep counting so they stay unique."""
        for g in self.groups:
            g.keep(np.zeros(len(g), dtype=bool))
            g.state = None
        self.last_timestamp = None
        self.frame_count = 0

    def warm_up(self) -> None:
        """Track two synthetic frames (one box per label, 0.5 s apart, so that every group predicts, associates,
        corrects and starts tracks), then forget them (:meth:`reset`; track ids continue as before). The
        one-time start of the compiled kernels (numba loading their cached machine code and initialising its
        type registry, which imports scipy.linalg) and of the torch operators is paid here instead of by the
        first frames tracked."""
        next_id = self.next_id
        n = len(self.group_of_class)
        boxes = np.zeros((n + 1, 9))
        boxes[:n, 0] = 50.0 * np.arange(n)
        boxes[n, 0] = 0.2  # overlaps the first box: non-maximum suppression has work
        boxes[:, 3:6] = (2.0, 4.0, 1.5)
        boxes[:, 7] = 1.0
        labels = np.append(np.arange(n), 0)
        scores = np.append(np.ones(n), 0.99)
        self.reset()
        try:
            for k in range(2):
                moved = boxes.copy()
                moved[:, 0] += 0.5 * k
                self.step(BoxSet(moved, scores, labels), 500_000 * k)
        finally:
            self.reset()
            self.next_id = next_id

    def step(self, dets: BoxSet, timestamp: int) -> BoxSet:
        """Process one frame: detections (canonical, global frame) at ``timestamp`` (µs).

        Tracks are predicted by the time since the previous frame, or by the preset's fixed ``time_step``.

        Returns the boxes to write for this frame with their track ids (``ids`` int64).
        """
        return self._step(dets, timestamp, None)

    def step_with_updates(
        self, dets: BoxSet, timestamp: int, output: bool = True
    ) -> tuple[BoxSet | None, list[GroupUpdate]]:
        """:meth:`step`, also returning a :class:`GroupUpdate` per group that had tracks (training reads the
        filter states of the tracks corrected in this frame from them). ``output=False``: the same tracking
        without forming the frame's output boxes (returned as None; training reads only the updates)."""
        updates: list[GroupUpdate] = []
        return self._step(dets, timestamp, updates, output), updates

    def _step(
        self, dets: BoxSet, timestamp: int, updates: list[GroupUpdate] | None, output: bool = True
    ) -> BoxSet | None:
        """:meth:`step`; appends the groups' :class:`GroupUpdate` s to ``updates`` unless it is None; forms no
        output (returns None) without ``output``."""
        dt = 0.0 if self.last_timestamp is None else (timestamp - self.last_timestamp) * 1e-6
        if self.cfg.time_step is not None and self.last_timestamp is not None:
            dt = self.cfg.time_step  # a fixed prediction step (preset motion.time_step), e.g. Poly-MOT's 0.5 s
        self.last_timestamp = timestamp
        self.frame_count += 1
        self._predict(dt)
        cfg = self.cfg
        dets = preprocess_frame(dets, cfg)
        trk_boxes = np.concatenate([g.backend.boxes(g.state) if len(g) else empty_boxes() for g in self.groups])
        trk_labels = np.concatenate([g.labels for g in self.groups])
        if getattr(self.associate, "wants_tracks", False):  # e.g. MCTrack's pose choice: ids, last-update boxes
            m = self.associate(dets, trk_boxes, trk_labels, dt, tracks=self._track_view(trk_boxes))
        else:
            m = self.associate(dets, trk_boxes, trk_labels, dt)
        out = self._update_groups(dets, m.dets, m.tracks, updates, output)
        out.append(self._births(dets, m.unmatched_dets, output))
        return _concat_boxsets(out) if output else None

    def _track_view(self, trk_boxes: np.ndarray) -> TrackView:
        """The tracks' ids and last-update boxes (a backend's ``last_boxes``, else its current boxes: ``trk_boxes``
        (T, 9) itself when no backend keeps last-update boxes)."""
        ids, hits, misses = (np.concatenate([getattr(g, k) for g in self.groups]) for k in ("ids", "hits", "misses"))
        if not any(hasattr(g.backend, "last_boxes") for g in self.groups):
            return TrackView(ids, trk_boxes, hits, misses)
        last = [
            (g.backend.last_boxes(g.state) if hasattr(g.backend, "last_boxes") else g.backend.boxes(g.state))
            if len(g)
            else empty_boxes()
            for g in self.groups
        ]
        return TrackView(ids, np.concatenate(last) if last else trk_boxes, hits, misses)

    def _predict(self, dt: float) -> None:
        for g in self.groups:
            if len(g):
                if getattr(g.backend, "coast_held", None) is not None:  # predicted before without an update: coasting
                    g.state = g.backend.predict(g.state, dt, g.misses >= 1)
                else:
                    g.state = g.backend.predict(g.state, dt)
                g.misses += 1

    def _update_groups(
        self,
        dets: BoxSet,
        mdets: np.ndarray,
        mtracks: np.ndarray,
        updates: list[GroupUpdate] | None,
        output: bool = True,
    ) -> list[BoxSet]:
        """Correct matched tracks, decay the others, kill the expired; return each group's output (none without
        ``output``) (and append each group's :class:`GroupUpdate` to ``updates`` unless it is None)."""
        out, offset = [], 0
        for gi, g in enumerate(self.groups):
            n = len(g)
            sel = (mtracks >= offset) & (mtracks < offset + n)
            rows, drows = mtracks[sel] - offset, mdets[sel]
            offset += n
            if n == 0:
                continue
            prior = g.state
            if len(rows):
                g.state = g.backend.update(g.state, rows, dets.boxes[drows], dets.scores[drows])
            if hasattr(g.backend, "miss") and len(rows) < n:  # a backend that treats missed tracks itself
                missed = np.ones(n, dtype=bool)
                missed[rows] = False
                g.state = g.backend.miss(g.state, np.flatnonzero(missed))
            if updates is not None:  # copies: the lifecycle kernel changes hits and misses in place
                updates.append(
                    GroupUpdate(gi, rows, drows, g.ids, g.labels, g.hits.copy(), g.misses.copy(), prior, g.state)
                )
            matched, alive, emit = np.empty(n, dtype=bool), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
            cfg = self.cfg
            lifecycle_kernel(
                rows,
                dets.scores[drows],
                g.labels,
                g.scores,
                g.misses,
                g.hits,
                g.score_total,
                g.score_count,
                *self._life,
                cfg.score_update == "multiply",
                cfg.termination == "average_score",
                self._punish,
                self.frame_count,
                cfg.write_first_frames,
                matched,
                alive,
                emit,
            )
            if output:
                boxes = g.backend.boxes(g.state)
                if self.cfg.matched_box == "detection" and len(rows):
                    boxes[rows, :6] = dets.boxes[drows, :6]  # detection centre and size; filter yaw, velocity
                written = self._written(g.scores[emit], g.hits[emit])
                out.append(BoxSet(boxes[emit], written, g.labels[emit], g.ids[emit]))
            g.keep(alive)
        return out

    def _written(self, scores: np.ndarray, hits: np.ndarray) -> np.ndarray:
        """(M,) float64 written scores of tracks with scores (M,) and hits (M,) int64 matched frames since birth:
        ``s (1 - d^h)``, d the preset's ``young_track_discount`` (0: the scores themselves). With d the chance that
        one detection is a false alarm, ``1 - d^h`` is the chance that h of them are not all false."""
        d = self.cfg.young_track_discount
        return scores if d == 0.0 else scores * (1.0 - d ** hits.astype(np.float64))

    def _confirmed(self, hits: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """(N,) bool: tracks with at least min_hits matched frames, or all while the scene is that young."""
        need = self.cfg.min_hits[labels]
        return (hits >= need) | (self.frame_count <= need)

    def _births(self, dets: BoxSet, new: np.ndarray, output: bool = True) -> BoxSet:
        """Start a track for every unmatched detection (in its class's group, or in the group of its class's
        moving model when its detected speed is at least that model's ``speed``); returns their boxes as this
        frame's output (none without ``output``)."""
        out = []
        ids = np.arange(self.next_id, self.next_id + len(new), dtype=np.int64)
        self.next_id += len(new)
        labels = dets.labels[new]
        moving = np.hypot(dets.boxes[new, 7], dets.boxes[new, 8]) >= self.moving_speed[labels]
        owner = np.where(moving, self.moving_group[labels], self.group_of_class[labels])
        for gi, g in enumerate(self.groups):
            sel = owner == gi
            if sel.any():
                d = new[sel]
                g.add(dets.boxes[d], dets.labels[d], dets.scores[d], ids[sel])
                if not output:
                    continue
                show = self._confirmed(np.ones(len(d), dtype=np.int64), dets.labels[d])
                out.append(
                    BoxSet(
                        g.backend.boxes(g.state)[-len(d) :][show],
                        self._written(dets.scores[d][show], np.ones(int(show.sum()), dtype=np.int64)),
                        dets.labels[d][show],
                        ids[sel][show],
                    )
                )
        return _concat_boxsets(out)


def _concat_boxsets(sets: list[BoxSet]) -> BoxSet:
    sets = [s for s in sets if len(s)]
    if not sets:
        return BoxSet(empty_boxes(), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    return BoxSet(
        np.concatenate([s.boxes for s in sets]),
        np.concatenate([s.scores for s in sets]),
        np.concatenate([s.labels for s in sets]),
        np.concatenate([s.ids for s in sets]),
    )


@dataclass
class TrackingRun:
    """Output of :func:`track_scenes`: per-sample tracked boxes and loop timing."""

    results: dict[str, BoxSet]
    frames: int
    seconds: float
    #: the tracker's one-time start before the loop (:meth:`Tracker.warm_up`), not part of ``seconds``
    start_seconds: float = 0.0

    @property
    def fps(self) -> float:
        """Frames per second of the tracking loop alone (no I/O)."""
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


def track_scenes(
    tracker: Tracker, scenes: Iterable[Scene], detections: dict[str, BoxSet], progress=None
) -> TrackingRun:
    """Run ``tracker`` over every scene; ``detections`` maps sample token -> canonical detections.

    ``progress``: optional callable(n_frames) called after each scene (e.g. a tqdm ``update``).
    The tracker is warmed up first (:meth:`Tracker.warm_up`; its seconds are ``start_seconds``), so that the
    loop's frames/s is the per-frame cost.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        return _track_scenes(tracker, scenes, detections, progress)


def _track_scenes(
    tracker: Tracker, scenes: Iterable[Scene], detections: dict[str, BoxSet], progress=None
) -> TrackingRun:
    # the filter's linear algebra is many tiny batched solves: multi-threaded BLAS only adds thread
    # hand-offs (and stalls badly when other processes share the cores), so the loop runs single-threaded
    t0 = time.perf_counter()
    tracker.warm_up()
    start = time.perf_counter() - t0
    results, frames, seconds = {}, 0, 0.0
    for scene in scenes:
        tracker.reset()
        t0 = time.perf_counter()
        for frame in scene.frames:
            results[frame.token] = tracker.step(detections[frame.token], frame.timestamp)
        seconds += time.perf_counter() - t0
        frames += len(scene.frames)
        if progress is not None:
            progress(len(scene.frames))
    return TrackingRun(results, frames, seconds, start)
