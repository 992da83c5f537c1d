"""The default tracker preset decided by evidence: AMOTA of candidate presets against Poly-MOT, Fast-Poly and MCTrack.

For every detection set (the four reference sets of ../shared/data/nuscenes/reference, three of them SYNTHETIC and
one the real PointPillars file; and SYNTHETIC sets made here with ``simulate_nuscenes`` for other detector profiles
and seeds) the script tracks with the three trackers' presets (``polymot``, ``fastpoly``, ``mctrack``: box for box
their own code's output) and with every candidate (the ``ekf`` preset with one or more keys changed), scores each
output with the fast evaluator (equal to the devkit) and prints one table: AMOTA per set, the best of the three,
and per candidate the sets where it is below that best and by how much.

    .venv/bin/python benchmarks/bench_default_tracker.py                      # reference + held-out sets
    .venv/bin/python benchmarks/bench_default_tracker.py --groups reference,dev --candidates ekf,ekf_mct_nms

Groups: ``reference`` (the four reference sets), ``dev`` / ``dev2`` (SYNTHETIC, seeds 100-101 / 110-111: the sets
the candidates were compared on while choosing) and ``heldout`` ... ``heldout4`` (SYNTHETIC, seeds 300-302,
500-502, 700-702, 900-902, mini_val and mini_train, all four profiles: each first looked at once a decision was
frozen; docs/results/default_tracker.md says which decision each group checked); ``variants`` (SYNTHETIC, seeds
1001-1003, four detector profiles Decisions 1-3 never saw, :data:`VARIANTS`: noisier velocities, three times
the false positives, noisier poses, a weaker recall); ``fresh`` / ``fresh_train`` (SYNTHETIC, seeds 2000-2049
on mini_val / 2000-2009 on mini_train, the four profiles: made after Decision 8 to count how often the preset falls
below on sets no decision saw; the bus score threshold of default_tracker.md#bus-score was then chosen on them too);
``fresh2`` / ``fresh2_train`` (the same with seeds 3000-3049 / 3000-3009: made after that choice, the count on
unseen sets again); ``fresh3`` / ``fresh3_train`` (seeds 4000-4049 / 4000-4009: made after the confidence-weighted
noise was chosen on ``fresh``, its check on unseen sets); ``fresh4`` / ``fresh4_train`` (seeds 5000-5049 /
5000-5009: made after Decision 10, the check of its pedestrian Q candidate on sets no decision saw); ``strong`` /
``strong_train`` (seeds 6000-6049 / 6000-6009, the profile ``cp_strong`` of :data:`PROFILE_VARIANTS`: a stronger
detector than any the decisions saw, made after Decision 10); ``variants_val`` / ``variants_train`` (seeds
7000-7024 on mini_val / 7000-7009 on mini_train, the profiles of :data:`VARIANTS`: made after Decision 11, the
count on other detectors than the four the decisions were taken on); ``fresh5`` (seeds 8000-8049 on mini_val, the
four profiles: made after Decision 12, the count on sets no decision saw; Decision 13 was then taken on it);
``fresh6`` (seeds 9000-9049 on mini_val, the four profiles: made after Decision 13, its count on unseen sets);
``fresh6_train`` (seeds 9000-9024 on mini_train, 8 scenes a set: made after Decision 13, the count on larger unseen
sets); ``fresh7`` (seeds 10000-10049 on mini_val, the four profiles) and ``fresh7_variants`` (seeds 10000-10019
on mini_val, the profiles of :data:`VARIANTS` and ``cp_strong``): made after Decision 13, the count on sets no
decision or candidate had seen; ``dense``, ``dense_variants`` and ``dense_train`` (:data:`DENSE`: the first seeds of
``fresh7``, ``fresh7_variants`` and ``fresh6_train``, each set made denser and messier by
benchmarks/densify_detections.py, as a real detector's file is; Decisions 14 and 15 were taken on them);
``dense2``, ``dense2_variants`` and ``dense2_train`` (the next seeds of the same groups, densified alike: made after
Decision 15, its count on dense sets no decision saw; Decision 16 was then taken on them with the first);
``dense3``, ``dense3_variants`` and ``dense3_train`` (the seeds after those, densified alike: made after Decision
16, its count on dense sets no decision saw; Decision 17 was then taken on the first two); ``dense4``,
``dense4_variants`` and ``dense4_train`` (the seeds after those, densified alike: made after Decision 17's choice,
its count on dense sets no decision saw; Decision 18 was then taken on the first two); ``dense5`` and ``dense5_train``
(the last seeds of ``fresh7`` and ``fresh6_train``, densified alike: made after Decision 18's choice, its count on
dense sets no decision saw; Decision 19 was then measured on every dense group before); ``dense6``,
``dense6_variants`` and ``dense6_train`` (new seeds, ``fresh8``, ``fresh8_variants`` and ``fresh8_train``,
densified alike: made after Decision 19's choice, its count on dense sets no decision saw); ``dense7``,
``dense7_variants`` and ``dense7_train`` (the next seeds of the same groups, densified alike: made after Decision
19's note, a second count of Decision 19 on dense sets no decision saw); ``worlds`` and
``towed`` (:data:`WORLDS`: SYNTHETIC demo worlds of 20 scenes, every scene tracked, the four profiles; ``towed``
with a third of the trailers towed; ``worlds_variants`` with the variant profiles; ``worlds_fresh``, worlds 11-20
made after Decision 13, its count on larger unseen sets). Candidates:
:data:`CANDIDATES` (names; ``--candidates`` a comma list). ``--class NAME`` prints one class's AMOTA instead (sets
without that class left out). ``--compose SPEC`` (repeatable) adds a column composed from the runs already made:
the first candidate with some classes' AMOTA taken from other candidates (``car=+car_ro_gdiou,bus=+bus_punish1``),
the mean over the classes the set has. Each class is tracked on its own (class-aware NMS, association, motion and
lifecycle per class), so this is the AMOTA of the preset that takes those candidates' settings for those classes,
provided each candidate changes per-class settings only and the 500-box limit of a sample does not bind (checked
in the summary: the composed column of a candidate with itself equals its own). For the sets below, the summary
also names the class that decides each (:func:`deciding_class`).
docs/results/default_tracker.md records the table and the decision.
"""

from __future__ import annotations

import argparse
import atexit
import copy
import dataclasses
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import yaml

from grutrack.data import detection_sim
from grutrack.data.detection_sim import simulate_nuscenes
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.evaluation.nuscenes_fast.amota import fast_tracking_eval
from grutrack.export.nuscenes_json import build_submission
from grutrack.io import write_json_atomic
from grutrack.tracking.config import preset_path
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes

sys.path.insert(0, str(Path(__file__).resolve().parent))
from densify_detections import densify_file  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nuscenes"
CLASSES = ("bicycle", "bus", "car", "motorcycle", "pedestrian", "trailer", "truck")
THREE = ("polymot", "fastpoly", "mctrack")
PROFILES = ("centerpoint", "pointpillars", "centerpoint_drift", "centerpoint_velfail")

#: reference set -> (split, detection file relative to the nuScenes data root)
REFERENCE = {
    "ref mini_val cp s7": ("mini_val", "reference/mini_val_centerpoint_sim_s7.json"),
    "ref mini_val pp s7": ("mini_val", "reference/mini_val_pointpillars_sim_s7.json"),
    "ref mini_train cp s7": ("mini_train", "reference/mini_train_centerpoint_sim_s7.json"),
    "REAL mini_val pointpillars": ("mini_val", "detections/pointpillars_mini_val.json"),
}


def _scaled(**factors):
    """A profile edit multiplying ``defaults`` keys (and the same keys in every class override) by ``factors``."""

    def edit(prof: dict) -> None:
        for block in (prof["defaults"], *prof["classes"].values()):
            for key, f in factors.items():
                if key in block:
                    block[key] = block[key] * f

    return edit


#: the noise and false-positive settings the profile ``cp_strong`` halves
STRONG_HALVED = (
    "pos_sigma_m", "pos_sigma_per_m", "pos_tail_prob", "z_sigma_m", "size_sigma_rel", "yaw_sigma_rad", "yaw_flip_prob",
    "vel_sigma_mps", "vel_sigma_rel", "vel_tail_prob", "free_fp_per_frame", "near_fp_rate", "duplicate_prob",
)  # fmt: skip

#: edited detector profiles (groups ``variants``, ``worlds_variants``, ``strong``): name -> (shipped profile, edit)
PROFILE_VARIANTS = {
    "cp_noisyvel": ("centerpoint", _scaled(vel_sigma_mps=2.5, vel_sigma_rel=2.0, vel_tail_prob=2.0)),
    "cp_highfp": ("centerpoint", _scaled(free_fp_per_frame=3.0, near_fp_rate=3.0, fp_score_logit_mean=0.5)),
    "cp_noisypose": ("centerpoint", _scaled(yaw_sigma_rad=2.5, yaw_flip_prob=3.0, pos_sigma_m=1.8)),
    "pp_lowrecall": ("pointpillars", _scaled(recall_max=0.9, score_logit_sigma=1.5)),
    # a stronger detector than any profile the decisions saw: half the pose, size and velocity noise and half the
    # false positives of the CenterPoint-like profile
    "cp_strong": ("centerpoint", _scaled(**dict.fromkeys(STRONG_HALVED, 0.5))),
}


#: the four variants Decisions 1-3 never saw (groups ``variants`` and ``worlds_variants``)
VARIANTS = ("cp_noisyvel", "cp_highfp", "cp_noisypose", "pp_lowrecall")


def profile_arg(profile: str, folder: Path) -> str:
    """What ``simulate_nuscenes`` takes for ``profile``: a shipped name, or a variant's YAML written to ``folder``."""
    if profile not in PROFILE_VARIANTS:
        return profile
    base, edit = PROFILE_VARIANTS[profile]
    prof = yaml.safe_load((detection_sim.PROFILE_DIR / f"{base}.yaml").read_text())
    edit(prof)
    prof["name"], prof["description"] = profile, f"{base} edited for benchmarks/bench_default_tracker.py (SYNTHETIC)"
    path = folder / f"profile_{profile}.yaml"
    path.write_text(yaml.safe_dump(prof, sort_keys=False))
    return str(path)


def generated(
    seeds: tuple[int, ...], splits: tuple[str, ...], profiles: tuple[str, ...] = PROFILES
) -> dict[str, tuple[str, str, int]]:
    """name -> (split, profile, seed) of SYNTHETIC sets."""
    return {
        f"{split} {profile} s{seed}": (split, profile, seed)
        for split in splits
        for seed in seeds
        for profile in profiles
    }


GROUPS = {
    "reference": None,
    "dev": ((100, 101), ("mini_val",)),
    "heldout": ((300, 301, 302), ("mini_val", "mini_train")),
    "dev2": ((110, 111), ("mini_val", "mini_train")),
    "heldout2": ((500, 501, 502), ("mini_val", "mini_train")),
    "heldout3": ((700, 701, 702), ("mini_val", "mini_train")),
    "heldout4": ((900, 901, 902), ("mini_val", "mini_train")),
    "trailer": ((110, 111, 300, 301, 302), ("mini_train",)),
    "trailer_pp": ((110, 111, 300, 301, 302, 500, 501, 502, 700, 701, 702), ("mini_train",)),
    "variants": ((1001, 1002, 1003), ("mini_val", "mini_train"), VARIANTS),
    "fresh": (tuple(range(2000, 2050)), ("mini_val",)),
    "fresh_train": (tuple(range(2000, 2010)), ("mini_train",)),
    "fresh2": (tuple(range(3000, 3050)), ("mini_val",)),
    "fresh2_train": (tuple(range(3000, 3010)), ("mini_train",)),
    "fresh3": (tuple(range(4000, 4050)), ("mini_val",)),
    "fresh3_train": (tuple(range(4000, 4010)), ("mini_train",)),
    "fresh4": (tuple(range(5000, 5050)), ("mini_val",)),
    "fresh4_train": (tuple(range(5000, 5010)), ("mini_train",)),
    "strong": (tuple(range(6000, 6050)), ("mini_val",), ("cp_strong",)),
    "strong_train": (tuple(range(6000, 6010)), ("mini_train",), ("cp_strong",)),
    "variants_val": (tuple(range(7000, 7025)), ("mini_val",), VARIANTS),
    "variants_train": (tuple(range(7000, 7010)), ("mini_train",), VARIANTS),
    "fresh5": (tuple(range(8000, 8050)), ("mini_val",)),
    "fresh6": (tuple(range(9000, 9050)), ("mini_val",)),
    "fresh6_train": (tuple(range(9000, 9025)), ("mini_train",)),
    "fresh7": (tuple(range(10000, 10050)), ("mini_val",)),
    "fresh7_variants": (tuple(range(10000, 10020)), ("mini_val",), (*VARIANTS, "cp_strong")),
    # made after Decision 19, for dense sets no decision saw
    "fresh8": (tuple(range(12000, 12020)), ("mini_val",)),
    "fresh8_variants": (tuple(range(12000, 12010)), ("mini_val",), (*VARIANTS, "cp_strong")),
    "fresh8_train": (tuple(range(12000, 12010)), ("mini_train",)),
}

#: SYNTHETIC sets made denser and messier, as a real detector's file is (benchmarks/densify_detections.py with its
#: defaults: 120 boxes more a sample, copies of its boxes moved by N(0, 6 m) and given any of the ten detection
#: classes and a score U(0.01, 0.3); every score at 2 decimals; 5 % of the boxes repeated exactly; its seed the set's):
#: group -> (the group whose sets are densified, how many of its first seeds). Made after Decision 13.
#: densified groups: name -> (group, first seed's index, count)
DENSE = {
    "dense": ("fresh7", 0, 10),
    "dense_variants": ("fresh7_variants", 0, 5),
    "dense_train": ("fresh6_train", 0, 5),
    "dense2": ("fresh7", 10, 10),
    "dense2_variants": ("fresh7_variants", 5, 5),
    "dense2_train": ("fresh6_train", 5, 5),
    "dense3": ("fresh7", 20, 10),
    "dense3_variants": ("fresh7_variants", 10, 5),
    "dense3_train": ("fresh6_train", 10, 5),
    "dense4": ("fresh7", 30, 10),
    "dense4_variants": ("fresh7_variants", 15, 5),
    "dense4_train": ("fresh6_train", 15, 5),
    "dense5": ("fresh7", 40, 10),
    "dense5_train": ("fresh6_train", 20, 5),
    "dense6": ("fresh8", 0, 10),
    "dense6_variants": ("fresh8_variants", 0, 5),
    "dense6_train": ("fresh8_train", 0, 3),
    "dense7": ("fresh8", 10, 10),
    "dense7_variants": ("fresh8_variants", 5, 5),
    "dense7_train": ("fresh8_train", 3, 3),
}

#: SYNTHETIC demo worlds (grutrack.data.demo, the main job's dataset), ``WORLD_SCENES`` scenes each, every scene
#: tracked (split demo_all): group -> (world seeds, edit of the demo's class specs or None, detector profiles).
#: ``worlds``: the demo as shipped (trailers parked, as in mini); ``towed``: a third of the trailers towed at truck
#: speeds, which mini lacks; ``worlds_variants``: the ``worlds`` with the profiles of :data:`VARIANTS`.
WORLD_SCENES = 20
WORLDS = {
    "worlds": ((1, 2, 3), None, PROFILES),
    "towed": ((4, 5), "towed", PROFILES),
    "worlds_variants": ((1, 2, 3), None, VARIANTS),
    "worlds_fresh": (tuple(range(11, 21)), None, PROFILES),
}


def _towed(specs: dict) -> dict:
    """The demo's class specs with trailers also towed (moving like trucks, 7 +- 2 m/s)."""
    trailer = dataclasses.replace(
        specs["trailer"], static_per_100m=0.5, moving_per_100m=1.5, motion="vehicle", speed=(7.0, 2.0)
    )
    return {**specs, "trailer": trailer}


def world_root(cache: Path, seed: int, edit: str | None) -> Path:
    """The dataroot of one SYNTHETIC world under ``cache`` (generated once)."""
    from grutrack.data import demo

    root = cache / f"world_{edit or 'demo'}_s{seed}"
    if not (root / "v1.0-demo").is_dir():
        shipped = demo.CLASS_SPECS
        demo.CLASS_SPECS = _towed(shipped) if edit == "towed" else shipped
        try:
            demo.generate_demo(root, scenes=WORLD_SCENES, seed=seed)
        finally:
            demo.CLASS_SPECS = shipped
    return root


def _per_class(value) -> dict:
    return {c: value for c in CLASSES}


def _mctrack() -> dict:
    return yaml.safe_load(preset_path("mctrack").read_text())


# --- candidates: each a function of the ekf preset's dict (changed in place) ---------------------------------------


def _nms(raw):  # MCTrack's per-class NMS thresholds (kept box's class)
    raw["preprocessing"]["nms_threshold"] = _mctrack()["preprocessing"]["nms_threshold"]


def _nms_order(raw):  # detections numbered in NMS's score order
    raw["preprocessing"]["nms_order"] = "score"


def _stage_one_ro_gdiou(a: dict, classes) -> None:
    """``association`` ``a`` with Ro_GDIoU as the first metric of ``classes``: their crowded rule off (stage 1 is
    Ro_GDIoU already; the config refuses both), and with it the lost newborns' skip when no class keeps the rule
    or every class is on Ro_GDIoU (MCTrack's one-stage association, which has no size gate either)."""
    if "crowded_threshold" in a:
        a["crowded_threshold"] = {**a["crowded_threshold"], **dict.fromkeys(classes, 0.0)}
    if not any(v > 0 for v in a.get("crowded_threshold", {}).values()) or set(classes) == set(CLASSES):
        a.pop("crowded_skips_lost_newborns", None)
    if set(classes) == set(CLASSES):
        a.pop("size_gate", None)


def _ro_gdiou(raw):  # Ro_GDIoU one stage, MCTrack's weights and thresholds, predicted pose
    m = _mctrack()["association"]
    a = raw["association"]
    a.update(
        first_metric=m["first_metric"], first_threshold=m["first_threshold"], ro_gdiou_weights=m["ro_gdiou_weights"]
    )
    _stage_one_ro_gdiou(a, CLASSES)
    a["two_stage"] = False
    a["distance_gate"] = dict.fromkeys(CLASSES, 0.0)  # MCTrack's association has no centre gate


def _first_frames(raw):  # every live track written in a scene's first 3 frames
    raw["lifecycle"]["write_first_frames"] = 3


def _lifetimes(raw):  # MCTrack's max_age
    raw["lifecycle"]["max_age"] = _mctrack()["lifecycle"]["max_age"]


def _decoupled(raw):  # MCTrack's decoupled CV position / size filters with all their options
    m = _mctrack()["motion"]
    raw["motion"] = {k: v for k, v in m.items()}


def _decoupled_ts(raw):  # the same with the timestamps' step
    _decoupled(raw)
    raw["motion"]["time_step"] = "timestamps"


def _motion_q(scale_q: float, scale_r: float, name: str):
    """Per-class Q / R: a motion config equal to the ekf preset's with each class's Q and R scaled."""

    def change(raw):
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        for cls in base["classes"].values():
            for key, s in (("Q", scale_q), ("R", scale_r)):
                v = cls[key]
                cls[key] = [x * s for x in v] if isinstance(v, list) else v * s
        raw["motion"]["config"] = _write_motion(base, name)

    return change


def _velocity_r(values: dict, name: str):
    """Per-class measurement noise of the detector's velocity (R entries vx, vy, (m/s)^2) for the classes given."""

    def change(raw):
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        for cls, r in values.items():
            entry = base["classes"][cls]
            entry["R"] = list(entry["R"][:7]) + [r, r]
        raw["motion"]["config"] = _write_motion(base, name)

    return change


def _process_q(values: dict, name: str, then=None):
    """Per-class process noise Q (one scale for the diagonal) for the classes given; ``then``: a change first."""

    def change(raw):
        if then is not None:
            then(raw)
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        for cls, q in values.items():
            base["classes"][cls]["Q"] = q
        raw["motion"]["config"] = _write_motion(base, name)

    return change


#: MCTrack's per-class velocity noise relative to its position noise (R_v / R_xy of KALMAN_FILTER_POSE.CV), applied
#: to the ekf preset's position noise 1; trailer (CA, no velocity measurement of this form) keeps its own
MCT_VEL_RATIO = {"bicycle": 10.0, "bus": 333.3, "car": 0.714, "motorcycle": 1.0, "pedestrian": 1.75, "truck": 2.667}


def _motion_file(name: str) -> str:
    p = Path(name)
    return str(p) if p.suffix else str(Path(preset_path("ekf")).parents[1] / "motion" / f"{name}.yaml")


_TMP = Path(tempfile.mkdtemp(prefix="bench_default_tracker_"))  # candidate presets; removed at exit
atexit.register(shutil.rmtree, _TMP, True)


_WRITTEN: dict[str, str] = {}  # motion file name -> its text, so two candidates never share a name


def _write_motion(cfg: dict, name: str) -> str:
    """The motion config ``cfg`` written as ``motion_<name>.yaml``; a name written before with other contents is a
    ValueError (the later candidate would change the file the earlier one's preset points to)."""
    text = yaml.safe_dump(cfg)
    if _WRITTEN.setdefault(name, text) != text:
        raise ValueError(f"motion file name {name!r} is used by two candidates with different configs")
    path = _TMP / f"motion_{name}.yaml"
    path.write_text(text)
    return str(path)


def _punish(values: dict):
    def change(raw):
        raw["lifecycle"]["punish_num"].update(values)

    return change


def _model(values: dict):
    """Per-class motion model override (a class switched takes that model's defaults of the motion config)."""

    def change(raw):
        raw["motion"]["model_override"] = {**raw["motion"].get("model_override", {}), **values}

    return change


def _first_stage(cls: str, metric: str, threshold: float):
    """One class's stage-1 metric and threshold (e.g. BEV GIoU for trailers), the rest unchanged."""

    def change(raw):
        raw["association"]["first_metric"][cls] = metric
        raw["association"]["first_threshold"][cls] = threshold

    return change


def _class_motion(cls: str, name: str, model: str | None = None, scale: dict | None = None, **noise):
    """One class's motion model and noise in the motion config: ``model`` (None keeps it), ``noise`` P0 / Q / R
    (number or diagonal list) replacing the entry, ``scale``: {key: factor} applied after."""

    def change(raw):
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        entry = base["classes"][cls]
        if model is not None and model != entry["model"]:
            entry.update(copy.deepcopy(base["models"][model]), model=model)
            entry.pop("params", None)
        entry.update(noise)
        for key, f in (scale or {}).items():
            v = entry[key]
            entry[key] = [x * f for x in v] if isinstance(v, list) else v * f
        raw["motion"]["config"] = _write_motion(base, name)

    return change


def _moving_motion(cls: str, name: str, speed: float, model: str, **noise):
    """A second model for one class's tracks born at or above ``speed`` m/s (motion config ``moving``)."""

    def change(raw):
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        base["classes"][cls]["moving"] = {"speed": speed, "model": model, **noise}
        raw["motion"]["config"] = _write_motion(base, name)

    return change


def _without_moving(cls: str, name: str):
    """One class's ``moving`` model removed (its tracks all on the class's model)."""

    def change(raw):
        base = yaml.safe_load(Path(_motion_file(raw["motion"]["config"])).read_text())
        base["classes"][cls].pop("moving", None)
        raw["motion"]["config"] = _write_motion(base, name)

    return change


#: MCTrack-like CV noise for one class (its position / velocity R, Q of the decoupled filter) on the CV state
#: (x, y, z, w, l, h, vx, vy, yaw); measurement order (x, y, z, w, l, h, yaw, vx, vy)
def _cv_mct(q_xy, q_v, r_xy, r_v):
    return dict(
        P0=[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 10.0, 10.0, 1.0],
        Q=[q_xy, q_xy, q_xy, 0.5, 0.5, 0.5, q_v, q_v, 1.0],
        R=[r_xy, r_xy, r_xy, 2.0, 2.0, 2.0, 1.0, r_v, r_v],
    )


def _coast(turn, accel):
    """The classes ``turn`` hold their turn rate, the classes ``accel`` their acceleration at 0 while coasting."""

    def change(raw):
        raw["motion"]["coast_yaw_rate"] = {c: "zero" if c in turn else "keep" for c in CLASSES}
        raw["motion"]["coast_acceleration"] = {c: "zero" if c in accel else "keep" for c in CLASSES}

    return change


def _nms_class(raw, cls: str, threshold: float):
    """One class's NMS threshold (the others keep the preset's)."""
    t = raw["preprocessing"]["nms_threshold"]
    raw["preprocessing"]["nms_threshold"] = {
        **({c: t for c in CLASSES} if not isinstance(t, dict) else t),
        cls: threshold,
    }


def _age(values: dict):
    def change(raw):
        raw["lifecycle"]["max_age"].update(values)

    return change


def _young(discount: float):
    def change(raw):
        raw["lifecycle"]["young_track_discount"] = discount

    return change


def _nis(limit: float):  # the robust update's limit, on every track (nis_min_hits 0)
    def change(raw):
        raw["motion"].update(nis_limit=limit, nis_min_hits=0)

    return change


def _nis_hits(hits: int):  # the robust update only for tracks with this many matched detections before
    def change(raw):
        raw["motion"]["nis_min_hits"] = hits

    return change


def _crowded(classes: dict[str, tuple[float, list[float]]]):
    """``association.crowded_threshold`` of ``classes`` (name -> MCTrack's threshold and weights): Ro_GDIoU for
    their stage-1 rows and columns with more than one candidate."""

    def change(raw):
        a = raw["association"]
        a.setdefault("crowded_threshold", _per_class(0.0))
        a.setdefault("ro_gdiou_weights", _per_class([1.0, 1.0]))
        for cls, (threshold, weights) in classes.items():
            a["crowded_threshold"][cls], a["ro_gdiou_weights"][cls] = threshold, weights

    return change


def _prev12(raw):
    """The preset before Decision 12: cars' crowded stage-1 rows judged by the first metric (car threshold 0, the
    default Ro_GDIoU weights), and no lost newborn left out of the crowded test."""
    a = raw["association"]
    a["crowded_threshold"]["car"] = 0.0
    a.pop("ro_gdiou_weights", None)
    a.pop("crowded_skips_lost_newborns", None)


def _lost_newborn(penalty: float):
    """``association.lost_newborn_penalty`` ``penalty`` for every class."""

    def change(raw):
        raw["association"]["lost_newborn_penalty"] = _per_class(penalty)

    return change


def _ro_gdiou_class(classes: dict[str, tuple[float, list[float]]]):
    """Stage 1 of ``classes`` (name -> MCTrack's threshold and weights) on Ro_GDIoU, the track's predicted box
    against the detection; the other classes and stage 2 as they are."""

    def change(raw):
        a = raw["association"]
        a["ro_gdiou_weights"] = _per_class([1.0, 1.0])
        for cls, (threshold, weights) in classes.items():
            a["first_metric"][cls], a["first_threshold"][cls] = "ro_gdiou_bev", threshold
            a["ro_gdiou_weights"][cls] = weights
        _stage_one_ro_gdiou(a, classes)

    return change


def _combine(*changes):
    def change(raw):
        for c in changes:
            c(raw)

    return change


#: Decision 5's trailers taken back: Poly-MOT's CA for every trailer
_TRAILER_CA = _combine(
    _class_motion("trailer", "trlca", "CA", P0=0.01, Q=100.0, R=0.001), _without_moving("trailer", "trlcanomov")
)


#: the preset before this decision (punish_num 1 for bus, trailer, truck); every candidate but ``ekf`` (the preset as
#: it is) starts from it, so ``+punish_large2`` is the preset now
BEFORE = {"bus": 1, "trailer": 1, "truck": 1}


def _heading_r(r_yaw: float) -> list[float]:
    """The CTRA classes' R of grutrack_nusc with the detected heading's variance (rad^2) ``r_yaw``."""
    return [1, 1, 1, 1, 1, 1, r_yaw, 2, 2]


_CTRA_R = _heading_r(1.0)  # Poly-MOT's heading R, the preset's before Decision 13


def _bus_score(threshold: float):
    """Bus detections scored below ``threshold`` dropped."""
    return lambda raw: raw["preprocessing"]["score_threshold"].update(bus=threshold)


def _bus_gate(radius: float, growth: str | float):
    """The buses' distance gate at ``radius`` metres, ``growth`` fixed, missed_frames or a speed in m/s (the other
    classes fixed)."""

    def change(raw):
        a = raw["association"]
        a["distance_gate"]["bus"] = radius
        a["distance_gate_growth"] = {
            **dict.fromkeys(CLASSES, "fixed"),
            **a.get("distance_gate_growth", {}),
            "bus": growth,
        }

    return change


def _bicycle_gate(radius: float):
    """The bicycles' distance gate at ``radius`` metres (0: none), fixed unless a candidate grows it."""
    return lambda raw: raw["association"]["distance_gate"].update(bicycle=radius)


def _size_gate(ratio: float):
    """Every class's ``association.size_gate`` at ``ratio`` (0: off): a pair is scored only when the smaller
    footprint area is at least this fraction of the larger."""
    return lambda raw: raw["association"].update(size_gate=dict.fromkeys(CLASSES, ratio))


def _bus_delete(threshold: float):
    """Buses' ``lifecycle.delete_threshold`` (a track dies once the mean of its per-frame scores falls below it)."""
    return lambda raw: raw["lifecycle"]["delete_threshold"].update(bus=threshold)


#: Decision 15 taken back: no bus gate, no grown gate, every bus detection kept (Decision 14's preset)
_PREV15 = _combine(
    lambda raw: raw["association"]["distance_gate"].update(bus=0.0),
    lambda raw: raw["association"].pop("distance_gate_growth"),
    _bus_score(0.0),
)

#: Decision 16 taken back: the buses' gate at 6 m grown with the missed frames (Decision 15's preset)
_PREV16 = _bus_gate(6.0, "missed_frames")

#: Decision 17 taken back: no bicycle gate (Decision 16's preset)
_PREV17 = _bicycle_gate(0.0)
#: the bicycle gates measured (candidate name suffix, radius in metres)
_BICYCLE_RADII = (("1", 1.0), ("1_5", 1.5), ("2", 2.0), ("2_5", 2.5), ("3", 3.0), ("4", 4.0))


CANDIDATES = {
    "ekf": lambda raw: None,
    "ekf_before": lambda raw: None,
    "+mct_nms": _nms,
    "+nms_order": _nms_order,
    "+ro_gdiou": _ro_gdiou,
    "+first_frames": _first_frames,
    "+ro_gdiou_own_thr": _combine(
        lambda raw: raw["association"].update(
            first_metric=dict.fromkeys(CLASSES, "ro_gdiou_bev"),
            two_stage=False,
            distance_gate=dict.fromkeys(CLASSES, 0.0),
        ),
        lambda raw: _stage_one_ro_gdiou(raw["association"], CLASSES),
    ),
    "+mct_max_age": _lifetimes,
    "+decoupled_cv": _decoupled,
    "+decoupled_cv_ts": _decoupled_ts,
    "+Q2": _motion_q(2.0, 1.0, "q2"),
    "+Q05": _motion_q(0.5, 1.0, "q05"),
    "+Q02": _motion_q(0.2, 1.0, "q02"),
    "+R2": _motion_q(1.0, 2.0, "r2"),
    "+R_vel_bus100": _velocity_r({"bus": 100.0}, "rbus100"),
    "+R_vel_bus10": _velocity_r({"bus": 10.0}, "rbus10"),
    "+R_vel_mct": _velocity_r(MCT_VEL_RATIO, "rmct"),
    "+R_vel_bic10": _velocity_r({"bicycle": 10.0}, "rbic10"),
    "+R_vel_bic5": _velocity_r({"bicycle": 5.0}, "rbic5"),
    "+R_vel_bic30": _velocity_r({"bicycle": 30.0}, "rbic30"),
    "+R_vel_bic100": _velocity_r({"bicycle": 100.0}, "rbic100"),
    "+R_vel_bic10_bus30": _velocity_r({"bicycle": 10.0, "bus": 30.0}, "rbic10bus30"),
    "+R_vel_bic10_bus100": _velocity_r({"bicycle": 10.0, "bus": 100.0}, "rbic10bus100"),
    "+R_vel_car07": _velocity_r({"car": 0.714}, "rcar07"),
    "+R_vel_car1": _velocity_r({"car": 1.0}, "rcar1"),
    "+R_vel_mct_nocar": _velocity_r({k: v for k, v in MCT_VEL_RATIO.items() if k != "car"}, "rmctnocar"),
    "+R_vel_bic10+Q_bus4": _process_q({"bus": 4.0}, "bic10qbus4", _velocity_r({"bicycle": 10.0}, "rbic10")),
    "+R_vel_bic10+Q_bus10": _process_q({"bus": 10.0}, "bic10qbus10", _velocity_r({"bicycle": 10.0}, "rbic10")),
    "+R_vel_bic10+punish_bus2": _combine(_velocity_r({"bicycle": 10.0}, "rbic10"), _punish({"bus": 2})),
    "+R_vel_bic10+punish_car2": _combine(_velocity_r({"bicycle": 10.0}, "rbic10"), _punish({"car": 2})),
    "+R_vel_bic10+punish_large2": _combine(
        _velocity_r({"bicycle": 10.0}, "rbic10"), _punish({"bus": 2, "trailer": 2, "truck": 2})
    ),
    "+trailer_ctra": _model({"trailer": "CTRA"}),
    "+ped_age8": _age({"pedestrian": 8}),
    "+ped_cv_mct": _class_motion("pedestrian", "pedcv", "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
    "+ped_cv_q3": _class_motion("pedestrian", "pedcvq3", "CV", **_cv_mct(3.0, 3.0, 2.0, 3.5)),
    "+ped_cv_q07": _class_motion("pedestrian", "pedcvq07", "CV", **_cv_mct(0.75, 0.75, 2.0, 3.5)),
    "+ped_cv_r1": _class_motion("pedestrian", "pedcvr1", "CV", **_cv_mct(1.5, 1.5, 1.0, 3.5)),
    "+ped_cv_r4": _class_motion("pedestrian", "pedcvr4", "CV", **_cv_mct(1.5, 1.5, 4.0, 3.5)),
    "+ped_cv_rv2": _class_motion("pedestrian", "pedcvrv2", "CV", **_cv_mct(1.5, 1.5, 2.0, 2.0)),
    "+ped_cv_rv7": _class_motion("pedestrian", "pedcvrv7", "CV", **_cv_mct(1.5, 1.5, 2.0, 7.0)),
    "+ped_ctra_mct": _class_motion("pedestrian", "pedctramct", scale={"R": 2.0, "Q": 1.5}),
    "+trailer_ca_R3": _class_motion("trailer", "trlcar3", R=3.0, Q=1.0, P0=1.0),
    "+trailer_ca_R1Q03": _class_motion("trailer", "trlcar1q03", R=1.0, Q=0.3, P0=1.0),
    "+trailer_ca_R01": _class_motion("trailer", "trlcar01", R=0.1, Q=1.0, P0=1.0),
    "+trailer_cv_R1": _class_motion("trailer", "trlcvr1", "CV", R=1.0, Q=1.0, P0=1.0),
    "+trailer_cv_fp": _class_motion("trailer", "trlcvfp", "CV", P0=0.01, Q=0.04, R=0.001),
    "+trailer_ca_q004": _class_motion("trailer", "trlcaq004", P0=0.01, Q=0.04, R=0.001),
    "+trailer_ca_q1": _class_motion("trailer", "trlcaq1", P0=0.01, Q=1.0, R=0.001),
    "+trailer_cv_q1": _class_motion("trailer", "trlcvq1", "CV", P0=0.01, Q=1.0, R=0.001),
    "+trailer_score017": lambda raw: raw["preprocessing"]["score_threshold"].update(trailer=0.17),
    "+trailer_punish1": _punish({"trailer": 1}),
    "+trailer_age8": _age({"trailer": 8}),
    "+trailer_median": lambda raw: raw["motion"]["geometry_filter"].update(trailer="median"),
    "+trailer_thr116": lambda raw: raw["association"]["first_threshold"].update(trailer=1.16),
    "+trailer_thr14": lambda raw: raw["association"]["first_threshold"].update(trailer=1.4),
    "+trailer_giou_bev": _first_stage("trailer", "giou_bev", 1.25),
    "+trailer_nms012": lambda raw: _nms_class(raw, "trailer", 0.12),
    "+trailer_nms02": lambda raw: _nms_class(raw, "trailer", 0.2),
    "+trailer_nms05": lambda raw: _nms_class(raw, "trailer", 0.5),
    "+trailer_gate3": lambda raw: raw["association"]["distance_gate"].update(trailer=3.0),
    "+trailer_gate5": lambda raw: raw["association"]["distance_gate"].update(trailer=5.0),
    "+trailer_thr1": lambda raw: raw["association"]["first_threshold"].update(trailer=1.0),
    "+trailer_gate5+cv_fp": lambda raw: (
        raw["association"]["distance_gate"].update(trailer=5.0),
        _class_motion("trailer", "trlcvfp", "CV", P0=0.01, Q=0.04, R=0.001)(raw),
    ),
    "+trailer_gate5+thr116": lambda raw: (
        raw["association"]["distance_gate"].update(trailer=5.0),
        raw["association"]["first_threshold"].update(trailer=1.16),
    ),
    # the preset before the pedestrian / trailer decision (pedestrian CTRA, no trailer gate)
    "ekf_prev": lambda raw: (
        raw["association"]["distance_gate"].update(trailer=0.0),
        _class_motion("pedestrian", "pedctra", "CTRA")(raw),
    ),
    "-trailer_gate": lambda raw: raw["association"]["distance_gate"].update(trailer=0.0),
    "-ped_cv": _class_motion("pedestrian", "pedctra", "CTRA"),  # the preset before the pedestrian decision
    "-velocity_check": lambda raw: raw["motion"].update(velocity_check_updates=0),  # the preset before it
    "+velocity_check3": lambda raw: raw["motion"].update(velocity_check_updates=3),
    "+velocity_check4": lambda raw: raw["motion"].update(velocity_check_updates=4),
    "+velocity_check5": lambda raw: raw["motion"].update(velocity_check_updates=5),
    "+velocity_check6": lambda raw: raw["motion"].update(velocity_check_updates=6),
    "+ped_cv_mct+trailer_ca_R01": _combine(
        _class_motion("pedestrian", "pedcv", "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
        _class_motion("trailer", "pedcv_trlcar01", R=0.1, Q=1.0, P0=1.0),
    ),
    "+moto_cv_mct": _class_motion("motorcycle", "motocvmct", "CV", **_cv_mct(0.5, 4.0, 0.1, 0.1)),
    "+moto_cv_ped": _class_motion("motorcycle", "motocvped", "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
    "+moto_cv_ped_thr16": _combine(
        _class_motion("motorcycle", "motocvped", "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
        lambda raw: raw["association"]["first_threshold"].update(motorcycle=1.6),
    ),
    "+moto_moving_cv": _moving_motion("motorcycle", "motomovcv", 2.0, "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
    "+moto_moving_cv1": _moving_motion("motorcycle", "motomovcv1", 1.0, "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
    # Decision 5 taken back: trailers on Poly-MOT's CA (the box is the detection), bicycles all on Bicycle
    "-trailer_cv": _TRAILER_CA,
    "-bic_moving": _without_moving("bicycle", "bicnomov"),
    "-trailer_towed_ca": _without_moving("trailer", "trlcvall"),  # every trailer on CV, towed ones too
    "ekf_prev5": _combine(_TRAILER_CA, _without_moving("bicycle", "bicnomov5"), _young(0.0), _nis(0.0)),
    # CTRA vehicles' position measured with more noise (R x, y, z), i.e. smoothed over their detections
    "+truck_rpos2": _class_motion("truck", "trkrpos2", R=[2, 2, 2, 1, 1, 1, 1, 2, 2]),
    "+truck_rpos4": _class_motion("truck", "trkrpos4", R=[4, 4, 4, 1, 1, 1, 1, 2, 2]),
    "+vehicle_rpos2": _combine(
        *(_class_motion(c, f"{c}rpos2v", R=[2, 2, 2, 1, 1, 1, 1, 2, 2]) for c in ("bus", "car", "truck"))
    ),
    "+bic_moving_cv": _moving_motion("bicycle", "bicmovcv", 2.0, "CV", **_cv_mct(1.5, 1.5, 2.0, 3.5)),
    "+bic_moving_mct": _moving_motion("bicycle", "bicmovmct", 2.0, "CV", **_cv_mct(0.3, 1.0, 0.1, 1.0)),
    # riding bicycles' CV with a position R of 1 or 0.5 m^2 instead of MCTrack's 0.1 (one off detection pulls less)
    "+bic_moving_r1": _moving_motion("bicycle", "bicmovr1", 2.0, "CV", **_cv_mct(0.3, 1.0, 1.0, 1.0)),
    "+bic_moving_r05": _moving_motion("bicycle", "bicmovr05", 2.0, "CV", **_cv_mct(0.3, 1.0, 0.5, 1.0)),
    "+bic_all_mct": _moving_motion("bicycle", "bicallmct", 0.01, "CV", **_cv_mct(0.3, 1.0, 0.1, 1.0)),
    "+bic_moving1_mct": _moving_motion("bicycle", "bicmov1mct", 1.0, "CV", **_cv_mct(0.3, 1.0, 0.1, 1.0)),
    "+bic_age14": _age({"bicycle": 14}),
    "+bic_punish1": _punish({"bicycle": 1}),
    "+bic_thr18": lambda raw: raw["association"]["first_threshold"].update(bicycle=1.8),
    # MCTrack's stage 1 (Ro_GDIoU, its thresholds and weights) for some classes, stage 2 kept
    "+ped_ro_gdiou": _ro_gdiou_class({"pedestrian": (2.06, [1.0, 1.0])}),
    "+car_ro_gdiou": _ro_gdiou_class({"car": (1.1, [0.5, 1.5])}),
    "+car_ped_ro_gdiou": _ro_gdiou_class({"pedestrian": (2.06, [1.0, 1.0]), "car": (1.1, [0.5, 1.5])}),
    "+vehicle_ped_ro_gdiou": _ro_gdiou_class(
        {
            "pedestrian": (2.06, [1.0, 1.0]),
            "car": (1.1, [0.5, 1.5]),
            "bus": (1.6, [1.0, 1.0]),
            "truck": (1.16, [1.0, 1.0]),
        }
    ),
    # Ro_GDIoU (MCTrack's threshold and weights) only for the crowded rows and columns of stage 1
    "+car_ped_crowded": _crowded({"car": (1.1, [0.5, 1.5]), "pedestrian": (2.06, [1.0, 1.0])}),
    "+car_crowded": _crowded({"car": (1.1, [0.5, 1.5])}),
    "+car_crowded_punish0": _combine(_crowded({"car": (1.1, [0.5, 1.5])}), _punish({"car": 0})),
    # a lost newborn track (matched at birth only, missed since) yields a near tie in stage 1
    "+lost_newborn": _lost_newborn(0.1),
    "+car_crowded+lost_newborn": _combine(_crowded({"car": (1.1, [0.5, 1.5])}), _lost_newborn(0.1)),
    # lost newborns left out of the crowded test (they make no row crowded, their pairs keep the first metric)
    "+skip_lost": lambda raw: raw["association"].update(crowded_skips_lost_newborns=True),
    "+car_crowded+skip_lost": _combine(
        _crowded({"car": (1.1, [0.5, 1.5])}), lambda raw: raw["association"].update(crowded_skips_lost_newborns=True)
    ),
    "+ped_crowded": _crowded({"pedestrian": (2.06, [1.0, 1.0])}),
    # the preset before Decision 10 (crowded pedestrians judged by the first metric, as every pair)
    "ekf_prev10": _combine(_prev12, lambda raw: raw["association"].pop("crowded_threshold"), _coast((), ())),
    # the preset before Decision 11 (every coasting track predicted by its model, Poly-MOT's)
    "ekf_prev11": _combine(_prev12, _coast((), ())),
    # the preset before Decision 12 (cars' crowded rows judged by the first metric; no lost newborn skipped)
    "ekf_prev12": _prev12,
    # the preset before Decision 13 (buses' and trucks' detected heading measured with Poly-MOT's R 1)
    "ekf_prev13": _combine(_class_motion("bus", "prev13bus", R=_CTRA_R), _class_motion("truck", "prev13", R=_CTRA_R)),
    "-bus_heading": _class_motion("bus", "busyaw1", R=_CTRA_R),  # Decision 13 for trucks only
    "-truck_heading": _class_motion("truck", "truckyaw1", R=_CTRA_R),  # Decision 13 for buses only
    "+long_heading001": _combine(
        _class_motion("bus", "busyaw001", R=_heading_r(0.01)), _class_motion("truck", "truckyaw001", R=_heading_r(0.01))
    ),
    "+car_heading": _class_motion("car", "caryaw01", R=_heading_r(0.1)),  # cars' heading R 0.1 as well
    "+bus_bicycle": _model({"bus": "Bicycle"}),  # buses on Poly-MOT's Bicycle model (slip angle at the centre)
    # Decision 12 without its skip: lost newborns make rows crowded as any track
    "-skip_lost": lambda raw: raw["association"].update(crowded_skips_lost_newborns=False),
    "+bus_ro_gdiou": _ro_gdiou_class({"bus": (1.6, [1.0, 1.0])}),
    "+bic_ro_gdiou": _ro_gdiou_class({"bicycle": (2.0, [1.0, 1.0])}),
    "+bus_bic_ro_gdiou": _ro_gdiou_class({"bus": (1.6, [1.0, 1.0]), "bicycle": (2.0, [1.0, 1.0])}),
    "+bus_score016": lambda raw: raw["preprocessing"]["score_threshold"].update(bus=0.16),
    "+bus_score010": lambda raw: raw["preprocessing"]["score_threshold"].update(bus=0.1),
    "+bus_score016_ro": _combine(
        lambda raw: raw["preprocessing"]["score_threshold"].update(bus=0.16),
        _ro_gdiou_class({"bus": (1.6, [1.0, 1.0])}),
    ),
    "+bic_score02": lambda raw: raw["preprocessing"]["score_threshold"].update(bicycle=0.2),
    "+bic_score017": lambda raw: raw["preprocessing"]["score_threshold"].update(bicycle=0.17),
    # confidence-weighted noise, R / score^e (motion.r_score_exponent)
    "+r_score": lambda raw: raw["motion"].update(r_score_exponent=1.0),
    "-r_score": lambda raw: raw["motion"].update(r_score_exponent=0.0),
    "+r_score05": lambda raw: raw["motion"].update(r_score_exponent=0.5),
    "+r_score2": lambda raw: raw["motion"].update(r_score_exponent=2.0),
    "+r_score_bus016": _combine(
        lambda raw: raw["motion"].update(r_score_exponent=1.0),
        lambda raw: raw["preprocessing"]["score_threshold"].update(bus=0.16),
    ),
    # stage 2 (BEV GIoU on what stage 1 left) with a looser threshold
    # a coasting track goes straight on at constant speed (turn rate and acceleration held at 0)
    "+coast_zero": _coast(CLASSES, CLASSES),
    "+coast_turn0": _coast(CLASSES, ()),
    "+coast_accel0": _coast((), CLASSES),
    "+bic_s2_13": lambda raw: raw["association"]["second_threshold"].update(bicycle=1.3),
    "+bic_s2_15": lambda raw: raw["association"]["second_threshold"].update(bicycle=1.5),
    "+all_s2_12": lambda raw: raw["association"]["second_threshold"].update(dict.fromkeys(CLASSES, 1.2)),
    "+car_punish0": _punish({"car": 0}),
    "+bus_punish1": _punish({"bus": 1}),
    "+bus_age15": _age({"bus": 15}),
    "+moto_bic_qyaw01": _class_motion("motorcycle", "motobicqyaw01", Q=[1, 1, 1, 1, 1, 1, 1, 1, 0.1, 0.1]),
    "+ped_R05": _class_motion("pedestrian", "pedr05", scale={"R": 0.5}),
    "+ped_R2": _class_motion("pedestrian", "pedr2", scale={"R": 2.0}),
    "+ped_R3": _class_motion("pedestrian", "pedr3", scale={"R": 3.0}),
    "+ped_R4": _class_motion("pedestrian", "pedr4", scale={"R": 4.0}),
    "+ped_R2Q05": _class_motion("pedestrian", "pedr2q05", scale={"R": 2.0, "Q": 0.5}),
    "+ped_Q025": _class_motion("pedestrian", "pedq025", scale={"Q": 0.25}),
    "+ped_Q05": _class_motion("pedestrian", "pedq05", scale={"Q": 0.5}),
    "+ped_Q2": _class_motion("pedestrian", "pedq2", scale={"Q": 2.0}),
    "+trailer_cv_mct": _class_motion("trailer", "trlcv", "CV", **_cv_mct(0.3, 0.1, 2.0, 2.5)),
    "+trailer_ctra_R2": _class_motion("trailer", "trlctrar2", "CTRA", scale={"R": 2.0}),
    "+trailer_ca_R1": _class_motion("trailer", "trlcar1", R=1.0, Q=1.0, P0=1.0),
    "+trailer_mct_life": _combine(  # MCTrack's trailer score threshold, NMS, max_age and punish_num together
        lambda raw: raw["preprocessing"]["score_threshold"].update(trailer=0.17),
        lambda raw: _nms_class(raw, "trailer", 0.12),
        _age({"trailer": 8}),
        _punish({"trailer": 1}),
    ),
    "+mct_score": lambda raw: raw["preprocessing"].update(  # MCTrack's per-class score thresholds
        score_threshold=_mctrack()["preprocessing"]["score_threshold"]
    ),
    "+score_detection": lambda raw: raw["lifecycle"].update(score_update="detection"),
    "+punish_bus2": _punish({"bus": 2}),
    "+punish_large2": _punish({"bus": 2, "trailer": 2, "truck": 2}),
    "+nms+first_frames": _combine(_nms, _first_frames),
    "+nms+ro_gdiou+first_frames": _combine(_nms, _ro_gdiou, _first_frames),
    # a young track's box written at a lower score: s (1 - d^hits); ekf_prev6 the preset before Decision 6 (off)
    "ekf_prev6": _combine(_young(0.0), _nis(0.0)),
    **{f"+young{d}": _young(d) for d in (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)},
    # a 5 m centre gate (stage 1) beyond trailers: a far-off detection starts a track instead of pulling one
    "+bus_gate5": lambda raw: raw["association"]["distance_gate"].update(bus=5.0),
    "+bus_truck_gate5": lambda raw: raw["association"]["distance_gate"].update(bus=5.0, truck=5.0),
    # a gate on every class is Fast-Poly's gated association, which has no crowded rule (measured before Decision 10)
    "+all_gate5": _combine(
        lambda raw: raw["association"]["distance_gate"].update(dict.fromkeys(CLASSES, 5.0)),
        lambda raw: raw["association"].pop("crowded_threshold", None),
        lambda raw: raw["association"].pop("ro_gdiou_weights", None),
        lambda raw: raw["association"].pop("crowded_skips_lost_newborns", None),
        lambda raw: raw["association"].pop("distance_gate_growth", None),  # Fast-Poly's gate is fixed
        lambda raw: raw["association"].pop("size_gate", None),  # its dense costs have no size gate
    ),
    "+young0.4+score_detection": _combine(_young(0.4), lambda raw: raw["lifecycle"].update(score_update="detection")),
    # robust update: a detection's R scaled by NIS / g when its position NIS exceeds g (motion.nis_limit); ekf_prev7
    # the preset before Decision 7 (off)
    "ekf_prev7": _nis(0.0),
    **{f"+nis{g}": _nis(g) for g in (1.5, 2.0, 3.0)},
    # the robust update only for tracks with at least h matched detections before the update (motion.nis_min_hits)
    **{f"+nis_hits{h}": _nis_hits(h) for h in (3, 4, 6)},
    # Fast-Poly's termination (a track also dies once the mean of its per-frame scores since birth falls below its
    # class's delete threshold, Fast-Poly's life_cycle.score.delete_thre): the preset since Decision 14, which
    # ekf_prev14 takes back (death by age alone)
    "ekf_prev14": lambda raw: (raw["lifecycle"].update(termination="age"), raw["lifecycle"].pop("delete_threshold")),
    # buses' stage-1 cost threshold at Fast-Poly's 1.16 (GIoU above -0.16) or halfway, 1.25
    "+bus116": lambda raw: raw["association"]["first_threshold"].update(bus=1.16),
    "+bus125": lambda raw: raw["association"]["first_threshold"].update(bus=1.25),
    # bus detections scored below Fast-Poly's 0.12 dropped, on Decision 14's preset (Decision 15 took it)
    "+bus_score012": _combine(_PREV15, _bus_score(0.12)),
    # a 3 m centre gate for buses (Fast-Poly's gate radius)
    "+bus_gate3": lambda raw: raw["association"]["distance_gate"].update(bus=3.0),
    # Decision 15: buses gated at 6 m grown with the frames since the track's last detection
    # (association.distance_gate_growth), bus detections scored below 0.12 dropped; ekf_prev15 takes it back
    "ekf_prev15": _PREV15,
    # other bus choices measured against Decision 14 (ekf_prev15)
    "ekf_prev15+bus_gate4_fixed": _combine(_PREV15, _bus_gate(4.0, "fixed")),
    "ekf_prev15+bus_gate4_grown": _combine(_PREV15, _bus_gate(4.0, "missed_frames")),
    "ekf_prev15+bus_gate5_grown_score012": _combine(_PREV15, _bus_gate(5.0, "missed_frames"), _bus_score(0.12)),
    # Decision 16: the buses' gate at 5 m grown at 3 m/s since the track's last detection; ekf_prev16 takes it back
    # (Decision 15's 6 m grown with the missed frames)
    "ekf_prev16": _PREV16,
    # Decision 17: the bicycles' 2 m gate; ekf_prev17 takes it back (Decision 16's preset)
    "ekf_prev17": _PREV17,
    # Decision 16's bicycles with written-score changes instead of the gate (measured for Decision 17)
    "ekf_prev17+young0.3": _combine(_PREV17, _young(0.3)),
    "ekf_prev17+bic_punish1": _combine(_PREV17, _punish({"bicycle": 1})),
    # Decision 18: buses' tracks die once their mean score falls below 0.14; ekf_prev18 takes it back (Fast-Poly's
    # 0.08, Decision 17's preset); other thresholds measured for it
    "ekf_prev18": _bus_delete(0.08),
    **{f"+bus_delete{round(v * 100):03d}": _bus_delete(v) for v in (0.1, 0.12, 0.16, 0.2, 0.25, 0.3)},
    # Decision 19: every class's size gate at 0.3; ekf_prev19 takes it back (Decision 18's preset); 0.5 and 0.7
    # measured for it
    "ekf_prev19": _size_gate(0.0),
    **{f"+size_gate{round(v * 10):02d}": _size_gate(v) for v in (0.5, 0.7)},
    # buses' position noise R (x, y) 0.5 and 0.25 m^2 instead of Poly-MOT's 1, measured after Decision 19's second
    # held-out count (its failing-velocity buses), not adopted
    **{
        f"+bus_rxy{name}": _class_motion("bus", f"bus_rxy{name}", R=[r, r, 1.0, 1.0, 1.0, 1.0, 0.1, 2.0, 2.0])
        for name, r in (("05", 0.5), ("025", 0.25))
    },
    # other radii (m) and speeds (m/s) of the buses' gate, measured for Decision 16
    **{
        f"+bus_gate{r}_{v}mps": _bus_gate(float(r), float(v))
        for r, v in ((3, 4), (3, 5), (4, 2), (4, 3), (4, 4), (5, 4), (6, 3))
    },
    **{f"+bus_gate{r}_fixed": _bus_gate(float(r), "fixed") for r in (3, 4, 5, 6)},
    # a bicycle gate: 2 m (Decision 17, adopted; measured for Decisions 15 and 16 and left out then for the GRU-KF),
    # 1, 1.5, 2.5, 3 and 4 m, or 2 m grown with the missed frames or at 1 m/s
    **{f"+bicycle_gate{name}": _bicycle_gate(r) for name, r in _BICYCLE_RADII},
    # no bicycle gate, a tighter stage-1 threshold instead (measured for Decision 17)
    "+bic_thr13": _combine(_PREV17, lambda raw: raw["association"]["first_threshold"].update(bicycle=1.3)),
    "+bicycle_gate2_1mps": _combine(
        _bicycle_gate(2.0), lambda raw: raw["association"]["distance_gate_growth"].update(bicycle=1.0)
    ),
    "+bicycle_gate2_grown": _combine(
        _bicycle_gate(2.0), lambda raw: raw["association"]["distance_gate_growth"].update(bicycle="missed_frames")
    ),
    # the trailers' 5 m gate grown as the buses'
    "+trailer_gate_grown": lambda raw: raw["association"]["distance_gate_growth"].update(trailer="missed_frames"),
    # fixed gates for cars (3 m), motorcycles (3 m) and pedestrians (2 m) too
    "+more_gates": lambda raw: raw["association"]["distance_gate"].update(car=3.0, motorcycle=3.0, pedestrian=2.0),
}


#: candidates the preset has taken since they were measured: each writes the preset itself (kept so that the
#: commands of docs/results/default_tracker.md still run)
ADOPTED = (
    "+trailer_gate5",
    "+velocity_check5",
    "+ped_crowded",
    "+car_crowded",
    "+car_ped_crowded",
    "+skip_lost",
    "+car_crowded+skip_lost",
    "+r_score",
    "+punish_bus2",
    "+punish_large2",
    "+young0.5",
    "+nis_hits6",
    "+bus_gate5",  # its 5 m radius, with the growth of Decision 16
    "+bicycle_gate2",  # Decision 17
)


def candidate_path(name: str, base: str = "now") -> Path:
    """The candidate's preset file; ``base``: ``now`` (the preset) or ``before`` (the preset before the punish_num
    decision, Decision 1's baseline)."""
    raw = yaml.safe_load(preset_path("ekf").read_text())
    raw = copy.deepcopy(raw)
    if name == "ekf_before" or (name != "ekf" and base == "before"):
        _punish(BEFORE)(raw)
    CANDIDATES[name](raw)
    path = _TMP / f"{name.replace('+', 'plus_')}.yaml"
    path.write_text(yaml.safe_dump(raw, sort_keys=False))
    return path


def amota(nusc, preset, split: str, det_path: Path, scenes) -> dict[str, float]:
    """AMOTA of one preset on one detection file: ``{"all": mean, class: AMOTA}`` (NaN for a class the split has
    none of)."""
    tokens = [f.token for s in scenes for f in s.frames]
    tracker = build_tracker("ekf", preset)
    dets = load_detections(det_path, tokens, tracker.cfg.measured_yaw)
    run = track_scenes(tracker, scenes, dets)
    sub = build_submission(run.results, tokens, tracker.cfg.max_boxes_per_sample)
    summary = fast_tracking_eval(nusc, sub, split)
    return {"all": float(summary["amota"]), **{c: float(v) for c, v in summary["label_metrics"]["amota"].items()}}


def parse_compose(spec: str, names: list[str]) -> dict[str, str]:
    """``"car=+A,bus=+B"`` -> {class: candidate}; a class or candidate not known (candidates: ``names``, the ones
    run) is a ValueError naming it."""
    out = {}
    for part in filter(None, spec.split(",")):
        cls, _, cand = part.partition("=")
        if cls not in CLASSES:
            raise ValueError(f"--compose {spec!r}: {cls!r} is not a tracking class ({', '.join(CLASSES)})")
        if cand not in names:
            raise ValueError(f"--compose {spec!r}: {cand!r} is not among --candidates ({', '.join(names)})")
        out[cls] = cand
    return out


def composed(row: dict[str, dict[str, float]], base: str, mix: dict[str, str]) -> float:
    """AMOTA of ``base`` with the classes of ``mix`` ({class: candidate}) taken from those candidates: the mean
    over the classes present (not NaN) of ``row`` ({preset: {"all", class: AMOTA}})."""
    vals = [row[mix.get(c, base)][c] for c in CLASSES]
    vals = [v for v in vals if v == v]
    return sum(vals) / len(vals) if vals else float("nan")


def _world_sets(group: str, cache: Path, data: dict) -> dict[str, tuple[str, Path]]:
    """The SYNTHETIC sets of a world group (each of its profiles, detection seed = world seed); adds the worlds to
    ``data`` (key -> (database, scenes of demo_all))."""
    seeds, edit, profiles = WORLDS[group]
    out = {}
    for seed in seeds:
        root = world_root(cache, seed, edit)
        where = f"world_{edit or 'demo'}_s{seed}"
        if where not in data:
            db = open_nuscenes(root, "v1.0-demo")
            data[where] = (db, load_scenes(db, "demo_all"))
        for profile in profiles:
            path = cache / f"{where}_{profile}.json"
            if not path.is_file():
                prof = profile_arg(profile, cache)
                simulate_nuscenes(None, "v1.0-demo", "demo_all", prof, seed, out=path, nusc=data[where][0])
            out[f"{group} s{seed} {profile}"] = (where, path)
    return out


def _simulated(cache: Path, split: str, profile: str, seed: int, nusc) -> Path:
    """The SYNTHETIC detection file of one set in ``cache``, simulated on first use."""
    path = cache / f"{split}_{profile}_s{seed}.json"
    if not path.is_file():
        simulate_nuscenes(None, "v1.0-mini", split, profile_arg(profile, cache), seed, out=path, nusc=nusc)
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="nuScenes data root (holds v1.0-mini)")
    ap.add_argument(
        "--groups", default="reference,heldout", help="comma list of: " + ", ".join([*GROUPS, *DENSE, *WORLDS])
    )
    ap.add_argument("--candidates", default=",".join(CANDIDATES), help="comma list of: " + ", ".join(CANDIDATES))
    ap.add_argument(
        "--base",
        choices=("before", "now"),
        default="now",
        help="what a +candidate changes: the preset now (now) or the preset before the punish_num decision (before, "
        "Decision 1's baseline)",
    )
    ap.add_argument("--cache", type=Path, default=None, help="folder for the simulated detection files (reused)")
    ap.add_argument(
        "--json", type=Path, default=None, help="also write the table and every preset's per-class AMOTA as JSON here"
    )
    ap.add_argument("--class", dest="cls", choices=CLASSES, default=None, help="one class's AMOTA instead of the mean")
    ap.add_argument(
        "--summary",
        type=Path,
        action="append",
        default=[],
        metavar="JSON",
        help="print the report of runs saved with --json (repeatable: their sets merged) instead of tracking",
    )
    ap.add_argument(
        "--compose",
        action="append",
        default=[],
        metavar="CLASS=CANDIDATE,...",
        help="a column: the first candidate with these classes' AMOTA from these candidates (repeatable)",
    )
    args = ap.parse_args(argv)
    if args.summary:
        return summarize(args.summary, args.cls, args.compose)
    names = [c for c in args.candidates.split(",") if c]
    unknown = [c for c in names if c not in CANDIDATES]
    if unknown:
        print(f"unknown candidate(s): {', '.join(unknown)}", file=sys.stderr)
        return 2
    known_groups = (*GROUPS, *DENSE, *WORLDS)
    bad_groups = [g for g in args.groups.split(",") if g not in known_groups]
    if bad_groups:
        print(
            f"--groups: unknown group(s) {', '.join(bad_groups)}; expected of: {', '.join(known_groups)}",
            file=sys.stderr,
        )
        return 2
    try:
        mixes = {spec: parse_compose(spec, names) for spec in args.compose}
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    cache = args.cache or _TMP
    cache.mkdir(parents=True, exist_ok=True)
    nusc = open_nuscenes(args.data, "v1.0-mini")
    data = {s: (nusc, load_scenes(nusc, s)) for s in ("mini_val", "mini_train")}

    sets: dict[str, tuple[str, Path]] = {}  # name -> (key of ``data``, detection file)
    for group in args.groups.split(","):
        if group == "reference":
            sets.update({k: (split, args.data / rel) for k, (split, rel) in REFERENCE.items()})
        elif group in WORLDS:
            sets.update(_world_sets(group, cache, data))
        elif group in DENSE:
            base, start, count = DENSE[group]
            seeds, *rest = GROUPS[base]
            for key, (split, profile, seed) in generated(seeds[start : start + count], *rest).items():
                path = _simulated(cache, split, profile, seed, nusc)
                dense = path.with_name(f"{path.stem}_dense.json")
                if not dense.is_file():
                    densify_file(path, dense, seed=seed)
                sets[f"{key} dense"] = (split, dense)
        else:
            for key, (split, profile, seed) in generated(*GROUPS[group]).items():
                sets[key] = (split, _simulated(cache, split, profile, seed, nusc))

    presets = {t: t for t in THREE} | {c: candidate_path(c, args.base) for c in names}
    classes: dict[str, dict[str, dict[str, float]]] = {}  # set -> preset -> {"all", class: AMOTA}
    t0 = time.perf_counter()
    for key, (where, path) in sets.items():
        db, scenes = data[where]
        split = "demo_all" if where.startswith("world_") else where
        classes[key] = {p: amota(db, cfg, split, path, scenes) for p, cfg in presets.items()}
        print(f"  {key}: done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    table = report(classes, names, args.cls, mixes)
    if args.json:
        write_json_atomic(args.json, {"table": table, "per_class": classes}, indent=1)
    return 0


def summarize(paths: list[Path], cls: str | None, compose: list[str]) -> int:
    """``--summary``: the report of :func:`report` for the runs saved by ``--json`` in ``paths`` (their sets merged;
    the candidates those of the first file, in its order), without tracking. A file that is not such a run, or a
    candidate missing from one, exits 2 with one line naming the file."""
    classes: dict[str, dict[str, dict[str, float]]] = {}
    names: list[str] | None = None
    for path in paths:
        try:
            per_class = json.loads(path.read_text())["per_class"]
            first = next(iter(per_class.values()))
            if not all(t in first for t in THREE):
                raise KeyError(", ".join(THREE))
        except (OSError, ValueError, KeyError, StopIteration, TypeError, AttributeError) as exc:
            err = f"expected a JSON written by --json, with per_class AMOTA ({exc!r})"
            print(f"--summary {path}: {err}", file=sys.stderr)
            return 2
        mine = [p for p in first if p not in THREE]
        names = names or mine
        if missing := [n for n in names if n not in mine]:
            print(f"--summary {path}: no AMOTA for candidate(s) {', '.join(missing)} of {paths[0]}", file=sys.stderr)
            return 2
        classes.update(per_class)
    try:
        mixes = {spec: parse_compose(spec, names) for spec in compose}
    except ValueError as exc:
        print(exc, file=sys.stderr)
        return 2
    report(classes, names, cls, mixes)
    return 0


def report(
    classes: dict[str, dict[str, dict[str, float]]], names: list[str], cls: str | None, mixes: dict[str, dict]
) -> dict[str, dict[str, float]]:
    """Print the table (AMOTA, or ``cls``'s) of every set and preset of ``classes`` (set -> preset -> {"all", class:
    AMOTA}) with the three trackers and ``names`` (then one column per composition of ``mixes``), and the summaries
    below it; returns the table (set -> column -> AMOTA)."""
    table: dict[str, dict[str, float]] = {}
    for key, per_class in classes.items():
        table[key] = {p: v[cls or "all"] for p, v in per_class.items()}
        for spec, mix in mixes.items():
            one = cls and per_class[mix.get(cls, names[0])][cls]
            table[key][f"mix:{spec}"] = one if cls else composed(per_class, names[0], mix)
    columns = names + [f"mix:{spec}" for spec in mixes]
    if mixes and not cls:
        drift = max(abs(composed(row, names[0], {}) - row[names[0]]["all"]) for row in classes.values())
        print(f"composition check: {names[0]} composed from its classes differs from its AMOTA by {drift:.1e}")

    if cls:  # sets without the class (AMOTA NaN) are left out
        table = {k: row for k, row in table.items() if all(v == v for v in row.values())}
    width = max(len(k) for k in classes) + 1
    what = f"{cls} AMOTA" if cls else "AMOTA"
    print(f"{what} (fast evaluator = devkit); best3: the best of Poly-MOT, Fast-Poly, MCTrack; * below best3")
    print(f"{'set':<{width}}" + "".join(f"{c:>{max(9, len(c) + 1)}}" for c in THREE + ("best3",) + tuple(columns)))
    for key, row in table.items():
        best = max(row[t] for t in THREE)
        cells = [f"{row[t]:.4f}" for t in THREE] + [f"{best:.4f}"]
        cells += [f"{row[c]:.4f}{'*' if row[c] < best else ' '}" for c in columns]
        heads = THREE + ("best3",) + tuple(columns)
        print(f"{key:<{width}}" + "".join(f"{v:>{max(9, len(h) + 1)}}" for v, h in zip(cells, heads)))
    print()
    print("per candidate over the sets: mean margin to best3, sets below best3 (worst margin, set)")
    for c in columns:
        margins = {k: row[c] - max(row[t] for t in THREE) for k, row in table.items()}
        below = {k: m for k, m in margins.items() if m < 0}
        worst = min(margins, key=margins.get)
        mean = sum(margins.values()) / len(margins)
        print(
            f"  {c:<28} mean {mean:+.4f}  below on {len(below)}/{len(margins)}"
            + (f"  worst {margins[worst]:+.4f} ({worst})" if below else "")
        )
    _print_three_against_the_rest(table, columns[:1])
    if not cls:
        _print_deciding_classes(classes, names)
        _print_spread(classes, names[0])
    return table


def _print_three_against_the_rest(table: dict[str, dict[str, float]], first: list[str]) -> None:
    """How often each of the three trackers is below the best of the other two (and of those and the first
    candidate): the same test as a candidate's "below best3", so its rate has a yardstick."""
    print()
    others = " and ".join(["the other two"] + first)
    print(f"each of the three: sets below the best of the other two / of {others}")
    for t in THREE:
        rest = [u for u in THREE if u != t]
        below2 = sum(row[t] < max(row[u] for u in rest) for row in table.values())
        below3 = sum(row[t] < max(row[u] for u in rest + first) for row in table.values())
        print(f"  {t:<28} {below2}/{len(table)}  {below3}/{len(table)}")


def deciding_class(row: dict[str, dict[str, float]], cand: str) -> str | None:
    """The class that decides a set where ``cand`` is below the best of the three: the one whose AMOTA falls
    furthest below that of the set's best tracker (``row``: {preset: {"all", class: AMOTA}}); None where it is not
    below."""
    best = max(THREE, key=lambda t: row[t]["all"])
    if row[cand]["all"] >= row[best]["all"]:
        return None
    present = [c for c in CLASSES if not math.isnan(row[cand].get(c, math.nan))]  # classes the set has
    return min(present, key=lambda c: row[cand][c] - row[best][c])


def _print_deciding_classes(classes: dict[str, dict[str, dict[str, float]]], names: list[str]) -> None:
    """Per candidate, how many of the sets below the best of the three each class decides (:func:`deciding_class`)."""
    print()
    print("sets below best3 by the class that decides them (largest class loss against the set's best tracker)")
    for c in names:
        counts: dict[str, int] = {}
        for row in classes.values():
            cls = deciding_class(row, c)
            if cls:
                counts[cls] = counts.get(cls, 0) + 1
        ranked = sorted(counts.items(), key=lambda kv: -kv[1])
        print(f"  {c:<28} " + (", ".join(f"{k} {v}" for k, v in ranked) or "none below"))


def set_kind(key: str) -> str:
    """The detection set's kind: its name without the seed (``"mini_val centerpoint s2000"`` -> ``"mini_val
    centerpoint"``, ``"worlds s1 pointpillars"`` -> ``"worlds pointpillars"``); a reference set is its own kind."""
    return " ".join(w for w in key.split() if not (w[0] == "s" and w[1:].isdigit()))


def spread(classes: dict[str, dict[str, dict[str, float]]], cand: str) -> dict[str, dict]:
    """Per kind of set (:func:`set_kind`): ``n`` sets, ``below`` (``cand`` below the best of the three), the mean
    and population standard deviation (``sd``) of its margin to that best (AMOTA); ``gain_1pct`` / ``gain_none``:
    the AMOTA a uniform gain on every set would need to leave at most 1 % of them / none below (0 where already
    so); ``per_class``: for each class, the mean over the sets that have it of ``cand``'s AMOTA minus the best of
    the three's in that class."""
    out: dict[str, dict] = {}
    kinds: dict[str, list[str]] = {}
    for key in classes:
        kinds.setdefault(set_kind(key), []).append(key)
    for kind, keys in kinds.items():
        m = sorted(classes[k][cand]["all"] - max(classes[k][t]["all"] for t in THREE) for k in keys)
        mean = sum(m) / len(m)
        per_class = {}
        for c in CLASSES:
            gaps = [
                classes[k][cand].get(c, math.nan) - max(classes[k][t].get(c, math.nan) for t in THREE) for k in keys
            ]
            gaps = [g for g in gaps if not math.isnan(g)]
            if gaps:
                per_class[c] = sum(gaps) / len(gaps)
        out[kind] = {
            "n": len(m),
            "below": sum(x < 0 for x in m),
            "mean": mean,
            "sd": math.sqrt(sum((x - mean) ** 2 for x in m) / len(m)),
            "gain_1pct": max(0.0, -m[int(0.01 * len(m))]),  # the sets allowed below are the int(n / 100) lowest
            "gain_none": max(0.0, -m[0]),
            "per_class": per_class,
        }
    return out


def _print_spread(classes: dict[str, dict[str, dict[str, float]]], cand: str) -> None:
    """:func:`spread` of ``cand`` as a table."""
    print()
    print(f"{cand} per kind of set: sets below best3, margin to best3 (mean, sd), the uniform AMOTA gain that would")
    print("leave at most 1 % / none below; per class the mean AMOTA against the best3 in that class")
    for kind, s in spread(classes, cand).items():
        cls = " ".join(f"{c[:4]} {v:+.3f}" for c, v in s["per_class"].items())
        print(
            f"  {kind:<30} {s['below']:>3}/{s['n']:<3} mean {s['mean']:+.4f} sd {s['sd']:.4f}"
            f"  gain {s['gain_1pct']:.4f} / {s['gain_none']:.4f}   {cls}"
        )


if __name__ == "__main__":
    sys.exit(main())
