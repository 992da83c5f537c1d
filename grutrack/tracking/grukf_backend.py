"""The GRU-Kalman filter as a tracker motion backend: all tracks of a frame form one batch.

Per-track tensors (state, the previous posteriors/prior and measurement that feed the network, and the GRU
hidden states) are rows of arrays indexed like the track group; they are born and removed with the tracks.
In inference no autograd graph is kept; in training (``train=True``) the graph spans the frames of a scene.

With an EKF gain prior (``GRUKFConfig.gain_prior == "ekf"``) every track also carries the EKF covariance P, which
is propagated here with the numpy EKF (:class:`grutrack.motion.kalman.BatchKalmanFilter`, the same SS model and
form, the network's per-class Q, R, P0), linearised at the GRU-KF's own (detached) state:

* predict: ``P^- = F P F^T + Q``, F the Jacobian of f at the posterior;
* update: ``K_ekf = P^- H^T S^-1``, ``S = H P^- H^T + R`` (given to the network, which adds its residual), and
  ``P = (I - K_ekf H) P^- (I - K_ekf H)^T + K_ekf R K_ekf^T`` (Joseph form): the EKF's own update, whose gain
  (:class:`~grutrack.motion.kalman.Correction`) is the one given to the network.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch

from grutrack.errors import ConfigError
from grutrack.motion.grukf import GRUKalmanNet
from grutrack.tracking.velocity_check import CheckState, VelocityCheck


def resolve_device(device: str = "auto", what: str = "--device") -> torch.device:
    """The torch device for ``device``: a named one (cpu, cuda, cuda:N), which must exist here, or ``auto``.
    ``what`` names the flag or config field the value came from, for the error message.

    ``auto`` is the CPU, with or without a GPU. A frame is a few dozen tracks through a small network, and the
    tracker's association and bookkeeping between the network calls run on the CPU either way; on an H100 machine
    every setting measured, tracking and training with 1, 8 and 32 scenes per step, ran slower on its GPU than on
    its CPU (docs/results/lockstep.md#gpu). Naming ``cuda`` uses the GPU."""
    if device == "auto":
        return torch.device("cpu")
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError) as exc:
        raise ConfigError(f"{what}: unknown torch device {device!r} (expected auto, cpu, cuda or cuda:N)") from exc
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            why = (
                (f"this torch build ({torch.__version__}) has no CUDA support (see the README: a CUDA build of torch)")
                if torch.version.cuda is None
                else "no CUDA GPU is visible"
            )
            raise ConfigError(f"{what}: {device!r} asked for a GPU, but {why}; use auto or cpu")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise ConfigError(f"{what}: {device!r} but only {torch.cuda.device_count()} CUDA device(s) are visible")
    elif dev.type != "cpu":
        raise ConfigError(f"{what}: unsupported torch device {device!r} (expected auto, cpu, cuda or cuda:N)")
    return dev


#: width of the last-measurement block (y_prev) of a track row (``GRUState.rows``)
_MEAS = 9


@dataclass
class GRUState:
    """N tracks, their tensors packed in two arrays (one row gather and one row write per update, whatever the
    number of fields): ``rows`` (N, 4m + 10) float64 = ``[x | y_prev | post1 | post2 | prior1 | gain_abs_max]``
    with x the current state (posterior after an update, prior after a predict) (m), y_prev the last
    measurement (9), post1 / post2 the last two posteriors and prior1 the prior of the last update (m each),
    gain_abs_max the largest |K| entry of the track's last gain (0 before its first update; no autograd graph);
    ``hid`` (N, H) the GRU hidden states side by side (network dtype; see :meth:`GRUKFBackend.hidden`); labels
    (N,) int64, n_updates (N,) int64 the updates each track has had and since (N,) int64 the frames predicted
    since its last update or birth (numpy); P (N, m, m) float64 numpy, the EKF covariance of each track
    (``gain_prior="ekf"`` only, else None)."""

    rows: torch.Tensor
    hid: torch.Tensor
    labels: np.ndarray
    n_updates: np.ndarray
    since: np.ndarray
    P: np.ndarray | None = None
    #: after an update: the posterior (K, m) of the K tracks just corrected, in the order of their rows (with
    #: its graph in training; the same values as their rows of x); None otherwise
    corrected: torch.Tensor | None = None
    #: after an update: the largest |K| entry (K, 1) float64 of each corrected track's gain (no graph); None otherwise
    corrected_gain: torch.Tensor | None = None
    #: the velocity check's memory of the tracks (:mod:`grutrack.tracking.velocity_check`); None without a check
    check: CheckState | None = None

    @property
    def m(self) -> int:
        """State dimension."""
        return (self.rows.shape[1] - _MEAS - 1) // 4

    @property
    def x(self) -> torch.Tensor:
        """Current state (N, m) (a view of ``rows``)."""
        return self.rows[:, : self.m]

    @property
    def gain_abs_max(self) -> torch.Tensor:
        """(N,) float64: the largest |K| entry of each track's last gain."""
        return self.rows[:, -1].detach()

    def with_x(self, x: torch.Tensor, P: np.ndarray | None, dt: float) -> GRUState:
        """The tracks with state ``x`` (N, m) and covariance ``P``, one more frame (``dt`` seconds) since their
        last update."""
        check = None if self.check is None else self.check.predicted(dt)
        rows = torch.cat([x, self.rows[:, self.m :]], dim=1)
        return GRUState(rows, self.hid, self.labels, self.n_updates, self.since + 1, P, check=check)

    def take(self, r: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(x, y_prev, post1, post2, prior1, hid) of tracks ``r`` (K,) int64: two row gathers."""
        m = self.m
        x, y_prev, post1, post2, prior1, _ = self.rows.index_select(0, r).split_with_sizes([m, _MEAS, m, m, m, 1], 1)
        return x, y_prev, post1, post2, prior1, self.hid.index_select(0, r)


class GRUKFBackend:
    """Batched GRU-KF over the tracks of one group (every class of the group shares the network and SS model).

    ``class_index`` (n_labels,) int: the tracking class (row of the network's per-class gain) of each dataset
    label; None = the labels are the tracking classes. ``correct``: what runs the network's update (default
    ``net.correct``; training several scenes per step passes one that batches the scenes' calls,
    :mod:`grutrack.training.lockstep`). ``ss_model``: the group's SS model when it is not the network's own
    (``network_classes: own_model``: e.g. the Bicycle classes of a CTRA network; same state layout, the weights
    shared). ``velocity_check``: the check of the detector's velocity (:mod:`grutrack.tracking.velocity_check`; a
    track whose velocity failed gets its predicted velocity as the measured one, zero innovation, and the EKF gain
    prior leaves the velocity out), or None. ``robust``: the EKF gain prior's robust update
    (:class:`~grutrack.motion.kalman.RobustUpdate`), or None.
    """

    def __init__(
        self,
        net: GRUKalmanNet,
        device: torch.device | str = "auto",
        train: bool = False,
        class_index: np.ndarray | None = None,
        correct=None,
        ss_model: str | None = None,
        velocity_check: VelocityCheck | None = None,
        robust=None,
    ):
        self.net = net
        self.velocity_check = velocity_check
        own = ss_model is None or ss_model.upper() == net.cfg.ss_model.upper()
        self.ss = net.ss if own else net.cfg.torch_model(ss_model)
        correct = net.correct if correct is None else correct
        self.correct = correct if own else functools.partial(correct, ss=self.ss)
        self.class_index = None if class_index is None else np.asarray(class_index, dtype=np.int64)
        self.device = resolve_device(device) if isinstance(device, str) else device
        self.net.to(self.device)
        self.train = train
        h = net.init_hidden(0, self.device)  # names and widths of the hidden states, in their packed order
        self._hidden_layout = (tuple(h), tuple(v.shape[1] for v in h.values()))
        self._hidden_dtype = next(iter(h.values())).dtype
        self.kf = None
        if net.cfg.gain_prior == "ekf":  # the prior EKF: same SS model, the network's noise tables (numpy)
            from grutrack.motion.kalman import BatchKalmanFilter
            from grutrack.motion.models import make_model

            name = net.cfg.ss_model if own else ss_model
            params = dict(net.cfg.ss_params if own else net.cfg.model_params.get(ss_model.upper(), {}))
            form = params.pop("form", "arc")  # the torch model's form (:meth:`GRUKFConfig.torch_model`)
            model = make_model(name, form, **params)
            self.kf = BatchKalmanFilter(model, yaw_flip=net.cfg.yaw_flip, robust=robust)
            self.Q, self.R, self.P0 = (
                getattr(net, k).detach().cpu().numpy().astype(np.float64) for k in ("ekf_Q", "ekf_R", "ekf_P0")
            )

    def _classes(self, labels: np.ndarray) -> np.ndarray:
        """Tracking class (N,) int64 of dataset labels (N,)."""
        return labels if self.class_index is None else self.class_index[labels]

    def _t(self, a: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.asarray(a, dtype=np.float64), device=self.device)

    def _ctx(self):
        """Training: autograd records the scene's graph. Tracking: inference mode (no graph, and none of the
        per-operator bookkeeping autograd needs, e.g. version counters)."""
        return torch.enable_grad() if self.train else torch.inference_mode()

    def initiate(self, z: np.ndarray, labels: np.ndarray) -> GRUState:
        """New tracks from detections z (N, 9)."""
        with self._ctx():
            zt = self._t(z)
            x = self.ss.init_state(zt)
            zero = np.zeros(len(z), dtype=np.int64)
            P = None if self.kf is None else self.P0[self._classes(labels)].copy()  # P = P0 of the class
            rows = torch.cat([x, zt, x, x, x, zt.new_zeros(len(z), 1)], dim=1)
            hid = torch.zeros(len(z), sum(self._hidden_layout[1]), dtype=self._hidden_dtype, device=self.device)
            check = None if self.velocity_check is None else self.velocity_check.start(np.asarray(z).reshape(-1, 9))
            return GRUState(rows, hid, labels.copy(), zero, zero, P, check=check)

    def hidden(self, hid: torch.Tensor) -> dict[str, torch.Tensor]:
        """The network's hidden states {name: (K, size)} from packed rows ``hid`` (K, H) (one split)."""
        names, sizes = self._hidden_layout
        return dict(zip(names, hid.split_with_sizes(list(sizes), 1)))

    def _cells(self, s: GRUState, rows: np.ndarray):
        """The gain-table cells of tracks ``rows`` at this update (None when the network has no table)."""
        if not self.net.cfg.has_table:
            return None
        cells = self.net.table_index(self._classes(s.labels[rows]), s.n_updates[rows] + 1, np.maximum(s.since[rows], 1))
        return torch.as_tensor(cells, device=self.device)

    def _counts(self, s: GRUState, rows: np.ndarray) -> torch.Tensor | None:
        """(K, 2) update count at this update and frames since the last one of tracks ``rows`` (None unless
        the network has aux inputs)."""
        if not self.net.cfg.aux_inputs:
            return None
        c = np.stack([s.n_updates[rows] + 1, np.maximum(s.since[rows], 1)], axis=1)
        return torch.as_tensor(c, device=self.device, dtype=torch.float64)

    def predict(self, s: GRUState, dt: float) -> GRUState:
        """x <- f(x, dt) for every track; with ``coast_yaw_rate: zero`` (``coast_acceleration: zero``) the tracks
        already predicted once since their last update (``since >= 1``: coasting) have their turn-rate
        (acceleration) slot set to 0 first."""
        x = self._coasted(s)
        P = None
        if self.kf is not None:  # P^- = F P F^T + Q, F at the posterior
            _, P = self.kf.predict(self._np(x), s.P, self.Q[self._classes(s.labels)], dt)
        with self._ctx():
            return s.with_x(self.ss.f(x, dt), P, dt)

    def _coast_slots(self) -> list[int]:
        """State columns a coasting track holds at 0: the turn rate (CTRA omega, Bicycle steering angle) with
        ``coast_yaw_rate: zero``, the acceleration with ``coast_acceleration: zero``."""
        cfg = self.net.cfg
        return ([self.ss.turn_index] if cfg.coast_yaw_rate == "zero" else []) + (
            [self.ss.accel_index] if cfg.coast_acceleration == "zero" else []
        )

    def _coasted(self, s: GRUState) -> torch.Tensor:
        """The state (N, m) to predict from: ``s.x``, with the :meth:`_coast_slots` of coasting tracks
        (``since >= 1``) set to 0."""
        coasting = s.since >= 1
        slots = self._coast_slots()
        if not slots or not coasting.any():
            return s.x
        with self._ctx():
            held = torch.zeros(s.x.shape[1], dtype=torch.bool, device=s.x.device)
            held[slots] = True  # (m,)
            rows = torch.as_tensor(coasting, device=s.x.device)[:, None]  # (N, 1)
            return torch.where(rows & held, torch.zeros((), dtype=s.x.dtype, device=s.x.device), s.x)

    @staticmethod
    def _np(t: torch.Tensor) -> np.ndarray:
        """A detached float64 numpy copy of a tensor."""
        return t.detach().cpu().numpy().astype(np.float64)

    def _ekf_gain(
        self,
        s: GRUState,
        rows: np.ndarray,
        z: np.ndarray,
        R: np.ndarray | None,
        R_index: np.ndarray | None,
        scores: np.ndarray | None = None,
    ) -> tuple[torch.Tensor | None, np.ndarray | None]:
        """The EKF's Joseph-form update of tracks ``rows`` with z (K, 9) scored ``scores`` (K,) and noise
        ``R[R_index]`` (confidence-weighted with the preset's ``motion.r_score_exponent``) at the GRU-KF's
        (detached) prior: the gain ``K_ekf = P^- H^T S^-1`` (K, m, 9) tensor it applied and the covariance of all
        tracks after it ((N, m, m)); (None, None) without an EKF gain prior. A singular S (a state driven far off)
        raises LinAlgError."""
        if self.kf is None:
            return None, None
        P = np.ascontiguousarray(s.P, dtype=np.float64).copy()
        K = self.kf.correct(self._np(s.x), P, rows, z, R, R_index, s.n_updates[rows], scores).K
        if not np.isfinite(K).all():
            raise np.linalg.LinAlgError("Singular matrix")
        return torch.as_tensor(K, device=self.device), P

    def _checked(self, s: GRUState, rows: np.ndarray, z: np.ndarray, prior: torch.Tensor):
        """The velocity check at this update (:mod:`grutrack.tracking.velocity_check`): (z, R, R_index, check)
        with the tracks whose velocity failed taking none (``prior`` (K, m) their prior states)."""
        R = self.R if self.kf is not None else None
        R_index = self._classes(s.labels[rows]) if self.kf is not None else None
        if self.velocity_check is None:
            return z, R, R_index, None
        return self.velocity_check.apply(s.check, rows, z, lambda: self._np(self.ss.h(prior)), R, R_index)

    def update(self, s: GRUState, rows: np.ndarray, z: np.ndarray, scores: np.ndarray | None = None) -> GRUState:
        """Correct tracks ``rows`` (K,) with measurements z (K, 9) scored ``scores`` (K,) through the learned gain
        (the scores reach the EKF gain prior only)."""
        with self._ctx():
            r = torch.as_tensor(rows, device=self.device, dtype=torch.long)
            prior, y_prev, post1, post2, prior1, hid = s.take(r)
            z, R, R_index, check = self._checked(s, rows, z, prior)
            y = self._t(z)
            K_ekf, P = self._ekf_gain(s, rows, z, R, R_index, scores)
            post, new_hidden, K = self.correct(
                prior,
                y,
                y_prev,
                post1,
                prior1,
                post2,
                self.hidden(hid),
                self._cells(s, rows),
                self._counts(s, rows),
                K_prior=K_ekf,
            )
            gain = K.detach().abs().amax(dim=(1, 2)).to(post.dtype)[:, None]
            new_rows = torch.cat([post, y, post, post1, prior, gain], dim=1)
            new_hid = torch.cat([new_hidden[k] for k in self._hidden_layout[0]], dim=1).to(s.hid.dtype)
            return GRUState(
                s.rows.index_copy(0, r, new_rows),
                s.hid.index_copy(0, r, new_hid),
                s.labels,
                _incremented(s.n_updates, rows),
                _zeroed(s.since, rows),
                P,
                corrected=post,
                corrected_gain=gain,
                check=check,
            )

    def measure(self, s: GRUState) -> torch.Tensor:
        """h(x) (N, 9) as a tensor (keeps the graph in training)."""
        return self.ss.h(s.x)

    def measure_corrected(self, s: GRUState) -> torch.Tensor:
        """h(x) (K, 9) of the K tracks the update that made ``s`` corrected, in the order of their rows (keeps the
        graph in training)."""
        return self.ss.h(s.corrected)

    def boxes(self, s: GRUState) -> np.ndarray:
        """Canonical boxes (N, 9) float64 of the current state."""
        with torch.no_grad() if self.train else torch.inference_mode():
            b = self.ss.h(s.x).detach().cpu().numpy().astype(np.float64)
        b[:, 6] = (b[:, 6] + np.pi) % (2 * np.pi) - np.pi
        return b

    def select(self, s: GRUState, index: np.ndarray) -> GRUState:
        """Subset of the tracks (mask or indices)."""
        idx = np.flatnonzero(index) if np.asarray(index).dtype == bool else np.asarray(index)
        with self._ctx():
            it = torch.as_tensor(idx, device=self.device, dtype=torch.long)
            return GRUState(
                s.rows.index_select(0, it),
                s.hid.index_select(0, it),
                s.labels[idx],
                s.n_updates[idx],
                s.since[idx],
                None if s.P is None else s.P[idx],
                check=None if s.check is None else s.check.select(idx),
            )

    def concat(self, a: GRUState, b: GRUState) -> GRUState:
        """Tracks of a then b."""
        with self._ctx():
            return self._concat(a, b)

    @staticmethod
    def _concat(a: GRUState, b: GRUState) -> GRUState:
        return GRUState(
            torch.cat([a.rows, b.rows]),
            torch.cat([a.hid, b.hid]),
            *(np.concatenate([getattr(a, n), getattr(b, n)]) for n in ("labels", "n_updates", "since")),
            None if a.P is None else np.concatenate([a.P, b.P]),
            check=CheckState.concat(a.check, b.check),
        )


def _zeroed(counts: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """A copy of ``counts`` (N,) with ``rows`` set to zero."""
    out = counts.copy()
    out[rows] = 0
    return out


def _incremented(counts: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """A copy of ``counts`` (N,) with ``rows`` incremented by one."""
    out = counts.copy()
    out[rows] += 1
    return out
