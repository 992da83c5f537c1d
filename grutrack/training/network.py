"""What a training config asks of the filters: the network's architecture (:func:`network_config`), the classes the
network runs while training, and the parallel EKF whose posterior is the pseudo-label (:func:`ekf_backend`), with
the track groups a training tracker runs (:func:`track_groups`)."""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from grutrack.motion.grukf import NETWORK_MODELS, GRUKFConfig
from grutrack.tracking.config import TrackerConfig, load_tracker_config
from grutrack.tracking.ekf_backend import KalmanBackend
from grutrack.tracking.factory import ekf_groups, network_members, network_models
from grutrack.tracking.tracker import TrackGroup
from grutrack.training.config import TrainConfig


def network_config(cfg: TrainConfig) -> GRUKFConfig:
    """The network architecture a training config asks for: its network options (``cfg.network``, each a field of
    :class:`GRUKFConfig`), with the SS model's parameters (and those of the other models an ``own_model`` network
    runs) from the training motion config."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.config import load_motion_config

    def params(model: str) -> dict:
        return dict(load_motion_config(cfg.motion_config, model)[TRACKING_CLASSES[0]]["params"])

    others = {m: {**params(m), "form": form} for m, form in _model_forms(cfg).items()}
    return GRUKFConfig(**cfg.network, ss_params=params(ss_model(cfg)), model_params=others)


def ss_model(cfg: TrainConfig) -> str:
    """The network's SS model (``network.ss_model``), the parallel EKF's for the network's own classes."""
    return cfg.network["ss_model"]


def training_network_classes(cfg: TrainConfig) -> str:
    """Which classes the network runs while training: ``network_classes``, or "own_model" with
    ``training_classes: own_model`` (validation and the checkpoint keep ``network_classes``)."""
    return "own_model" if cfg.training_classes == "own_model" else cfg.network["network_classes"]


def training_arch(arch: GRUKFConfig, cfg: TrainConfig) -> GRUKFConfig:
    """``arch`` with the classes the network runs while training (:func:`training_network_classes`)."""
    kind = training_network_classes(cfg)
    return arch if kind == arch.network_classes else replace(arch, network_classes=kind)


def _model_forms(cfg: TrainConfig) -> dict[str, str]:
    """The tracker preset's form ("arc" or "piecewise") of each model an ``own_model`` network runs besides its
    own (``{MODEL NAME: form}``; the network's own model is always the arc form)."""
    if training_network_classes(cfg) != "own_model":
        return {}
    preset = load_tracker_config(cfg.tracker_preset)
    forms = {"CTRA": "arc", "BICYCLE": preset.bicycle_form}  # CTRA's piecewise form has no torch model
    return {m: forms[m] for m in NETWORK_MODELS if m != ss_model(cfg).upper()}


def ekf_backend(
    cfg: TrainConfig, index: np.ndarray, model: str | None = None, velocity_check=None, robust=None
) -> KalmanBackend:
    """The parallel EKF: the training SS model (or ``model``, a network group's own, ``network_classes:
    own_model``) for every label, with the motion config's Q, R, P0 of the tracking class each label takes its
    parameters from (``index`` (n_labels,), :func:`~grutrack.tracking.factory.param_index`) under that model, and
    the tracker preset's velocity check (``velocity_check``, :func:`~grutrack.tracking.factory.velocity_check`) and
    robust update (``robust``, :func:`~grutrack.tracking.factory.robust_update`)."""
    form = "arc" if model is None else _model_forms(cfg).get(model.upper(), "arc")
    index = tuple(int(c) for c in index)
    return _ekf_backend(cfg.motion_config, model or ss_model(cfg), index, form, velocity_check, robust)


@functools.lru_cache(maxsize=16)
def _ekf_backend(
    motion_config: str, ss_model: str, index: tuple[int, ...], form: str = "arc", velocity_check=None, robust=None
) -> KalmanBackend:
    """:func:`ekf_backend`, made once per process and settings (run once per training scene; the backend keeps
    no state of its own)."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.config import load_motion_config
    from grutrack.motion.models import make_model

    motion = load_motion_config(motion_config, ss_model)
    first = motion[TRACKING_CLASSES[0]]
    tables = {k: np.stack([motion[TRACKING_CLASSES[c]][k] for c in index]) for k in ("Q", "R", "P0")}
    model = make_model(first["model"], form, **first["params"])
    return KalmanBackend(model, tables["Q"], tables["R"], tables["P0"], velocity_check=velocity_check, robust=robust)


def ekf_noise(cfg: TrainConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The prior EKF's Q, P0 (n_classes, m, m) and R (n_classes, 9, 9) per tracking class, from the motion config:
    every class under ``ss_model``; when the network runs ``own_model`` groups (``network_classes`` or
    ``training_classes: own_model``, :func:`training_network_classes`) a class whose own model is one of
    :data:`NETWORK_MODELS` keeps that model's noise (the network runs it with that model)."""
    from grutrack.classes import TRACKING_CLASSES
    from grutrack.motion.config import load_motion_config

    shared = load_motion_config(cfg.motion_config, ss_model(cfg))
    own = load_motion_config(cfg.motion_config) if training_network_classes(cfg) == "own_model" else {}
    rows = [own[c] if c in own and own[c]["model"].upper() in NETWORK_MODELS else shared[c] for c in TRACKING_CLASSES]
    return tuple(np.stack([r[k] for r in rows]) for k in ("Q", "R", "P0"))


def track_groups(backends: list, arch: GRUKFConfig, tracker_cfg: TrackerConfig, index: np.ndarray) -> list[TrackGroup]:
    """The network's groups first, ``backends[i]`` for the labels of the i-th
    (:func:`~grutrack.tracking.factory.network_models`); then the preset's EKF groups for the other labels (none
    with ``network_classes: all``)."""
    models = network_models(arch, tracker_cfg, index)
    members = network_members(arch, tracker_cfg, index)
    # the network's classes keep every track while training, those born moving too (training material)
    rest = ekf_groups(tracker_cfg, index, only=~members, hand_off_moving=False) if not members.all() else []
    return [*(TrackGroup(b, m) for b, (_, m) in zip(backends, models)), *rest]
