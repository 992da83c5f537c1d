"""Build a ready-to-run tracker from a tracker name and preset."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from grutrack.classes import TRACKING_CLASSES
from grutrack.errors import ConfigError
from grutrack.tracking.config import TrackerConfig, load_tracker_config
from grutrack.tracking.names import TRACKERS  # noqa: F401  (re-exported: the selectable trackers)
from grutrack.tracking.tracker import Tracker, TrackGroup

#: tracker name -> preset used when --config is not given (the GRU-KF shares the EKF tracker's preset:
#: pre-processing, association, lifecycle and output are the same, only the motion backend differs)
DEFAULT_PRESET = {"ekf": "ekf", "grukf": "ekf", "greedy": "greedy", "ab3dmot": "ab3dmot"}


def build_tracker(
    name: str = "ekf",
    config: str | Path | None = None,
    param_classes: tuple[str, ...] | None = None,
    checkpoint: str | Path | None = None,
    device: str = "auto",
) -> Tracker:
    """A :class:`Tracker` for ``name`` with the preset ``config`` (default: the preset named ``name``).

    ``param_classes``: for a dataset whose labels are not the 7 nuScenes tracking classes (e.g. AV2
    categories), the nuScenes tracking class whose parameters each dataset label uses; labels stay distinct
    (boxes of different labels never match) while thresholds and motion models come from the mapped class.
    ``checkpoint``: the trained GRU-KF (``grukf`` only; without ``config`` the preset's ``output.matched_box``
    is the one stored in the checkpoint's training config); ``device``: auto, cpu, cuda, ...
    """
    if name not in TRACKERS:
        raise ConfigError(f"unknown tracker '{name}' (available: {', '.join(TRACKERS)})")
    if checkpoint is not None and name != "grukf":
        raise ConfigError(
            f"--checkpoint is for --tracker grukf; --tracker {name} has no learned model (drop "
            f"--checkpoint, or use --tracker grukf)"
        )
    cfg = load_tracker_config(config or DEFAULT_PRESET[name])
    index = param_index(param_classes)
    cfg = remap_config(cfg, index)
    if name == "grukf":
        if checkpoint is None:
            raise ConfigError("--tracker grukf needs --checkpoint CKPT (a model written by `grutrack train`)")
        from grutrack.documents import Checkpoint
        from grutrack.motion.checkpoint import load_network
        from grutrack.tracking.grukf_backend import resolve_device

        device = resolve_device(device)  # a device this machine lacks is refused before the model is read
        ck = Checkpoint.read(checkpoint)  # read once: the network and the training config's matched box
        if config is None:  # the default preset writes what the network was trained to give (see grukf.yaml)
            cfg = replace(cfg, matched_box=ck.matched_box)
        return Tracker(cfg, network_groups(load_network(ck, where=checkpoint), cfg, index, device), _association(cfg))
    return Tracker(cfg, _baseline_groups(name, cfg, index), _association(cfg))


def _baseline_groups(name: str, cfg: TrackerConfig, index: np.ndarray) -> list[TrackGroup]:
    """Track groups of ekf / ab3dmot (one per motion model) or greedy (one group for every label)."""
    from grutrack.tracking.baselines import DetectionBackend, NoVelocityKalmanBackend

    if name == "greedy":
        return [TrackGroup(DetectionBackend(), np.ones(len(index), dtype=bool))]
    if cfg.filter == "decoupled_cv":
        return [decoupled_group(cfg, len(index))]
    return ekf_groups(cfg, index, NoVelocityKalmanBackend if name == "ab3dmot" else None)


def decoupled_group(cfg: TrackerConfig, n_labels: int) -> TrackGroup:
    """One track group for every label with MCTrack's decoupled filters (``motion.filter: decoupled_cv``)."""
    from grutrack.tracking.decoupled_backend import DecoupledCVBackend

    backend = DecoupledCVBackend(
        cfg.position_noise,
        cfg.size_noise,
        dt=cfg.time_step if cfg.time_step is not None else 0.5,
        missed_update=cfg.missed_update,
        size_steps=cfg.size_steps,
        compared_size=cfg.compared_size,
        written_velocity=cfg.written_velocity,
    )
    return TrackGroup(backend, np.ones(n_labels, dtype=bool))


def _association(cfg: TrackerConfig):
    """The association the preset asks for: None (the tracker's two-stage Hungarian, Ro_GDIoU for some classes
    included), greedy, or MCTrack's Ro_GDIoU for every class."""
    if all(m == "ro_gdiou_bev" for m in cfg.first_metric):
        from grutrack.tracking.ro_gdiou import ro_gdiou_association

        return ro_gdiou_association(cfg)
    if cfg.algorithm == "greedy":
        from grutrack.tracking.baselines import greedy_association

        return greedy_association(cfg.max_distance)
    return None


def grukf_group(
    net,
    n_labels: int,
    device: str = "auto",
    train: bool = False,
    class_index: np.ndarray | None = None,
    members: np.ndarray | None = None,
    correct=None,
    ss_model: str | None = None,
    velocity_check=None,
    robust=None,
) -> TrackGroup:
    """One track group run by the GRU-Kalman filter ``net`` for the labels ``members`` (n_labels,) bool (default:
    every label); ``class_index`` (n_labels,) int maps a dataset label to the tracking class the network's
    per-class gain uses (default: identity); ``correct``, ``ss_model``, ``velocity_check``, ``robust``: see
    :class:`GRUKFBackend`."""
    from grutrack.tracking.grukf_backend import GRUKFBackend

    members = np.ones(n_labels, dtype=bool) if members is None else np.asarray(members, dtype=bool)
    backend = GRUKFBackend(
        net,
        device,
        train=train,
        class_index=class_index,
        correct=correct,
        ss_model=ss_model,
        velocity_check=velocity_check,
        robust=robust,
    )
    return TrackGroup(backend, members)


def network_models(arch, cfg: TrackerConfig, index: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The network's track groups under the preset ``cfg`` (already re-indexed by dataset label; ``index``
    (n_labels,) the tracking class of each label): ``[(SS model name, members (n_labels,) bool)]``, the network's
    own model first, no empty group. ``arch.network_classes`` (``arch`` a ``GRUKFConfig``) "all": every label with
    ``arch.ss_model``; "ss_model": the labels whose model in the preset's motion config (with its
    ``model_override``) is ``arch.ss_model``; "own_model": the labels whose preset model is one of
    :data:`~grutrack.motion.grukf.NETWORK_MODELS`, one group per model."""
    if arch.network_classes == "all":
        return [(arch.ss_model, np.ones(len(index), dtype=bool))]
    from grutrack.motion.config import load_motion_config
    from grutrack.motion.grukf import NETWORK_MODELS

    motion = load_motion_config(cfg.motion_config, cfg.model_override or None)
    model = np.array([motion[TRACKING_CLASSES[c]]["model"].upper() for c in index])
    own = arch.ss_model.upper()
    names = [own] + ([m for m in NETWORK_MODELS if m != own] if arch.network_classes == "own_model" else [])
    groups = [(name if name != own else arch.ss_model, model == name) for name in names]
    return [g for i, g in enumerate(groups) if i == 0 or g[1].any()]


def network_members(arch, cfg: TrackerConfig, index: np.ndarray) -> np.ndarray:
    """(n_labels,) bool: the labels a network of architecture ``arch`` filters under the preset ``cfg``, in any
    of its groups (:func:`network_models`)."""
    return np.logical_or.reduce([m for _, m in network_models(arch, cfg, index)])


def network_groups(net, cfg: TrackerConfig, index: np.ndarray, device: str = "auto") -> list[TrackGroup]:
    """The track groups of a GRU-KF tracker: the network's groups (:func:`network_models`) and the preset's
    EKF groups (:func:`ekf_groups`) for the other labels (none with ``network_classes: all``)."""
    models = network_models(net.cfg, cfg, index)
    members = np.logical_or.reduce([m for _, m in models])
    rest = ekf_groups(cfg, index, only=~members) if not members.all() else []
    return [
        *(
            grukf_group(
                net,
                len(index),
                device,
                class_index=index,
                members=m,
                ss_model=name,
                velocity_check=velocity_check(cfg),
                robust=robust_update(cfg),
            )
            for name, m in models
        ),
        *rest,
    ]


def param_index(param_classes: tuple[str, ...] | None) -> np.ndarray:
    """(n_labels,) int: the tracking-class row each dataset label takes its parameters from."""
    if param_classes is None:
        return np.arange(len(TRACKING_CLASSES))
    unknown = [c for c in param_classes if c not in TRACKING_CLASSES]
    if unknown:
        raise ConfigError(f"class map names {unknown}, expected tracking classes {', '.join(TRACKING_CLASSES)}")
    return np.array([TRACKING_CLASSES.index(c) for c in param_classes], dtype=np.int64)


def remap_config(cfg: TrackerConfig, index: np.ndarray) -> TrackerConfig:
    """The config with every per-class array re-indexed by dataset label (``index`` (n_labels,))."""
    return replace(
        cfg,
        score_threshold=cfg.score_threshold[index],
        first_metric=tuple(cfg.first_metric[i] for i in index),
        first_threshold=cfg.first_threshold[index],
        second_threshold=cfg.second_threshold[index],
        max_distance=cfg.max_distance[index],
        max_age=cfg.max_age[index],
        min_hits=cfg.min_hits[index],
        decay_rate=cfg.decay_rate[index],
        punish_num=cfg.punish_num[index],
        nms_metric=tuple(cfg.nms_metric[i] for i in index),
        nms_scale=cfg.nms_scale[index],
        nms_distance_gate=cfg.nms_distance_gate[index],
        distance_gate=cfg.distance_gate[index],
        distance_gate_growth=tuple(cfg.distance_gate_growth[i] for i in index),
        size_gate=cfg.size_gate[index],
        delete_threshold=cfg.delete_threshold[index],
        geometry_filter=tuple(cfg.geometry_filter[i] for i in index),
        coast_yaw_rate=tuple(cfg.coast_yaw_rate[i] for i in index),
        coast_acceleration=tuple(cfg.coast_acceleration[i] for i in index),
        geometry_window=cfg.geometry_window[index],
        nms_threshold=cfg.nms_threshold[index] if isinstance(cfg.nms_threshold, np.ndarray) else cfg.nms_threshold,
        ro_gdiou_weights=cfg.ro_gdiou_weights[index],
        crowded_threshold=cfg.crowded_threshold[index],
        lost_newborn_penalty=cfg.lost_newborn_penalty[index],
        track_pose=tuple(cfg.track_pose[i] for i in index),
        track_pose_blend=cfg.track_pose_blend[index],
        position_noise=None if cfg.position_noise is None else {k: v[index] for k, v in cfg.position_noise.items()},
        size_noise=None if cfg.size_noise is None else {k: v[index] for k, v in cfg.size_noise.items()},
    )


def ekf_groups(
    cfg: TrackerConfig,
    index: np.ndarray | None = None,
    backend_cls=None,
    only: np.ndarray | None = None,
    hand_off_moving: bool = True,
) -> list[TrackGroup]:
    """One track group per state-space model in use, each with per-label (n_labels, d, d) Q, R, P0 tables.

    ``index`` (n_labels,) maps dataset labels to tracking classes (identity for nuScenes). Labels of other
    groups keep zero rows in a group's tables; they are never indexed there. ``backend_cls``: a
    ``KalmanBackend`` subclass to use instead (AB3DMOT's velocity-free start), default ``KalmanBackend``.
    ``only`` (n_labels,) bool: groups for these labels alone (default: every label). A class with a ``moving``
    model in the motion config has rows in that model's group too, which takes its tracks born at or above the
    model's speed (``TrackGroup.moving_speed``). With ``hand_off_moving`` those rows are built for every label,
    ``only`` or not, so a GRU-KF network that owns a class hands that class's tracks born moving to the model its
    motion config names; without it, for ``only``'s labels alone (while training, the network keeps them all).
    """
    index = np.arange(len(TRACKING_CLASSES)) if index is None else index
    from grutrack.motion.config import load_motion_config
    from grutrack.motion.models import make_model
    from grutrack.tracking.ekf_backend import KalmanBackend

    motion = load_motion_config(cfg.motion_config, cfg.model_override or None)
    moves = {c: m["moving"] for c, m in motion.items() if "moving" in m}  # a class's model for its moving tracks
    keep = np.ones(len(index), dtype=bool) if only is None else np.asarray(only, dtype=bool)
    groups = []
    for model_name in sorted({m["model"] for m in motion.values()} | {m["model"] for m in moves.values()}):
        entries = [motion[TRACKING_CLASSES[c]] for c in index]
        members = np.array([e["model"] == model_name for e in entries]) & keep
        moving = [moves.get(TRACKING_CLASSES[c]) for c in index]
        moving = [
            m if m is not None and m["model"] == model_name and (hand_off_moving or keep[i]) else None
            for i, m in enumerate(moving)
        ]
        if not members.any() and all(m is None for m in moving):
            continue
        rows = [e if members[i] else moving[i] for i, e in enumerate(entries)]  # each label's noise in this group
        first = next(r for r in rows if r is not None)
        form = {"CTRA": cfg.ctra_form, "Bicycle": cfg.bicycle_form}.get(model_name, "arc")
        model = make_model(model_name, form, **first["params"])
        tables = {
            key: np.stack([r[key] if r is not None else np.zeros_like(first[key]) for r in rows])
            for key in ("Q", "R", "P0")
        }
        backend = (backend_cls or KalmanBackend)(
            model,
            tables["Q"],
            tables["R"],
            tables["P0"],
            yaw_flip=cfg.yaw_flip,
            velocity_check=velocity_check(cfg),
            robust=robust_update(cfg),
        )
        backend.coast_held = coast_held(model, cfg)
        backend = with_geometry_filter(backend, cfg)
        speed = np.array([np.inf if m is None else m["speed"] for m in moving])
        groups.append(TrackGroup(backend, members, None if np.isinf(speed).all() else speed))
    return groups


def coast_held(model, cfg: TrackerConfig) -> np.ndarray | None:
    """(n_labels, dim_x) bool: the state slots of ``model`` a coasting track of each label holds at 0, its turn
    rate (CTRA omega, Bicycle delta) where ``motion.coast_yaw_rate`` is zero, its acceleration (CTRA and Bicycle
    a, CA ax and ay) where ``motion.coast_acceleration`` is zero; None when no label holds any (e.g. CV)."""
    names = model.state_names
    turn = np.isin(names, ("omega", "delta"))
    accel = np.isin(names, ("a", "ax", "ay"))
    held = np.array(
        [
            (turn & (t == "zero")) | (accel & (a == "zero"))
            for t, a in zip(cfg.coast_yaw_rate, cfg.coast_acceleration, strict=True)
        ]
    )
    return held if held.any() else None


def velocity_check(cfg: TrackerConfig):
    """The preset's check of the detector's velocity (``motion.velocity_check_*``): a
    :class:`~grutrack.tracking.velocity_check.VelocityCheck`, or None when ``velocity_check_updates`` is 0."""
    if cfg.velocity_check_updates == 0:
        return None
    from grutrack.tracking.velocity_check import VelocityCheck

    return VelocityCheck(
        cfg.velocity_check_updates, cfg.velocity_check_difference, cfg.velocity_check_ratio, cfg.velocity_check_window
    )


def robust_update(cfg: TrackerConfig):
    """The preset's robust update (``motion.nis_limit``, ``motion.nis_min_hits``) and confidence-weighted noise
    (``motion.r_score_exponent``): a :class:`~grutrack.motion.kalman.RobustUpdate`, or None when both are off."""
    if cfg.nis_limit <= 0 and cfg.r_score_exponent <= 0:
        return None
    from grutrack.motion.kalman import RobustUpdate

    return RobustUpdate(cfg.nis_limit, cfg.nis_min_hits, cfg.r_score_exponent)


def with_geometry_filter(backend, cfg: TrackerConfig):
    """``backend`` wrapped in Fast-Poly's decoupled geometry when the preset asks for it for some label
    (``motion.geometry_filter`` not ``none``), else ``backend`` itself. Per-label tables come from ``cfg``
    (already re-indexed by dataset label)."""
    use = np.array([f != "none" for f in cfg.geometry_filter])
    if not use.any():
        return backend
    from grutrack.tracking.geometry_filter_backend import GeometryFilterBackend

    window = np.where(use, cfg.geometry_window, 0)
    return GeometryFilterBackend(backend, window, np.array([f == "mean" for f in cfg.geometry_filter]))
