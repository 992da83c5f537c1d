"""The GRU-Kalman filter: a KalmanNet-style ("architecture 2") learned Kalman gain on a fixed SS model.

Prediction uses the SS transition f (CTRA by default, Bicycle selectable) for every class. The update is
``x = x^- + K (y - h(x^-))`` with the yaw residual wrapped, where the gain K comes from a network with
separate GRUs tracking the process noise Q, the prior state covariance Sigma and the innovation covariance
S, fully connected layers between them, and dedicated input and output layers (ARCHITECTURE.md, "The method"):

    Q-GRU   <- FC(forward-update difference  x_{n-1|n-1} - x_{n-1|n-2})
    Σ-GRU   <- [h_Q, FC(forward-evolution difference  x_{n-1|n-1} - x_{n-2|n-2})]
    S-GRU   <- [FC(h_Σ), FC([observation difference y_n - y_{n-1}, innovation y_n - y_{n|n-1}])]
    K       =  output layer([h_Σ, h_S])                      (dim_x x 9)
    h_Σ     <- FC([h_Σ, FC([h_S, K])])                       (backward flow, as in KalmanNet)

Each input is L2-normalised per track. Hidden states live per track and are carried across frames.
The ``four_gru`` variant (the authors' public code) adds an R-GRU over the observation difference whose
state joins the S-GRU input; it is off by default (the paper has three GRUs).

Heading frame (a grutrack choice, documented): the planar components of every input (x, y and vx, vy) are
expressed in the track's heading frame (longitudinal / lateral) and the planar part of the correction is
rotated back to the global frame, so the learned gain does not depend on the direction of travel. The
output layer's bias starts at a given gain (the EKF's mean gain on the training data, see
:mod:`grutrack.training`), so an untrained network is a constant-gain filter close to the EKF.

EKF gain prior (``gain_prior="ekf"``, a grutrack option): the network's gain is a learned residual added to the
gain of an EKF run on the GRU-KF's own state, ``K = K_ekf + dK`` with ``K_ekf = P^- H^T S^-1``,
``S = H P^- H^T + R``, where each track's covariance P is propagated as the EKF does (``P^- = F P F^T + Q``,
Joseph-form update with K_ekf) from the per-class Q, R, P0 the network carries. The output layer (and the gain
table) starts at zero, so an untrained network IS that EKF, with its per-track adaptivity (a young track or one
after missed detections takes a large gain, a settled one a small gain); training moves it away from the EKF only
as far as the loss asks. The covariance is computed by the backend (:mod:`grutrack.tracking.grukf_backend`) on
the detached state: gradients flow through the state and the innovation, not through K_ekf.
"""

from __future__ import annotations

import contextlib
import functools
import math
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from grutrack.motion.torch_models import make_torch_model, wrap_angle_t

MEAS_DIM = 9
#: extra inputs with ``aux_inputs``: log(1 + norm) of the four features, log(update count), log(gap)
AUX_DIM = 6
MIN_SIZE = 0.05  # metres: the default lower bound of the posterior w, l, h (GRUKFConfig.min_size)
_YAW_Z = 6
#: what the network's output is added to: nothing ("constant", the paper) or the per-track EKF gain ("ekf")
GAIN_PRIORS = ("constant", "ekf")
#: which classes a tracker runs through the network (GRUKFConfig.network_classes)
NETWORK_CLASSES = ("all", "ss_model", "own_model")
#: how a coasting track is predicted (GRUKFConfig.coast_yaw_rate)
COAST_YAW_RATES = ("keep", "zero")
#: how a coasting track's acceleration is predicted (GRUKFConfig.coast_acceleration)
COAST_ACCELERATIONS = ("keep", "zero")
#: SS models with the state layout ``[x, y, z, w, l, h, v, a, yaw, *]`` one network can serve (``own_model``)
NETWORK_MODELS = ("CTRA", "BICYCLE")


@dataclass(frozen=True)
class GRUKFConfig:
    """Architecture of the GRU-Kalman filter (stored in checkpoints).

    ss_model: CTRA or Bicycle; in_mult / out_mult: widths of the input / output FC layers as multiples of
    the feature size (KalmanNet's defaults 5 and 40); four_gru: the authors' four-GRU variant.
    class_gain / age_bins / gap_bins: a learned gain table (n_classes or 1, age_bins or 1, gap_bins or 1,
    m * n) added to the output layer's gain, looked up per track by its class (with ``class_gain``), by its
    update count (1, 2, ..., age_bins and more) and by the frames since its last update (1 = the previous
    frame, ..., gap_bins and more). Each cell starts at the EKF's mean gain in that cell minus the shared one,
    so an untrained network follows the EKF's gain schedule, which grows after missed detections as the EKF's
    covariance does (a grutrack choice; the network and SS model stay shared by all classes).
    yaw_flip: a yaw innovation (and observation difference) beyond 90 degrees is taken as a detection with the
    reversed heading and turned by pi, as the EKF does (``grutrack.motion.kalman``; a grutrack addition).
    aux_inputs: the magnitudes the L2 normalisation removes, ``log(1 + |f|)`` of each of the four features
    (metres-like units), and ``log(n_updates)``, ``log(gap)`` of the track (see :func:`aux_features`), as AUX_DIM
    extra inputs of the S-GRU's input layer and of the output layer (a grutrack addition).
    ss_params: constructor parameters of the SS model (Bicycle: wheelbase_ratio, front_ratio), the training
    motion config's, so that the network's f and h are the parallel EKF's.
    gain_prior: "constant" (the network's output is the gain; it starts at the EKF's mean gain) or "ekf" (the
    output is a residual added to the per-track EKF gain K_ekf; it starts at zero; the network then carries the
    EKF's per-class Q, R, P0 as buffers ``ekf_Q``, ``ekf_R``, ``ekf_P0``; see the module docstring).
    network_classes: which classes a tracker runs through the network: "all" (the paper) or "ss_model" (only the
    classes whose model in the tracker preset's motion config is ``ss_model``; the others keep the preset's EKF
    with their own model; a grutrack option) or "own_model" (every class whose preset model is one of
    :data:`NETWORK_MODELS`, each through the network with its own SS model and noise: one track group per model,
    the weights shared; the others, e.g. CA, keep the preset's EKF). It changes no weight; the tracker and the
    trainer read it.
    coast_yaw_rate: "keep" (the paper: a coasting track is predicted with the SS model as it stands) or "zero"
    (a grutrack option: from a track's second frame without a detection on, its predictions hold the turn-rate
    slot, CTRA's omega and the Bicycle's steering angle, at zero, so that a track keeps its heading through a
    detection gap instead of turning on with a rate the learned gain may have overestimated). It changes no
    weight; the tracker and the trainer read it.
    coast_acceleration: "keep" (the paper) or "zero" (a grutrack option: from a track's second frame without a
    detection on, its predictions hold the acceleration slot at zero, so that it coasts at the speed it had
    instead of extrapolating an acceleration, which over a gap of k frames moves the box by a (k dt)^2 / 2 and can
    turn the speed's sign: a bus estimated at -2 m/s^2 is predicted 6 m backwards after 2.5 s). Same rule and
    scope as ``coast_yaw_rate``.
    model_params: constructor parameters of the other SS models an ``own_model`` network runs (or trains with,
    ``training_classes: own_model`` of the training config)
    (``{model name: params}``, the training motion config's, and ``form``: "arc" or "piecewise", the tracker
    preset's form of that model, so that the untrained network is the preset's EKF for those classes too).
    min_size: the lower bound (metres) of the posterior's w, l, h (a learned gain can overshoot; sizes stay
    physical); :data:`MIN_SIZE` by default and in checkpoints written before the option.
    """

    ss_model: str = "CTRA"
    in_mult: int = 5
    out_mult: int = 40
    four_gru: bool = False
    class_gain: bool = False
    age_bins: int = 0
    gap_bins: int = 0
    n_classes: int = 7
    yaw_flip: bool = False
    aux_inputs: bool = False
    ss_params: dict = field(default_factory=dict)  # the SS model's constructor parameters (motion config)
    gain_prior: str = "constant"  # "constant": K = network output; "ekf": K = K_ekf + network output
    network_classes: str = "all"  # "all", "ss_model" or "own_model" (see above)
    model_params: dict = field(default_factory=dict)  # own_model: {model name: constructor parameters}
    coast_yaw_rate: str = "keep"  # "keep" or "zero" (see above)
    coast_acceleration: str = "keep"  # "keep" or "zero" (see above)
    min_size: float = MIN_SIZE  # metres: lower bound of the posterior w, l, h

    def torch_model(self, name: str | None = None):
        """The torch SS model ``name`` (default ``ss_model``) with its parameters (:mod:`torch_models`)."""
        if name is None or name.upper() == self.ss_model.upper():
            return make_torch_model(self.ss_model, **self.ss_params)
        return make_torch_model(name, **self.model_params.get(name.upper(), {}))

    @property
    def table_shape(self) -> tuple[int, int, int]:
        """(class, age, gap) sizes of the gain offset table ((1, 1, 1): no table)."""
        return (self.n_classes if self.class_gain else 1, max(self.age_bins, 1), max(self.gap_bins, 1))

    @property
    def has_table(self) -> bool:
        """Whether the network carries a gain offset table."""
        return self.class_gain or self.age_bins > 0 or self.gap_bins > 0


def _fc(i: int, o: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(i, o), nn.ReLU())


_EPS = 1e-6  # added to the L2 norm of each input before dividing by it (zero rows stay zero)


class DeferredWeightGrads:
    """The weight gradients of Linear layers summed over a whole scene in one product per layer.

    A layer used in every frame of a scene gets, from autograd, one full weight gradient per frame,
    ``dL/dW = sum_t G_t^T X_t`` built as a separate (out, in) matrix each frame and accumulated into ``W.grad``
    (G_t (K_t, out) the gradient of the layer's output, X_t (K_t, in) its input, K_t the tracks of frame t). For
    the GRU-KF's output layer (181 -> 724 -> 90) those per-frame matrices of a few tracks each are most of the
    backward pass. Here the layer runs on its detached weight and bias (autograd computes only the gradient of
    the input) and its input and output are kept; :meth:`backward` asks autograd for the outputs' gradients G_t
    beside the parameters' and adds ``G^T X`` and ``sum_t G_t`` with G, X the frames' rows stacked: the same
    gradient, one matrix product per layer and scene.
    """

    def __init__(self):
        #: (weight, bias) -> the frames' (input X_t detached, output Y_t with its graph)
        self._uses: dict[tuple[nn.Parameter, nn.Parameter], list[tuple[torch.Tensor, torch.Tensor]]] = {}
        #: (weight, bias) -> their detached tensors (made once per scene: the weights do not change within it)
        self._detached: dict[tuple[nn.Parameter, nn.Parameter], tuple[torch.Tensor, torch.Tensor]] = {}

    def linear(self, lin: nn.Linear, x: torch.Tensor) -> torch.Tensor:
        """``F.linear(x, lin.weight, lin.bias)`` (K, out), its weight gradient deferred (:meth:`linear_params`)."""
        return self.linear_params(lin.weight, lin.bias, x)

    def linear_params(self, weight: nn.Parameter, bias: nn.Parameter, x: torch.Tensor) -> torch.Tensor:
        """``x W^T + b`` (K, out) for x (K, in), W (out, in), b (out,), the gradient of W and b deferred; an input
        without a graph (the first frame's features) takes the ordinary path."""
        if not (x.requires_grad and weight.requires_grad and torch.is_grad_enabled()):
            return F.linear(x, weight, bias)
        key = (weight, bias)
        wb = self._detached.get(key)
        if wb is None:
            wb = self._detached[key] = (weight.detach(), bias.detach())
        y = F.linear(x, *wb)
        self._uses.setdefault(key, []).append((x.detach(), y))
        return y

    def backward(self, loss: torch.Tensor, params: list[nn.Parameter]) -> None:
        """``loss.backward()`` for ``params`` (their ``.grad`` set or accumulated), the deferred layers' weight
        and bias gradients included: one autograd pass for the parameters and the kept outputs."""
        uses = [(key, x, y) for key, pairs in self._uses.items() for x, y in pairs]
        leaves = [p for p in params if p.requires_grad]
        grads = torch.autograd.grad(loss, [y for _, _, y in uses] + leaves, allow_unused=True)
        acc: dict[tuple[nn.Parameter, nn.Parameter], tuple[list, list]] = {}
        for (key, x, _), g in zip(uses, grads[: len(uses)]):
            if g is not None:
                xs, gs = acc.setdefault(key, ([], []))
                xs.append(x)
                gs.append(g)
        extra = [(p, g) for p, g in zip(leaves, grads[len(uses) :]) if g is not None]
        for (weight, bias), (xs, gs) in acc.items():
            G = torch.cat(gs)
            extra += [(weight, G.t().mm(torch.cat(xs))), (bias, G.sum(0))]
        for param, grad in extra:
            param.grad = grad if param.grad is None else param.grad + grad
        self._uses.clear()
        self._detached.clear()


def _linear(x: torch.Tensor, lin: nn.Linear, deferred: DeferredWeightGrads | None) -> torch.Tensor:
    """``lin(x)`` through ``torch.nn.functional`` (with ``deferred``: its weight gradient deferred)."""
    return F.linear(x, lin.weight, lin.bias) if deferred is None else deferred.linear(lin, x)


def _fc_apply(fc: nn.Sequential, x: torch.Tensor, deferred: DeferredWeightGrads | None = None) -> torch.Tensor:
    """``fc(x)`` for an :func:`_fc` block (Linear then ReLU), through ``torch.nn.functional``."""
    return torch.relu(_linear(x, fc._modules["0"], deferred))


def _gru(
    cell: nn.GRUCell, x: torch.Tensor, h: torch.Tensor, deferred: DeferredWeightGrads | None = None
) -> torch.Tensor:
    """``cell(x, h)`` for batched (N, ·) inputs: the operator GRUCell.forward calls; with ``deferred``, the same
    equations written out (torch's CPU composite of ``gru_cell``) with the two input products' weight gradients
    deferred: ``r = sigma(W_ir x + b_ir + W_hr h + b_hr)``, ``z = sigma(W_iz x + b_iz + W_hz h + b_hz)``,
    ``n = tanh(W_in x + b_in + r * (W_hn h + b_hn))``, ``h' = (h - n) * z + n``."""
    if deferred is None:
        return torch.gru_cell(x, h, cell.weight_ih, cell.weight_hh, cell.bias_ih, cell.bias_hh)
    gi = deferred.linear_params(cell.weight_ih, cell.bias_ih, x)  # [i_r, i_z, i_n]  (N, 3H)
    gh = deferred.linear_params(cell.weight_hh, cell.bias_hh, h)  # [h_r, h_z, h_n]
    H = h.shape[1]
    (i_rz, i_n), (h_rz, h_n) = gi.split_with_sizes([2 * H, H], 1), gh.split_with_sizes([2 * H, H], 1)
    r, z = torch.sigmoid(i_rz + h_rz).chunk(2, 1)
    n = torch.tanh(torch.addcmul(i_n, r, h_n))
    return torch.lerp(n, h, z)  # n + z (h - n)


@functools.cache
def _rotation_masks(
    pairs: tuple[tuple[int, int], ...], d: int, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Constants of :func:`rotate_pairs` for (N, d) rows (made once; normal tensors even when first asked for
    under ``torch.inference_mode``, so that training can save them): ``in_pair`` (1, d) bool, ``sign`` (1, d)
    +1 at each pair's first column, -1 at its second, 0 elsewhere, ``swap`` (d,) int64 the column order with each
    pair's columns exchanged."""
    with torch.inference_mode(False):
        in_pair, sign, swap = torch.zeros(1, d, dtype=torch.bool), torch.zeros(1, d, dtype=dtype), torch.arange(d)
        for i, j in pairs:
            in_pair[0, i] = in_pair[0, j] = True
            sign[0, i], sign[0, j] = 1.0, -1.0
            swap[i], swap[j] = j, i
        return in_pair.to(device), sign.to(device), swap.to(device)


def rotate_pairs(v: torch.Tensor, c: torch.Tensor, s: torch.Tensor, pairs: tuple[tuple[int, int], ...]) -> torch.Tensor:
    """Rotate the planar column pairs (i, j) of v (N, d) by -angle, given ``c, s`` (N, 1) = cos, sin of the angle:
    ``[v_i, v_j] <- [c v_i + s v_j, -s v_i + c v_j]``, other columns unchanged. As ``v * C + v[:, swap] * S`` with
    C = c on the pairs' columns and 1 elsewhere, S = +-s on them and 0 elsewhere: five operators for all pairs."""
    in_pair, sign, swap = _rotation_masks(pairs, v.shape[1], v.dtype, v.device)
    return torch.addcmul(v * torch.where(in_pair, c, 1.0), v.index_select(1, swap), s * sign)


def to_heading_frame(v: torch.Tensor, yaw: torch.Tensor, pairs: tuple[tuple[int, int], ...]) -> torch.Tensor:
    """Rotate the planar column pairs (i, j) of v (N, d) by -yaw (N,) into the heading frame:
    ``[v_i, v_j] <- [c v_i + s v_j, -s v_i + c v_j]`` with ``c, s = cos yaw, sin yaw``; other columns unchanged
    (:func:`rotate_pairs`)."""
    return rotate_pairs(v, torch.cos(yaw)[:, None], torch.sin(yaw)[:, None], pairs)


def from_heading_frame(v: torch.Tensor, yaw: torch.Tensor, pairs: tuple[tuple[int, int], ...]) -> torch.Tensor:
    """Inverse of :func:`to_heading_frame`."""
    return to_heading_frame(v, -yaw, pairs)


def wrap_offset(a: torch.Tensor, flip: bool = False) -> torch.Tensor:
    """What to subtract from angles ``a`` (radians, any shape) to wrap them to [-pi, pi) (with ``flip``: and to
    turn by pi those then beyond pi/2, a reversed heading), as a tensor without a graph: subtracting it wraps
    with derivative 1, as ``remainder`` has, in one autograd node."""
    with torch.no_grad():
        w = wrap_angle_t(a)
        if flip:
            w = torch.where(w.abs() > 0.5 * math.pi, wrap_angle_t(w + math.pi), w)
        return a - w


MEAS_PLANAR = ((0, 1), (7, 8))  # (x, y), (vx, vy) in the measurement
STATE_PLANAR = ((0, 1),)  # (x, y) in the CTRA / Bicycle state


class GRUKalmanNet(nn.Module):
    """The learned gain network; see the module docstring. m = state dim (10), n = measurement dim (9)."""

    def __init__(self, cfg: GRUKFConfig = GRUKFConfig(), generator: torch.Generator | None = None):
        """Layers of architecture ``cfg`` initialised from ``generator`` (a CPU ``torch.Generator``; None = torch's
        global generator), see :meth:`reset_parameters`."""
        super().__init__()
        self.cfg = cfg
        self.deferred: DeferredWeightGrads | None = None  # set while training a scene (see deferring_weight_grads)
        self.ss = cfg.torch_model()
        if cfg.gain_prior not in GAIN_PRIORS:
            raise ValueError(f"gain_prior must be one of {', '.join(GAIN_PRIORS)}, got {cfg.gain_prior!r}")
        if cfg.network_classes not in NETWORK_CLASSES:
            raise ValueError(
                f"network_classes must be one of {', '.join(NETWORK_CLASSES)}, got {cfg.network_classes!r}"
            )
        if cfg.coast_yaw_rate not in COAST_YAW_RATES:
            raise ValueError(f"coast_yaw_rate must be one of {', '.join(COAST_YAW_RATES)}, got {cfg.coast_yaw_rate!r}")
        if cfg.coast_acceleration not in COAST_ACCELERATIONS:
            raise ValueError(
                f"coast_acceleration must be one of {', '.join(COAST_ACCELERATIONS)}, got {cfg.coast_acceleration!r}"
            )
        with torch.device("meta"):  # allocated without drawing from any generator, initialised below
            self._build(cfg)
        self.to_empty(device="cpu")
        self.reset_parameters(generator)
        if cfg.gain_prior == "ekf":  # the EKF's per-class noise (tracking classes), float64 like the state
            m, n = self.m, self.n
            self.register_buffer("ekf_Q", torch.zeros(cfg.n_classes, m, m, dtype=torch.float64))
            self.register_buffer("ekf_R", torch.zeros(cfg.n_classes, n, n, dtype=torch.float64))
            self.register_buffer("ekf_P0", torch.zeros(cfg.n_classes, m, m, dtype=torch.float64))

    def _build(self, cfg: GRUKFConfig) -> None:
        """Create the layers (parameters uninitialised)."""
        m, n = self.ss.dim_x, MEAS_DIM
        self.m, self.n = m, n
        self.h_q, self.h_sigma, self.h_s = m * m, m * m, n * n
        self.fc_fwd_update = _fc(m, m * cfg.in_mult)  # input layer of the Q-GRU
        self.gru_q = nn.GRUCell(m * cfg.in_mult, self.h_q)
        self.fc_fwd_evol = _fc(m, m * cfg.in_mult)  # input layer of the Σ-GRU
        self.gru_sigma = nn.GRUCell(self.h_q + m * cfg.in_mult, self.h_sigma)
        self.fc_sigma_to_s = _fc(self.h_sigma, n * n)
        a = AUX_DIM if cfg.aux_inputs else 0
        self.fc_obs = _fc(2 * n + a, 2 * n * cfg.in_mult)  # input layer of the S-GRU
        r_dim = 0
        if cfg.four_gru:
            self.gru_r = nn.GRUCell(n * cfg.in_mult, n * n)
            self.fc_r_in = _fc(n, n * cfg.in_mult)
            r_dim = n * n
        self.gru_s = nn.GRUCell(n * n + 2 * n * cfg.in_mult + r_dim, self.h_s)
        hidden = (self.h_sigma + self.h_s) * cfg.out_mult // 10
        self.fc_gain = nn.Sequential(
            nn.Linear(self.h_sigma + self.h_s + a, hidden), nn.ReLU(), nn.Linear(hidden, m * n)
        )  # output layer: K
        self.fc_back1 = _fc(self.h_s + m * n, m * m)
        self.fc_back2 = _fc(self.h_sigma + m * m, self.h_sigma)
        if cfg.has_table:
            self.gain_table = nn.Parameter(torch.zeros(*cfg.table_shape, m * n))

    def reset_parameters(self, generator: torch.Generator | None = None) -> None:
        """PyTorch's default initialisation of every layer, drawn from ``generator`` in the order the layers
        were created (so a generator seeded with s gives the weights ``torch.manual_seed(s)`` gives a network
        built with default-initialised layers): Linear weights kaiming-uniform (a = sqrt(5)) and biases
        U(+-1/sqrt(fan_in)), GRU cells U(+-1/sqrt(hidden)); then the output layer's last Linear and the gain
        table are zeroed (the gain comes from :meth:`set_gain_prior`)."""
        with torch.no_grad():
            for mod in self.modules():
                if isinstance(mod, nn.Linear):
                    nn.init.kaiming_uniform_(mod.weight, a=math.sqrt(5), generator=generator)
                    bound = 1 / math.sqrt(mod.in_features)
                    nn.init.uniform_(mod.bias, -bound, bound, generator=generator)
                elif isinstance(mod, nn.GRUCell):
                    stdv = 1 / math.sqrt(mod.hidden_size)
                    for w in mod.parameters():
                        nn.init.uniform_(w, -stdv, stdv, generator=generator)
            nn.init.zeros_(self.fc_gain[2].weight)
            nn.init.zeros_(self.fc_gain[2].bias)
            if self.cfg.has_table:
                nn.init.zeros_(self.gain_table)

    @contextlib.contextmanager
    def deferring_weight_grads(self):
        """Context for one training step: the Linear layers' and GRU cells' weight gradients are kept per frame
        and summed by the :class:`DeferredWeightGrads` it yields; call its ``backward(loss, parameters)`` instead
        of ``loss.backward()``. Same gradient as without, fewer and larger matrix products."""
        self.deferred = DeferredWeightGrads()
        try:
            yield self.deferred
        finally:
            self.deferred = None

    def set_gain_prior(
        self, K0: torch.Tensor, K_table: torch.Tensor | None = None, generator: torch.Generator | None = None
    ) -> None:
        """Start from the constant gain K0 (m, n) in the heading frame: output bias = K0, small weights
        (N(0, 1e-3^2), drawn from ``generator``, a torch.Generator on the network's device; None = torch's
        global generator).

        With a gain table, ``K_table`` (*table_shape, m, n) gives the starting gain of each (class, age, gap)
        cell (a NaN cell had no update in the training data: it starts at K0).
        """
        with torch.no_grad():
            w = self.fc_gain[2].weight
            self.fc_gain[2].bias.copy_(K0.reshape(-1).to(self.fc_gain[2].bias))
            w.mul_(0.0).add_(torch.randn(w.shape, generator=generator, dtype=w.dtype, device=w.device) * 1e-3)
            if self.cfg.has_table and K_table is not None:
                off = K_table.reshape(*self.cfg.table_shape, -1).to(self.gain_table) - self.fc_gain[2].bias
                self.gain_table.copy_(torch.nan_to_num(off, nan=0.0))

    def set_ekf_noise(self, Q: torch.Tensor, R: torch.Tensor, P0: torch.Tensor) -> None:
        """The prior EKF's noise per tracking class: Q, P0 (n_classes, m, m), R (n_classes, 9, 9) (state and
        measurement units squared, per step of the motion config). ``gain_prior="ekf"`` only."""
        if self.cfg.gain_prior != "ekf":
            raise ValueError("set_ekf_noise is for a GRU-KF with gain_prior 'ekf'")
        with torch.no_grad():
            for buf, v in ((self.ekf_Q, Q), (self.ekf_R, R), (self.ekf_P0, P0)):
                buf.copy_(torch.as_tensor(v, dtype=torch.float64).reshape(buf.shape))

    def table_index(self, labels: np.ndarray, n_updates: np.ndarray, gaps: np.ndarray) -> np.ndarray:
        """Flat cells of the gain table ((K,) int64 row of ``gain_table`` viewed as (cells, m * n)) for tracks of
        classes ``labels`` (K,) at their ``n_updates``-th update (K,) (1 = the first after birth), ``gaps`` (K,)
        frames after their last update (1 = the previous frame); the last age and gap bins take larger values."""
        C, A, G = self.cfg.table_shape
        zero = np.zeros(len(labels), dtype=np.int64)
        c = np.asarray(labels, dtype=np.int64) if self.cfg.class_gain else zero
        a = np.clip(n_updates, 1, self.cfg.age_bins) - 1 if self.cfg.age_bins > 0 else zero
        g = np.clip(gaps, 1, self.cfg.gap_bins) - 1 if self.cfg.gap_bins > 0 else zero
        return (c * A + a) * G + g

    def init_hidden(self, n_tracks: int, device=None) -> dict[str, torch.Tensor]:
        """Zero hidden states for new tracks (N, hidden) each."""
        dt = self.fc_gain[2].weight.dtype
        h = {
            "q": torch.zeros(n_tracks, self.h_q, device=device, dtype=dt),
            "sigma": torch.zeros(n_tracks, self.h_sigma, device=device, dtype=dt),
            "s": torch.zeros(n_tracks, self.h_s, device=device, dtype=dt),
        }
        if self.cfg.four_gru:
            h["r"] = torch.zeros(n_tracks, self.n * self.n, device=device, dtype=dt)
        return h

    def _layout(self, device: torch.device) -> dict[str, torch.Tensor]:
        """Constants (on ``device``, made once) of the four inputs side by side (K, D = 2n + 2m):
        ``[obs_diff (n), innovation (n), fwd_evol (m), fwd_update (m)]``: ``diff`` (3n + 3m, D) the +-1 matrix
        taking ``[y, y_prev, h(x^-), x_{n-1|n-1}, x_{n-2|n-2}, x_{n-1|n-2}]`` to them; ``angles`` their yaw
        columns; ``flip`` (1, 4) which of those are measurement-space residuals; ``pairs`` (i, j) the planar
        column pairs in the heading frame (x, y and vx, vy of the measurements; x, y of the states); ``part``
        (D, 4) the input each column belongs to (one-hot); ``lower`` (1, m) the posterior's lower bounds (sizes
        at ``min_size``, -inf elsewhere); ``yaw`` the state's yaw column."""
        cache = self.__dict__.setdefault("_layout_cache", {})
        if device not in cache:
            n, m, yi = self.n, self.m, self.ss.yaw_index
            starts = (0, n, 2 * n, 2 * n + m)
            pairs = tuple(
                (o + i, o + j)
                for o, planar in zip(starts, (MEAS_PLANAR, MEAS_PLANAR, STATE_PLANAR, STATE_PLANAR))
                for i, j in planar
            )
            with torch.inference_mode(False):  # normal tensors: training saves them for the backward pass
                sizes = (n, n, m, m)
                diff = torch.zeros(3 * n + 3 * m, 2 * n + 2 * m, dtype=torch.float64)
                eye_n, eye_m = torch.eye(n, dtype=torch.float64), torch.eye(m, dtype=torch.float64)
                # rows: y [0, n), y_prev [n, 2n), h(x^-) [2n, 3n), post1 [3n, 3n+m), post2 [.., 3n+2m), prior1
                diff[0:n, 0:n], diff[n : 2 * n, 0:n] = eye_n, -eye_n  # y - y_prev
                diff[0:n, n : 2 * n], diff[2 * n : 3 * n, n : 2 * n] = eye_n, -eye_n  # y - h(x^-)
                p1, p2, q1 = 3 * n, 3 * n + m, 3 * n + 2 * m
                diff[p1 : p1 + m, 2 * n : 2 * n + m], diff[p2 : p2 + m, 2 * n : 2 * n + m] = (
                    eye_m,
                    -eye_m,
                )  # post1 - post2
                diff[p1 : p1 + m, 2 * n + m :], diff[q1 : q1 + m, 2 * n + m :] = eye_m, -eye_m  # post1 - prior1
                part = torch.zeros(2 * n + 2 * m, 4, dtype=torch.float64)
                for k, (o, size) in enumerate(zip(starts, sizes)):
                    part[o : o + size, k] = 1.0
                lower = torch.full((1, m), -math.inf, dtype=torch.float64)
                lower[0, 3:6] = self.cfg.min_size
                cache[device] = {
                    "diff": diff.to(device),
                    "pairs": pairs,
                    "part": part.to(device),
                    "angles": torch.tensor([_YAW_Z, n + _YAW_Z, 2 * n + yi, 2 * n + m + yi], device=device),
                    "flip": torch.tensor([[True, True, False, False]], device=device),
                    "yaw": torch.tensor([yi], device=device),
                    "lower": lower.to(device),
                }
        return cache[device]

    def gain(
        self,
        feats: torch.Tensor,
        hidden: dict[str, torch.Tensor],
        cells: torch.Tensor | None = None,
        aux: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Gain K (N, m, n) from the four normalised inputs side by side, ``feats`` (N, 2n + 2m) =
        ``[obs_diff, innovation, fwd_evol, fwd_update]`` (see :meth:`_layout`), and the hidden states (and, with
        a gain table, the tracks' cells of it, see :meth:`table_index`; with ``aux_inputs``, ``aux`` (N,
        AUX_DIM), see :func:`aux_features`); returns new hidden states. The layers are applied through
        ``torch.nn.functional`` (the same operators as the modules' forward, without the module call
        machinery: this runs once per frame)."""
        dt = self.fc_gain[2].weight.dtype
        n, m = self.n, self.m
        f = feats.to(dt)
        f_obs, f_evol, f_upd = f.split_with_sizes([2 * n, m, m], 1)
        aux = [aux.to(dt)] if self.cfg.aux_inputs else []
        if aux:
            f_obs = torch.cat([f_obs, *aux], dim=1)
        d = self.deferred
        h_q = _gru(self.gru_q, _fc_apply(self.fc_fwd_update, f_upd, d), hidden["q"], d)
        h_sigma = _gru(
            self.gru_sigma, torch.cat([h_q, _fc_apply(self.fc_fwd_evol, f_evol, d)], dim=1), hidden["sigma"], d
        )
        s_in = [_fc_apply(self.fc_sigma_to_s, h_sigma, d), _fc_apply(self.fc_obs, f_obs, d)]
        new = {"q": h_q}
        if self.cfg.four_gru:
            h_r = _gru(self.gru_r, _fc_apply(self.fc_r_in, f[:, :n], d), hidden["r"], d)
            s_in.append(h_r)
            new["r"] = h_r
        h_s = _gru(self.gru_s, torch.cat(s_in, dim=1), hidden["s"], d)
        g0, g2 = self.fc_gain._modules["0"], self.fc_gain._modules["2"]
        K = _linear(torch.relu(_linear(torch.cat([h_sigma, h_s, *aux], dim=1), g0, d)), g2, d)
        if self.cfg.has_table:
            if cells is None:
                raise ValueError("this GRU-KF's gain table needs the class, update count and gap of every track")
            K = K + self.gain_table.view(-1, K.shape[1]).index_select(0, cells)
        back = _fc_apply(self.fc_back1, torch.cat([h_s, K], dim=1), d)
        new["sigma"] = _fc_apply(self.fc_back2, torch.cat([h_sigma, back], dim=1), d)
        new["s"] = h_s
        return K.reshape(-1, self.m, self.n), new

    def correct(
        self,
        x_prior: torch.Tensor,
        y: torch.Tensor,
        y_prev: torch.Tensor,
        x_post_prev: torch.Tensor,
        x_prior_prev: torch.Tensor,
        x_post_prev2: torch.Tensor,
        hidden: dict[str, torch.Tensor],
        cells: torch.Tensor | None = None,
        counts: torch.Tensor | None = None,
        K_prior: torch.Tensor | None = None,
        ss=None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor], torch.Tensor]:
        """One update of K tracks (all (K, ·) float64): prior x^-_n, measurement y_n, previous measurement,
        previous posterior x_{n-1|n-1}, previous prior x_{n-1|n-2}, posterior before that x_{n-2|n-2};
        ``cells`` (K,) int64: the tracks' cells of the gain table (:meth:`table_index`; only with a table); ``counts``
        (K, 2): each track's update count at this update (1 = the first) and frames since its last update
        (only with ``aux_inputs``); ``K_prior`` (K, m, 9) float64: the EKF gain ``P^- H^T S^-1`` of each track,
        global frame (only with ``gain_prior="ekf"``); ``ss``: the tracks' torch SS model when it is not the
        network's own (``network_classes: own_model``; same state layout). Returns the posterior (K, m), the new
        hidden states and the network's gain K (K, m, n) it applied (heading frame; the trainer checks it for
        divergence).

        ``x = x^- + K_prior r + Rs(yaw) dK r_h``: r the innovation (yaw wrapped), r_h = Rm(-yaw) r the same in
        the heading frame, dK (K, m, 9) the network's heading-frame gain (the whole gain with
        ``gain_prior="constant"``, where K_prior is absent).

        The four inputs are formed side by side in one (K, 2n + 2m) tensor (:meth:`_layout`): their yaw
        components wrapped, their planar pairs turned into the heading frame and each input L2-normalised by a
        few operators on the whole, not a chain of them per input (the same values).
        """
        ss = self.ss if ss is None else ss
        n, m, yi = self.n, self.m, ss.yaw_index
        lay = self._layout(x_prior.device)
        yaw = x_prior[:, yi : yi + 1]
        c, s = torch.cos(yaw), torch.sin(yaw)
        raw = torch.cat([y, y_prev, ss.h_at(x_prior, c, s), x_post_prev, x_post_prev2, x_prior_prev], dim=1).mm(
            lay["diff"]
        )  # the four differences (exact: +-1 entries)
        ang = raw.detach().index_select(1, lay["angles"])
        off = wrap_offset(ang)
        if self.cfg.yaw_flip:  # the measurement-space yaw residuals (observation difference, innovation)
            off = torch.where(lay["flip"], wrap_offset(ang, flip=True), off)
        wrapped = raw - torch.zeros_like(raw).index_copy_(1, lay["angles"], off)
        raw = rotate_pairs(wrapped, c, s, lay["pairs"])
        # per-input L2 norms (K, 4) as one product; a zero input (no graph behind it) keeps a zero gradient
        norms = raw.square().mm(lay["part"]).clamp_min(1e-300).sqrt()
        feats = raw / (norms + _EPS).mm(lay["part"].t())
        aux = None
        if self.cfg.aux_inputs:
            if counts is None:
                raise ValueError("this GRU-KF's aux inputs need the update count and gap of every track")
            aux = aux_features(
                {
                    "innovation": raw[:, n : 2 * n],
                    "obs_diff": raw[:, :n],
                    "fwd_evol": raw[:, 2 * n : 2 * n + m],
                    "fwd_update": raw[:, 2 * n + m :],
                },
                counts,
            )
        innov_h = raw[:, n : 2 * n]
        K, new_hidden = self.gain(feats, hidden, cells, aux)
        delta = torch.bmm(K.to(innov_h.dtype), innov_h[:, :, None])[:, :, 0]
        delta = rotate_pairs(delta, c, -s, STATE_PLANAR)  # back to the global frame
        if self.cfg.gain_prior == "ekf":
            if K_prior is None:
                raise ValueError("this GRU-KF's EKF gain prior needs every track's EKF gain")
            innov = wrapped[:, n : 2 * n]  # global frame
            delta = delta + torch.bmm(K_prior.to(innov.dtype), innov[:, :, None])[:, :, 0]  # K_ekf r
        # sizes stay physical (a learned gain can overshoot); the yaw is wrapped
        x = torch.clamp(x_prior + delta, min=lay["lower"])
        x = x - torch.zeros_like(x).index_copy_(1, lay["yaw"], wrap_offset(x.detach()[:, yi : yi + 1]))
        return x, new_hidden, K

    def _yaw_res(self, r: torch.Tensor) -> torch.Tensor:
        """Yaw residuals (K, 1) wrapped to [-pi, pi); with ``yaw_flip`` those beyond pi/2 turned by pi."""
        r = wrap_angle_t(r)
        if self.cfg.yaw_flip:
            r = torch.where(r.abs() > 0.5 * math.pi, wrap_angle_t(r + math.pi), r)
        return r

    def config_dict(self) -> dict:
        """The architecture as a plain dict (for checkpoints)."""
        return asdict(self.cfg)


def aux_features(raw: dict[str, torch.Tensor], counts: torch.Tensor) -> torch.Tensor:
    """The magnitudes normalisation hides: (K, AUX_DIM) = log(1 + L2 norm) of the innovation, observation
    difference, forward-evolution and forward-update differences (raw (K, ·) each, metres / radians / m/s
    mixed as in the state), then log(update count) and log(frames since the last update) from ``counts`` (K, 2)
    (both >= 1)."""
    norms = [torch.log1p(raw[k].norm(dim=1)) for k in ("innovation", "obs_diff", "fwd_evol", "fwd_update")]
    c = torch.log(counts.to(raw["innovation"].dtype).clamp_min(1.0))
    return torch.stack([*norms, c[:, 0], c[:, 1]], dim=1)
