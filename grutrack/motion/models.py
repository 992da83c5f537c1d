"""State-space motion models, batched over tracks (numpy, with numba-compiled passes for the EKF's models).

Every model maps a state batch ``x (N, dim_x)`` through

* ``f(x, dt) -> (N, dim_x)``: the transition over ``dt`` seconds (scalar or ``(N,)``),
* ``F(x, dt) -> (N, dim_x, dim_x)``: its Jacobian ``df/dx`` at ``x`` (exact; constant for linear models),
* ``h(x) -> (N, 9)``: the predicted measurement in the canonical box layout
  ``[x, y, z, w, l, h, yaw, vx, vy]`` of :mod:`grutrack.boxes` (the detector measures its velocity),
* ``H(x) -> (N, 9, dim_x)``: the Jacobian ``dh/dx``,
* ``init_state(z (N, 9)) -> (N, dim_x)`` and ``to_boxes(x) -> (N, 9)`` (yaw wrapped, global ``[vx, vy]``),
* ``transition(x, dt) -> (f, F)`` and ``measurement(x) -> (h, H)``: both at once, what the filter calls.

Conventions: metres, radians, seconds, m/s. ``f`` and ``h`` never wrap angles (so that they are smooth and their
Jacobians check against finite differences); the filter wraps the yaw state and the yaw residual. The singular
limits (turn rate or steering angle -> 0, speed -> 0) use series expansions of the arc integrals, never a division
by a small number. The arithmetic is elementwise, so a torch mirror (:mod:`grutrack.motion.torch_models`) is a
line-by-line copy. CTRA and the Bicycle models run f with F, h with H and the output boxes as one compiled loop
over the tracks (the tracker predicts and corrects every frame; numpy's per-call cost dominated at tens of tracks);
each loop performs the numpy form's operations in the same order, and takes from numpy what numba computes
differently in the last bit (``dt**3``, the slip angle's arctan), so the results are the numpy form's bit for bit
wherever numba's sin and cos are numpy's (libm on the x86-64 machines measured; tests/test_motion.py allows 1e-13).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from grutrack.boxes import BOX_DIM, wrap_angle

# ----------------------------------------------------------------------------------------------------------------
# Arc integrals E_n(phi) = int_0^1 s^n exp(i phi s) ds, n = 0, 1, 2, as (real, imaginary) pairs.
# A body moving along a circle of curvature kappa for an arc length L is displaced by exp(i psi) * L * E_0(kappa L);
# dE_n/dphi = i E_{n+1}. Closed form by the recursion E_0 = (e^{i phi} - 1) / (i phi),
# E_n = (e^{i phi} - n E_{n-1}) / (i phi); a power series below |phi| < _SERIES_LIMIT (no cancellation).
# ----------------------------------------------------------------------------------------------------------------

_SERIES_LIMIT = 0.25
_SERIES_TERMS = 8  # error < 1e-18 at |phi| = 0.25


def _series_coefficients(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of Re E_n = sum_k c_k phi^(2k) and Im E_n = phi * sum_k d_k phi^(2k)."""
    k = np.arange(_SERIES_TERMS)
    sign = (-1.0) ** k
    c = np.array([sign[j] / (math.factorial(2 * j) * (2 * j + n + 1)) for j in k])
    d = np.array([sign[j] / (math.factorial(2 * j + 1) * (2 * j + n + 2)) for j in k])
    return c, d


_COEFFS = [_series_coefficients(n) for n in range(3)]


_COEFF_TABLE = np.array([[c, d] for c, d in _COEFFS])  # (3, 2, _SERIES_TERMS): Re / Im series per order


@njit(cache=True, inline="always")
def _arc_moments_at(ph, cp, sp, coeffs, e) -> None:
    """``e (order+1, 2)``: Re and Im of ``E_n(ph)`` for one angle ``ph`` (rad), with ``cp, sp = cos, sin`` of
    the safe divisor (``ph``, or 1 where ``|ph| < _SERIES_LIMIT``). Closed form by the recursion
    ``E_n = (e^{i ph} - n E_{n-1}) / (i ph)``; Horner-evaluated power series below the limit."""
    n_terms = coeffs.shape[2]
    small = abs(ph) < _SERIES_LIMIT
    p = 1.0 if small else ph
    u = ph * ph
    prev_r, prev_i = 1.0, 0.0  # "n E_{n-1}" term for n = 0 is 1
    for n in range(e.shape[0]):
        # (e^{ip} - n E_{n-1}) / (i p) = (b / p, -a / p) with a + ib the numerator
        num_r = cp - (prev_r if n == 0 else n * prev_r)
        num_i = sp - (prev_i if n == 0 else n * prev_i)
        closed_r, closed_i = num_i / p, -num_r / p
        if small:
            er, ei = coeffs[n, 0, n_terms - 1], coeffs[n, 1, n_terms - 1]
            for t in range(n_terms - 2, -1, -1):
                er = er * u + coeffs[n, 0, t]
                ei = ei * u + coeffs[n, 1, t]
            e[n, 0], e[n, 1] = er, ph * ei
        else:
            e[n, 0], e[n, 1] = closed_r, closed_i
        prev_r, prev_i = closed_r, closed_i


@njit(cache=True, inline="always")
def _arc_moments_of(ph, coeffs, e) -> None:
    """:func:`_arc_moments_at` of one angle ``ph`` (rad), its cosine and sine taken here."""
    p = 1.0 if abs(ph) < _SERIES_LIMIT else ph
    _arc_moments_at(ph, np.cos(p), np.sin(p), coeffs, e)


@njit(cache=True)
def _arc_moments_kernel(phi, cp, sp, coeffs, out) -> None:
    """``out (order+1, 2, N)``: :func:`_arc_moments_at` of every ``phi (N,)`` (``cp, sp (N,)``)."""
    e = np.empty((out.shape[0], 2))
    for k in range(phi.shape[0]):
        _arc_moments_at(phi[k], cp[k], sp[k], coeffs, e)
        out[:, :, k] = e


def arc_moments(phi: np.ndarray, order: int = 2) -> list[tuple[np.ndarray, np.ndarray]]:
    """``[(Re E_n, Im E_n) for n in 0..order]`` for ``phi (N,)`` (radians turned over the step)."""
    phi = np.ascontiguousarray(phi, dtype=np.float64)
    p = np.where(np.abs(phi) < _SERIES_LIMIT, 1.0, phi)  # a safe divisor for the closed form
    out = np.empty((order + 1, 2) + phi.shape)
    _arc_moments_kernel(
        phi.reshape(-1), np.cos(p).reshape(-1), np.sin(p).reshape(-1), _COEFF_TABLE, out.reshape(order + 1, 2, -1)
    )
    return [(out[n, 0], out[n, 1]) for n in range(order + 1)]


def _arc_step(x: np.ndarray, ds: np.ndarray, psi: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A copy of ``x (N, 10)`` moved along a circular arc: ``(x + i y) += ds exp(i psi) E_0(phi)`` and
    ``yaw += phi`` (arc length ``ds`` m, initial direction ``psi`` rad, turned angle ``phi`` rad, all ``(N,)``)."""
    ((e0r, e0i),) = arc_moments(phi, order=0)
    cp, sp = np.cos(psi), np.sin(psi)
    out = x.copy()
    out[:, 0] += ds * (cp * e0r - sp * e0i)
    out[:, 1] += ds * (sp * e0r + cp * e0i)
    out[:, 8] = x[:, 8] + phi
    return out


@njit(cache=True, inline="always")
def _wrap(a: float) -> float:
    """An angle (rad) wrapped to [-pi, pi), as :func:`grutrack.boxes.wrap_angle`."""
    return np.remainder(a + np.pi, 2.0 * np.pi) - np.pi


def _as_dt(dt, n: int) -> np.ndarray:
    """``dt`` (scalar or ``(N,)`` seconds) as a ``(N,)`` float64 array."""
    return np.broadcast_to(np.asarray(dt, dtype=np.float64), (n,)).astype(np.float64)


def _eye_batch(n: int, d: int) -> np.ndarray:
    """``(n, d, d)`` stack of identities (writable)."""
    return np.repeat(np.eye(d)[None], n, axis=0)


class MotionModel:
    """Interface of a batched state-space model; see the module docstring for the method contracts."""

    name: str = ""
    dim_x: int = 0
    yaw_index: int = -1
    state_names: tuple[str, ...] = ()
    linear: bool = False

    def init_state(self, z: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def f(self, x: np.ndarray, dt) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def F(self, x: np.ndarray, dt) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def h(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def H(self, x: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    def transition(self, x: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """``(f(x, dt), F(x, dt))`` at once (a model may share the work of the two)."""
        return self.f(x, dt), self.F(x, dt)

    def measurement(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(h(x) (N, 9), H(x) (N, 9, dim_x))`` at once (a model may share the work of the two)."""
        return self.h(x), self.H(x)

    def to_boxes(self, x: np.ndarray) -> np.ndarray:
        """Boxes ``(N, 9)`` to write out: ``h(x)`` with the yaw wrapped to [-pi, pi)."""
        boxes = self.h(x)
        boxes[:, 6] = wrap_angle(boxes[:, 6])
        return boxes

    def wrap_state(self, x: np.ndarray) -> np.ndarray:
        """A copy of ``x (N, dim_x)`` with the yaw component wrapped to [-pi, pi)."""
        x = np.array(x, dtype=np.float64, copy=True)
        x[:, self.yaw_index] = wrap_angle(x[:, self.yaw_index])
        return x

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


# ----------------------------------------------------------------------------------------------------------------
# CTRA
# ----------------------------------------------------------------------------------------------------------------


@njit(cache=True)
def _ctra_kernel(x, dt, dt3, coeffs, out, J) -> None:
    """CTRA's transition ``out (N, 10)`` and its Jacobian ``J (N, 10, 10)`` (zeros on entry) at ``x (N, 10)``
    over ``dt (N,)`` s (``dt3 = dt**3`` as numpy's power gives it, which differs from libm's in the last bit).

    With ``E_n = E_n(omega dt)`` and ``c, s = cos, sin yaw``: the displacement
    ``d = exp(i yaw) (v dt E_0 + a dt^2 E_1)``; ``x' = x + d``, v' = v + a dt, yaw' = yaw + omega dt;
    ``dd/dv = exp(i yaw) dt E_0``, ``dd/da = exp(i yaw) dt^2 E_1``, ``dd/dyaw = i d``,
    ``dd/domega = exp(i yaw) i (v dt^2 E_1 + a dt^3 E_2)``.
    """
    e = np.empty((3, 2))
    for n in range(x.shape[0]):
        v, a, yaw, om, t = x[n, 6], x[n, 7], x[n, 8], x[n, 9], dt[n]
        _arc_moments_of(om * t, coeffs, e)
        ar = v * t * e[0, 0] + a * t * t * e[1, 0]
        ai = v * t * e[0, 1] + a * t * t * e[1, 1]
        c, s = np.cos(yaw), np.sin(yaw)
        dx, dy = c * ar - s * ai, s * ar + c * ai
        for i in range(10):
            out[n, i] = x[n, i]
            J[n, i, i] = 1.0
        out[n, 0] += dx
        out[n, 1] += dy
        out[n, 6] = v + a * t
        out[n, 8] = yaw + om * t
        J[n, 0, 6] = t * (c * e[0, 0] - s * e[0, 1])
        J[n, 1, 6] = t * (s * e[0, 0] + c * e[0, 1])
        J[n, 0, 7] = t * t * (c * e[1, 0] - s * e[1, 1])
        J[n, 1, 7] = t * t * (s * e[1, 0] + c * e[1, 1])
        J[n, 0, 8] = -dy
        J[n, 1, 8] = dx
        br = v * (t * t) * e[1, 0] + a * dt3[n] * e[2, 0]
        bi = v * (t * t) * e[1, 1] + a * dt3[n] * e[2, 1]
        J[n, 0, 9] = -c * bi - s * br
        J[n, 1, 9] = -s * bi + c * br
        J[n, 6, 7] = t
        J[n, 8, 9] = t


@njit(cache=True)
def _ctra_measurement_kernel(x, h, H, wrap_yaw) -> None:
    """CTRA's predicted measurement ``h (N, 9) = [x, y, z, w, l, h, yaw, v cos yaw, v sin yaw]`` (with
    ``wrap_yaw`` the yaw wrapped to [-pi, pi), as a box) and its Jacobian ``H (N, 9, 10)`` (zeros on entry; not
    written when it has no rows) at ``x (N, 10)``."""
    for n in range(x.shape[0]):
        v, yaw = x[n, 6], x[n, 8]
        c, s = np.cos(yaw), np.sin(yaw)
        for i in range(6):
            h[n, i] = x[n, i]
        h[n, 6], h[n, 7], h[n, 8] = _wrap(yaw) if wrap_yaw else yaw, v * c, v * s
        if H.shape[0] == 0:
            continue
        for i in range(6):
            H[n, i, i] = 1.0
        H[n, 6, 8] = 1.0
        H[n, 7, 6], H[n, 7, 8] = c, -v * s
        H[n, 8, 6], H[n, 8, 8] = s, v * c


@njit(cache=True)
def _bicycle_measurement_kernel(x, beta, dbeta, offset_ratio, delta_terms, h, H, wrap_yaw) -> None:
    """The bicycle model's predicted measurement ``h (N, 9)`` (``wrap_yaw``: the yaw wrapped to [-pi, pi)) and its
    Jacobian ``H (N, 9, 10)`` (zeros on entry; not written when it has no rows) at ``x (N, 10)`` with slip angles
    ``beta (N,)`` rad and ``dbeta/ddelta (N,)``; the box centre lies ``d = offset_ratio * l`` behind the reference
    point. ``delta_terms``: whether H has d(vx, vy)/ddelta."""
    for n in range(x.shape[0]):
        v, yaw = x[n, 6], x[n, 8]
        c, s = np.cos(yaw), np.sin(yaw)
        cp, sp = np.cos(yaw + beta[n]), np.sin(yaw + beta[n])
        d = offset_ratio * x[n, 4]
        h[n, 0], h[n, 1] = x[n, 0] - d * c, x[n, 1] - d * s
        for i in range(2, 6):
            h[n, i] = x[n, i]
        h[n, 6], h[n, 7], h[n, 8] = _wrap(yaw) if wrap_yaw else yaw, v * cp, v * sp
        if H.shape[0] == 0:
            continue
        for i in range(6):
            H[n, i, i] = 1.0
        H[n, 0, 4], H[n, 0, 8] = -offset_ratio * c, d * s
        H[n, 1, 4], H[n, 1, 8] = -offset_ratio * s, -d * c
        H[n, 6, 8] = 1.0
        H[n, 7, 6], H[n, 7, 8] = cp, -v * sp
        H[n, 8, 6], H[n, 8, 8] = sp, v * cp
        if delta_terms:
            H[n, 7, 9], H[n, 8, 9] = -v * sp * dbeta[n], v * cp * dbeta[n]


class CTRA(MotionModel):
    """Constant turn rate and acceleration.

    State ``[x, y, z, w, l, h, v, a, yaw, omega]``: centre (m), size (m), signed speed along the heading v (m/s),
    its rate a (m/s^2), heading yaw (rad), turn rate omega (rad/s). Over dt the body follows
    ``d/dt (x + i y) = (v + a t) exp(i (yaw + omega t))`` exactly: v' = v + a dt, yaw' = yaw + omega dt,
    ``(x + i y)' = (x + i y) + exp(i yaw) (v dt E_0(omega dt) + a dt^2 E_1(omega dt))``. z, w, l, h, a, omega stay.
    Measurement: ``[x, y, z, w, l, h, yaw, v cos yaw, v sin yaw]``.
    """

    name = "CTRA"
    dim_x = 10
    yaw_index = 8
    state_names = ("x", "y", "z", "w", "l", "h", "v", "a", "yaw", "omega")

    def init_state(self, z: np.ndarray) -> np.ndarray:
        """State from detections ``z (N, 9)``: v = |(vx, vy)| (as Poly-MOT), a = omega = 0."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        x = np.zeros((z.shape[0], self.dim_x))
        x[:, 0:6] = z[:, 0:6]
        x[:, 6] = np.hypot(z[:, 7], z[:, 8])
        x[:, 8] = wrap_angle(z[:, 6])
        return x

    def f(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition ``(N, 10) -> (N, 10)`` over ``dt`` s."""
        return self.transition(x, dt)[0]

    def F(self, x: np.ndarray, dt) -> np.ndarray:
        """Jacobian ``(N, 10, 10)`` of :meth:`f` at ``x``."""
        return self.transition(x, dt)[1]

    def transition(self, x: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`f` ``(N, 10)`` and :meth:`F` ``(N, 10, 10)`` in one compiled pass (:func:`_ctra_kernel`)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        n = x.shape[0]
        out, J = np.empty((n, self.dim_x)), np.zeros((n, self.dim_x, self.dim_x))
        dt = _as_dt(dt, n)
        _ctra_kernel(x, dt, dt**3, _COEFF_TABLE, out, J)
        return out, J

    def measurement(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`h` ``(N, 9)`` and :meth:`H` ``(N, 9, 10)`` in one compiled pass (:func:`_ctra_measurement_kernel`)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        n = x.shape[0]
        h, H = np.empty((n, BOX_DIM)), np.zeros((n, BOX_DIM, self.dim_x))
        _ctra_measurement_kernel(x, h, H, False)
        return h, H

    def to_boxes(self, x: np.ndarray) -> np.ndarray:
        """Boxes ``(N, 9)`` to write out: ``h(x)`` with the yaw wrapped to [-pi, pi) (compiled)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        h = np.empty((x.shape[0], BOX_DIM))
        _ctra_measurement_kernel(x, h, np.zeros((0, BOX_DIM, self.dim_x)), True)
        return h

    def h(self, x: np.ndarray) -> np.ndarray:
        """Predicted measurement ``(N, 9)`` ``[x, y, z, w, l, h, yaw, v cos yaw, v sin yaw]``."""
        x = np.asarray(x, dtype=np.float64)
        out = np.empty((x.shape[0], BOX_DIM))
        out[:, 0:6] = x[:, 0:6]
        out[:, 6] = x[:, 8]
        out[:, 7] = x[:, 6] * np.cos(x[:, 8])
        out[:, 8] = x[:, 6] * np.sin(x[:, 8])
        return out

    def H(self, x: np.ndarray) -> np.ndarray:
        """Jacobian ``(N, 9, 10)`` of :meth:`h`."""
        x = np.asarray(x, dtype=np.float64)
        n = x.shape[0]
        v, c, s = x[:, 6], np.cos(x[:, 8]), np.sin(x[:, 8])
        J = np.zeros((n, BOX_DIM, self.dim_x))
        J[:, np.arange(6), np.arange(6)] = 1.0
        J[:, 6, 8] = 1.0
        J[:, 7, 6], J[:, 7, 8] = c, -v * s
        J[:, 8, 6], J[:, 8, 8] = s, v * c
        return J


# ----------------------------------------------------------------------------------------------------------------
# Bicycle
# ----------------------------------------------------------------------------------------------------------------


class Bicycle(MotionModel):
    """Kinematic bicycle model (Poly-MOT's assumptions).

    State ``[x, y, z, w, l, h, v, a, yaw, delta]``: (x, y) is the reference point (Poly-MOT's "gravity centre"),
    ``d = l * wheelbase_ratio * (0.5 - front_ratio)`` metres ahead of the box centre along the heading (0 with
    the defaults), v the signed speed of that point (m/s), a its rate (m/s^2), yaw the heading, delta the
    (constant) steering angle (rad). Wheelbase ``l * wheelbase_ratio``; front / rear axle distances
    ``lf = front_ratio * wheelbase``, ``lr = (1 - front_ratio) * wheelbase``; slip angle
    ``beta = atan2(lr/(lf+lr) sin delta, cos delta)`` (= atan(lr/(lf+lr) tan delta) for |delta| < pi/2).
    Over dt the point runs an arc of length ``ds = v dt + a dt^2 / 2`` with constant curvature
    ``kappa = sin(beta) / lr`` in direction yaw + beta: ``(x + i y)' = (x + i y) + exp(i (yaw + beta)) ds
    E_0(kappa ds)``, yaw' = yaw + kappa ds, v' = v + a dt; z, w, l, h, a, delta stay.
    Measurement: ``[x - d cos yaw, y - d sin yaw, z, w, l, h, yaw, v cos(yaw + beta), v sin(yaw + beta)]``.

    Differences from Poly-MOT's BICYCLE: Poly-MOT drops the acceleration (a' = 0, v' = v) once |beta| > 0.001 and
    switches to a straight line below it; here the same arc formula holds for every beta (continuous at beta = 0)
    and the Jacobians include the l and delta derivatives that Poly-MOT leaves out. :class:`BicyclePiecewise` is
    Poly-MOT's form.
    """

    name = "Bicycle"
    dim_x = 10
    yaw_index = 8
    state_names = ("x", "y", "z", "w", "l", "h", "v", "a", "yaw", "delta")
    _MIN_LENGTH = 1e-3  # m; a shorter box is treated as this long for the curvature (no division by ~0)

    def __init__(self, wheelbase_ratio: float = 0.8, front_ratio: float = 0.5) -> None:
        """Poly-MOT's values: wheelbase 0.8 l (``w_r``), front axle ratio 0.5 (``lf_r``)."""
        if not 0.0 < wheelbase_ratio <= 1.0:
            raise ValueError(f"wheelbase_ratio must be in (0, 1], got {wheelbase_ratio}")
        if not 0.0 <= front_ratio < 1.0:
            raise ValueError(f"front_ratio must be in [0, 1), got {front_ratio}")
        self.wheelbase_ratio = float(wheelbase_ratio)
        self.front_ratio = float(front_ratio)
        self._k = 1.0 - self.front_ratio  # lr / (lf + lr)
        self._offset_ratio = self.wheelbase_ratio * (0.5 - self.front_ratio)  # d / l

    def __repr__(self) -> str:
        return f"Bicycle(wheelbase_ratio={self.wheelbase_ratio}, front_ratio={self.front_ratio})"

    def init_state(self, z: np.ndarray) -> np.ndarray:
        """State from detections ``z (N, 9)``: v = |(vx, vy)| (as Poly-MOT), a = delta = 0."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        x = np.zeros((z.shape[0], self.dim_x))
        yaw = wrap_angle(z[:, 6])
        d = self._offset_ratio * z[:, 4]
        x[:, 0] = z[:, 0] + d * np.cos(yaw)
        x[:, 1] = z[:, 1] + d * np.sin(yaw)
        x[:, 2:6] = z[:, 2:6]
        x[:, 6] = np.hypot(z[:, 7], z[:, 8])
        x[:, 8] = yaw
        return x

    def _slip(self, delta: np.ndarray):
        """Slip angle beta (N,) and dbeta/ddelta (N,)."""
        k = self._k
        cd, sd = np.cos(delta), np.sin(delta)
        beta = np.arctan2(k * sd, cd)
        dbeta = k / (cd * cd + k * k * sd * sd)
        return beta, dbeta

    def _curvature(self, x: np.ndarray):
        """(beta, dbeta/ddelta, kappa, dkappa/ddelta, dkappa/dl), each (N,)."""
        length = x[:, 4]
        long_enough = length > self._MIN_LENGTH
        l_safe = np.where(long_enough, length, self._MIN_LENGTH)
        lr = l_safe * self.wheelbase_ratio * self._k
        beta, dbeta = self._slip(x[:, 9])
        kappa = np.sin(beta) / lr
        dkappa_ddelta = np.cos(beta) * dbeta / lr
        dkappa_dl = np.where(long_enough, -kappa / l_safe, 0.0)
        return beta, dbeta, kappa, dkappa_ddelta, dkappa_dl

    def f(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition ``(N, 10) -> (N, 10)`` over ``dt`` s."""
        x = np.asarray(x, dtype=np.float64)
        dt = _as_dt(dt, x.shape[0])
        v, a, yaw = x[:, 6], x[:, 7], x[:, 8]
        beta, _, kappa, _, _ = self._curvature(x)
        ds = v * dt + 0.5 * a * dt * dt
        out = _arc_step(x, ds, yaw + beta, kappa * ds)
        out[:, 6] = v + a * dt
        return out

    def F(self, x: np.ndarray, dt) -> np.ndarray:
        """Jacobian ``(N, 10, 10)`` of :meth:`f` at ``x``."""
        x = np.asarray(x, dtype=np.float64)
        n = x.shape[0]
        dt = _as_dt(dt, n)
        v, a, yaw = x[:, 6], x[:, 7], x[:, 8]
        beta, dbeta, kappa, dk_ddelta, dk_dl = self._curvature(x)
        ds = v * dt + 0.5 * a * dt * dt
        phi = kappa * ds
        (e0r, e0i), (e1r, e1i) = arc_moments(phi, order=1)
        psi = yaw + beta
        cp, sp = np.cos(psi), np.sin(psi)
        disp_r, disp_i = ds * (cp * e0r - sp * e0i), ds * (sp * e0r + cp * e0i)
        # d disp / d ds = exp(i (psi + phi)); d disp / d kappa = exp(i psi) i ds^2 E1; d disp / d psi = i disp
        g_r, g_i = np.cos(psi + phi), np.sin(psi + phi)
        k_r = ds * ds * (-cp * e1i - sp * e1r)
        k_i = ds * ds * (-sp * e1i + cp * e1r)
        ddt_a = 0.5 * dt * dt
        J = _eye_batch(n, self.dim_x)
        J[:, 0, 4], J[:, 1, 4] = k_r * dk_dl, k_i * dk_dl
        J[:, 0, 6], J[:, 1, 6] = g_r * dt, g_i * dt
        J[:, 0, 7], J[:, 1, 7] = g_r * ddt_a, g_i * ddt_a
        J[:, 0, 8], J[:, 1, 8] = -disp_i, disp_r
        J[:, 0, 9] = -disp_i * dbeta + k_r * dk_ddelta
        J[:, 1, 9] = disp_r * dbeta + k_i * dk_ddelta
        J[:, 6, 7] = dt
        J[:, 8, 4] = ds * dk_dl
        J[:, 8, 6] = kappa * dt
        J[:, 8, 7] = kappa * ddt_a
        J[:, 8, 9] = ds * dk_ddelta
        return J

    #: whether H has the d(vx, vy)/ddelta terms (Poly-MOT's piecewise form leaves them out)
    _delta_terms = True

    def measurement(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`h` ``(N, 9)`` and :meth:`H` ``(N, 9, 10)`` in one compiled pass
        (:func:`_bicycle_measurement_kernel`; slip angle from :meth:`_slip`)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        n = x.shape[0]
        beta, dbeta = self._slip(x[:, 9])
        h, H = np.empty((n, BOX_DIM)), np.zeros((n, BOX_DIM, self.dim_x))
        _bicycle_measurement_kernel(x, beta, dbeta, self._offset_ratio, self._delta_terms, h, H, False)
        return h, H

    def to_boxes(self, x: np.ndarray) -> np.ndarray:
        """Boxes ``(N, 9)`` to write out: ``h(x)`` with the yaw wrapped to [-pi, pi) (compiled)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        beta, dbeta = self._slip(x[:, 9])
        h = np.empty((x.shape[0], BOX_DIM))
        _bicycle_measurement_kernel(
            x, beta, dbeta, self._offset_ratio, self._delta_terms, h, np.zeros((0, BOX_DIM, self.dim_x)), True
        )
        return h

    def h(self, x: np.ndarray) -> np.ndarray:
        """Predicted measurement ``(N, 9)``: box centre, size, yaw, velocity of the reference point."""
        x = np.asarray(x, dtype=np.float64)
        yaw, v = x[:, 8], x[:, 6]
        beta, _ = self._slip(x[:, 9])
        d = self._offset_ratio * x[:, 4]
        out = np.empty((x.shape[0], BOX_DIM))
        out[:, 0] = x[:, 0] - d * np.cos(yaw)
        out[:, 1] = x[:, 1] - d * np.sin(yaw)
        out[:, 2:6] = x[:, 2:6]
        out[:, 6] = yaw
        out[:, 7] = v * np.cos(yaw + beta)
        out[:, 8] = v * np.sin(yaw + beta)
        return out

    def H(self, x: np.ndarray) -> np.ndarray:
        """Jacobian ``(N, 9, 10)`` of :meth:`h`."""
        x = np.asarray(x, dtype=np.float64)
        n = x.shape[0]
        yaw, v = x[:, 8], x[:, 6]
        beta, dbeta = self._slip(x[:, 9])
        c, s = np.cos(yaw), np.sin(yaw)
        cp, sp = np.cos(yaw + beta), np.sin(yaw + beta)
        d = self._offset_ratio * x[:, 4]
        J = np.zeros((n, BOX_DIM, self.dim_x))
        J[:, np.arange(6), np.arange(6)] = 1.0
        J[:, 0, 4], J[:, 0, 8] = -self._offset_ratio * c, d * s
        J[:, 1, 4], J[:, 1, 8] = -self._offset_ratio * s, -d * c
        J[:, 6, 8] = 1.0
        J[:, 7, 6], J[:, 7, 8], J[:, 7, 9] = cp, -v * sp, -v * sp * dbeta
        J[:, 8, 6], J[:, 8, 8], J[:, 8, 9] = sp, v * cp, v * cp * dbeta
        return J


# ----------------------------------------------------------------------------------------------------------------
# Piecewise forms (Poly-MOT's CTRA and BICYCLE, motion_module/motion_model.py at its HEAD 5fead68)
# ----------------------------------------------------------------------------------------------------------------

#: |omega| (rad/s) or |beta| (rad) at which the piecewise forms switch to straight-line motion (Poly-MOT: 0.001)
PIECEWISE_SWITCH = 1e-3


def _straight_jacobian(J: np.ndarray, rows: np.ndarray, v, a, yaw, dt) -> None:
    """Write, in place for the tracks ``rows (K,)`` of ``J (N, 10, 10)``, the position rows of a straight-line
    step ``(x, y) += (v dt + a dt^2 / 2) (cos yaw, sin yaw)`` over [x, y, z, w, l, h, v, a, yaw, .]; the last
    column (turn rate or steering) gets no entry."""
    c, s, t = np.cos(yaw[rows]), np.sin(yaw[rows]), dt[rows]
    ds = v[rows] * t + 0.5 * a[rows] * t * t
    J[rows, 0:2, :] = 0.0
    J[rows, 0, 0] = J[rows, 1, 1] = 1.0
    J[rows, 0, 6], J[rows, 1, 6] = t * c, t * s
    J[rows, 0, 7], J[rows, 1, 7] = 0.5 * t * t * c, 0.5 * t * t * s
    J[rows, 0, 8], J[rows, 1, 8] = -ds * s, ds * c


class CTRAPiecewise(CTRA):
    """CTRA in Poly-MOT's piecewise form (tracker preset ``motion.ctra_form: piecewise``).

    For ``|omega| >= 0.001`` rad/s it is :class:`CTRA` (the same arc, the same exact Jacobian). Below, the
    position moves in a straight line, ``(x, y) += (v dt + a dt^2 / 2) (cos yaw, sin yaw)`` (yaw still advances
    by omega dt), and F is the straight line's Jacobian: ``d(x, y)/d omega = 0``. Since every track starts at
    omega = 0 this changes the covariance from the first prediction on. Discontinuous at |omega| = 0.001.
    """

    name = "CTRA"

    def transition(self, x: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`f` ``(N, 10)`` and :meth:`F` ``(N, 10, 10)``: CTRA's, with straight-line rows below the switch."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        dt = _as_dt(dt, x.shape[0])
        out, J = super().transition(x, dt)
        small = np.abs(x[:, 9]) < PIECEWISE_SWITCH
        if small.any():
            v, a, yaw, t = x[small, 6], x[small, 7], x[small, 8], dt[small]
            ds = v * t + 0.5 * a * t * t
            out[small, 0] = x[small, 0] + ds * np.cos(yaw)
            out[small, 1] = x[small, 1] + ds * np.sin(yaw)
            _straight_jacobian(J, np.flatnonzero(small), x[:, 6], x[:, 7], x[:, 8], dt)
        return out, J


@njit(cache=True)
def _bicycle_piecewise_kernel(x, dt, beta, kappa, coeffs, out, J) -> None:
    """:class:`BicyclePiecewise`'s transition ``out (N, 10)`` and Jacobian ``J (N, 10, 10)`` (zeros on entry) at
    ``x (N, 10)`` over ``dt (N,)`` s, with slip angles ``beta (N,)`` rad and curvatures ``kappa (N,)`` 1/m.

    Turning (``|beta| > PIECEWISE_SWITCH``): ``ds = v dt``, ``psi = yaw + beta``, ``phi = kappa ds``,
    ``(x + i y)' = (x + i y) + ds exp(i psi) E_0(phi)``, yaw' = yaw + phi, v' = v, a' = 0; F: d/dv, d/dyaw of the
    position, d yaw'/dv = kappa dt, a zero row for a. Straight: ``ds = v dt + a dt^2 / 2`` along yaw, v' = v + a dt;
    F of the straight line (:func:`_straight_jacobian`) and dv'/da = dt.
    """
    e = np.empty((1, 2))
    for n in range(x.shape[0]):
        v, a, yaw, t, b, k = x[n, 6], x[n, 7], x[n, 8], dt[n], beta[n], kappa[n]
        turning = abs(b) > PIECEWISE_SWITCH
        ds = v * t if turning else v * t + 0.5 * a * t * t
        psi = yaw + b if turning else yaw
        phi = k * ds if turning else 0.0
        _arc_moments_of(phi, coeffs, e)
        cp, sp = np.cos(psi), np.sin(psi)
        for i in range(10):
            out[n, i] = x[n, i]
            J[n, i, i] = 1.0
        out[n, 0] += ds * (cp * e[0, 0] - sp * e[0, 1])
        out[n, 1] += ds * (sp * e[0, 0] + cp * e[0, 1])
        out[n, 8] = yaw + phi
        out[n, 6] = v if turning else v + a * t
        out[n, 7] = 0.0 if turning else a
        if turning:
            J[n, 0, 6], J[n, 1, 6] = t * np.cos(psi + phi), t * np.sin(psi + phi)
            J[n, 0, 8] = -ds * (sp * e[0, 0] + cp * e[0, 1])
            J[n, 1, 8] = ds * (cp * e[0, 0] - sp * e[0, 1])
            J[n, 7, 7] = 0.0
            J[n, 8, 6] = t * k
        else:
            c, s = np.cos(yaw), np.sin(yaw)
            J[n, 0, 6], J[n, 1, 6] = t * c, t * s
            J[n, 0, 7], J[n, 1, 7] = 0.5 * t * t * c, 0.5 * t * t * s
            J[n, 0, 8], J[n, 1, 8] = -ds * s, ds * c
            J[n, 6, 7] = t


class BicyclePiecewise(Bicycle):
    """The bicycle model in Poly-MOT's piecewise form (tracker preset ``motion.bicycle_form: piecewise``).

    Slip angle ``beta = atan(lr / (lf + lr) tan delta)``. For ``|beta| > 0.001`` rad the reference point runs the
    arc of :class:`Bicycle` at constant speed: ds = v dt, v' = v, and the acceleration is reset, a' = 0. For
    ``|beta| <= 0.001`` it moves in a straight line along the heading, ``ds = v dt + a dt^2 / 2``, v' = v + a dt,
    with the yaw unchanged. The Jacobians are Poly-MOT's: F has no d/dl and no d/ddelta column (and in the arc
    branch no d/da column, with a zero row for a); H has no d(vx, vy)/ddelta terms.
    """

    name = "Bicycle"

    def _slip(self, delta: np.ndarray):
        """Slip angle beta = atan(k tan delta) (N,) and dbeta/ddelta (N,)."""
        k = self._k
        cd, sd = np.cos(delta), np.sin(delta)
        return np.arctan(k * np.tan(delta)), k / (cd * cd + k * k * sd * sd)

    def f(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition ``(N, 10) -> (N, 10)`` over ``dt`` s."""
        return self.transition(x, dt)[0]

    def F(self, x: np.ndarray, dt) -> np.ndarray:
        """Poly-MOT's Jacobian ``(N, 10, 10)`` of :meth:`f` (no d/dl, d/ddelta columns)."""
        return self.transition(x, dt)[1]

    def transition(self, x: np.ndarray, dt) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`f` ``(N, 10)`` and :meth:`F` ``(N, 10, 10)`` in one compiled pass
        (:func:`_bicycle_piecewise_kernel`; slip angle and curvature from :meth:`_curvature`)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        n = x.shape[0]
        beta, _, kappa, _, _ = self._curvature(x)
        out, J = np.empty((n, self.dim_x)), np.zeros((n, self.dim_x, self.dim_x))
        _bicycle_piecewise_kernel(x, _as_dt(dt, n), beta, kappa, _COEFF_TABLE, out, J)
        return out, J

    _delta_terms = False

    def H(self, x: np.ndarray) -> np.ndarray:
        """Jacobian ``(N, 9, 10)`` of :meth:`h` without the d(vx, vy)/ddelta terms (Poly-MOT's H)."""
        J = super().H(x)
        J[:, 7, 9] = 0.0
        J[:, 8, 9] = 0.0
        return J


# ----------------------------------------------------------------------------------------------------------------
# Linear models
# ----------------------------------------------------------------------------------------------------------------


class _LinearModel(MotionModel):
    """A linear model: ``f(x) = F(dt) x``, ``h(x) = H x`` with H a selection matrix."""

    linear = True
    _meas_index: tuple[int, ...] = ()  # state index measured by each of the 9 box components

    def _H0(self) -> np.ndarray:
        """The constant ``(9, dim_x)`` measurement matrix."""
        H0 = np.zeros((BOX_DIM, self.dim_x))
        H0[np.arange(BOX_DIM), list(self._meas_index)] = 1.0
        return H0

    def h(self, x: np.ndarray) -> np.ndarray:
        """Predicted measurement ``(N, 9)`` (a selection of state components)."""
        return np.asarray(x, dtype=np.float64)[:, list(self._meas_index)].copy()

    def H(self, x: np.ndarray) -> np.ndarray:
        """Constant Jacobian ``(N, 9, dim_x)``."""
        return np.repeat(self._H0()[None], np.asarray(x).shape[0], axis=0)


class CA(_LinearModel):
    """Constant acceleration (linear).

    State ``[x, y, z, w, l, h, vx, vy, ax, ay, yaw]``: ground-plane velocity (m/s) and acceleration (m/s^2) in the
    global frame; yaw a random walk. x' = x + vx dt + ax dt^2 / 2, vx' = vx + ax dt (same in y).
    Poly-MOT's CA has 13 states with vz, az that its F maps to 0 and nothing observes; dropping them leaves the
    filter on the other 11 unchanged. Measurement: ``[x, y, z, w, l, h, yaw, vx, vy]``.
    """

    name = "CA"
    dim_x = 11
    yaw_index = 10
    state_names = ("x", "y", "z", "w", "l", "h", "vx", "vy", "ax", "ay", "yaw")
    _meas_index = (0, 1, 2, 3, 4, 5, 10, 6, 7)

    def init_state(self, z: np.ndarray) -> np.ndarray:
        """State from detections ``z (N, 9)``: velocity from the detection, acceleration 0."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        x = np.zeros((z.shape[0], self.dim_x))
        x[:, 0:6] = z[:, 0:6]
        x[:, 6:8] = z[:, 7:9]
        x[:, 10] = wrap_angle(z[:, 6])
        return x

    def f(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition ``(N, 11) -> (N, 11)`` over ``dt`` s."""
        x = np.asarray(x, dtype=np.float64)
        dt = _as_dt(dt, x.shape[0])[:, None]
        out = x.copy()
        out[:, 0:2] = x[:, 0:2] + x[:, 6:8] * dt + 0.5 * x[:, 8:10] * dt * dt
        out[:, 6:8] = x[:, 6:8] + x[:, 8:10] * dt
        return out

    def F(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition matrix ``(N, 11, 11)``."""
        n = np.asarray(x).shape[0]
        dt = _as_dt(dt, n)
        J = _eye_batch(n, self.dim_x)
        for i in (0, 1):
            J[:, i, 6 + i] = dt
            J[:, i, 8 + i] = 0.5 * dt * dt
            J[:, 6 + i, 8 + i] = dt
        return J


class CV(_LinearModel):
    """Constant velocity (linear).

    State ``[x, y, z, w, l, h, vx, vy, yaw]``; x' = x + vx dt (same in y); yaw a random walk.
    Poly-MOT's CV additionally carries a vz that its F maps to 0 and nothing observes (dropped here, no effect).
    Measurement: ``[x, y, z, w, l, h, yaw, vx, vy]``.
    """

    name = "CV"
    dim_x = 9
    yaw_index = 8
    state_names = ("x", "y", "z", "w", "l", "h", "vx", "vy", "yaw")
    _meas_index = (0, 1, 2, 3, 4, 5, 8, 6, 7)

    def init_state(self, z: np.ndarray) -> np.ndarray:
        """State from detections ``z (N, 9)``: velocity from the detection."""
        z = np.asarray(z, dtype=np.float64).reshape(-1, BOX_DIM)
        x = np.zeros((z.shape[0], self.dim_x))
        x[:, 0:6] = z[:, 0:6]
        x[:, 6:8] = z[:, 7:9]
        x[:, 8] = wrap_angle(z[:, 6])
        return x

    def f(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition ``(N, 9) -> (N, 9)`` over ``dt`` s."""
        x = np.asarray(x, dtype=np.float64)
        dt = _as_dt(dt, x.shape[0])[:, None]
        out = x.copy()
        out[:, 0:2] = x[:, 0:2] + x[:, 6:8] * dt
        return out

    def F(self, x: np.ndarray, dt) -> np.ndarray:
        """Transition matrix ``(N, 9, 9)``."""
        n = np.asarray(x).shape[0]
        dt = _as_dt(dt, n)
        J = _eye_batch(n, self.dim_x)
        J[:, 0, 6] = dt
        J[:, 1, 7] = dt
        return J


#: Model classes by the name used in configuration files.
MODELS: dict[str, type[MotionModel]] = {"CTRA": CTRA, "Bicycle": Bicycle, "CA": CA, "CV": CV}


#: The piecewise forms by model name (tracker preset keys ``motion.ctra_form``, ``motion.bicycle_form``).
PIECEWISE: dict[str, type[MotionModel]] = {"CTRA": CTRAPiecewise, "Bicycle": BicyclePiecewise}


def make_model(name: str, form: str = "arc", **params) -> MotionModel:
    """Instantiate a model by name (``CTRA``, ``Bicycle``, ``CA``, ``CV``; case-insensitive).

    ``form``: "arc" (the models above) or "piecewise" (:data:`PIECEWISE`; the linear models have one form).
    """
    lookup = {k.lower(): k for k in MODELS}
    try:
        key = lookup[name.lower()]
    except KeyError:
        raise ValueError(f"unknown motion model {name!r}; choose one of {sorted(MODELS)}") from None
    if form not in ("arc", "piecewise"):
        raise ValueError(f"unknown model form {form!r}; choose 'arc' or 'piecewise'")
    return (PIECEWISE.get(key, MODELS[key]) if form == "piecewise" else MODELS[key])(**params)
