"""State-space models in torch, batched and differentiable, for the GRU-Kalman filter.

They mirror :mod:`grutrack.motion.models` (same state layouts, same canonical measurement
``[x, y, z, w, l, h, yaw, vx, vy]``) so that gradients flow through the transition f and measurement h.
The arc integrals of CTRA and Bicycle are evaluated with 4-point Gauss-Legendre quadrature: smooth at zero
turn rate and zero speed, and within 1e-9 m of the closed form for the turns of one 0.5 s frame
(tested against the numpy models).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

# 4-point Gauss-Legendre nodes / weights on [0, 1]
_GL_NODES = (np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526]) + 1) / 2
_GL_WEIGHTS = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538]) / 2


def wrap_angle_t(a: torch.Tensor) -> torch.Tensor:
    """Wrap radians to [-pi, pi) (differentiable almost everywhere)."""
    return torch.remainder(a + math.pi, 2 * math.pi) - math.pi


@functools.cache
def _ctra_bases(dtype: torch.dtype, device: torch.device) -> tuple[torch.Tensor, ...]:
    """dt-free parts of :func:`_ctra_tables` (made once per dtype and device): I, D (10, 10); M0, M1 (4, 8); W1
    (8, 10), so that A^T = I + dt D, M = M0 + dt M1, W = dt W1."""
    D = np.zeros((10, 10))
    D[7, 6] = D[9, 8] = 1.0  # (A^T)[7, 6]: v' gets a dt; (A^T)[9, 8]: yaw' gets omega dt
    M0, M1 = np.zeros((4, 8)), np.zeros((4, 8))
    M0[0, :4], M0[2, 4:] = 1.0, 1.0
    M1[1, :4], M1[3, 4:] = _GL_NODES, _GL_NODES
    W1 = np.zeros((8, 10))
    W1[:4, 0], W1[4:, 1] = _GL_WEIGHTS, _GL_WEIGHTS
    with torch.inference_mode(False):  # normal tensors: training saves what is made from them
        return tuple(torch.tensor(a, dtype=dtype, device=device) for a in (np.eye(10), D, M0, M1, W1))


def _ctra_tables(
    dt: float, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Constant matrices of :meth:`TorchCTRA.f` over ``dt`` seconds: A^T (10, 10) the linear part; M (4, 8) taking
    ``[v, a, yaw, omega]`` to the speeds ``v + a t_i`` and headings ``yaw + omega t_i`` at the 4 quadrature nodes
    ``t_i`` in [0, dt]; W (8, 10) taking ``[speed_i cos_i | speed_i sin_i]`` to ``sum_i w_i (.)`` in state columns
    x (0) and y (1)."""
    eye, D, M0, M1, W1 = _ctra_bases(dtype, device)
    return eye + dt * D, M0 + dt * M1, dt * W1


class TorchCTRA:
    """CTRA, state ``[x, y, z, w, l, h, v, a, yaw, omega]`` (see :class:`grutrack.motion.models.CTRA`)."""

    name = "CTRA"
    dim_x = 10
    yaw_index = 8
    turn_index = 9  # the turn-rate slot: omega
    accel_index = 7  # the acceleration slot: a (m/s^2)

    def init_state(self, z: torch.Tensor) -> torch.Tensor:
        """(N, 9) canonical boxes -> (N, 10): v = |(vx, vy)|, a = omega = 0."""
        x = z.new_zeros((z.shape[0], self.dim_x))
        x[:, 0:6] = z[:, 0:6]
        x[:, 6] = torch.hypot(z[:, 7], z[:, 8])
        x[:, 8] = wrap_angle_t(z[:, 6])
        return x

    def f(self, x: torch.Tensor, dt: float) -> torch.Tensor:
        """Transition (N, 10) -> (N, 10) over dt seconds:
        ``x' = A x + [dx, dy, 0, ...]`` with A the linear part (``v' = v + a dt``, ``yaw' = yaw + omega dt``, the
        rest kept) and the arc ``(dx, dy) = integral_0^dt (v + a t) (cos, sin)(yaw + omega t) dt``, by quadrature
        at the nodes t_i: ``[speed_i | heading_i] = [v, a, yaw, omega] M`` and ``(dx, dy) = sum_i w_i speed_i
        (cos, sin)(heading_i)``, each step one small matrix product (a handful of autograd nodes per frame)."""
        A_T, M, W = _ctra_tables(float(dt), x.dtype, x.device)
        speed, heading = x[:, 6:10].mm(M).chunk(2, 1)  # (N, 4) each: at the nodes
        arc = torch.cat([speed * torch.cos(heading), speed * torch.sin(heading)], dim=1)  # (N, 8)
        return torch.addmm(x.mm(A_T), arc, W)  # A x + (dx, dy) in columns 0, 1

    def h(self, x: torch.Tensor) -> torch.Tensor:
        """Measurement (N, 10) -> (N, 9) ``[x, y, z, w, l, h, yaw, v cos yaw, v sin yaw]``."""
        box, v, _, yaw, _ = x.split_with_sizes([6, 1, 1, 1, 1], 1)
        return torch.cat([box, yaw, v * torch.cos(yaw), v * torch.sin(yaw)], dim=1)

    def h_at(self, x: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        """:meth:`h` given ``c, s`` (N, 1) = cos, sin of the state's yaw (when the caller has them already)."""
        box, v, _, yaw, _ = x.split_with_sizes([6, 1, 1, 1, 1], 1)
        return torch.cat([box, yaw, v * c, v * s], dim=1)


class TorchBicycle:
    """Kinematic bicycle, state ``[x, y, z, w, l, h, v, a, yaw, delta]`` (see
    :class:`grutrack.motion.models.Bicycle`): (x, y) is the reference point ``d = l * wheelbase_ratio *
    (0.5 - front_ratio)`` ahead of the box centre along the heading (0 with the defaults); slip
    ``beta = atan2((1 - front_ratio) sin(delta), cos(delta))``, curvature ``sin(beta) / lr`` with
    ``lr = (1 - front_ratio) L``, ``L = wheelbase_ratio * l``.
    """

    name = "Bicycle"
    dim_x = 10
    yaw_index = 8
    turn_index = 9  # the turn-rate slot: the steering angle delta
    accel_index = 7  # the acceleration slot: a (m/s^2)

    def __init__(self, wheelbase_ratio: float = 0.8, front_ratio: float = 0.5):
        self.wheelbase_ratio, self.front_ratio = wheelbase_ratio, front_ratio

    def _offset(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 1) metres from the box centre to the reference point, along the heading."""
        return self.wheelbase_ratio * (0.5 - self.front_ratio) * x[:, 4:5]

    def init_state(self, z: torch.Tensor) -> torch.Tensor:
        """(N, 9) canonical boxes -> (N, 10): the reference point, v = |(vx, vy)|, a = delta = 0."""
        x = TorchCTRA.init_state(self, z)  # same layout, delta in the omega slot
        d, yaw = self._offset(x), x[:, 8:9]
        return torch.cat([x[:, 0:1] + d * torch.cos(yaw), x[:, 1:2] + d * torch.sin(yaw), x[:, 2:]], dim=1)

    def _beta(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lr = (1 - self.front_ratio) * self.wheelbase_ratio * x[:, 4:5].clamp_min(1e-3)
        beta = torch.atan2((1 - self.front_ratio) * torch.sin(x[:, 9:10]), torch.cos(x[:, 9:10]))
        return beta, lr

    def f(self, x: torch.Tensor, dt: float) -> torch.Tensor:
        """Transition (N, 10) -> (N, 10) over dt seconds."""
        v, a, yaw = x[:, 6:7], x[:, 7:8], x[:, 8:9]
        beta, lr = self._beta(x)
        k = torch.sin(beta) / lr  # curvature: heading change per metre travelled
        ds = v * dt + 0.5 * a * dt * dt  # arc length over dt
        u = torch.as_tensor(_GL_NODES, dtype=x.dtype, device=x.device)[None, :]
        wts = torch.as_tensor(_GL_WEIGHTS, dtype=x.dtype, device=x.device)[None, :]
        heading = yaw + beta + k * ds * u
        dx = ds[:, 0] * (wts * torch.cos(heading)).sum(1)
        dy = ds[:, 0] * (wts * torch.sin(heading)).sum(1)
        return torch.cat(
            [(x[:, 0] + dx)[:, None], (x[:, 1] + dy)[:, None], x[:, 2:6], v + a * dt, a, yaw + k * ds, x[:, 9:10]],
            dim=1,
        )

    def h_at(self, x: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        """:meth:`h` (the velocity is along yaw + beta, so cos, sin of the yaw ``c, s`` are not used)."""
        return self.h(x)

    def h(self, x: torch.Tensor) -> torch.Tensor:
        """Measurement (N, 10) -> (N, 9): the box centre, size, yaw, velocity along yaw + beta."""
        beta, _ = self._beta(x)
        yaw, v, d = x[:, 8:9], x[:, 6:7], self._offset(x)
        return torch.cat(
            [
                x[:, 0:1] - d * torch.cos(yaw),
                x[:, 1:2] - d * torch.sin(yaw),
                x[:, 2:6],
                yaw,
                v * torch.cos(yaw + beta),
                v * torch.sin(yaw + beta),
            ],
            dim=1,
        )


class TorchBicyclePiecewise(TorchBicycle):
    """The bicycle model in Poly-MOT's piecewise form (see :class:`grutrack.motion.models.BicyclePiecewise`):
    turning (``|beta| > PIECEWISE_SWITCH``) the reference point runs the arc at constant speed, ``ds = v dt``,
    v' = v, a' = 0; otherwise a straight line along the heading, ``ds = v dt + a dt^2 / 2``, v' = v + a dt, the
    yaw unchanged. The branch is chosen on the detached slip angle (a piecewise function; its gradient is each
    branch's)."""

    def f(self, x: torch.Tensor, dt: float) -> torch.Tensor:
        """Transition (N, 10) -> (N, 10) over dt seconds."""
        from grutrack.motion.models import PIECEWISE_SWITCH

        v, a, yaw = x[:, 6:7], x[:, 7:8], x[:, 8:9]
        beta, lr = self._beta(x)
        turning = beta.detach().abs() > PIECEWISE_SWITCH
        ds = torch.where(turning, v * dt, v * dt + 0.5 * a * dt * dt)  # arc length over dt
        psi = torch.where(turning, yaw + beta, yaw)
        phi = torch.where(turning, torch.sin(beta) / lr * ds, torch.zeros_like(ds))  # heading change
        u = torch.as_tensor(_GL_NODES, dtype=x.dtype, device=x.device)[None, :]
        wts = torch.as_tensor(_GL_WEIGHTS, dtype=x.dtype, device=x.device)[None, :]
        heading = psi + phi * u
        dx = ds[:, 0] * (wts * torch.cos(heading)).sum(1)
        dy = ds[:, 0] * (wts * torch.sin(heading)).sum(1)
        return torch.cat(
            [
                (x[:, 0] + dx)[:, None],
                (x[:, 1] + dy)[:, None],
                x[:, 2:6],
                torch.where(turning, v, v + a * dt),
                torch.where(turning, torch.zeros_like(a), a),
                yaw + phi,
                x[:, 9:10],
            ],
            dim=1,
        )


TORCH_MODELS = {"CTRA": TorchCTRA, "BICYCLE": TorchBicycle}
#: the piecewise forms (tracker preset ``motion.bicycle_form: piecewise``); CTRA's piecewise form has none here
TORCH_PIECEWISE = {"BICYCLE": TorchBicyclePiecewise}


def make_torch_model(name: str, form: str = "arc", **params):
    """A torch SS model by name (CTRA or Bicycle, case-insensitive) in ``form`` "arc" (default) or "piecewise"
    (Bicycle only)."""
    key = name.upper()
    if key not in TORCH_MODELS:
        raise ValueError(f"GRU-Kalman filter SS model must be one of CTRA, Bicycle; got {name!r}")
    if form not in ("arc", "piecewise") or (form == "piecewise" and key not in TORCH_PIECEWISE):
        raise ValueError(
            f"GRU-Kalman filter SS model {name}: form must be 'arc'"
            f"{' or ' + repr('piecewise') if key in TORCH_PIECEWISE else ''}, got {form!r}"
        )
    return (TORCH_PIECEWISE[key] if form == "piecewise" else TORCH_MODELS[key])(**params)
