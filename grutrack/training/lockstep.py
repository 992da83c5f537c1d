"""Several scenes per optimizer step with the network run once per frame over all of them (``scenes_per_step``).

Each scene is tracked by its own :class:`~grutrack.tracking.tracker.Tracker` in its own thread, the scenes in
lockstep by frame. A scene's tracker has one network track group per SS model the network runs (one group for
``training_classes: tracked`` with ``network_classes`` all or ss_model; with ``own_model`` one per model of
:data:`~grutrack.motion.grukf.NETWORK_MODELS`, e.g. the CTRA classes and the Bicycle classes, the weights shared),
and the tracker updates its groups in a fixed order. Each group is a *channel* here: in every frame each scene still
running passes every channel once, in that order, either asking for one network correction (the group's update,
:meth:`GRUKFBackend.update`) or passing it without one, and once every scene has arrived at a channel the step's
network thread (:meth:`LockstepCorrect.serve`) runs ``net.correct`` once on the tracks of all that channel's requests
(concatenated along the track axis, with the channel's SS model) and hands each scene its rows. Every operator of
the network acts on one track's row, so the result equals one call per scene and group; what changes is the number
of kernel launches and autograd nodes per frame: one set per channel for k scenes (on a GPU the launches, not the
arithmetic, are the cost of a few hundred tracks).

The tracking itself (association, lifecycle, numpy) stays per scene and runs under the interpreter lock one scene
at a time; on a CPU the gain is the network's per-operator overhead only.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence

import torch


class LockstepAborted(RuntimeError):
    """Raised in the other scenes' threads when one of them failed (its own exception is re-raised by the caller)."""


def _cat(parts: list):
    """Concatenate one argument of several ``correct`` calls along the track axis: tensors (K_i, ...) -> (sum K_i,
    ...), dicts of tensors key by key, None stays None; any other value (a group's torch SS model, ``ss``) is the
    same model in every call of a channel and passed on once."""
    first = parts[0]
    if first is None:
        return None
    if isinstance(first, dict):
        return {k: torch.cat([p[k] for p in parts]) for k in first}
    if isinstance(first, torch.Tensor):
        return torch.cat(parts)
    if any(type(p) is not type(first) for p in parts):
        raise TypeError(f"one lockstep channel got calls with different {type(first).__name__} arguments")
    return first


def _split(value, sizes: list[int]) -> list:
    """Inverse of :func:`_cat` for one output: a tensor or a dict of tensors split into ``sizes`` rows."""
    if isinstance(value, dict):
        pieces = {k: v.split(sizes) for k, v in value.items()}
        return [{k: pieces[k][i] for k in value} for i in range(len(sizes))]
    return list(value.split(sizes))


class LockstepCorrect:
    """The network's ``correct`` shared by the scenes of one step (see the module docstring).

    ``channels``: the names of the network's track groups in the order a tracker updates them (e.g. ``("CTRA",
    "BICYCLE")``; a scene may lack some of them). Protocol per scene thread ``slot``: during a frame at most one call
    of ``bind(slot, channel)(...)`` per channel, in channel order (same signature as :meth:`GRUKalmanNet.correct`);
    after the frame :meth:`frame_done`; after its last frame :meth:`leave`. A thread that fails calls
    :meth:`abort`, which wakes the others with :class:`LockstepAborted`.

    The scenes pass the points (frame, channel) one round at a time: round r is channel r mod len(channels) of
    the frame the scenes are in; a round runs when every scene still active has arrived at it (with a request or
    passing it), so that every scene's requests of a frame and channel meet in one network call. The rounds run in
    one thread of their own, :meth:`serve` (started fresh for the step): autograd numbers the nodes it records per
    thread and its backward pass orders the independent branches of the graph (e.g. the CTRA and the Bicycle
    groups' chains of frames) by those numbers, so a network call made by whichever scene arrived last would
    sum a shared weight's gradient terms in an order that changes from run to run (a rounding difference); made
    by one thread that starts at zero, the step's gradient is the same bit for bit every time.
    """

    def __init__(self, correct: Callable, slots: int, channels: Sequence[str] = ("",)):
        if not channels:
            raise ValueError("a lockstep needs at least one channel")
        self._correct = correct
        self._channels = {name: i for i, name in enumerate(channels)}
        self._cond = threading.Condition()
        self._active = set(range(slots))
        self._waiting: dict[int, tuple | None] = {}  # slot -> (args, kwargs), or None: passing the round
        self._results: dict[int, tuple] = {}
        self._next = [0] * slots  # per slot: the channel of the current frame it arrives at next
        self._round = 0
        self._error: BaseException | None = None

    def bind(self, slot: int, channel: str | None = None) -> Callable:
        """``correct`` for scene ``slot``'s group ``channel`` (None: the first channel): blocks until the round's
        batched call has run; returns its rows."""
        c = 0 if channel is None else self._channels[channel]

        def correct(*args, **kwargs):
            if c < self._next[slot]:
                raise RuntimeError(f"lockstep: scene {slot} asked twice, or out of order, in one frame")
            self._pass_to(slot, c)
            self._next[slot] = c + 1
            return self._arrive(slot, (args, kwargs))

        return correct

    def frame_done(self, slot: int) -> None:
        """Scene ``slot`` finished a frame (passes the channels it asked nothing of in it)."""
        self._pass_to(slot, len(self._channels))
        self._next[slot] = 0

    def _pass_to(self, slot: int, c: int) -> None:
        """Scene ``slot`` passes the rounds of its current frame before channel ``c`` it has not arrived at."""
        while self._next[slot] < c:
            self._next[slot] += 1
            self._arrive(slot, None)

    def leave(self, slot: int) -> None:
        """Scene ``slot`` has no more frames: the rounds no longer wait for it."""
        with self._cond:
            self._active.discard(slot)
            self._cond.notify_all()

    def abort(self, exc: BaseException) -> None:
        """Stop every waiting scene (a scene's thread failed with ``exc``)."""
        with self._cond:
            self._error = self._error or exc
            self._cond.notify_all()

    def serve(self) -> None:
        """Run the rounds, each once every active scene has arrived at it, until every scene has left or one
        failed (the step's network thread: every network call of the step is made here). A failing network call
        stops the scenes (:meth:`abort`) and is raised."""
        with self._cond:
            while True:
                self._cond.wait_for(self._ready)
                if self._error is not None or not self._active:
                    return
                self._run_round()

    def _ready(self) -> bool:
        """(lock held) Whether :meth:`serve` has something to do: a round to run, or nothing more."""
        if self._error is not None or not self._active:
            return True
        return bool(self._waiting) and set(self._waiting) >= self._active

    def _arrive(self, slot: int, request):
        with self._cond:
            if self._error is not None:
                raise LockstepAborted("another scene of the step failed") from self._error
            self._waiting[slot] = request
            this = self._round
            self._cond.notify_all()
            self._cond.wait_for(lambda: self._round != this or self._error is not None)
            if self._round == this:
                raise LockstepAborted("another scene of the step failed") from self._error
            return self._results.pop(slot, None)

    def _run_round(self) -> None:
        """One network call on every request of the round (called by :meth:`serve` with the lock held); wakes the
        scenes."""
        asks = sorted((s, r) for s, r in self._waiting.items() if r is not None)
        self._waiting.clear()
        try:
            if asks:
                self._results.update(self._batched(asks))
        except BaseException as exc:
            self._error = exc
            self._cond.notify_all()
            raise
        self._round += 1
        self._cond.notify_all()

    def _batched(self, asks: list) -> dict[int, tuple]:
        """Run the network once on the concatenated requests [(slot, (args, kwargs))]; {slot: (x, hidden, K)}."""
        sizes = [a[0].shape[0] for _, (a, _) in asks]
        n_args = len(asks[0][1][0])
        args = [_cat([a[i] for _, (a, _) in asks]) for i in range(n_args)]
        kwargs = {k: _cat([kw[k] for _, (_, kw) in asks]) for k in asks[0][1][1]}
        with torch.enable_grad():  # grad mode is per thread: the serving thread's own
            outs = self._correct(*args, **kwargs)
        split = [_split(o, sizes) for o in outs]
        return {slot: tuple(s[i] for s in split) for i, (slot, _) in enumerate(asks)}
