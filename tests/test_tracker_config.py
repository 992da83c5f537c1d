"""Tracker presets: every key documented in the shipped preset loads; misspelt / missing / bad keys fail clearly."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml

from grutrack.classes import TRACKING_CLASSES
from grutrack.errors import ConfigError
from grutrack.tracking.config import PRESET_DIR, config_from_dict, load_tracker_config

#: association.crowded_threshold off (the preset's crowded stage 1 taken out where a case tests another rule)
NO_CROWD = dict.fromkeys(TRACKING_CLASSES, 0.0)

GROWN_GATE_REFUSED = (
    "'association.distance_gate_growth' missed_frames or a speed above 0 needs 'association.algorithm: "
    "hungarian', no alignment GIoU metric and no distance gate on every class"
)


def _grown_gate_on_every_class(growth):
    """A preset edit: a gate on every class (Fast-Poly's dense association) with the buses' gate grown by
    ``growth``."""

    def edit(r):
        r["association"].pop("ro_gdiou_weights")
        r["association"].update(
            distance_gate=dict.fromkeys(TRACKING_CLASSES, 2.0),
            crowded_threshold=NO_CROWD,
            crowded_skips_lost_newborns=False,
            distance_gate_growth={**dict.fromkeys(TRACKING_CLASSES, "fixed"), "bus": growth},
        )

    return edit


def _raw():
    return yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())


def test_ekf_preset_values():
    cfg = load_tracker_config("ekf")
    assert cfg.nms_threshold == 0.08 and cfg.two_stage and cfg.second_metric == "giou_bev"
    assert cfg.first_metric[1] == "giou_bev" and cfg.first_metric[2] == "giou_3d"  # bus, car
    assert cfg.max_age.tolist() == [10, 10, 15, 20, 10, 10, 20]
    assert cfg.punish_num.tolist() == [2, 2, 1, 2, 1, 2, 2]  # all but car and pedestrian coast two frames
    assert cfg.algorithm == "hungarian" and cfg.min_hits.tolist() == [1] * 7  # Poly-MOT's min_hit 1
    assert np.isinf(cfg.max_distance).all()  # the greedy gate: not read by hungarian, so not in the preset
    assert cfg.size_gate.tolist() == [0.3] * 7  # Decision 19: a pair's footprint areas within a factor 1 / 0.3


def test_baseline_presets():
    greedy, ab3dmot = load_tracker_config("greedy"), load_tracker_config("ab3dmot")
    assert greedy.algorithm == "greedy" and not greedy.two_stage and greedy.punish_num.tolist() == [0] * 7
    assert greedy.max_distance.tolist() == [8.75, 14.0, 16.0, 13.0, 2.0, 16.0, 15.0]  # AV2 baseline gates
    assert greedy.max_age.tolist() == [3] * 7 and greedy.nms_threshold == 1.0
    assert ab3dmot.algorithm == "hungarian" and ab3dmot.first_metric == ("iou_3d",) * 7
    assert ab3dmot.first_threshold.tolist() == [0.99] * 7  # IoU_min 0.01
    assert ab3dmot.max_age.tolist() == [2] * 7 and ab3dmot.min_hits.tolist() == [3] * 7
    assert ab3dmot.motion_config == "ab3dmot" and not ab3dmot.two_stage


@pytest.mark.parametrize("preset", ["ekf", "polymot", "greedy", "ab3dmot"])
def test_every_preset_key_has_a_comment(preset):
    text = (PRESET_DIR / f"{preset}.yaml").read_text().splitlines()
    for i, line in enumerate(text):
        s = line.strip()
        if s and not s.startswith("#") and s.endswith(":") is False and ":" in s and line.startswith("  "):
            assert text[i - 1].strip().startswith("#"), f"key without a comment above it: {s}"


def _decoupled_cv(**motion):
    """A preset edit: MCTrack's decoupled filters (its position and size noise) with ``motion`` keys set too."""

    def edit(r):
        mct = yaml.safe_load((PRESET_DIR / "mctrack.yaml").read_text())["motion"]
        r["motion"].update(
            filter="decoupled_cv", position_noise=mct["position_noise"], size_noise=mct["size_noise"], **motion
        )

    return edit


@pytest.mark.parametrize(
    "mutate, message",
    [
        (
            lambda r: r["association"].__setitem__("first_treshold", r["association"].pop("first_threshold")),
            "unknown key 'association.first_treshold'",
        ),
        (lambda r: r["lifecycle"].pop("punish_num"), "missing key 'lifecycle.punish_num'"),
        (lambda r: r["lifecycle"]["max_age"].pop("car"), "missing key 'lifecycle.max_age.car'"),
        (
            lambda r: r["preprocessing"].__setitem__("nms_threshold", 1.5),
            "'preprocessing.nms_threshold' must be a number in",
        ),
        (lambda r: r["association"].__setitem__("second_metric", "giou"), "must be one of giou_3d"),
        (
            lambda r: r["motion"].__setitem__("model_override", {"car": "CTRV"}),
            "'motion.model_override.car' must be one of",
        ),
        (lambda r: r["lifecycle"]["max_age"].__setitem__("bus", 2.5), "must be an integer"),
        (lambda r: r["association"].__setitem__("algorithm", "greedyy"), "'association.algorithm' must be one of"),
        (
            lambda r: r["association"].__setitem__("algorithm", "greedy"),
            "'association.max_distance' is required with 'association.algorithm: greedy'",
        ),
        (
            lambda r: (
                r["association"].update(
                    algorithm="greedy", max_distance=dict.fromkeys(TRACKING_CLASSES, 2.0), crowded_threshold=NO_CROWD
                ),
                r["association"].pop("ro_gdiou_weights", None),
            ),
            "'association.two_stage' must be false",
        ),
        (
            lambda r: r["association"].__setitem__("max_distance", {**dict.fromkeys(TRACKING_CLASSES, 2.0), "car": -1}),
            "'association.max_distance.car' must be a positive distance",
        ),
        (
            lambda r: r["association"].pop("second_threshold"),
            "'association.second_threshold' is required with 'association.two_stage: true'",
        ),
        (
            lambda r: (
                r["lifecycle"].__setitem__("termination", "average_score"),
                r["lifecycle"].pop("delete_threshold"),
            ),
            "'lifecycle.delete_threshold' is required with 'lifecycle.termination: average_score'",
        ),
        (
            lambda r: r["lifecycle"]["min_hits"].__setitem__("car", 0),
            "'lifecycle.min_hits.car' must be an integer >= 1",
        ),
        (lambda r: r["lifecycle"].pop("min_hits"), "missing key 'lifecycle.min_hits'"),
        (
            lambda r: r["lifecycle"].__setitem__("punish_num", -1),
            "'lifecycle.punish_num' must be an integer >= 0 or a mapping over the tracking classes",
        ),
        (lambda r: r["lifecycle"]["punish_num"].pop("bus"), "missing key 'lifecycle.punish_num.bus'"),
        (
            lambda r: r["lifecycle"]["punish_num"].__setitem__("car", 1.5),
            "'lifecycle.punish_num.car' must be an integer",
        ),
        (
            lambda r: r["lifecycle"].__setitem__("young_track_discount", 1.0),
            r"'lifecycle.young_track_discount' must be a number in \[0, 1\), got 1.0",
        ),
        (
            lambda r: r["motion"].__setitem__("velocity_check_updates", -1),
            "'motion.velocity_check_updates' must be an integer >= 0",
        ),
        (
            lambda r: r["motion"].__setitem__("velocity_check_difference", 0),
            "'motion.velocity_check_difference' must be a positive speed in metres per second",
        ),
        (
            lambda r: r["motion"].__setitem__("velocity_check_window", -0.1),
            "'motion.velocity_check_window' must be a number of seconds >= 0",
        ),
        (lambda r: r["motion"].__setitem__("nis_limit", -1.0), "'motion.nis_limit' must be a number >= 0"),
        (lambda r: r["motion"].__setitem__("nis_min_hits", 2.5), "'motion.nis_min_hits' must be an integer >= 0"),
        (
            lambda r: r["motion"].__setitem__("r_score_exponent", -1.0),
            "'motion.r_score_exponent' must be a number >= 0",
        ),
        (_decoupled_cv(), "'motion.velocity_check_updates' must be 0 with 'motion.filter: decoupled_cv'"),
        (
            _decoupled_cv(velocity_check_updates=0, nis_limit=2.0),
            "'motion.nis_limit' must be 0 with 'motion.filter: decoupled_cv'",
        ),
        (
            _decoupled_cv(velocity_check_updates=0, nis_limit=0.0, r_score_exponent=1.0),
            "'motion.r_score_exponent' must be 0 with 'motion.filter: decoupled_cv'",
        ),
        (
            lambda r: (
                r["association"]["first_metric"].__setitem__("motorcycle", "ro_gdiou_bev"),
                r["association"].__setitem__("track_pose", dict.fromkeys(TRACKING_CLASSES, "last_update")),
            ),
            "'association.track_pose' is read only with 'association.first_metric: ro_gdiou_bev' for every class "
            r"\(with some classes, stage 1 compares the track's predicted box\)",
        ),
        (
            lambda r: r["association"].update(
                first_metric={**r["association"]["first_metric"], "motorcycle": "ro_gdiou_bev"},
                distance_gate=dict.fromkeys(TRACKING_CLASSES, 2.0),
            ),
            "'association.first_metric: ro_gdiou_bev' for some classes needs 'association.algorithm: hungarian', "
            "no alignment GIoU metric and no distance gate on every class",
        ),
        (
            lambda r: r["association"]["distance_gate_growth"].__setitem__("bus", "sometimes"),
            r"'association.distance_gate_growth.bus' must be fixed, missed_frames or a number >= 0 \(metres per "
            r"second\), got 'sometimes'",
        ),
        (
            lambda r: r["association"]["distance_gate_growth"].__setitem__("bus", -1.5),
            r"'association.distance_gate_growth.bus' must be fixed, missed_frames or a number >= 0 \(metres per "
            r"second\), got -1.5",
        ),
        *[
            (_grown_gate_on_every_class(growth), GROWN_GATE_REFUSED)  # Fast-Poly's dense association
            for growth in ("missed_frames", 3.0)
        ],
        (
            lambda r: (
                _grown_gate_on_every_class("fixed")(r),
                r["association"].__setitem__("size_gate", {**dict.fromkeys(TRACKING_CLASSES, 0.0), "bus": 0.3}),
            ),
            "'association.size_gate' above 0 needs 'association.algorithm: hungarian', no alignment GIoU metric, no "
            "distance gate on every class",
        ),
        (
            lambda r: r["association"].update(
                first_metric=dict.fromkeys(TRACKING_CLASSES, "ro_gdiou_bev"),
                two_stage=False,
                distance_gate=dict.fromkeys(TRACKING_CLASSES, 0.0),
                distance_gate_growth=dict.fromkeys(TRACKING_CLASSES, "fixed"),
                crowded_threshold=NO_CROWD,
                crowded_skips_lost_newborns=False,
                size_gate=dict.fromkeys(TRACKING_CLASSES, 0.3),
            ),
            "'association.size_gate' above 0 needs .* a first_metric other than ro_gdiou_bev for some class",
        ),
        (
            lambda r: r["association"].__setitem__("size_gate", {**dict.fromkeys(TRACKING_CLASSES, 0.0), "car": 1.5}),
            r"'association.size_gate.car' must be a number in \[0, 1\], got 1.5",
        ),
        (
            lambda r: r["association"].update(
                first_metric=dict.fromkeys(TRACKING_CLASSES, "ro_gdiou_bev"), crowded_threshold=NO_CROWD
            ),
            "'association.two_stage' must be false with 'association.first_metric: ro_gdiou_bev'",
        ),
        (
            lambda r: r["association"].update(
                first_metric=dict.fromkeys(TRACKING_CLASSES, "ro_gdiou_bev"),
                two_stage=False,
                distance_gate={**dict.fromkeys(TRACKING_CLASSES, 0.0), "trailer": 5.0},
                crowded_threshold=NO_CROWD,
            ),
            "'association.distance_gate' must be 0 for every class with 'association.first_metric: ro_gdiou_bev'",
        ),
        (
            lambda r: r["association"].update(
                first_metric=dict.fromkeys(TRACKING_CLASSES, "ro_gdiou_bev"),
                two_stage=False,
                distance_gate=dict.fromkeys(TRACKING_CLASSES, 0.0),
                algorithm="greedy",
                max_distance=dict.fromkeys(TRACKING_CLASSES, 2.0),
                crowded_threshold=NO_CROWD,
            ),
            "'association.algorithm' must be hungarian with 'association.first_metric: ro_gdiou_bev'",
        ),
        (
            lambda r: r["association"].__setitem__("track_pose", dict.fromkeys(TRACKING_CLASSES, "last_update")),
            "'association.track_pose' is read only with 'association.first_metric: ro_gdiou_bev'",
        ),
        (
            lambda r: (
                r["association"].update(geometry_precision="float32", crowded_threshold=NO_CROWD),
                r["association"].pop("ro_gdiou_weights", None),
            ),
            "'association.geometry_precision' is read only with 'association.first_metric: ro_gdiou_bev'",
        ),
        (
            lambda r: r["association"].update(
                first_metric={**r["association"]["first_metric"], "pedestrian": "ro_gdiou_bev"},
                crowded_threshold={**dict.fromkeys(TRACKING_CLASSES, 0.0), "pedestrian": 2.0},
            ),
            r"'association.crowded_threshold.pedestrian' must be 0 when its 'association.first_metric' is "
            r"ro_gdiou_bev \(stage 1 is Ro_GDIoU already\)",
        ),
        (
            lambda r: r["association"].update(
                crowded_threshold={**dict.fromkeys(TRACKING_CLASSES, 0.0), "car": 1.1},
                distance_gate=dict.fromkeys(TRACKING_CLASSES, 2.0),
            ),
            "'association.crowded_threshold' needs 'association.algorithm: hungarian', no alignment GIoU metric and "
            "no distance gate on every class",
        ),
        (
            lambda r: r["association"].update(
                crowded_threshold={**dict.fromkeys(TRACKING_CLASSES, 0.0), "car": 1.1},
                track_pose=dict.fromkeys(TRACKING_CLASSES, "last_update"),
            ),
            r"'association.track_pose' is read only with 'association.first_metric: ro_gdiou_bev' for every class "
            r"\(crowded pairs compare the track's predicted box\)",
        ),
    ],
)
def test_bad_preset_keys(mutate, message):
    raw = copy.deepcopy(_raw())
    mutate(raw)
    with pytest.raises(ConfigError, match=message):
        config_from_dict(raw, "preset.yaml")


def test_crowded_threshold_reads_the_ro_gdiou_keys_it_uses():
    raw = copy.deepcopy(_raw())
    a = raw["association"]
    a["crowded_threshold"] = {**dict.fromkeys(TRACKING_CLASSES, 0.0), "car": 1.1, "pedestrian": 2.06}
    a["ro_gdiou_weights"] = {**dict.fromkeys(TRACKING_CLASSES, [1.0, 1.0]), "car": [0.5, 1.5]}
    a["geometry_precision"] = "float32"
    cfg = config_from_dict(raw, "preset.yaml")
    car = TRACKING_CLASSES.index("car")
    assert cfg.crowded_threshold[car] == 1.1 and cfg.ro_gdiou_weights[car].tolist() == [0.5, 1.5]
    assert cfg.geometry_precision == "float32"


def test_punish_num_one_integer_or_per_class():
    raw = copy.deepcopy(_raw())
    raw["lifecycle"]["punish_num"] = 3
    assert config_from_dict(raw).punish_num.tolist() == [3] * 7
    raw["lifecycle"]["punish_num"] = {c: i for i, c in enumerate(raw["lifecycle"]["max_age"])}
    assert config_from_dict(raw).punish_num.tolist() == list(range(7))


def test_unknown_preset_name_lists_available():
    with pytest.raises(ConfigError, match="unknown tracker preset 'ekff'.*ekf"):
        load_tracker_config("ekff")


def test_presets_carry_only_what_their_algorithm_reads():
    """Keys a preset's settings never read are left out of the shipped presets (their schema default is a
    placeholder), and leaving out a key with a default gives the tracker's behaviour without it."""
    unread = {
        "greedy": (
            "association.assignment",
            "association.two_stage",
            "association.first_metric",
            "association.first_threshold",
            "association.second_metric",
            "association.second_threshold",
            "association.distance_gate",
        ),
        "hungarian": ("association.max_distance",),
    }
    for path in sorted(PRESET_DIR.glob("*.yaml")):
        raw = yaml.safe_load(path.read_text())
        keys = {f"{sec}.{k}" for sec, body in raw.items() for k in body}
        assoc, pre, life = raw["association"], raw["preprocessing"], raw["lifecycle"]
        never = set(unread[assoc["algorithm"]])
        if not assoc.get("two_stage", False):
            never |= {"association.second_metric", "association.second_threshold"}
        if pre.get("nms_method", "blend") == "blend":
            never |= {"preprocessing.nms_metric", "preprocessing.nms_scale", "preprocessing.nms_distance_gate"}
        if life.get("termination", "age") == "age":
            never.add("lifecycle.delete_threshold")
        assert not keys & never, (path.name, sorted(keys & never))
        assert ("motion" in raw) == (assoc["algorithm"] != "greedy"), path.name  # greedy: no motion filter
    # a key left out takes its schema default: the same tracker as with the default written out
    raw = copy.deepcopy(_raw())
    raw["output"]["max_boxes_per_sample"] = 500
    raw["motion"]["model_override"] = {}
    short = {**raw, "output": {"matched_box": raw["output"]["matched_box"]}}
    full, short = config_from_dict(raw), config_from_dict(short)
    assert full.max_boxes_per_sample == short.max_boxes_per_sample == 500
    # a preset without a motion section runs the default motion config with every motion default
    no_motion = config_from_dict({k: v for k, v in _raw().items() if k != "motion"})
    assert (no_motion.motion_config, no_motion.time_step, no_motion.ctra_form, no_motion.yaw_flip) == (
        "polymot_nusc",
        None,
        "arc",
        False,
    )


def test_nis_limit_reaches_every_kalman_filter_of_the_ekf_and_the_gru_kf(tmp_path):
    """``motion.nis_limit``, ``nis_min_hits`` and ``r_score_exponent`` are the robust update and confidence-weighted
    noise of every joint filter the preset builds: the EKF groups and the GRU-KF's EKF gain prior."""
    from grutrack.motion.kalman import RobustUpdate
    from grutrack.tracking.factory import build_tracker
    from grutrack.training.pretrained import pretrained_dir

    raw = yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())
    raw["motion"].update(nis_limit=2.5, nis_min_hits=4, r_score_exponent=0.5)
    path = tmp_path / "robust.yaml"
    path.write_text(yaml.safe_dump(raw))
    ckpt = pretrained_dir("grukf_default") / "model.pt"
    for name, kw in (("ekf", {}), ("grukf", {"checkpoint": ckpt, "device": "cpu"})):
        groups = build_tracker(name, path, **kw).groups
        filters = [getattr(g.backend, "inner", g.backend).kf for g in groups]
        assert filters and [f.robust for f in filters] == [RobustUpdate(2.5, 4, 0.5)] * len(filters), name


def test_the_tracker_name_sets_the_motion_model_and_the_preset_the_rest():
    """`--tracker greedy --config polymot` (as `grutrack track --help` says): greedy tracks, Poly-MOT's
    two-stage Hungarian association and lifecycle; `--tracker greedy` alone: the greedy association too."""
    from grutrack.tracking.baselines import DetectionBackend
    from grutrack.tracking.factory import build_tracker

    hybrid, greedy = build_tracker("greedy", "polymot"), build_tracker("greedy")
    assert all(isinstance(g.backend, DetectionBackend) for g in hybrid.groups + greedy.groups)
    assert hybrid.cfg.algorithm == "hungarian" and hybrid.cfg.two_stage
    assert hybrid.cfg.max_age.tolist() == load_tracker_config("polymot").max_age.tolist()
    assert hybrid.associate.__qualname__.startswith("two_stage_association.")
    assert greedy.cfg.algorithm == "greedy" and greedy.associate.__qualname__.startswith("greedy_association.")
