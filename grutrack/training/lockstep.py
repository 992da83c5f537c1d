"""Several scenes per optimizer step with the network run once per frame over all of them (``scenes_per_step``).

Each scene is tracked by its own :class:`~grutrack.tracking.tracker.Tracker` in its own thread, the scenes in
lockstep by frame: in every frame each scene still running either asks for one network correction (the GRU-KF
group's update, :meth:`GRUKFBackend.update`) or ends the frame without one, and the last of them to arrive runs
``net.correct`` once on the tracks of all requests (concatenated along the track axis) and hands each scene its
rows. Every operator of the network acts on one track's row, so the result equals one call per scene; what
changes is the number of kernel launches and autograd nodes per frame: one set for k scenes (on a GPU the
launches, not the arithmetic, are the cost of a few hundred tracks).

The tracking itself (association, lifecycle, numpy) stays per scene and runs under the interpreter lock one scene
at a time; on a CPU the gain is the network's per-operator overhead only.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import torch


class LockstepAborted(RuntimeError):
    """Raised in the other scenes' threads when one of them failed (its own exception is re-raised by the caller)."""


def _cat(parts: list):
    """Concatenate one argument of several ``correct`` calls along the track axis: tensors (K_i, ...) -> (sum K_i,
    ...), dicts of tensors key by key, None stays None."""
    first = parts[0]
    if first is None:
        return None
    if isinstance(first, dict):
        return {k: torch.cat([p[k] for p in parts]) for k in first}
    return torch.cat(parts)


def _split(value, sizes: list[int]) -> list:
    """Inverse of :func:`_cat` for one output: a tensor or a dict of tensors split into ``sizes`` rows."""
    if isinstance(value, dict):
        pieces = {k: v.split(sizes) for k, v in value.items()}
        return [{k: pieces[k][i] for k in value} for i in range(len(sizes))]
    return list(value.split(sizes))


class LockstepCorrect:
    """The network's ``correct`` shared by the scenes of one step (see the module docstring).

    Protocol per scene thread ``slot``: during a frame at most one call of ``bind(slot)(...)`` (same signature as
    :meth:`GRUKalmanNet.correct`); after the frame :meth:`frame_done`; after its last frame :meth:`leave`. A thread
    that fails calls :meth:`abort`, which wakes the others with :class:`LockstepAborted`.
    """

    def __init__(self, correct: Callable, slots: int):
        self._correct = correct
        self._cond = threading.Condition()
        self._active = set(range(slots))
        self._waiting: dict[int, tuple | None] = {}  # slot -> (args, kwargs), or None: a frame without request
        self._results: dict[int, tuple] = {}
        self._asked: set[int] = set()  # slots that asked in their current frame
        self._round = 0
        self._error: BaseException | None = None

    def bind(self, slot: int) -> Callable:
        """``correct`` for scene ``slot``: blocks until the round's batched call has run; returns its rows."""

        def correct(*args, **kwargs):
            self._asked.add(slot)
            return self._arrive(slot, (args, kwargs))

        return correct

    def frame_done(self, slot: int) -> None:
        """Scene ``slot`` finished a frame (arrives now if it asked for nothing in it)."""
        if slot in self._asked:
            self._asked.discard(slot)
        else:
            self._arrive(slot, None)

    def leave(self, slot: int) -> None:
        """Scene ``slot`` has no more frames: the rounds no longer wait for it."""
        with self._cond:
            self._active.discard(slot)
            if self._error is None and self._waiting and set(self._waiting) >= self._active:
                self._run_round()

    def abort(self, exc: BaseException) -> None:
        """Stop every waiting scene (a scene's thread failed with ``exc``)."""
        with self._cond:
            self._error = self._error or exc
            self._cond.notify_all()

    def _arrive(self, slot: int, request):
        with self._cond:
            if self._error is not None:
                raise LockstepAborted("another scene of the step failed") from self._error
            self._waiting[slot] = request
            this = self._round
            if set(self._waiting) >= self._active:
                self._run_round()
            else:
                self._cond.wait_for(lambda: self._round != this or self._error is not None)
                if self._round == this:
                    raise LockstepAborted("another scene of the step failed") from self._error
            return self._results.pop(slot, None)

    def _run_round(self) -> None:
        """One network call on every request of the round (called with the lock held); wakes the scenes."""
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
        with torch.enable_grad():  # grad mode is per thread: the last to arrive may be outside its backend's context
            outs = self._correct(*args, **kwargs)
        split = [_split(o, sizes) for o in outs]
        return {slot: tuple(s[i] for s in split) for i, (slot, _) in enumerate(asks)}
