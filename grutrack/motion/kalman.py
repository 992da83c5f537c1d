"""Batched extended / linear Kalman filter over N tracks that share one motion model.

Every track carries its own state ``x (N, dim_x)``, covariance ``P (N, dim_x, dim_x)`` and noise
``Q (N, dim_x, dim_x)``, ``R (N, 9, 9)``, so tracks of different classes that use the same model (car, bus and
truck all use CTRA) are filtered in one array operation with their own class noise. ``Q``, ``R`` and
``P0`` may also be given as one ``(d, d)`` matrix for all tracks. With a linear model the same code is the
ordinary Kalman filter (its F and H are exact).

* predict: ``F = F(x)`` at the prior state, ``x = f(x, dt)``, ``P = F P F^T + Q``; yaw state wrapped.
* update: residual ``r = z - h(x)`` with the yaw component wrapped to [-pi, pi) (and, with ``yaw_flip``, turned
  by pi when it exceeds pi/2, see below), ``S = H P H^T + R``, ``K = P H^T S^-1`` (LU with partial pivoting),
  ``x = x + K r`` with the yaw wrapped again, and Joseph form ``P = (I-KH) P (I-KH)^T + K R K^T``, symmetrised.
  :meth:`BatchKalmanFilter.correct` does this in place for selected rows with a per-class R table (the tracker's
  call: one compiled pass, no gathered copies of P) and returns what it computed, r, S and K (a
  :class:`Correction`, as filterpy's update keeps ``y``, ``S``, ``K``): nobody computes the gain again.

Heading ambiguity (``yaw_flip``, default True): a box's footprint is the same under a 180 degree turn and
detectors often return the reversed heading. When the wrapped yaw residual exceeds pi/2 in magnitude the
detection's yaw is taken to be flipped and the residual is replaced by ``wrap(r + pi)`` (the measured yaw turned
by pi); position, size and the detector's velocity are used unchanged. A real heading change of more than 90
degrees between two frames (0.5 s on nuScenes) is not physically plausible for the tracked classes. Poly-MOT
does NOT do this: it only wraps the yaw residual to [-pi, pi) (``warpResYawToPi``), so a flipped detection pulls
the heading by up to K * pi; ``yaw_flip=False`` reproduces that.

Outlying detections (``nis_limit`` g, default 0: off): a detection whose position innovation is improbable under
the prior, normalised innovation squared ``d2 = r_xy^T S_xy^-1 r_xy`` (x, y: 2 degrees of freedom) above g, is
taken with its whole R scaled by ``d2 / g`` (R of the others unchanged): its NIS under the inflated ``S`` falls
toward g (to g where R dominates S). One far-off detection (a neighbour's box, a detector's ghost) then moves the
track by a bounded step instead of the gain's full pull, and a real manoeuvre still moves it, over two or three
frames. This is the chi-square-scaled R of robust Kalman filtering (a Huber-type M-estimate of the innovation; e.g.
Chang 2014, "Robust Kalman filtering based on Mahalanobis distance as outlier judging criterion", J. Geodesy
88:391-401). The test needs a prior worth trusting: with ``min_hits`` h (:class:`RobustUpdate`) a track is tested
only once it has h matched detections (birth included) before the update; a newborn track's prior carries its
first detections' errors (a failed detected velocity among them), and its large innovations are its own lag.

Confidence-weighted noise (``score_exponent`` e, default 0: off): a detection scored c in (0, 1] is taken with
``R / c^e`` (c floored at :data:`SCORE_FLOOR`), so a detection its detector doubts moves the track less than a
confident one; with e = 1 the noise variance is inversely proportional to the score. Detectors' scores track their
boxes' localisation quality (e.g. IoU-aware scoring, Wu et al. 2020; the confidence-scaled R of GIAOTracker's NSA
Kalman filter, Du et al. 2021, which takes ``(1 - c) R``). It is applied before the outlier test above, which then
tests the innovation under the scaled R.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from grutrack.boxes import BOX_DIM, wrap_angle
from grutrack.motion.models import MotionModel, _wrap

YAW_Z = 6  # yaw column of the canonical measurement / box
SCORE_FLOOR = 0.01  # the least score confidence-weighted noise takes (a score of 0 would give an infinite R)


def _batch(M: np.ndarray, n: int, d: int, name: str) -> np.ndarray:
    """``M`` as an ``(n, d, d)`` float64 array (a single ``(d, d)`` matrix is broadcast)."""
    M = np.asarray(M, dtype=np.float64)
    if n == 0:
        return np.zeros((0, d, d))
    if M.shape == (d, d):
        return np.broadcast_to(M, (n, d, d))
    if M.shape != (n, d, d):
        raise ValueError(f"{name} must have shape ({n}, {d}, {d}) or ({d}, {d}), got {M.shape}")
    return M


def wrap_yaw_residual(r_yaw: np.ndarray, yaw_flip: bool) -> np.ndarray:
    """Yaw residuals ``(N,)`` wrapped to [-pi, pi); with ``yaw_flip`` those beyond pi/2 are turned by pi."""
    r = wrap_angle(r_yaw)
    if yaw_flip:
        r = np.where(np.abs(r) > 0.5 * np.pi, wrap_angle(r + np.pi), r)
    return r


@njit(cache=True, inline="always")
def _mm(A, B, out, a_t=False, b_t=False, sparse_b=False) -> None:
    """``out = op(A) op(B)`` for 2-D arrays, ``op`` the transpose where ``a_t`` / ``b_t`` is set.

    ``out[i, j] = sum_k op(A)[i, k] op(B)[k, j]`` summed in ascending k, k the outer loop, so the inner loops
    run over independent entries. Zero entries of ``op(A)`` (of ``op(B)`` with ``sparse_b``: use it when B is
    the sparse factor, e.g. a Jacobian) are skipped: a zero product adds nothing to a finite sum, so the
    result is that of the plain triple loop, bit for bit.
    """
    out[:] = 0.0
    for k in range(A.shape[0] if a_t else A.shape[1]):
        if sparse_b:
            for j in range(out.shape[1]):
                b = B[j, k] if b_t else B[k, j]
                if b != 0.0:
                    for i in range(out.shape[0]):
                        out[i, j] += (A[k, i] if a_t else A[i, k]) * b
        else:
            for i in range(out.shape[0]):
                a = A[k, i] if a_t else A[i, k]
                if a != 0.0:
                    for j in range(out.shape[1]):
                        out[i, j] += a * (B[j, k] if b_t else B[k, j])


@njit(cache=True, inline="always")
def _sym_into(A, out) -> None:
    """``out = (A + A^T) / 2`` for square 2-D arrays."""
    for i in range(A.shape[0]):
        for j in range(A.shape[0]):
            out[i, j] = 0.5 * (A[i, j] + A[j, i])


@njit(cache=True)
def _propagate_kernel(F, P, Q, out) -> None:
    """``out[n] = sym(F[n] P[n] F[n]^T + Q[n])`` for ``F, P, Q, out (N, d, d)``; ``sym(A) = (A + A^T) / 2``."""
    d = F.shape[1]
    FP, A = np.empty((d, d)), np.empty((d, d))
    for n in range(F.shape[0]):
        _mm(F[n], P[n], FP)
        _mm(FP, F[n], A, b_t=True, sparse_b=True)
        A += Q[n]
        _sym_into(A, out[n])


@njit(cache=True)
def _correct_kernel(x, P, rows, z, h, H, R, R_index, yaw_flip, yaw_index, y_out, S_out, K_out) -> None:
    """EKF correction, Joseph form, of the tracks ``rows (K,)`` of ``x (N, d)`` and ``P (N, d, d)``, in place.

    ``z (K, m)`` measurements, ``h (K, m)`` = h(x[rows]), ``H (K, m, d)`` its Jacobian, ``R (C, m, m)`` a table
    indexed by ``R_index (K,)``. Residual ``r = z - h`` with the yaw component (``YAW_Z``) wrapped to [-pi, pi)
    (and turned by pi beyond pi/2 with ``yaw_flip``); ``S = sym(H P H^T + R)``, ``K = P H^T S^-1``
    (``K^T = S^-1 (H P)`` by LU with partial pivoting), ``x' = x + K r`` with the yaw state ``yaw_index``
    wrapped, ``P' = sym((I - K H) P (I - K H)^T + K R K^T)``. Row k's r, S and K are written to ``y_out (K, m)``,
    ``S_out (K, m, m)`` and ``K_out (K, d, m)``.
    """
    d, m = x.shape[1], H.shape[1]
    HP, KT, S, S_sym = np.empty((m, d)), np.empty((m, d)), np.empty((m, m)), np.empty((m, m))
    IKH, T1, KR, A, B = np.empty((d, d)), np.empty((d, d)), np.empty((d, m)), np.empty((d, d)), np.empty((d, d))
    r, Kr = np.empty((1, m)), np.empty((d, 1))
    perm = np.empty(m, dtype=np.int64)
    for k in range(rows.shape[0]):
        n = rows[k]
        Rk, Hk, Pn = R[R_index[k]], H[k], P[n]
        for i in range(m):
            r[0, i] = z[k, i] - h[k, i]
        r[0, YAW_Z] = _wrap(r[0, YAW_Z])
        if yaw_flip and abs(r[0, YAW_Z]) > 0.5 * np.pi:
            r[0, YAW_Z] = _wrap(r[0, YAW_Z] + np.pi)
        _mm(Hk, Pn, HP)  # H P
        _mm(HP, Hk, S, b_t=True, sparse_b=True)  # H P H^T
        S += Rk
        _sym_into(S, S_sym)
        S_out[k] = S_sym
        _lu_solve(S_sym, HP, KT, perm)  # K^T = S^-1 H P (S_sym overwritten by its LU factors)
        for i in range(m):
            y_out[k, i] = r[0, i]
            for j in range(d):
                K_out[k, j, i] = KT[i, j]
        _mm(KT, r, Kr, a_t=True, b_t=True)  # K r
        _mm(KT, Hk, IKH, a_t=True, sparse_b=True)  # K H
        IKH *= -1.0
        for i in range(d):
            IKH[i, i] += 1.0  # I - K H
        _mm(IKH, Pn, T1)
        _mm(T1, IKH, A, b_t=True, sparse_b=True)  # (I - K H) P (I - K H)^T
        _mm(KT, Rk, KR, a_t=True, sparse_b=True)  # K R
        _mm(KR, KT, B)  # K R K^T
        A += B
        for i in range(d):
            x[n, i] += Kr[i, 0]
        x[n, yaw_index] = _wrap(x[n, yaw_index])
        _sym_into(A, Pn)


@njit(cache=True)
def _lu_solve(S, B, X, perm) -> None:
    """``X = S^-1 B`` for ``S (m, m)`` (overwritten by its LU factors) and ``B, X (m, k)``; partial pivoting."""
    m, k = S.shape[0], B.shape[1]
    for i in range(m):
        perm[i] = i
    for c in range(m):
        p = c
        for i in range(c + 1, m):
            if abs(S[i, c]) > abs(S[p, c]):
                p = i
        if p != c:
            for j in range(m):
                S[c, j], S[p, j] = S[p, j], S[c, j]
            perm[c], perm[p] = perm[p], perm[c]
        for i in range(c + 1, m):
            S[i, c] /= S[c, c]
            for j in range(c + 1, m):
                S[i, j] -= S[i, c] * S[c, j]
    for col in range(k):
        for i in range(m):  # forward substitution with the unit lower factor
            acc = B[perm[i], col]
            for j in range(i):
                acc -= S[i, j] * X[j, col]
            X[i, col] = acc
        for i in range(m - 1, -1, -1):  # back substitution with the upper factor
            acc = X[i, col]
            for j in range(i + 1, m):
                acc -= S[i, j] * X[j, col]
            X[i, col] = acc / S[i, i]


@dataclass(frozen=True)
class RobustUpdate:
    """How an update adapts each detection's R (module docstring): the robust update, ``nis_limit`` g (0: off) and
    ``min_hits`` the matched detections a track needs before the update for its detection to be tested (0 or 1: from
    its first update); confidence-weighted noise, ``score_exponent`` e (0: off)."""

    nis_limit: float
    min_hits: int = 0
    score_exponent: float = 0.0

    @property
    def active(self) -> bool:
        """Whether either adaptation is on."""
        return self.nis_limit > 0 or self.score_exponent > 0

    def score_scale(self, scores: np.ndarray) -> np.ndarray:
        """(K,) float64 factors of R for detections scored ``scores`` (K,): ``max(c, SCORE_FLOOR)^-e``."""
        return np.maximum(np.asarray(scores, dtype=np.float64), SCORE_FLOOR) ** -self.score_exponent

    def tested(self, updates: np.ndarray | None, k: int) -> np.ndarray:
        """(k,) bool: which of k updates are tested, ``updates`` (k,) int64 the corrections each track has had
        before (its hits minus its birth; None: all tested)."""
        if updates is None or self.min_hits <= 1:
            return np.ones(k, dtype=bool)
        return np.asarray(updates) + 1 >= self.min_hits


@dataclass
class Correction:
    """What an update of K tracks computed, row k for the k-th corrected track: the innovation ``y = z - h(x^-)``
    (K, 9) with its yaw component wrapped (and flip-corrected with ``yaw_flip``), its covariance
    ``S = H P^- H^T + R`` (K, 9, 9) and the gain ``K = P^- H^T S^-1`` (K, dim_x, 9) the update applied."""

    y: np.ndarray
    S: np.ndarray
    K: np.ndarray

    @classmethod
    def empty(cls, dim_x: int) -> Correction:
        """The correction of no track."""
        return cls(np.zeros((0, BOX_DIM)), np.zeros((0, BOX_DIM, BOX_DIM)), np.zeros((0, dim_x, BOX_DIM)))


class BatchKalmanFilter:
    """EKF (non-linear model) or KF (linear model) over a batch of tracks; see the module docstring."""

    def __init__(self, model: MotionModel, yaw_flip: bool = True, robust: RobustUpdate | None = None) -> None:
        self.model = model
        self.yaw_flip = bool(yaw_flip)
        self.robust = robust if robust is not None and robust.active else None

    def __repr__(self) -> str:
        return f"BatchKalmanFilter({self.model!r}, yaw_flip={self.yaw_flip}, robust={self.robust})"

    def initiate(self, z: np.ndarray, P0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Start tracks from detections ``z (N, 9)`` -> ``x (N, dim_x)``, ``P (N, dim_x, dim_x)`` (a copy of P0)."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        n, d = z.shape[0], self.model.dim_x
        x = self.model.init_state(z)
        P = np.array(_batch(P0, n, d, "P0"), dtype=np.float64, copy=True)
        return x, P

    def predict(self, x: np.ndarray, P: np.ndarray, Q: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """Predict ``dt`` seconds (scalar or ``(N,)``) ahead -> ``(x (N, dim_x), P (N, dim_x, dim_x))``."""
        x = np.asarray(x, dtype=np.float64)
        n, d = x.shape[0], self.model.dim_x
        x_new, F = self.model.transition(x, dt)
        x_new = self.model.wrap_state(x_new)
        P_new = np.empty((n, d, d))
        _propagate_kernel(F, _batch(P, n, d, "P"), _batch(Q, n, d, "Q"), P_new)
        return x_new, P_new

    def residual(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Innovation ``z - h(x)`` ``(N, 9)`` with the yaw component wrapped (and flip-corrected if enabled)."""
        r = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM) - self.model.h(x)
        r[:, YAW_Z] = wrap_yaw_residual(r[:, YAW_Z], self.yaw_flip)
        return r

    def update(self, x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Correct with measurements ``z (N, 9)`` (row i for track i) -> ``(x, P)``, Joseph form."""
        x = np.array(x, dtype=np.float64)
        n, d = x.shape[0], self.model.dim_x
        if n == 0:
            return x, np.zeros((0, d, d))
        P = np.array(_batch(P, n, d, "P"))
        R = np.asarray(R, dtype=np.float64)
        rows = np.arange(n)
        if R.shape == (BOX_DIM, BOX_DIM):  # one matrix for all tracks: a table of one
            self.correct(x, P, rows, z, R[None], np.zeros(n, dtype=np.int64))
        else:
            self.correct(x, P, rows, z, _batch(R, n, BOX_DIM, "R"), rows)
        return x, P

    def correct(
        self,
        x: np.ndarray,
        P: np.ndarray,
        rows: np.ndarray,
        z: np.ndarray,
        R: np.ndarray,
        R_index: np.ndarray,
        updates: np.ndarray | None = None,
        scores: np.ndarray | None = None,
    ) -> Correction:
        """Correct the tracks ``rows (K,)`` of ``x (N, dim_x)``, ``P (N, dim_x, dim_x)`` (C-contiguous float64,
        changed in place) with ``z (K, 9)``; ``R (C, 9, 9)`` a table indexed by ``R_index (K,)`` (e.g. the
        per-class noise and the tracks' labels); ``updates`` (K,) int64 the corrections each of those tracks has had
        (the robust update's ``min_hits``; None: every track tested); ``scores`` (K,) the detections' scores in
        [0, 1] (confidence-weighted noise; None: R as given). Row k of the result equals :meth:`update` of that
        track.
        Returns the update's innovation, its covariance and the gain (:class:`Correction`)."""
        d, k = self.model.dim_x, len(rows)
        if k == 0:
            return Correction.empty(d)
        h, H = self.model.measurement(x[rows])
        z = np.ascontiguousarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        if self.robust is not None:
            R = np.asarray(R, dtype=np.float64)[R_index]  # (K, 9, 9): each update's own noise from here on
            R_index = np.arange(k, dtype=np.int64)
            if self.robust.score_exponent > 0 and scores is not None:
                R = R * self.robust.score_scale(scores)[:, None, None]  # R / c^e
            if self.robust.nis_limit > 0:
                R = self._inflated(P[rows], z, h, H, R, self.robust.tested(updates, k))
        out = Correction(np.empty((k, BOX_DIM)), np.empty((k, BOX_DIM, BOX_DIM)), np.empty((k, d, BOX_DIM)))
        _correct_kernel(
            x,
            P,
            np.asarray(rows, dtype=np.int64),
            z,
            h,
            H,
            np.asarray(R, dtype=np.float64),
            np.asarray(R_index, dtype=np.int64),
            self.yaw_flip,
            self.model.yaw_index,
            out.y,
            out.S,
            out.K,
        )
        return out

    def _inflated(
        self, P: np.ndarray, z: np.ndarray, h: np.ndarray, H: np.ndarray, R: np.ndarray, tested: np.ndarray
    ) -> np.ndarray:
        """Robust R of K updates (module docstring, ``nis_limit`` g): ``P (K, d, d)`` the priors, ``z``, ``h``
        (K, 9), ``H (K, 9, d)``, ``R (K, 9, 9)`` each update's noise, ``tested`` (K,) bool -> ``R * max(1, d2 /
        g)`` (K, 9, 9) with ``d2 = r^T (H P H^T + R)^-1 r`` over x, y (metres^2 normalised, 2 dof) for the tested
        updates, R itself for the others."""
        Hp = H[:, :2, :]  # (K, 2, d)
        S = Hp @ P @ np.swapaxes(Hp, 1, 2) + R[:, :2, :2]  # (K, 2, 2)
        r = (z[:, :2] - h[:, :2])[:, :, None]  # (K, 2, 1)
        d2 = (np.swapaxes(r, 1, 2) @ np.linalg.solve(S, r))[:, 0, 0]  # (K,)
        scale = np.where(tested, np.maximum(1.0, d2 / self.robust.nis_limit), 1.0)
        return R * scale[:, None, None]
