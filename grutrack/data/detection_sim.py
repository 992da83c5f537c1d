"""Detector simulator: detector-like 3D detections sampled from ground truth.

The core (:func:`simulate_frame`) knows no dataset format: it takes one :class:`GTFrame` of canonical arrays
(boxes ``(N, 9)`` global frame, detection-class names, lidar point counts, ego position) and a
:class:`DetectorProfile`, and returns a :class:`DetFrame`. Ground truth comes from the datasets' canonical
scenes (:func:`scene_gt_frames`; nuScenes through :func:`grutrack.data.nuscenes.load_scenes` with the 10
detection classes, :func:`nusc_gt_frames`), and the official detection-submission JSON writer
(:func:`detection_json`) sits apart, so the same core runs on any dataset's ground truth.

What is simulated, per class (parameters in ``grutrack/configs/detector_profiles/<name>.yaml``):

- recall as a logistic function of ``ln(lidar points)``, reduced with distance, zero beyond the detection range,
  and a small recall of objects without any lidar point (hallucinated from context);
- centre noise growing with distance, with a heavy-tailed (Laplace) component; log-normal size noise;
  yaw noise with 180 degree flips; velocity noise proportional to speed with heavy tails;
- optionally a centre error that drifts slowly over an object's life (``pos_drift_sigma_m``, correlation time
  ``pos_drift_time_s``; :func:`centre_drift`), the time-correlated error of real detectors that a filter cannot
  average away, and velocities under-reported over an object's whole life (``vel_track_fail_prob``);
- class confusions (car <-> truck, bicycle <-> motorcycle, ...) with a lower score;
- duplicates around true positives (same or confused class) that NMS has to remove;
- false positives near objects and in free space, with scores that overlap those of true positives.

Every frame draws from its own random stream, seeded by (seed, profile name, frame token), and effects fixed per
object are functions of (seed, profile name, instance id, time): output is identical for a seed and independent
of the order or the subset of frames processed.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grutrack.boxes import BOX_DIM, VX, VY, YAW, H, W, quaternion_from_yaw, wrap_angle
from grutrack.classes import DETECTION_CLASSES
from grutrack.data.nusc_detections import LIDAR_META
from grutrack.data.scene import BoxSet
from grutrack.errors import ConfigError
from grutrack.io import atomic_path

PROFILE_DIR = Path(__file__).resolve().parents[1] / "configs" / "detector_profiles"
DET_INDEX: dict[str, int] = {name: i for i, name in enumerate(DETECTION_CLASSES)}
_VEHICLES = ("car", "truck", "bus", "trailer", "construction_vehicle")
_CYCLES = ("bicycle", "motorcycle")
MOVING_SPEED = 0.5  # m/s; above it a vehicle/pedestrian attribute is "moving" (nuScenes attribute semantics)


# ----------------------------------------------------------------------------------------------------------------
# canonical ground truth and detections
# ----------------------------------------------------------------------------------------------------------------


@dataclass
class GTFrame:
    """Ground truth of one keyframe in canonical arrays (any dataset).

    token: frame id (nuScenes sample token). scene: scene / log name. timestamp: int, microseconds.
    ego_translation: (3,) float64 metres, global frame.
    boxes: (N, 9) float64 ``[x, y, z, w, l, h, yaw, vx, vy]`` global frame (velocity NaN already set to 0).
    names: (N,) str, detection class names (:data:`grutrack.classes.DETECTION_CLASSES`).
    num_lidar_pts: (N,) int64 lidar points inside the box (0 = occluded / not seen by the lidar).
    num_radar_pts: (N,) int64 radar points (0 where unknown).
    instance_ids: (N,) object, identity of each box across frames.
    """

    token: str
    scene: str
    timestamp: int
    ego_translation: np.ndarray
    boxes: np.ndarray
    names: np.ndarray
    num_lidar_pts: np.ndarray
    num_radar_pts: np.ndarray
    instance_ids: np.ndarray

    def __len__(self) -> int:
        return len(self.boxes)


@dataclass
class DetFrame:
    """Simulated detections of one frame: boxes (M, 9) global frame, scores (M,) in (0, 1), names (M,) str,
    and ``is_tp`` (M,) bool marking boxes drawn from a detected GT object (kept for diagnostics)."""

    token: str
    boxes: np.ndarray
    scores: np.ndarray
    names: np.ndarray
    is_tp: np.ndarray

    def __len__(self) -> int:
        return len(self.boxes)


# ----------------------------------------------------------------------------------------------------------------
# profiles
# ----------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ClassProfile:
    """Detector behaviour for one detection class. Units: metres, radians, m/s; rates are per frame."""

    recall_max: float = 0.9  # recall of well-observed objects
    points_half: float = 5.0  # lidar points at which recall is recall_max / 2
    points_slope: float = 1.5  # logistic slope in ln(points)
    recall_drop_per_10m: float = 0.0  # linear recall loss per 10 m of distance
    recall_zero_points: float = 0.02  # recall of boxes with no lidar point
    pos_sigma_m: float = 0.1  # centre noise (per axis) at the sensor
    pos_sigma_per_m: float = 0.003  # centre noise growth per metre of distance
    pos_tail_prob: float = 0.05  # probability of a heavy-tailed (Laplace) centre error
    pos_tail_scale_m: float = 0.6  # Laplace scale of that error
    pos_drift_sigma_m: float = 0.0  # centre error (per axis) drifting over the object's life (0: none)
    pos_drift_time_s: float = 2.0  # its correlation time: errors dt apart correlate by exp(-dt / this)
    z_sigma_m: float = 0.1  # height-of-centre noise
    size_sigma_rel: float = 0.06  # log-normal sigma of w, l, h
    yaw_sigma_rad: float = 0.08  # yaw noise
    yaw_flip_prob: float = 0.02  # probability of a 180 degree heading flip
    vel_sigma_mps: float = 0.2  # velocity noise per axis for a static object
    vel_sigma_rel: float = 0.1  # velocity noise growth, fraction of the speed
    vel_tail_prob: float = 0.03  # probability of a heavy-tailed velocity error
    vel_tail_scale_mps: float = 1.5  # Laplace scale of that error
    vel_track_fail_prob: float = 0.0  # probability that an object's velocity is under-reported its whole life
    vel_track_fail_scale: float = 0.3  # ... then its (noisy) velocity times u, u ~ U(0, this) drawn per object
    confusion: dict = field(default_factory=dict)  # {other detection class: probability}
    confusion_logit_penalty: float = 1.0  # score logit lowered for a confused label
    duplicate_prob: float = 0.05  # probability that a detection has a duplicate
    duplicate_offset_m: float = 0.3  # centre offset sigma of a duplicate
    duplicate_other_class_prob: float = 0.3  # share of duplicates carrying a confused class
    near_fp_rate: float = 0.05  # false positives per GT object per frame, 1.5-5 m away from it
    free_fp_per_frame: float = 0.5  # false positives per frame anywhere within range
    score_logit_base: float = 0.0  # TP score logit at 0 lidar points ...
    score_logit_per_log_pts: float = 0.6  # ... plus this times ln(1 + points)
    score_logit_sigma: float = 1.0  # TP score logit noise
    fp_score_logit_mean: float = -2.0  # FP score logit mean
    fp_score_logit_sigma: float = 1.0  # FP score logit noise
    mean_size: tuple = (1.0, 1.0, 1.0)  # [w, l, h] of free-space false positives


CLASS_KEYS = tuple(f.name for f in dataclasses.fields(ClassProfile))


@dataclass(frozen=True)
class DetectorProfile:
    """A simulated detector: global settings and one :class:`ClassProfile` per detection class."""

    name: str
    description: str
    reference: dict
    detection_range_m: float
    score_threshold: float
    max_boxes_per_sample: int
    classes: dict[str, ClassProfile]
    path: str = ""


def available_profiles() -> list[str]:
    """Names of the profiles shipped in ``grutrack/configs/detector_profiles``."""
    from grutrack.config_loader import shipped_names

    return shipped_names("detector_profile")


def load_profile(name_or_path: str | os.PathLike) -> DetectorProfile:
    """Load a profile by shipped name (``centerpoint``) or YAML path, checked against
    ``grutrack/configs/schemas/detector_profile.schema.yaml`` by the one config loader (a misspelt key is an
    error naming it, with the closest allowed key)."""
    from grutrack.config_loader import read_config, validate

    raw, source = read_config("detector_profile", name_or_path)
    for key in ("defaults", "classes"):  # an empty YAML section reads as None
        if raw.get(key) is None and key in raw:
            raw[key] = {}
    if isinstance(raw.get("classes"), dict):
        raw["classes"] = {c: ({} if v is None else v) for c, v in raw["classes"].items()}
    validate("detector_profile", raw, source)
    return _parse_profile(raw, source)


def _parse_profile(raw: dict, path: str) -> DetectorProfile:
    """Build the dataclasses of a schema-checked profile."""
    defaults = raw.get("defaults") or {}
    classes = {name: _class_profile({**defaults, **values}, path, name) for name, values in raw["classes"].items()}
    return DetectorProfile(
        name=str(raw["name"]),
        description=str(raw.get("description", "")),
        reference=dict(raw.get("reference") or {}),
        detection_range_m=float(raw["detection_range_m"]),
        score_threshold=float(raw["score_threshold"]),
        max_boxes_per_sample=int(raw["max_boxes_per_sample"]),
        classes=classes,
        path=path,
    )


def _class_profile(values: dict, path: str, name: str) -> ClassProfile:
    """One ClassProfile; checks what the schema cannot: no class confused with itself, confusions sum <= 1."""
    conv = {
        k: (
            {str(c): float(p) for c, p in (v or {}).items()}
            if k == "confusion"
            else tuple(float(x) for x in v)
            if k == "mean_size"
            else float(v)
        )
        for k, v in values.items()
    }
    prof = ClassProfile(**conv)
    if name in prof.confusion:
        raise ConfigError(f"{path}: classes.{name}.confusion has '{name}', expected another detection class")
    if sum(prof.confusion.values()) > 1.0:
        raise ConfigError(f"{path}: classes.{name}.confusion probabilities sum to more than 1")
    return prof


# ----------------------------------------------------------------------------------------------------------------
# the format-free core
# ----------------------------------------------------------------------------------------------------------------


class _Tables:
    """Per-class profile values as arrays indexed by detection class index (vectorised lookups)."""

    def __init__(self, profile: DetectorProfile):
        for key in CLASS_KEYS:
            if key in ("confusion", "mean_size"):
                continue
            setattr(self, key, np.array([getattr(profile.classes[c], key) for c in DETECTION_CLASSES]))
        self.mean_size = np.array([profile.classes[c].mean_size for c in DETECTION_CLASSES])
        conf = np.zeros((len(DETECTION_CLASSES), len(DETECTION_CLASSES)))
        for i, c in enumerate(DETECTION_CLASSES):
            for other, prob in profile.classes[c].confusion.items():
                conf[i, DET_INDEX[other]] = prob
            conf[i, i] = 1.0 - conf[i].sum()
        self.confusion_cdf = np.cumsum(conf, axis=1)
        off = conf.copy()
        np.fill_diagonal(off, 0.0)
        rows = off.sum(axis=1, keepdims=True)
        self.other_cdf = np.cumsum(np.where(rows > 0, off / np.where(rows > 0, rows, 1.0), np.eye(len(conf))), axis=1)
        free = self.free_fp_per_frame
        self.free_total = float(free.sum())
        self.free_cdf = np.cumsum(free / self.free_total) if self.free_total > 0 else None


def frame_rng(seed: int, profile_name: str, token: str) -> np.random.Generator:
    """The random stream of one frame: a function of (seed, profile name, frame token) only."""
    digest = hashlib.md5(f"{profile_name}|{token}".encode()).digest()
    words = [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]
    return np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, *words]))


def object_uniforms(seed: int, profile_name: str, instance_ids) -> np.ndarray:
    """(N, 2) uniforms in [0, 1) fixed per object over its life: a function of (seed, profile name, instance id)
    only (no draw from a frame's stream, so profiles without per-object effects simulate as before)."""
    out = np.empty((len(instance_ids), 2))
    for i, inst in enumerate(instance_ids):
        d = hashlib.md5(f"{int(seed)}|{profile_name}|{inst}".encode()).digest()
        out[i] = int.from_bytes(d[:8], "little") / 2.0**64, int.from_bytes(d[8:], "little") / 2.0**64
    return out


#: cosine features per axis of :func:`centre_drift`
DRIFT_FEATURES = 16


@functools.lru_cache(maxsize=1 << 14)
def _drift_features(seed: int, profile_name: str, instance) -> tuple[np.ndarray, np.ndarray]:
    """One object's drift features: (2, DRIFT_FEATURES) standard Cauchy frequencies and (2, DRIFT_FEATURES)
    phases in [0, 2 pi), a function of (seed, profile name, instance id) only (cached: an object appears in
    many frames)."""
    d = hashlib.md5(f"{int(seed)}|{profile_name}|drift|{instance}".encode()).digest()
    rng = np.random.default_rng(
        np.random.SeedSequence([int.from_bytes(d[i : i + 4], "little") for i in range(0, 16, 4)])
    )
    omega = np.tan(np.pi * (rng.random((2, DRIFT_FEATURES)) - 0.5))
    return omega, rng.uniform(0.0, 2.0 * np.pi, (2, DRIFT_FEATURES))


def centre_drift(
    seed: int, profile_name: str, instance_ids, t_s: float, sigma: np.ndarray, tau: np.ndarray
) -> np.ndarray:
    """The slowly drifting centre error ``(K, 2)`` metres (x, y, global frame) of K objects at time ``t_s``
    (seconds): per axis ``e(t) = sigma sqrt(2/J) sum_j cos(w_j t / tau + phi_j)`` with J = DRIFT_FEATURES,
    ``w_j`` standard Cauchy and ``phi_j`` uniform, drawn once per object (:func:`_drift_features`).

    Random Fourier features of the exponential kernel (its spectral density is the Cauchy one): over objects the
    error has variance ``sigma^2`` and autocorrelation ``exp(-|dt| / tau)``, a stationary Gauss-Markov process
    like an AR(1) sequence, but a function of (seed, profile, instance id, time) alone, so a frame simulates the
    same whichever other frames are simulated with it. sigma, tau: (K,) metres, seconds (tau > 0)."""
    feats = [_drift_features(seed, profile_name, inst) for inst in instance_ids]
    if not feats:
        return np.zeros((0, 2))
    omega = np.stack([f[0] for f in feats])  # (K, 2, J)
    phase = np.stack([f[1] for f in feats])
    arg = omega * (float(t_s) / np.asarray(tau, np.float64))[:, None, None] + phase
    return np.asarray(sigma, np.float64)[:, None] * np.sqrt(2.0 / DRIFT_FEATURES) * np.cos(arg).sum(axis=2)


def _under_reported_velocity(boxes: np.ndarray, cls: np.ndarray, u: np.ndarray, tab: _Tables) -> np.ndarray:
    """Boxes (K, 9) whose objects fail (``u[:, 0] < vel_track_fail_prob``) with their velocity scaled by
    ``u[:, 1] * vel_track_fail_scale`` (the same factor in every frame of the object): a detector that
    persistently reports a moving object as nearly static."""
    fail = u[:, 0] < tab.vel_track_fail_prob[cls]
    out = boxes.copy()
    out[fail, VX : VY + 1] *= (u[fail, 1] * tab.vel_track_fail_scale[cls[fail]])[:, None]
    return out


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-x))


def _sample_cdf(cdf_rows: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Index drawn from each row of a (K, C) cumulative distribution with uniforms u (K,)."""
    return np.minimum((u[:, None] > cdf_rows).sum(axis=1), cdf_rows.shape[1] - 1)


def detection_probability(
    cls: np.ndarray, dist: np.ndarray, pts: np.ndarray, tab: _Tables, det_range: float
) -> np.ndarray:
    """Probability that each GT box is detected.

    cls: (N,) detection class index; dist: (N,) metres from the ego (xy); pts: (N,) lidar points.
    Returns (N,) in [0, 1]: logistic in ln(points), linear loss with distance, 0 beyond ``det_range``.
    """
    logpts = np.log(np.maximum(pts, 1))
    p = tab.recall_max[cls] * _sigmoid(tab.points_slope[cls] * (logpts - np.log(tab.points_half[cls])))
    p = np.where(pts > 0, p, tab.recall_zero_points[cls])
    p = p * np.clip(1.0 - tab.recall_drop_per_10m[cls] * dist / 10.0, 0.0, 1.0)
    return np.where(dist <= det_range, p, 0.0)


def _noisy_boxes(
    boxes: np.ndarray, cls: np.ndarray, dist: np.ndarray, tab: _Tables, rng: np.random.Generator
) -> np.ndarray:
    """Detected versions of GT boxes (K, 9): centre, size, yaw and velocity noise, heavy tails, yaw flips."""
    k = len(boxes)
    out = boxes.copy()
    sigma = tab.pos_sigma_m[cls] + tab.pos_sigma_per_m[cls] * dist
    err = rng.normal(size=(k, 2)) * sigma[:, None]
    tail = rng.random(k) < tab.pos_tail_prob[cls]
    err += np.where(tail[:, None], rng.laplace(size=(k, 2)) * tab.pos_tail_scale_m[cls][:, None], 0.0)
    out[:, 0:2] += err
    out[:, 2] += rng.normal(size=k) * tab.z_sigma_m[cls]
    out[:, W : H + 1] *= np.exp(rng.normal(size=(k, 3)) * tab.size_sigma_rel[cls][:, None])
    flip = rng.random(k) < tab.yaw_flip_prob[cls]
    out[:, YAW] = wrap_angle(out[:, YAW] + rng.normal(size=k) * tab.yaw_sigma_rad[cls] + np.pi * flip)
    speed = np.hypot(boxes[:, VX], boxes[:, VY])
    vsig = tab.vel_sigma_mps[cls] + tab.vel_sigma_rel[cls] * speed
    verr = rng.normal(size=(k, 2)) * vsig[:, None]
    vtail = rng.random(k) < tab.vel_tail_prob[cls]
    verr += np.where(vtail[:, None], rng.laplace(size=(k, 2)) * tab.vel_tail_scale_mps[cls][:, None], 0.0)
    out[:, VX : VY + 1] += verr
    return out


def _tp_scores(cls: np.ndarray, pts: np.ndarray, tab: _Tables, rng: np.random.Generator) -> np.ndarray:
    """Score logits (K,) of true positives: rising with ln(1 + lidar points), Gaussian noise."""
    return (
        tab.score_logit_base[cls]
        + tab.score_logit_per_log_pts[cls] * np.log1p(pts)
        + rng.normal(size=len(cls)) * tab.score_logit_sigma[cls]
    )


def _fp_scores(cls: np.ndarray, tab: _Tables, rng: np.random.Generator) -> np.ndarray:
    """Score logits (K,) of false positives."""
    return tab.fp_score_logit_mean[cls] + rng.normal(size=len(cls)) * tab.fp_score_logit_sigma[cls]


def _near_fps(gt: GTFrame, cls: np.ndarray, tab: _Tables, rng: np.random.Generator):
    """False positives 1.5-5 m from GT objects: boxes (K, 9), class index (K,), logits (K,)."""
    counts = rng.poisson(tab.near_fp_rate[cls])
    src = np.repeat(np.arange(len(cls)), counts)
    k = len(src)
    boxes = gt.boxes[src].copy()
    ang, rad = rng.uniform(-np.pi, np.pi, k), rng.uniform(1.5, 5.0, k)
    boxes[:, 0] += rad * np.cos(ang)
    boxes[:, 1] += rad * np.sin(ang)
    boxes[:, W : H + 1] *= np.exp(rng.normal(size=(k, 3)) * 0.15)
    boxes[:, YAW] = wrap_angle(boxes[:, YAW] + rng.normal(size=k) * 0.5)
    boxes[:, VX : VY + 1] += rng.normal(size=(k, 2)) * 0.5
    fcls = _sample_cdf(tab.confusion_cdf[cls[src]], rng.random(k))
    return boxes, fcls, _fp_scores(fcls, tab, rng)


def _free_fps(ego: np.ndarray, det_range: float, tab: _Tables, rng: np.random.Generator):
    """False positives anywhere within range: boxes (K, 9), class index (K,), logits (K,)."""
    k = rng.poisson(tab.free_total) if tab.free_total > 0 else 0
    cls = np.searchsorted(tab.free_cdf, rng.random(k), side="right").clip(0, len(DETECTION_CLASSES) - 1)
    rad, ang = det_range * np.sqrt(rng.random(k)), rng.uniform(-np.pi, np.pi, k)
    boxes = np.zeros((k, BOX_DIM))
    boxes[:, 0] = ego[0] + rad * np.cos(ang)
    boxes[:, 1] = ego[1] + rad * np.sin(ang)
    size = tab.mean_size[cls] * np.exp(rng.normal(size=(k, 3)) * 0.15)
    boxes[:, W : H + 1] = size
    boxes[:, 2] = ego[2] + size[:, 2] / 2.0 + rng.normal(size=k) * 0.3
    boxes[:, YAW] = rng.uniform(-np.pi, np.pi, k)
    boxes[:, VX : VY + 1] = rng.normal(size=(k, 2)) * 0.3
    return boxes, cls, _fp_scores(cls, tab, rng)


def simulate_frame(
    gt: GTFrame, profile: DetectorProfile, rng: np.random.Generator, tables: _Tables | None = None, seed: int = 0
) -> DetFrame:
    """Detections of one frame sampled from its ground truth.

    gt: canonical GT arrays; profile: the simulated detector; rng: this frame's stream (:func:`frame_rng`);
    seed: the run's seed, for effects fixed per object over its life (:func:`object_uniforms`,
    :func:`centre_drift`).
    Returns boxes (M, 9), scores (M,) and names (M,), sorted by decreasing score, at most
    ``max_boxes_per_sample``, all with score >= ``score_threshold``. ``tables`` caches the profile's arrays.
    """
    tab = tables if tables is not None else _Tables(profile)
    cls = np.array([DET_INDEX[n] for n in gt.names], dtype=np.int64)
    pts = np.asarray(gt.num_lidar_pts, dtype=np.float64)
    dist = np.hypot(gt.boxes[:, 0] - gt.ego_translation[0], gt.boxes[:, 1] - gt.ego_translation[1])
    hit = rng.random(len(cls)) < detection_probability(cls, dist, pts, tab, profile.detection_range_m)
    idx = np.flatnonzero(hit)
    tp_boxes = _noisy_boxes(gt.boxes[idx], cls[idx], dist[idx], tab, rng)
    if tab.vel_track_fail_prob[cls[idx]].any():
        u = object_uniforms(seed, profile.name, np.asarray(gt.instance_ids, dtype=object)[idx])
        tp_boxes = _under_reported_velocity(tp_boxes, cls[idx], u, tab)
    if tab.pos_drift_sigma_m[cls[idx]].any():
        tp_boxes[:, 0:2] += centre_drift(
            seed,
            profile.name,
            np.asarray(gt.instance_ids, dtype=object)[idx],
            gt.timestamp * 1e-6,
            tab.pos_drift_sigma_m[cls[idx]],
            tab.pos_drift_time_s[cls[idx]],
        )
    tp_cls = _sample_cdf(tab.confusion_cdf[cls[idx]], rng.random(len(idx)))
    tp_logit = _tp_scores(cls[idx], pts[idx], tab, rng) - tab.confusion_logit_penalty[cls[idx]] * (tp_cls != cls[idx])

    dup = rng.random(len(idx)) < tab.duplicate_prob[cls[idx]]
    d_boxes = tp_boxes[dup].copy()
    d_src = cls[idx][dup]
    d_boxes[:, 0:2] += rng.normal(size=(len(d_boxes), 2)) * tab.duplicate_offset_m[d_src][:, None]
    d_boxes[:, YAW] = wrap_angle(d_boxes[:, YAW] + rng.normal(size=len(d_boxes)) * 0.1)
    other = rng.random(len(d_boxes)) < tab.duplicate_other_class_prob[d_src]
    d_cls = np.where(other, _sample_cdf(tab.other_cdf[d_src], rng.random(len(d_boxes))), tp_cls[dup])
    d_logit = tp_logit[dup] - rng.uniform(0.5, 3.0, len(d_boxes))

    n_boxes, n_cls, n_logit = _near_fps(gt, cls, tab, rng)
    f_boxes, f_cls, f_logit = _free_fps(
        np.asarray(gt.ego_translation, dtype=np.float64), profile.detection_range_m, tab, rng
    )
    boxes = np.concatenate([tp_boxes, d_boxes, n_boxes, f_boxes])
    labels = np.concatenate([tp_cls, d_cls, n_cls, f_cls]).astype(np.int64)
    scores = _sigmoid(np.concatenate([tp_logit, d_logit, n_logit, f_logit]))
    is_tp = np.concatenate([np.ones(len(tp_boxes), bool), np.zeros(len(boxes) - len(tp_boxes), bool)])
    ego = np.asarray(gt.ego_translation, dtype=np.float64)
    in_range = np.hypot(boxes[:, 0] - ego[0], boxes[:, 1] - ego[1]) <= profile.detection_range_m
    order = np.argsort(-scores, kind="stable")
    order = order[(scores[order] >= profile.score_threshold) & in_range[order]][: profile.max_boxes_per_sample]
    names = np.asarray(DETECTION_CLASSES, dtype=object)[labels[order]]
    return DetFrame(gt.token, boxes[order], scores[order], names, is_tp[order])


def simulate(frames: Iterable[GTFrame], profile: DetectorProfile, seed: int) -> list[DetFrame]:
    """Simulate every frame with its own stream (see :func:`frame_rng`)."""
    tab = _Tables(profile)
    return [simulate_frame(f, profile, frame_rng(seed, profile.name, f.token), tab, seed) for f in frames]


# ----------------------------------------------------------------------------------------------------------------
# any dataset: canonical scenes in, canonical detections out
# ----------------------------------------------------------------------------------------------------------------


def scene_gt_frames(scenes: Iterable, sim_class: tuple[str, ...]) -> list[GTFrame]:
    """GT frames of canonical scenes with ground truth (any dataset). ``sim_class[label]``: the detection
    class (:data:`DETECTION_CLASSES`) whose profile statistics a box of that label is simulated with; lidar
    points from ``gt.extra['num_lidar_pts']`` (else ``num_pts``; 0 where the dataset has none), radar points
    from ``num_radar_pts`` (0 where none)."""
    to_sim = np.asarray(sim_class, dtype=object)
    frames = []
    for s in scenes:
        for f in s.frames:
            gt = f.gt
            none = np.zeros(len(gt), np.int64)
            lidar = gt.extra.get("num_lidar_pts", gt.extra.get("num_pts", none))
            frames.append(
                GTFrame(
                    token=f.token,
                    scene=s.name,
                    timestamp=f.timestamp,
                    ego_translation=f.ego_translation,
                    boxes=gt.boxes,
                    names=to_sim[gt.labels],
                    num_lidar_pts=np.asarray(lidar, np.int64),
                    num_radar_pts=np.asarray(gt.extra.get("num_radar_pts", none), np.int64),
                    instance_ids=gt.ids if gt.ids is not None else np.arange(len(gt)).astype(object),
                )
            )
    return frames


def simulate_scenes(scenes: list, sim_class: tuple[str, ...], profile: DetectorProfile, seed: int) -> dict:
    """SYNTHETIC detections of every frame of ``scenes`` as canonical box sets ``{frame token: BoxSet}``
    (global / city frame) whose labels index the scenes' vocabulary. ``sim_class`` maps each label to a
    distinct detection class, so a simulated box's class maps back to exactly one label; boxes the simulator
    gives a class no label maps to (class confusion, ghosts of other classes) are dropped."""
    if len(set(sim_class)) != len(sim_class) or not set(sim_class) <= set(DETECTION_CLASSES):
        raise ConfigError(
            f"simulator classes {sim_class} must be distinct detection classes ({', '.join(DETECTION_CLASSES)})"
        )
    back = {c: i for i, c in enumerate(sim_class)}
    out = {}
    for det in simulate(scene_gt_frames(scenes, sim_class), profile, seed):
        lab = np.array([back.get(n, -1) for n in det.names], dtype=np.int64)
        keep = lab >= 0
        out[det.token] = BoxSet(det.boxes[keep], det.scores[keep], lab[keep])
    return out


# ----------------------------------------------------------------------------------------------------------------
# the nuScenes edge: GT in, detection-submission JSON out
# ----------------------------------------------------------------------------------------------------------------


def open_dataset(dataroot: str | os.PathLike, version: str):
    """``NuScenes(version, dataroot)`` quietly; :class:`grutrack.errors.DatasetError` when the folder or version
    is missing (shared with the nuScenes adapter)."""
    from grutrack.data.nuscenes import open_nuscenes

    return open_nuscenes(dataroot, version)


def nusc_gt_frames(nusc, split: str) -> list[GTFrame]:
    """Canonical GT frames of every sample of ``split``, scene by scene in time order: the annotations of the
    10 detection classes (devkit class mapping), as :func:`grutrack.data.nuscenes.load_scenes` reads them
    (velocity from the devkit's ``box_velocity`` with NaN set to 0)."""
    from grutrack.data.nuscenes import DETECTION_VOCABULARY, load_scenes

    scenes = load_scenes(nusc, split, with_gt=True, vocabulary=DETECTION_VOCABULARY)
    return scene_gt_frames(scenes, DETECTION_VOCABULARY.names)


def attribute_names(names: np.ndarray, boxes: np.ndarray) -> list[str]:
    """nuScenes attribute of each detection (M,) from its class and speed: moving/parked, moving/standing,
    with/without rider, '' for barrier and traffic_cone."""
    moving = np.hypot(boxes[:, VX], boxes[:, VY]) > MOVING_SPEED
    out = []
    for name, mov in zip(names, moving):
        if name in _VEHICLES:
            out.append("vehicle.moving" if mov else "vehicle.parked")
        elif name == "pedestrian":
            out.append("pedestrian.moving" if mov else "pedestrian.standing")
        elif name in _CYCLES:
            out.append("cycle.with_rider" if mov else "cycle.without_rider")
        else:
            out.append("")
    return out


def _frame_records(det: DetFrame) -> list[dict]:
    """Official detection-submission box dicts of one frame."""
    if len(det) == 0:
        return []
    b = det.boxes
    trans = np.round(b[:, 0:3], 4).tolist()
    size = np.round(b[:, W : H + 1], 4).tolist()
    rot = np.round(quaternion_from_yaw(b[:, YAW]), 8).tolist()
    vel = np.round(b[:, VX : VY + 1], 4).tolist()
    score = np.round(det.scores, 6).tolist()
    attrs = attribute_names(det.names, b)
    return [
        {
            "sample_token": det.token,
            "translation": trans[i],
            "size": size[i],
            "rotation": rot[i],
            "velocity": vel[i],
            "detection_name": str(det.names[i]),
            "detection_score": score[i],
            "attribute_name": attrs[i],
        }
        for i in range(len(det))
    ]


def detection_json(dets: list[DetFrame], profile: DetectorProfile, seed: int) -> dict:
    """The official nuScenes detection-submission object; a top-level ``synthetic`` entry says how it was made.
    Its meta is lidar-only with no map and no external data (:data:`~grutrack.data.nusc_detections.LIDAR_META`):
    the profiles describe lidar detectors, and tracks made from the file declare the same meta."""
    return {
        "meta": dict(LIDAR_META),
        "results": {d.token: _frame_records(d) for d in dets},
        "synthetic": {
            "generator": "grutrack simulate-detections",
            "profile": profile.name,
            "seed": int(seed),
            "note": "SYNTHETIC detections sampled from ground truth by a detector simulator; "
            "not the output of a real detector",
        },
    }


def simulate_nuscenes(
    dataroot: str | os.PathLike,
    version: str,
    split: str,
    profile: str | DetectorProfile,
    seed: int,
    out: str | os.PathLike | None = None,
    nusc=None,
) -> dict:
    """Simulate detections for every sample of a nuScenes(-format) split; write them atomically to ``out``.

    Returns the detection-submission object. ``nusc`` may be passed to reuse a loaded database.
    """
    prof = profile if isinstance(profile, DetectorProfile) else load_profile(profile)
    nusc = nusc if nusc is not None else open_dataset(dataroot, version)
    frames = nusc_gt_frames(nusc, split)
    sub = detection_json(simulate(frames, prof, seed), prof, seed)
    if out is not None:
        write_detection_json(out, sub)
    return sub


def write_detection_json(path: str | os.PathLike, sub: dict) -> None:
    """Write a detection-submission object atomically (compact JSON)."""
    text = json.dumps(sub, separators=(",", ":"))  # dumps uses the C encoder, dump does not
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text)
