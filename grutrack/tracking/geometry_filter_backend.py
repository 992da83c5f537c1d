"""Fast-Poly's decoupled geometry (Li et al., "Fast-Poly: A Fast Polyhedral Framework For 3D Multi-Object
Tracking", RA-L 2024; behaviour read from its public code at 694dec3) as a motion backend wrapper.

:class:`GeometryFilterBackend` wraps any motion backend (:class:`grutrack.tracking.tracker.MotionBackend`) and
takes ``[z, w, l, h]`` of a track's boxes from a :class:`GeometryWindow` (the median or mean of its last ``W``
matched detections) instead of the Kalman state; built by :func:`grutrack.tracking.factory.with_geometry_filter`
when a preset sets ``motion.geometry_filter`` (preset ``fastpoly``).

Box arrays follow :mod:`grutrack.boxes`: ``(N, 9) float64 [x, y, z, w, l, h, yaw, vx, vy]``, metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class GeometryWindow:
    """Decoupled track geometry: the last ``W`` matched ``[z, w, l, h]`` of every track.

    hist (N, W, 4) float64 metres, oldest first, NaN where the window is not yet full; mean (N,) bool: the
    track's estimate is the mean of its window (else the median).
    """

    hist: np.ndarray
    mean: np.ndarray

    @classmethod
    def start(cls, zwlh: np.ndarray, window: np.ndarray, mean: np.ndarray) -> GeometryWindow:
        """Windows holding one measurement each. zwlh (N, 4); window (N,) int >= 1; mean (N,) bool.

        The array width is the largest window; a track with a smaller window W_i keeps its last W_i entries
        (the entries before are NaN).
        """
        width = int(np.max(window)) if len(window) else 1
        hist = np.full((len(zwlh), width, 4), np.nan)
        hist[:, -1] = zwlh
        return cls(hist, np.asarray(mean, dtype=bool))

    def push(self, rows: np.ndarray, zwlh: np.ndarray, window: np.ndarray) -> None:
        """Append ``zwlh (K, 4)`` to the windows of tracks ``rows (K,)``; the oldest entry falls out once a
        window holds ``window[rows]`` (K,) entries."""
        h = self.hist[rows]
        h[:, :-1] = h[:, 1:]
        h[:, -1] = zwlh
        width = h.shape[1]
        stale = np.arange(width)[None, :] < (width - window)[:, None]  # (K, width) beyond the window
        h[stale] = np.nan
        self.hist[rows] = h

    def estimate(self) -> np.ndarray:
        """(N, 4) ``[z, w, l, h]``: per track the median (or mean) over its window, ignoring empty slots."""
        if len(self.hist) == 0:
            return np.zeros((0, 4))
        filled = ~np.isnan(self.hist[:, :, 0])
        n = filled.sum(axis=1)  # (N,) entries per window
        rows = np.arange(len(self.hist))
        s = np.sort(self.hist, axis=1)  # NaN sort last
        # median: the middle entry (odd n) or the mean of the two middle ones (even n), as numpy's median
        out = 0.5 * (s[rows, (n - 1) // 2] + s[rows, n // 2])
        if self.mean.any():
            total = np.where(filled[:, :, None], self.hist, 0.0).sum(axis=1)
            out[self.mean] = (total / n[:, None])[self.mean]
        return out

    def select(self, index: np.ndarray) -> GeometryWindow:
        """The tracks picked by a boolean mask or index array."""
        return GeometryWindow(self.hist[index], self.mean[index])

    @staticmethod
    def concat(a: GeometryWindow, b: GeometryWindow) -> GeometryWindow:
        """Tracks of ``a`` followed by those of ``b`` (windows padded to the wider one)."""
        w = max(a.hist.shape[1], b.hist.shape[1])
        pad = [np.concatenate([np.full((len(g.hist), w - g.hist.shape[1], 4), np.nan), g.hist], axis=1) for g in (a, b)]
        return GeometryWindow(np.concatenate(pad), np.concatenate([a.mean, b.mean]))


@dataclass
class GeometryState:
    """State of a :class:`GeometryFilterBackend`: the wrapped backend's state and the geometry windows."""

    motion: object
    geometry: GeometryWindow
    labels: np.ndarray


class GeometryFilterBackend:
    """A motion backend whose boxes take ``[z, w, l, h]`` from a window filter (Fast-Poly's decoupled geometry).

    The wrapped backend still filters every state (in grutrack's models z, w, l, h form an independent block,
    so the other states are unaffected); :meth:`boxes` replaces columns z, w, l, h by the median (or mean) of
    the track's last ``window[label]`` matched detections. ``window`` (C,) int >= 1 and ``mean`` (C,) bool per
    class label; a class with ``window`` 0 is passed through unchanged (geometry from the motion filter).
    """

    def __init__(self, inner, window: np.ndarray, mean: np.ndarray):
        self.inner = inner
        self.window = np.asarray(window, dtype=np.int64)
        self.mean = np.asarray(mean, dtype=bool)

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> GeometryState:
        """New tracks from detections z (N, 9)."""
        win = np.maximum(self.window[labels], 1)
        return GeometryState(
            self.inner.initiate(z, labels), GeometryWindow.start(z[:, 2:6], win, self.mean[labels]), labels.copy()
        )

    @property
    def coast_held(self) -> np.ndarray | None:
        """The wrapped backend's slots a coasting track holds at 0 (per label)."""
        return getattr(self.inner, "coast_held", None)

    def predict(self, s: GeometryState, dt: float, coasting: np.ndarray | None = None) -> GeometryState:
        """Motion predicted ``dt`` seconds ahead (``coasting``: as the wrapped backend's); the geometry is
        constant."""
        motion = self.inner.predict(s.motion, dt) if coasting is None else self.inner.predict(s.motion, dt, coasting)
        return GeometryState(motion, s.geometry, s.labels)

    def update(
        self, s: GeometryState, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None
    ) -> GeometryState:
        """Tracks ``rows (K,)`` corrected by z (K, 9) scored ``scores`` (K,); their windows take ``z[:, 2:6]``."""
        g = GeometryWindow(s.geometry.hist.copy(), s.geometry.mean)
        g.push(rows, z[:, 2:6], np.maximum(self.window[s.labels[rows]], 1))
        return GeometryState(self.inner.update(s.motion, rows, z, scores), g, s.labels)

    def boxes(self, s: GeometryState) -> np.ndarray:
        """(N, 9) boxes: the motion filter's, with z, w, l, h from the windows where the class uses them."""
        out = self.inner.boxes(s.motion)
        use = self.window[s.labels] > 0
        out[use, 2:6] = s.geometry.estimate()[use]
        return out

    def select(self, s: GeometryState, index: np.ndarray) -> GeometryState:
        return GeometryState(self.inner.select(s.motion, index), s.geometry.select(index), s.labels[index])

    def concat(self, a: GeometryState, b: GeometryState) -> GeometryState:
        return GeometryState(
            self.inner.concat(a.motion, b.motion),
            GeometryWindow.concat(a.geometry, b.geometry),
            np.concatenate([a.labels, b.labels]),
        )
