"""The embedded default: a SYNTHETIC dataset in nuScenes table format, generated from a seed.

``generate_demo(out)`` writes ``out/<version>/*.json`` (the 13 tables nuscenes-devkit reads), a custom
``out/<version>/splits.json`` (``demo_train``, ``demo_val``, ``demo_all``), a placeholder map PNG and a README,
so that ``NuScenes('v1.0-demo', dataroot=out)`` and the official detection / tracking evaluators run on it.

The world: an ego vehicle drives for 20 s (40 keyframes at 2 Hz) along a road; around it are parked and moving
vehicles, pedestrians, cyclists, barriers and traffic cones. Motion is simulated at 10 Hz with controls that
make it genuinely nonlinear: turns whose yaw rate rises and falls, lane changes, speed changes, braking to a
stop and starting again, pedestrians that stop and turn around, cyclists that steer. Objects enter and leave
the ego's range; lidar point counts fall with distance and drop to 0 while an object is occluded.

Each class's parameter carries, in a comment, the nuScenes statistic it imitates. "mini" means nuScenes
v1.0-mini (mini_train + mini_val), computed with ``grutrack dataset-stats`` on ../shared/data. The
``points_fit`` values are least-squares fits ln(num_lidar_pts) = a + b ln(distance) over the boxes with points:
on mini_val (exact counts), except barrier, trailer and construction vehicle, which mini_val lacks (fitted on
mini_train, whose counts are approximate).

Output is byte-identical for a seed: every random draw comes from a stream seeded by (seed, scene index),
tokens are hashes of (seed, version, names), and floats are rounded before they are written.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import lfilter
from scipy.spatial import cKDTree

from grutrack.data.demo_defaults import DEFAULT_SCENES, FRAMES_PER_SCENE, MARKER, VERSION
from grutrack.errors import ConfigError

DT = 0.5  # s between keyframes: nuScenes keyframes are at 2 Hz (mini: 0.40-0.60 s, mean 0.50)
SUBSTEPS = 5  # motion integrated at 10 Hz, fine enough for manoeuvres seen at 2 Hz
VAL_EVERY = 5  # every 5th scene is demo_val: 80/20 like nuScenes train/val (700/150); with fewer
# than 5 scenes the last one is demo_val (1 scene: demo_val is empty)
TIME_ORIGIN_US = 1_533_000_000_000_000  # 2018-07-31, the nuScenes recording period (2018-07 .. 2018-11)
LIDAR_TRANSLATION = [0.943713, 0.0, 1.84023]  # nuScenes n015 LIDAR_TOP extrinsics (mini calibrated_sensor)
LIDAR_ROTATION = [0.7071067812, 0.0, 0.0, -0.7071067812]  # LIDAR_TOP is yawed -90 deg on nuScenes cars

#: the 23 nuScenes categories (v1.0 category.json), so the devkit's class mappings apply unchanged
CATEGORIES = (
    "animal",
    "human.pedestrian.adult",
    "human.pedestrian.child",
    "human.pedestrian.construction_worker",
    "human.pedestrian.personal_mobility",
    "human.pedestrian.police_officer",
    "human.pedestrian.stroller",
    "human.pedestrian.wheelchair",
    "movable_object.barrier",
    "movable_object.debris",
    "movable_object.pushable_pullable",
    "movable_object.trafficcone",
    "static_object.bicycle_rack",
    "vehicle.bicycle",
    "vehicle.bus.bendy",
    "vehicle.bus.rigid",
    "vehicle.car",
    "vehicle.construction",
    "vehicle.emergency.ambulance",
    "vehicle.emergency.police",
    "vehicle.motorcycle",
    "vehicle.trailer",
    "vehicle.truck",
)
ATTRIBUTES = (
    "vehicle.moving",
    "vehicle.stopped",
    "vehicle.parked",
    "cycle.with_rider",
    "cycle.without_rider",
    "pedestrian.sitting_lying_down",
    "pedestrian.standing",
    "pedestrian.moving",
)
VISIBILITY = (("1", "v0-40"), ("2", "v40-60"), ("3", "v60-80"), ("4", "v80-100"))  # nuScenes visibility.json


# Road layout across the ego path (metres, left positive): the ego lane (centre 0), one more lane in the ego's
# direction (+3.5) and two oncoming lanes (-3.5, -7.0), 3.5 m wide (a common urban lane width); kerbs at
# +5.25 and -8.75. Static objects are placed at an offset beyond a kerb.
ROAD_LEFT, ROAD_RIGHT = 5.25, -8.75
# (offset, heading, share of moving vehicles, lane-change step to the neighbouring lane of the same direction)
LANES = ((0.0, 0.0, 0.15, 3.5), (3.5, 0.0, 0.3, -3.5), (-3.5, np.pi, 0.3, -3.5), (-7.0, np.pi, 0.25, 3.5))


@dataclass(frozen=True)
class ClassSpec:
    """How one detection class is generated (sizes in metres, speeds in m/s, densities per 100 m of road)."""

    categories: tuple  # ((nuScenes category, probability), ...)
    size: tuple  # mean (w, l, h)
    size_logsd: tuple  # per-instance log-normal spread of (w, l, h)
    static_per_100m: float  # parked / standing objects per 100 m of road (both sides)
    moving_per_100m: float  # moving objects per 100 m of (extended) road
    motion: str = "static"  # "vehicle", "cycle" or "pedestrian" for the moving ones
    speed: tuple = (0.0, 0.0)  # cruise speed mean, sd of the moving ones
    kerb_offset: tuple = (1.0, 3.0)  # static ones: distance range beyond the kerb
    lot_share: float = 0.0  # static vehicles: share parked in lots 8-30 m off the kerb, side by side
    cluster: int = 1  # static objects come in rows / groups of up to this many
    points_fit: tuple = (10.0, -2.5, 0.8)  # ln(lidar pts) = a + b ln(d), residual sd
    annot_range: float = 70.0  # annotated up to this distance from the ego
    occlusion: float = 0.05  # per-keyframe probability of becoming occluded at 20 m (grows with d)


# fmt: off
CLASS_SPECS: dict[str, ClassSpec] = {
    # car: 52.7 % of tracking-class boxes and 18.9 boxes per keyframe in mini (7619 / 14467; 404 keyframes);
    # 27.5 % of car boxes moving, mean moving speed 8.9 m/s; mean size (1.95, 4.61, 1.70), per-instance log-sd
    # (0.09, 0.07, 0.11); mean distance to the ego 36 m (mini).
    "car": ClassSpec(categories=(("vehicle.car", 1.0),), size=(1.95, 4.61, 1.70), size_logsd=(0.09, 0.07, 0.11),
                     static_per_100m=15.0, moving_per_100m=8.0, motion="vehicle", speed=(10.0, 3.0),
                     kerb_offset=(1.1, 2.0), lot_share=0.3, cluster=6, points_fit=(11.56, -2.84, 0.91),
                     annot_range=75.0, occlusion=0.035),
    # pedestrian: 34.7 % of boxes, 12.4 per keyframe (mini); 72 % of them moving, at 1.26 m/s mean; adult 95 %,
    # construction worker 3.8 %, child 0.9 %, police 0.2 % (mini category counts 4765 / 193 / 46 / 11);
    # size (0.68, 0.73, 1.76); mean distance 28 m (mini).
    "pedestrian": ClassSpec(categories=(("human.pedestrian.adult", 0.951), ("human.pedestrian.construction_worker",
                                         0.038), ("human.pedestrian.child", 0.009),
                                        ("human.pedestrian.police_officer", 0.002)),
                            size=(0.68, 0.73, 1.76), size_logsd=(0.15, 0.2, 0.07), static_per_100m=3.5,
                            moving_per_100m=11.0, motion="pedestrian", speed=(1.3, 0.25), kerb_offset=(2.5, 8.0),
                            cluster=3, points_fit=(7.00, -1.73, 0.61), annot_range=60.0, occlusion=0.012),
    # truck: 4.5 % of boxes, 1.6 per keyframe (mini; ~10 % in trainval), 24.5 % moving at 6.5 m/s;
    # size (2.35, 6.50, 2.62).
    "truck": ClassSpec(categories=(("vehicle.truck", 1.0),), size=(2.35, 6.50, 2.62), size_logsd=(0.12, 0.2, 0.2),
                       static_per_100m=1.8, moving_per_100m=1.5, motion="vehicle", speed=(7.0, 2.0),
                       kerb_offset=(1.3, 3.0), lot_share=0.3, cluster=2, points_fit=(12.75, -2.70, 0.78),
                       annot_range=80.0, occlusion=0.04),
    # bus: 2.8 % of boxes, 1.0 per keyframe, 53 % moving at 5.6 m/s (mini); rigid 86 %, bendy 14 %
    # (mini 353 / 57 boxes); size (2.94, 11.15, 3.74); seen from further away (mean distance 51 m, mini).
    "bus": ClassSpec(categories=(("vehicle.bus.rigid", 0.86), ("vehicle.bus.bendy", 0.14)),
                     size=(2.94, 11.15, 3.74), size_logsd=(0.05, 0.12, 0.08), static_per_100m=1.2,
                     moving_per_100m=2.5, motion="vehicle", speed=(6.5, 2.0), kerb_offset=(1.5, 3.0),
                     points_fit=(13.12, -2.48, 0.31), annot_range=90.0, occlusion=0.02),
    # trailer: 0.4 % of boxes, 0.15 per keyframe, parked (0 % moving in mini); size (2.28, 10.14, 3.71).
    "trailer": ClassSpec(categories=(("vehicle.trailer", 1.0),), size=(2.5, 10.1, 3.7), size_logsd=(0.06, 0.2, 0.08),
                         static_per_100m=0.25, moving_per_100m=0.0, kerb_offset=(1.5, 15.0),
                         points_fit=(14.93, -3.35, 0.5), annot_range=80.0, occlusion=0.02),
    # motorcycle: 3.3 % of boxes, 1.2 per keyframe, 28 % moving at 6.4 m/s; size (0.68, 1.95, 1.47) (mini).
    "motorcycle": ClassSpec(categories=(("vehicle.motorcycle", 1.0),), size=(0.72, 2.0, 1.48),
                            size_logsd=(0.2, 0.12, 0.12), static_per_100m=1.2, moving_per_100m=0.6,
                            motion="cycle", speed=(6.4, 2.0), kerb_offset=(1.0, 4.0), cluster=4,
                            points_fit=(8.48, -2.21, 0.82), annot_range=65.0, occlusion=0.025),
    # bicycle: 1.7 % of boxes, 0.6 per keyframe, 28 % moving at 4.3 m/s; size (0.64, 1.82, 1.39) (mini).
    "bicycle": ClassSpec(categories=(("vehicle.bicycle", 1.0),), size=(0.62, 1.80, 1.35), size_logsd=(0.15, 0.08, 0.15),
                         static_per_100m=0.55, moving_per_100m=0.45, motion="cycle", speed=(4.3, 1.0),
                         kerb_offset=(3.0, 6.0), cluster=4, points_fit=(6.97, -1.67, 0.81), annot_range=60.0,
                         occlusion=0.05),
    # detection-only classes, static: barrier 5.75, traffic cone 3.41, construction vehicle 0.49 boxes per
    # keyframe in mini; sizes (2.22, 0.62, 1.08), (0.46, 0.45, 0.80), (2.66, 5.54, 2.43) (mini).
    "barrier": ClassSpec(categories=(("movable_object.barrier", 1.0),), size=(2.22, 0.62, 1.08),
                         size_logsd=(0.15, 0.15, 0.1), static_per_100m=10.0, moving_per_100m=0.0,
                         kerb_offset=(0.3, 8.0), cluster=8, points_fit=(8.65, -2.03, 0.84), annot_range=60.0,
                         occlusion=0.08),
    "traffic_cone": ClassSpec(categories=(("movable_object.trafficcone", 1.0),), size=(0.46, 0.45, 0.80),
                              size_logsd=(0.15, 0.15, 0.15), static_per_100m=6.0, moving_per_100m=0.0,
                              kerb_offset=(0.2, 5.0), cluster=8, points_fit=(5.85, -1.92, 0.74), annot_range=50.0,
                              occlusion=0.08),
    "construction_vehicle": ClassSpec(categories=(("vehicle.construction", 1.0),), size=(2.66, 5.54, 2.43),
                                      size_logsd=(0.12, 0.2, 0.12), static_per_100m=0.6, moving_per_100m=0.0,
                                      kerb_offset=(3.0, 20.0), points_fit=(11.35, -2.40, 0.69), annot_range=70.0,
                                      occlusion=0.04),
}
# fmt: on


@dataclass(frozen=True)
class MotionSpec:
    """Manoeuvre statistics of a motion family (durations in s, angles in rad, speeds as factors)."""

    seg_duration: tuple  # manoeuvre segment duration range
    p_turn: float  # per-segment probability of a turn (heading change 60-90 deg; peds 45-180 deg)
    p_curve: float  # per-segment probability of a gentle curve (6-25 deg)
    p_lane_change: float  # per-segment probability of a lane change (vehicles and cycles)
    p_stop: float  # per-segment probability of braking to a stop (and waiting)
    speed_jitter: tuple  # per-segment cruise speed factor range
    tau: float  # speed response time constant (s): acceleration = (v_target - v) / tau
    accel_limits: tuple  # (max braking, max acceleration), m/s^2
    min_radius: float  # smallest turning radius, m
    wiggle: float  # std of the AR(1) curvature (1/m) or, for pedestrians, yaw-rate (rad/s) noise


MOTION_SPECS = {
    # Cars: urban manoeuvres every 2-6 s; braking up to 4 m/s^2 and accelerating up to 2.5 m/s^2 (typical urban
    # driving); minimum radius 5 m (a passenger car's turning circle).
    "vehicle": MotionSpec(
        seg_duration=(2.0, 6.0),
        p_turn=0.08,
        p_curve=0.12,
        p_lane_change=0.08,
        p_stop=0.08,
        speed_jitter=(0.75, 1.15),
        tau=1.5,
        accel_limits=(4.0, 2.5),
        min_radius=5.0,
        wiggle=0.001,
    ),
    # Cyclists (bicycle model with a steering wobble): tighter turns, more steering noise.
    "cycle": MotionSpec(
        seg_duration=(1.5, 5.0),
        p_turn=0.12,
        p_curve=0.25,
        p_lane_change=0.08,
        p_stop=0.06,
        speed_jitter=(0.7, 1.2),
        tau=1.2,
        accel_limits=(3.0, 1.5),
        min_radius=3.0,
        wiggle=0.01,
    ),
    # Pedestrians: walk / stop / turn around; mini pedestrians move in 72 % of boxes.
    "pedestrian": MotionSpec(
        seg_duration=(1.5, 5.0),
        p_turn=0.08,
        p_curve=0.2,
        p_lane_change=0.0,
        p_stop=0.08,
        speed_jitter=(0.8, 1.2),
        tau=0.5,
        accel_limits=(2.0, 1.5),
        min_radius=0.0,
        wiggle=0.03,
    ),
}

# Ego vehicle: mini ego mean speed 5.6 m/s over 10 scenes, 2 of them (almost) stationary; cruise 6-13 m/s.
EGO_SPEED_CHOICES = ((0.0, 0.15), (4.0, 0.3), (8.0, 0.4), (12.0, 0.15))  # (cruise speed, probability)
EGO_TURN_PROB = 0.35  # share of scenes with an intersection turn (mini descriptions: 5 of 10 mention turns)
ANNOT_NOISE_POS = 0.015  # m; nuScenes boxes are drawn per keyframe (centres on a mm grid, ~cm consistency)
ANNOT_NOISE_YAW = 0.003  # rad; keeps the |yaw rate| of parked cars well below mini's car mean of 0.013 rad/s


# ----------------------------------------------------------------------------------------------------------------
# motion
# ----------------------------------------------------------------------------------------------------------------


@dataclass
class Controls:
    """Controls of M agents over S substeps (dt = DT / SUBSTEPS), from :func:`manoeuvre_controls`.

    v_target: (M, S) m/s. curvature: (M, S) 1/m of turns, curves and lane changes (used when not following the
    road). wiggle: (M, S) 1/m steering noise, or yaw-rate noise rad/s for pedestrians. yaw_rate: (M, S) rad/s of
    pedestrian turns. lane_phase: (M, S) lane changes done so far (fractional while one is under way).
    free: (M, S) bool, True from the first turn on (the agent leaves the road it followed).
    """

    v_target: np.ndarray
    curvature: np.ndarray
    wiggle: np.ndarray
    yaw_rate: np.ndarray
    lane_phase: np.ndarray
    free: np.ndarray


@dataclass
class Agents:
    """Initial states, controls and road-following setup of M agents.

    x, y, yaw, v: (M,) initial state (m, rad, m/s). tau: (M,) s speed time constant. accel_limits: (M, 2)
    braking, acceleration m/s^2. min_radius: (M,) m. follow: (M,) bool, keeps to its lane of the road.
    lane: (M,) lateral lane offset (m, left +), lane_step: (M,) offset of a lane change, direction: (M,) +1 along
    the road, -1 against it, s: (M,) initial arc length on the road.
    """

    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    controls: Controls
    tau: np.ndarray
    accel_limits: np.ndarray
    min_radius: np.ndarray
    follow: np.ndarray
    lane: np.ndarray
    lane_step: np.ndarray
    direction: np.ndarray
    s: np.ndarray


def _ar1(rng: np.random.Generator, shape: tuple, sigma: float, corr_time: float, dt: float) -> np.ndarray:
    """Stationary AR(1) noise (M, S) with std ``sigma`` and correlation time ``corr_time`` seconds."""
    rho = float(np.exp(-dt / corr_time))
    eps = rng.normal(size=shape) * sigma * np.sqrt(1.0 - rho * rho)
    y_prev = rng.normal(size=(shape[0], 1)) * sigma
    return lfilter([1.0], [1.0, -rho], eps, axis=1, zi=rho * y_prev)[0]


def _segments(
    rng: np.random.Generator, spec: MotionSpec, m: int, n_steps: int, dt: float, forced_turn: np.ndarray | None
) -> dict[str, np.ndarray]:
    """Random manoeuvre segments of M agents: per-segment kinds and parameters (M, K), and for every substep
    the segment index ``seg`` (M, S) and the phase ``u`` in [0, 1] within it."""
    t = np.arange(n_steps) * dt
    horizon = n_steps * dt
    k_max = int(np.ceil(horizon / spec.seg_duration[0])) + 1
    dur = rng.uniform(*spec.seg_duration, size=(m, k_max))
    offset = rng.uniform(0, spec.seg_duration[0], (m, 1))
    draw = rng.random((m, k_max))
    c_turn, c_curve, c_lc, c_stop = np.cumsum([spec.p_turn, spec.p_curve, spec.p_lane_change, spec.p_stop])
    kinds = {
        "turn": draw < c_turn,
        "curve": (draw >= c_turn) & (draw < c_curve),
        "lc": (draw >= c_curve) & (draw < c_lc),
        "stop": (draw >= c_lc) & (draw < c_stop),
    }
    sign = rng.choice([-1.0, 1.0], size=(m, k_max))
    turn_range = (np.pi / 4, np.pi) if spec.min_radius == 0 else (np.pi / 3, np.pi / 2)
    dpsi = np.where(kinds["turn"], rng.uniform(*turn_range, (m, k_max)), 0.0)
    dpsi = dpsi + np.where(kinds["curve"], rng.uniform(0.1, 0.45, (m, k_max)), 0.0)
    start = np.concatenate([-offset, -offset + np.cumsum(dur[:, :-1], axis=1)], axis=1)
    if forced_turn is not None:
        rows = np.flatnonzero(forced_turn != 0)
        mid = np.clip((horizon / 2 >= start[rows]).sum(axis=1) - 1, 0, k_max - 1)
        for key in kinds:
            kinds[key][rows, mid] = key == "turn"
        dpsi[rows, mid], sign[rows, mid] = np.abs(forced_turn[rows]), np.sign(forced_turn[rows])
        dur[rows, mid] = np.maximum(dur[rows, mid], 5.0)
        start = np.concatenate([-offset, -offset + np.cumsum(dur[:, :-1], axis=1)], axis=1)
    seg = np.clip((t[None, :, None] >= start[:, None, :]).sum(axis=2) - 1, 0, k_max - 1)
    seg_dur = np.take_along_axis(dur, seg, 1)
    u = np.clip((t[None, :] - np.take_along_axis(start, seg, 1)) / seg_dur, 0.0, 1.0)
    return {"seg": seg, "u": u, "seg_dur": seg_dur, "psi": sign * dpsi, "sign": sign, **kinds}


def manoeuvre_controls(
    rng: np.random.Generator,
    kind: str,
    cruise: np.ndarray,
    n_steps: int,
    dt: float,
    forced_turn: np.ndarray | None = None,
) -> Controls:
    """Controls of M agents of one motion family ("vehicle", "cycle", "pedestrian") over n_steps substeps.

    cruise: (M,) cruise speed m/s. forced_turn: optional (M,) heading change (rad) made in the segment covering
    the middle of the scene (the ego's intersection turn); 0 = none. Turns and curves have a yaw rate that rises
    and falls (sin^2 profile); stops brake to 0 and wait for the segment's end.
    """
    spec = MOTION_SPECS[kind]
    m = len(cruise)
    sg = _segments(rng, spec, m, n_steps, dt, forced_turn)
    seg, u, seg_dur = sg["seg"], sg["u"], sg["seg_dur"]

    def per_step(x):
        return np.take_along_axis(x, seg, 1)

    speed_f = rng.uniform(*spec.speed_jitter, size=sg["turn"].shape)
    if kind != "pedestrian":
        speed_f = np.where(sg["turn"], speed_f * 0.6, speed_f)  # slow down for turns
    v_target = cruise[:, None] * per_step(np.where(sg["stop"], 0.0, speed_f))
    free = np.maximum.accumulate(per_step(sg["turn"]), axis=1)
    lc_done = np.concatenate([np.zeros((m, 1)), np.cumsum(sg["lc"], axis=1)[:, :-1]], axis=1)
    smooth = u * u * (3.0 - 2.0 * u)
    lane_phase = per_step(lc_done) + per_step(sg["lc"].astype(float)) * smooth
    zeros = np.zeros((m, n_steps))
    if kind == "pedestrian":
        turn_time = np.minimum(seg_dur, 2.0)  # pedestrians turn within 2 s
        tu = np.clip(u * seg_dur / turn_time, 0.0, 1.0)
        yaw_rate = per_step(sg["psi"]) * 2.0 / turn_time * np.sin(np.pi * tu) ** 2
        wiggle = _ar1(rng, (m, n_steps), spec.wiggle, 1.0, dt)
        return Controls(v_target, zeros, wiggle, yaw_rate, zeros, np.ones((m, n_steps), bool))
    v_plan = np.maximum(v_target, 1.0)
    curv = per_step(sg["psi"]) * 2.0 / (v_plan * seg_dur) * np.sin(np.pi * u) ** 2
    curv = curv + per_step(sg["lc"] * sg["sign"]) * 2.0 * np.pi * 3.5 / (v_plan * seg_dur) ** 2 * np.sin(2 * np.pi * u)
    wiggle = _ar1(rng, (m, n_steps), spec.wiggle, 1.0, dt)
    return Controls(v_target, curv, wiggle, zeros, lane_phase, free)


def _lane_shift(phase: np.ndarray) -> np.ndarray:
    """0 -> 1 -> 0 ... as lane changes complete (a triangle wave of the lane-change count)."""
    p = np.mod(phase, 2.0)
    return np.where(p <= 1.0, p, 2.0 - p)


def integrate(agents: Agents, dt: float, record_every: int, road: np.ndarray | None = None) -> np.ndarray:
    """Integrate the agents' kinematics (speed lag, curvature or yaw rate, midpoint rule).

    Agents with ``follow`` keep to their lane of ``road`` (pure pursuit on a point ``max(6, 1.2 v)`` metres
    ahead, with lane changes) until their first turn. Returns states (M, F, 4) ``[x, y, yaw, v]`` at every
    ``record_every``-th substep (F = S / record_every + 1, starting with the initial state).
    """
    c = agents.controls
    x, y, yaw, v, s = (np.asarray(a, np.float64).copy() for a in (agents.x, agents.y, agents.yaw, agents.v, agents.s))
    n_steps = c.v_target.shape[1]
    k_max = np.where(agents.min_radius > 0, 1.0 / np.maximum(agents.min_radius, 1e-6), np.inf)
    s_max = road[-1, 2] if road is not None else 0.0
    out = np.empty((len(x), n_steps // record_every + 1, 4))
    out[:, 0] = np.stack([x, y, yaw, v], axis=1)
    for k in range(n_steps):
        acc = np.clip((c.v_target[:, k] - v) / agents.tau, -agents.accel_limits[:, 0], agents.accel_limits[:, 1])
        v_new = np.maximum(v + acc * dt, 0.0)
        v_mid = 0.5 * (v + v_new)
        curv = c.curvature[:, k]
        if road is not None:
            look = np.maximum(6.0, 1.2 * v_mid)
            s_look = s + agents.direction * look
            follow = agents.follow & ~c.free[:, k] & (s_look > 0.0) & (s_look < s_max)
            if follow.any():
                lat = agents.lane + agents.lane_step * _lane_shift(c.lane_phase[:, k])
                tx, ty, _ = _on_road(road, s_look, lat)
                alpha = np.arctan2(ty - y, tx - x) - yaw
                curv = np.where(follow, 2.0 * np.sin(alpha) / look, curv)
        curv = np.clip(curv + c.wiggle[:, k] * (agents.min_radius > 0), -k_max, k_max)
        omega = v_mid * curv + c.yaw_rate[:, k] + c.wiggle[:, k] * (agents.min_radius == 0)
        yaw_mid = yaw + 0.5 * omega * dt
        x = x + v_mid * np.cos(yaw_mid) * dt
        y = y + v_mid * np.sin(yaw_mid) * dt
        yaw = yaw + omega * dt
        s = s + agents.direction * v_mid * dt
        v = v_new
        if (k + 1) % record_every == 0:
            out[:, (k + 1) // record_every] = np.stack([x, y, yaw, v], axis=1)
    return out


# ----------------------------------------------------------------------------------------------------------------
# one scene
# ----------------------------------------------------------------------------------------------------------------


@dataclass
class SceneObjects:
    """Simulated objects of a scene: M objects over F keyframes.

    det_class, category: (M,) str. size: (M, 3) w, l, h metres. z: (M,) centre height. states: (M, F, 4)
    ``[x, y, yaw, v]``. moving: (M,) bool, a moving-type agent (may stop). sitting: (M,) bool.
    """

    det_class: np.ndarray
    category: np.ndarray
    size: np.ndarray
    z: np.ndarray
    states: np.ndarray
    moving: np.ndarray
    sitting: np.ndarray


@dataclass
class SimScene:
    """One simulated scene: ego states (F, 4) and the objects; ``description`` says what happens."""

    index: int
    ego: np.ndarray
    objects: SceneObjects
    description: str


def _ego(rng: np.random.Generator, frames: int) -> tuple[np.ndarray, str]:
    """The ego trajectory (F, 4) in the global frame and a description of it."""
    speeds, probs = zip(*EGO_SPEED_CHOICES)
    cruise = float(rng.choice(speeds, p=probs)) * rng.uniform(0.85, 1.15)
    turn = rng.random() < EGO_TURN_PROB and cruise > 0
    forced = np.array([rng.choice([-1.0, 1.0]) * np.pi / 2 if turn else 0.0])
    n_steps = (frames - 1) * SUBSTEPS
    ctl = manoeuvre_controls(rng, "vehicle", np.array([cruise]), n_steps, DT / SUBSTEPS, forced)
    if not turn:
        ctl.curvature *= 0.3  # the ego mostly keeps to its road
    x0, y0 = rng.uniform(300.0, 2000.0, 2)  # nuScenes map coordinates are positive, 0-3000 m
    one, zero = np.ones(1), np.zeros(1)
    agents = Agents(
        np.array([x0]),
        np.array([y0]),
        np.array([rng.uniform(-np.pi, np.pi)]),
        ctl.v_target[:, 0].copy(),
        ctl,
        1.5 * one,
        np.array([[4.0, 2.5]]),
        5.0 * one,
        np.zeros(1, bool),
        zero,
        zero,
        one,
        zero,
    )
    states = integrate(agents, DT / SUBSTEPS, SUBSTEPS)[0]
    what = ("stationary ego" if cruise == 0 else f"ego at ~{cruise:.0f} m/s") + (
        ", ego turns " + ("left" if forced[0] > 0 else "right") + " at an intersection" if turn else ""
    )
    return states, what


def _road(ego: np.ndarray, margin: float) -> tuple[np.ndarray, float, float]:
    """A road centre line along the ego path (F, 4), extended straight by ``margin`` metres at both ends.

    Returns the line (P, 4) ``[x, y, arc length, heading]`` and the arc lengths of the ego's start and end.
    """
    pts = ego[:, :2]
    step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], step > 0.05])
    pts, yaw = pts[keep], ego[keep, 2]
    head = np.stack([np.cos(yaw[0]), np.sin(yaw[0])])
    tail = np.stack([np.cos(yaw[-1]), np.sin(yaw[-1])])
    ext = np.arange(2.0, margin + 2.0, 2.0)
    before = pts[0] - ext[::-1, None] * head
    after = pts[-1] + ext[:, None] * tail
    line = np.concatenate([before, pts, after])
    seg = np.linalg.norm(np.diff(line, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    d = np.diff(line, axis=0)
    heading = np.arctan2(d[:, 1], d[:, 0])
    heading = np.concatenate([heading, heading[-1:]])
    return np.column_stack([line, s, heading]), float(s[len(before)]), float(s[len(before) + len(pts) - 1])


def _on_road(road: np.ndarray, s: np.ndarray, lateral: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global positions and road headings at arc lengths s (N,) and signed lateral offsets (N,) (left +)."""
    cum = road[:, 2]
    x = np.interp(s, cum, road[:, 0])
    y = np.interp(s, cum, road[:, 1])
    idx = np.clip(np.searchsorted(cum, s) - 1, 0, len(cum) - 1)
    h = road[idx, 3]
    return x - lateral * np.sin(h), y + lateral * np.cos(h), h


def _sizes(rng: np.random.Generator, spec: ClassSpec, n: int, categories: np.ndarray) -> np.ndarray:
    """Per-instance sizes (n, 3): log-normal around the class mean; children and bendy buses rescaled."""
    size = np.asarray(spec.size) * np.exp(rng.normal(size=(n, 3)) * np.asarray(spec.size_logsd))
    child = categories == "human.pedestrian.child"
    size[child] *= np.array([0.65, 0.6, 0.8])  # mini child mean (0.44, 0.41, 1.41) vs adult
    bendy = categories == "vehicle.bus.bendy"
    size[bendy, 1] *= 1.6  # articulated buses are ~18 m long
    return size


def _kerb(side: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Signed lateral position (N,) of a point ``offset`` metres beyond the left (side > 0) or right kerb."""
    return np.where(side > 0, ROAD_LEFT + offset, ROAD_RIGHT - offset)


def _static_objects(rng, name: str, spec: ClassSpec, road: np.ndarray, s_lo: float, s_hi: float, frames: int):
    """Parked / standing objects in rows or groups beside the road (or in parking lots).

    Returns [class (M,), category (M,), size (M, 3), states (M, F, 4), moving (M,), sitting (M,)].
    """
    mean_group = (spec.cluster + 1) / 2.0
    n_groups = rng.poisson(spec.static_per_100m * (s_hi - s_lo) / 100.0 / mean_group)
    counts = rng.integers(1, spec.cluster + 1, n_groups)
    n = int(counts.sum())
    group = np.repeat(np.arange(n_groups), counts)
    lot = (rng.random(n_groups) < spec.lot_share)[group]
    side = rng.choice([-1.0, 1.0], n_groups)[group]
    offset = (
        np.where(lot, rng.uniform(8.0, 30.0, n_groups)[group], rng.uniform(*spec.kerb_offset, n_groups)[group])
        + rng.normal(size=n) * 0.15
    )
    cats = _categories(rng, spec, n)
    size = _sizes(rng, spec, n, cats)
    if name in ("pedestrian", "traffic_cone"):
        gap = rng.uniform(0.8, 2.0, n)
    else:  # rows along the kerb, side by side in lots
        gap = np.where(lot, size[:, 0], size[:, 1]) + rng.uniform(0.6, 2.5, n)
    cum = np.cumsum(gap)
    s = rng.uniform(s_lo, s_hi, n_groups)[group] + cum - np.repeat(cum[np.cumsum(counts) - counts], counts)
    x, y, h = _on_road(road, s, _kerb(side, offset))
    yaw = h + np.where(rng.random(n_groups)[group] < 0.3, np.pi, 0.0) + np.where(lot, np.pi / 2, 0.0)
    if name in ("pedestrian", "traffic_cone"):
        yaw = rng.uniform(-np.pi, np.pi, n)
    yaw = yaw + rng.normal(size=n) * 0.05
    states = np.zeros((n, frames, 4))
    states[:, :, 0], states[:, :, 1], states[:, :, 2] = x[:, None], y[:, None], yaw[:, None]
    sitting = (name == "pedestrian") & (rng.random(n) < 0.1)
    return [np.full(n, name, dtype=object), cats, size, states, np.zeros(n, bool), sitting]


def _categories(rng: np.random.Generator, spec: ClassSpec, n: int) -> np.ndarray:
    """nuScenes categories (n,) drawn with the class's subcategory shares."""
    names, probs = zip(*spec.categories)
    probs = np.asarray(probs) / np.sum(probs)
    return np.asarray(names, dtype=object)[rng.choice(len(names), size=n, p=probs)]


def _moving_objects(
    rng, name: str, spec: ClassSpec, road: np.ndarray, s_lo: float, s_hi: float, frames: int, crossing_s: float | None
):
    """Moving agents placed on lanes, sidewalks or crossing the road, then simulated."""
    n = rng.poisson(spec.moving_per_100m * (s_hi - s_lo) / 100.0)
    if n == 0:
        return None
    cats = _categories(rng, spec, n)
    size = _sizes(rng, spec, n, cats)
    s = rng.uniform(s_lo, s_hi, n)
    side = rng.choice([-1.0, 1.0], n)
    if spec.motion == "pedestrian":  # sidewalks, 2.5-6 m off the kerb
        lat = _kerb(side, rng.uniform(2.5, 6.0, n))
        along = rng.choice([0.0, np.pi], n)
        crossing = rng.random(n) < 0.2  # crossing the road
        along = np.where(crossing, np.where(side > 0, -np.pi / 2, np.pi / 2), along)
    elif spec.motion == "cycle":  # kerb-side, with the traffic
        lat = _kerb(side, -0.8 + rng.normal(size=n) * 0.2)
        along = np.where(side > 0, 0.0, np.pi)
    step = np.zeros(n)
    if spec.motion == "vehicle":
        offsets, headings, shares, steps = (np.array(v) for v in zip(*LANES))
        lane = rng.choice(len(offsets), size=n, p=shares / shares.sum())
        lat, along, step = offsets[lane] + rng.normal(size=n) * 0.2, headings[lane], steps[lane]
    follow = np.full(n, spec.motion != "pedestrian")
    if crossing_s is not None and spec.motion != "pedestrian":
        cross = rng.random(n) < 0.25  # cross traffic at the junction
        s = np.where(cross, crossing_s + rng.choice([-1.75, 1.75], n) + rng.normal(size=n) * 0.3, s)
        lat = np.where(cross, side * rng.uniform(30.0, 90.0, n), lat)
        along = np.where(cross, np.where(side > 0, -np.pi / 2, np.pi / 2), along)
        follow &= ~cross
    x, y, h = _on_road(road, s, lat)
    yaw = h + along + rng.normal(size=n) * 0.03
    cruise = np.maximum(rng.normal(spec.speed[0], spec.speed[1], n), 0.3 * spec.speed[0])
    ctl = manoeuvre_controls(rng, spec.motion, cruise, (frames - 1) * SUBSTEPS, DT / SUBSTEPS)
    ms = MOTION_SPECS[spec.motion]
    agents = Agents(
        x,
        y,
        yaw,
        ctl.v_target[:, 0].copy(),
        ctl,
        np.full(n, ms.tau),
        np.tile(np.asarray(ms.accel_limits, float), (n, 1)),
        np.full(n, ms.min_radius),
        follow,
        lat,
        step,
        np.where(np.cos(along) >= 0, 1.0, -1.0),
        s,
    )
    return [np.full(n, name, dtype=object), cats, size, agents]


def _concat_agents(parts: list[Agents]) -> Agents:
    """One Agents batch from several (integrated together: one loop per scene)."""

    def cat(objs, name):
        return np.concatenate([getattr(o, name) for o in objs])

    ctl = Controls(
        *(
            cat([p.controls for p in parts], f)
            for f in ("v_target", "curvature", "wiggle", "yaw_rate", "lane_phase", "free")
        )
    )
    return Agents(
        *(cat(parts, f) for f in ("x", "y", "yaw", "v")),
        ctl,
        *(
            cat(parts, f)
            for f in ("tau", "accel_limits", "min_radius", "follow", "lane", "lane_step", "direction", "s")
        ),
    )


def _remove_overlaps(size: np.ndarray, states: np.ndarray, ego: np.ndarray) -> np.ndarray:
    """Keep-mask (M,) such that no two kept objects (nor an object and the ego) overlap at any keyframe.

    Boxes are approximated by chains of 1-6 discs of radius 0.45 w along their length; earlier objects win,
    the ego always stays.
    """
    m, frames = states.shape[:2]
    lengths, widths = np.append(size[:, 1], 4.6), np.append(size[:, 0], 1.95)  # the ego is a car
    counts = np.clip(np.ceil(lengths / np.maximum(widths, 0.1)), 1, 6).astype(int)
    owner = np.repeat(np.arange(m + 1), counts)
    rank = np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
    frac = np.where(counts[owner] > 1, rank / np.maximum(counts[owner] - 1, 1) - 0.5, 0.0)
    offs = frac * np.maximum(lengths[owner] - widths[owner], 0.0)
    radius = 0.45 * widths[owner]
    all_states = np.concatenate([states, ego[None]], axis=0)[owner]  # (C, F, 4)
    cx = all_states[:, :, 0] + offs[:, None] * np.cos(all_states[:, :, 2])
    cy = all_states[:, :, 1] + offs[:, None] * np.sin(all_states[:, :, 2])
    found = []
    for f in range(frames):
        pairs = cKDTree(np.column_stack([cx[:, f], cy[:, f]])).query_pairs(2.0 * radius.max(), output_type="ndarray")
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            hit = (owner[i] != owner[j]) & (np.hypot(cx[i, f] - cx[j, f], cy[i, f] - cy[j, f]) < radius[i] + radius[j])
            found.append(np.sort(np.column_stack([owner[i][hit], owner[j][hit]]), axis=1))
    keep = np.ones(m + 1, bool)
    if found:
        for a, b in np.unique(np.concatenate(found), axis=0):
            if keep[a] and keep[b]:
                keep[a if b == m else b] = False  # never drop the ego (index m)
    return keep[:m]


def simulate_scene(index: int, frames: int, seed: int) -> SimScene:
    """Simulate scene ``index``: ego (F, 4) and all objects, from the stream seeded by (seed, index)."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(index)]))
    ego, what = _ego(rng, frames)
    margin = 90.0
    road, s0, s1 = _road(ego, 500.0)  # long enough for agents that follow it for 20 s
    crossing_s = 0.5 * (s0 + s1) + rng.uniform(-20, 20) if rng.random() < 0.5 else None
    movers = []
    for name, spec in CLASS_SPECS.items():
        if spec.moving_per_100m > 0:
            got = _moving_objects(rng, name, spec, road, s0 - margin - 60.0, s1 + margin + 60.0, frames, crossing_s)
            if got is not None:
                movers.append(got)
    parts = []
    if movers:
        states = integrate(_concat_agents([g[3] for g in movers]), DT / SUBSTEPS, SUBSTEPS, road)
        n = len(states)
        parts.append(
            [np.concatenate([g[i] for g in movers]) for i in range(3)] + [states, np.ones(n, bool), np.zeros(n, bool)]
        )
    for name, spec in CLASS_SPECS.items():
        if spec.static_per_100m > 0:
            parts.append(_static_objects(rng, name, spec, road, s0 - margin, s1 + margin, frames))
    det_class, cats, size, states, moving, sitting = (np.concatenate([p[i] for p in parts]) for i in range(6))
    keep = _remove_overlaps(size, states, ego)
    z = size[:, 2] / 2.0 + rng.normal(size=len(size)) * 0.08  # nuScenes ego z = 0 on the ground plane
    objs = SceneObjects(det_class[keep], cats[keep], size[keep], z[keep], states[keep], moving[keep], sitting[keep])
    desc = f"{MARKER}: {what}" + ("; crossing traffic at a junction" if crossing_s is not None else "")
    return SimScene(index=index, ego=ego, objects=objs, description=desc)


# ----------------------------------------------------------------------------------------------------------------
# sensing: lidar points, occlusion, visibility, annotation runs
# ----------------------------------------------------------------------------------------------------------------


def sense(rng: np.random.Generator, scene: SimScene) -> dict[str, np.ndarray]:
    """Lidar / radar point counts and visibility level of every object at every keyframe.

    Returns dist (M, F) m, lidar (M, F), radar (M, F) int64, visibility (M, F) int in 1..4.
    Occlusion is a per-object Markov chain (mean gap ~2 keyframes); visible objects get
    Poisson(exp(a + b ln d + noise) * visible fraction) points (nuScenes num_lidar_pts, single sweep).
    """
    obj = scene.objects
    m, frames = obj.states.shape[:2]
    dist = np.hypot(obj.states[:, :, 0] - scene.ego[None, :, 0], obj.states[:, :, 1] - scene.ego[None, :, 1])
    fit = np.array([CLASS_SPECS[c].points_fit for c in obj.det_class]).reshape(m, 3)
    occ_base = np.array([CLASS_SPECS[c].occlusion for c in obj.det_class])
    occluded = np.zeros((m, frames), bool)
    state = rng.random(m) < occ_base * 2.0
    for f in range(frames):
        p_enter = occ_base * (0.3 + dist[:, f] / 30.0)
        u = rng.random(m)
        state = np.where(state, u > 0.45, u < p_enter)  # leave occlusion with p 0.45 per keyframe
        occluded[:, f] = state
    frac = rng.beta(3.0, 1.0, (m, frames))  # partially occluded share of the object
    frac = np.where(occluded, rng.uniform(0.0, 0.2, (m, frames)), frac)
    log_mean = fit[:, :1] + fit[:, 1:2] * np.log(np.maximum(dist, 2.0))
    noise = rng.normal(size=(m, 1)) * fit[:, 2:3] * 0.75 + rng.normal(size=(m, frames)) * fit[:, 2:3] * 0.66
    lam = np.exp(np.minimum(log_mean + noise, 12.0)) * frac
    lidar = np.where(occluded, 0, rng.poisson(lam))
    is_vehicle = np.isin(obj.det_class, ["car", "truck", "bus", "trailer", "construction_vehicle"])
    radar_rate = np.where(is_vehicle, 3.0, 0.3)[:, None] * np.exp(-dist / 40.0)
    radar = np.where(lidar > 0, rng.poisson(radar_rate), 0)
    vis = np.digitize(frac, [0.4, 0.6, 0.8]) + 1
    return {"dist": dist, "lidar": lidar.astype(np.int64), "radar": radar.astype(np.int64), "visibility": vis}


def annotation_runs(dist: np.ndarray, lidar: np.ndarray, annot_range: np.ndarray) -> list[tuple[int, int, int]]:
    """Instances to annotate: (object, first frame, last frame) for every run of consecutive keyframes within
    the annotation range, trimmed to its first and last frame with lidar points (nuScenes annotates objects
    with at least one point; gaps inside a run are kept as occlusions with 0 points)."""
    inside = dist <= annot_range[:, None]
    runs = []
    for i in range(len(dist)):
        pad = np.concatenate([[False], inside[i], [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(pad) == 1)
        ends = np.flatnonzero(np.diff(pad) == -1) - 1
        for a, b in zip(starts, ends):
            seen = np.flatnonzero(lidar[i, a : b + 1] > 0)
            if len(seen):
                runs.append((i, int(a + seen[0]), int(a + seen[-1])))
    return runs


# ----------------------------------------------------------------------------------------------------------------
# tables
# ----------------------------------------------------------------------------------------------------------------


class _Tokens:
    """Deterministic 32-hex tokens: md5 of (seed, version, kind, key)."""

    def __init__(self, seed: int, version: str):
        self.prefix = f"grutrack-demo|{seed}|{version}|"

    def __call__(self, kind: str, *key) -> str:
        return hashlib.md5((self.prefix + kind + "|" + "|".join(map(str, key))).encode()).hexdigest()


def _quat(yaw: np.ndarray) -> list[list[float]]:
    """Yaw-only unit quaternions [w, x, y, z] (N, 4), rounded to 10 decimals."""
    yaw = np.asarray(yaw, dtype=np.float64)
    q = np.zeros((len(yaw), 4))
    q[:, 0], q[:, 3] = np.cos(yaw / 2.0), np.sin(yaw / 2.0)
    return np.round(q, 10).tolist()


def _attribute(det_class: str, moving_agent: bool, speed: float, sitting: bool) -> str | None:
    """The nuScenes attribute of one annotation (None for barrier and traffic cone)."""
    if det_class in ("car", "truck", "bus", "trailer", "construction_vehicle"):
        if not moving_agent:
            return "vehicle.parked"
        return "vehicle.moving" if speed > 0.5 else "vehicle.stopped"
    if det_class == "pedestrian":
        if sitting:
            return "pedestrian.sitting_lying_down"
        return "pedestrian.moving" if speed > 0.3 else "pedestrian.standing"
    if det_class in ("bicycle", "motorcycle"):
        return "cycle.with_rider" if moving_agent else "cycle.without_rider"
    return None


def static_tables(tok: _Tokens) -> dict[str, list]:
    """category, attribute, visibility and sensor tables."""
    return {
        "category": [
            {"token": tok("category", n), "name": n, "description": f"{MARKER}; nuScenes category {n}"}
            for n in CATEGORIES
        ],
        "attribute": [
            {"token": tok("attribute", n), "name": n, "description": f"{MARKER}; nuScenes attribute {n}"}
            for n in ATTRIBUTES
        ],
        "visibility": [
            {
                "token": t,
                "level": lvl,
                "description": f"visibility of whole object is between {lvl[1:].replace('-', ' and ')}%",
            }
            for t, lvl in VISIBILITY
        ],
        "sensor": [{"token": tok("sensor", "LIDAR_TOP"), "channel": "LIDAR_TOP", "modality": "lidar"}],
    }


def scene_tables(scene: SimScene, seed: int, version: str, tok: _Tokens) -> dict[str, list]:
    """The records of one scene for the scene, log, sample, sample_data, ego_pose, calibrated_sensor, instance
    and sample_annotation tables."""
    rng = np.random.default_rng(np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(scene.index), 1]))
    i, frames = scene.index, len(scene.ego)
    name = f"demo-scene-{i:04d}"
    log_tok, scene_tok, cs_tok = tok("log", i), tok("scene", i), tok("calibrated_sensor", i)
    t0 = TIME_ORIGIN_US + i * 3_600_000_000
    stamps = [t0 + int(round(f * DT * 1e6)) for f in range(frames)]
    samples = [tok("sample", i, f) for f in range(frames)]
    sds = [tok("sample_data", i, f) for f in range(frames)]
    logfile = f"demo-{i:04d}-synthetic"
    out: dict[str, list] = {
        k: []
        for k in (
            "scene",
            "log",
            "sample",
            "sample_data",
            "ego_pose",
            "calibrated_sensor",
            "instance",
            "sample_annotation",
        )
    }
    out["log"].append(
        {
            "token": log_tok,
            "logfile": logfile,
            "vehicle": "demo-ego",
            "date_captured": "2018-07-31",
            "location": "synthetic-demo",
        }
    )
    out["calibrated_sensor"].append(
        {
            "token": cs_tok,
            "sensor_token": tok("sensor", "LIDAR_TOP"),
            "translation": LIDAR_TRANSLATION,
            "rotation": LIDAR_ROTATION,
            "camera_intrinsic": [],
        }
    )
    ego_q = _quat(scene.ego[:, 2])
    ego_xy = np.round(scene.ego[:, :2], 6).tolist()
    for f in range(frames):
        out["sample"].append(
            {
                "token": samples[f],
                "timestamp": stamps[f],
                "prev": samples[f - 1] if f else "",
                "next": samples[f + 1] if f + 1 < frames else "",
                "scene_token": scene_tok,
            }
        )
        out["sample_data"].append(
            {
                "token": sds[f],
                "sample_token": samples[f],
                "ego_pose_token": sds[f],
                "calibrated_sensor_token": cs_tok,
                "timestamp": stamps[f],
                "fileformat": "pcd",
                "is_key_frame": True,
                "height": 0,
                "width": 0,
                "filename": f"samples/LIDAR_TOP/{logfile}__LIDAR_TOP__{stamps[f]}.pcd.bin",
                "prev": sds[f - 1] if f else "",
                "next": sds[f + 1] if f + 1 < frames else "",
            }
        )
        out["ego_pose"].append(
            {"token": sds[f], "timestamp": stamps[f], "rotation": ego_q[f], "translation": [*ego_xy[f], 0.0]}
        )
    n_anns = _annotations(scene, rng, tok, samples, out)
    out["scene"].append(
        {
            "token": scene_tok,
            "log_token": log_tok,
            "nbr_samples": frames,
            "first_sample_token": samples[0],
            "last_sample_token": samples[-1],
            "name": name,
            "description": f"{scene.description}; {len(out['instance'])} annotated objects, {n_anns} boxes",
        }
    )
    return out


def _annotations(
    scene: SimScene, rng: np.random.Generator, tok: _Tokens, samples: list[str], out: dict[str, list]
) -> int:
    """Append instance and sample_annotation records of a scene to ``out``; returns the box count."""
    obj = scene.objects
    sensed = sense(rng, scene)
    ranges = np.array([CLASS_SPECS[c].annot_range for c in obj.det_class])
    runs = annotation_runs(sensed["dist"], sensed["lidar"], ranges)
    m, frames = obj.states.shape[:2]
    jitter_xy = np.round(obj.states[:, :, :2] + rng.normal(size=(m, frames, 2)) * ANNOT_NOISE_POS, 3)
    jitter_z = np.round(obj.z[:, None] + rng.normal(size=(m, frames)) * 0.01, 3)
    yaw = obj.states[:, :, 2] + rng.normal(size=(m, frames)) * ANNOT_NOISE_YAW
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    size = np.round(obj.size, 3)
    cat_tok = {c: tok("category", c) for c in CATEGORIES}
    att_tok = {a: tok("attribute", a) for a in ATTRIBUTES}
    count = 0
    for k, (o, a, b) in enumerate(runs):
        inst = tok("instance", scene.index, k)
        anns = [tok("ann", scene.index, k, f) for f in range(a, b + 1)]
        quats = _quat(yaw[o, a : b + 1])
        for j, f in enumerate(range(a, b + 1)):
            attr = _attribute(obj.det_class[o], bool(obj.moving[o]), float(obj.states[o, f, 3]), bool(obj.sitting[o]))
            out["sample_annotation"].append(
                {
                    "token": anns[j],
                    "sample_token": samples[f],
                    "instance_token": inst,
                    "visibility_token": str(int(sensed["visibility"][o, f])),
                    "attribute_tokens": [att_tok[attr]] if attr else [],
                    "translation": [*jitter_xy[o, f].tolist(), float(jitter_z[o, f])],
                    "size": size[o].tolist(),
                    "rotation": quats[j],
                    "num_lidar_pts": int(sensed["lidar"][o, f]),
                    "num_radar_pts": int(sensed["radar"][o, f]),
                    "prev": anns[j - 1] if j else "",
                    "next": anns[j + 1] if j + 1 < len(anns) else "",
                }
            )
        out["instance"].append(
            {
                "token": inst,
                "category_token": cat_tok[obj.category[o]],
                "nbr_annotations": len(anns),
                "first_annotation_token": anns[0],
                "last_annotation_token": anns[-1],
            }
        )
        count += len(anns)
    return count


def build_tables(scenes: int, frames: int, seed: int, version: str) -> tuple[dict[str, list], dict[str, list]]:
    """All 13 tables and the splits (``demo_train``, ``demo_val``, ``demo_all``) of a demo dataset."""
    tok = _Tokens(seed, version)
    tables = static_tables(tok)
    for key in (
        "scene",
        "log",
        "sample",
        "sample_data",
        "ego_pose",
        "calibrated_sensor",
        "instance",
        "sample_annotation",
    ):
        tables[key] = []
    names = []
    for i in range(scenes):
        part = scene_tables(simulate_scene(i, frames, seed), seed, version, tok)
        for key, recs in part.items():
            tables[key].extend(recs)
        names.append(part["scene"][0]["name"])
    map_tok = tok("map", "demo")
    tables["map"] = [
        {
            "token": map_tok,
            "log_tokens": [r["token"] for r in tables["log"]],
            "category": "semantic_prior",
            "filename": f"maps/{map_tok}.png",
        }
    ]
    val = [n for i, n in enumerate(names) if i % VAL_EVERY == VAL_EVERY - 1]
    if not val and len(names) > 1:
        val = names[-1:]  # small demos still get a validation scene
    splits = {"demo_train": [n for n in names if n not in val], "demo_val": val, "demo_all": names}
    return tables, splits


# ----------------------------------------------------------------------------------------------------------------
# writing
# ----------------------------------------------------------------------------------------------------------------


def placeholder_png() -> bytes:
    """A valid 1x1 grayscale PNG (the devkit only checks that the map file exists)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", 1, 1, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\x00\x00", 9))
        + chunk(b"IEND", b"")
    )


def readme_text(scenes: int, frames: int, seed: int, version: str, splits: dict, tables: dict) -> str:
    """The README.txt placed in the dataroot."""
    return (
        f"{MARKER} -- NOT REAL SENSOR DATA\n\n"
        f"Generated by `grutrack demo-data` (seed {seed}): {scenes} scenes x {frames} keyframes at 2 Hz,\n"
        f"{len(tables['instance'])} instances, {len(tables['sample_annotation'])} annotations.\n"
        f"Format: nuScenes tables (load with NuScenes('{version}', dataroot=<this folder>)); custom splits in\n"
        f"{version}/splits.json: demo_train ({len(splits['demo_train'])} scenes), demo_val "
        f"({len(splits['demo_val'])}), demo_all.\n"
        "There are no point clouds, images or maps: sample_data filenames point to files that do not exist and\n"
        "the map PNG is a 1x1 placeholder. Every object, pose and point count is simulated; category and\n"
        "attribute names are nuScenes' so that the devkit's class mappings and evaluators apply.\n"
    )


def generate_demo(
    out: str | os.PathLike,
    scenes: int = DEFAULT_SCENES,
    frames: int = FRAMES_PER_SCENE,
    seed: int = 0,
    version: str = VERSION,
) -> dict:
    """Write a demo dataset to ``out`` atomically (built in a temporary folder beside it, then renamed).

    An existing ``out`` is replaced only if it is empty or a previous demo (has the README marker); one that
    already holds exactly this dataset is left untouched (so a workflow does not see it as new).
    Returns a summary: scenes, samples, instances, annotations, splits, unchanged (bool).
    """
    if scenes < 1 or frames < 2:
        raise ConfigError(f"demo-data: need at least 1 scene and 2 frames per scene (got {scenes}, {frames})")
    if not version or "/" in version or version.startswith("."):
        raise ConfigError(f"demo-data: bad version name '{version}'")
    out = Path(out)
    _check_replaceable(out)
    tables, splits = build_tables(scenes, frames, seed, version)
    files = {
        f"{version}/{name}.json": json.dumps(recs, separators=(",", ":")).encode() for name, recs in tables.items()
    }
    files[f"{version}/splits.json"] = json.dumps(splits, indent=1).encode()
    files[tables["map"][0]["filename"]] = placeholder_png()
    files["README.txt"] = readme_text(scenes, frames, seed, version, splits, tables).encode()
    summary = {
        "dataroot": str(out),
        "version": version,
        "scenes": scenes,
        "samples": len(tables["sample"]),
        "instances": len(tables["instance"]),
        "annotations": len(tables["sample_annotation"]),
        "splits": {k: len(v) for k, v in splits.items()},
        "unchanged": _same_files(out, files),
    }
    if summary["unchanged"]:
        return summary  # byte for byte the same dataset: leave it (and its times) alone
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    os.chmod(tmp, 0o755)  # mkdtemp makes it private; a dataset is for reading
    try:
        for rel, data in files.items():
            (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
            (tmp / rel).write_bytes(data)
        _swap_in(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return summary


def _same_files(out: Path, files: dict[str, bytes]) -> bool:
    """Whether ``out`` holds exactly ``files`` (relative path -> bytes) and nothing else (besides the
    ``.snakemake_timestamp`` a workflow keeps in the folders it writes)."""
    if not out.is_dir():
        return False
    present = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()} - {".snakemake_timestamp"}
    if present != set(files):
        return False
    return all((out / rel).read_bytes() == data for rel, data in files.items())


def _check_replaceable(out: Path) -> None:
    """Refuse to overwrite a folder that is neither empty nor a previous demo."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"demo-data: --out {out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        readme = out / "README.txt"
        if not (readme.is_file() and readme.read_text(errors="replace").startswith(MARKER)):
            raise ConfigError(
                f"demo-data: --out {out} exists and is not a grutrack demo dataset "
                f"(no {readme} starting with '{MARKER}'); choose an empty or new folder"
            )


def _swap_in(tmp: Path, out: Path) -> None:
    """Move the finished ``tmp`` folder onto ``out`` (the old demo, if any, is removed after the rename)."""
    if not out.exists():
        os.replace(tmp, out)
        return
    old = out.parent / f".{out.name}.old.{os.getpid()}"
    os.replace(out, old)
    os.replace(tmp, out)
    shutil.rmtree(old, ignore_errors=True)
