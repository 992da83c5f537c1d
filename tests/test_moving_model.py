"""A class's second motion model for the tracks born moving (motion config ``classes.<class>.moving``): loaded and
checked with the config, and a track is born in that model's group when its first detection's speed is at least the
model's speed, in the class's own group otherwise, for its whole life."""

import numpy as np
import pytest
import yaml

from grutrack.classes import CLASS_INDEX
from grutrack.data.scene import BoxSet
from grutrack.errors import ConfigError
from grutrack.motion.config import load_motion_config, resolve_config_path
from grutrack.tracking.config import preset_path
from grutrack.tracking.factory import build_tracker

MOTO = CLASS_INDEX["motorcycle"]
#: the pedestrians' CV noise of grutrack_nusc (state x, y, z, w, l, h, vx, vy, yaw; measurement ..., yaw, vx, vy)
CV_NOISE = {
    "P0": [1, 1, 1, 1, 1, 1, 10, 10, 1],
    "Q": [1.5, 1.5, 1.5, 0.5, 0.5, 0.5, 1.5, 1.5, 1],
    "R": [2, 2, 2, 2, 2, 2, 1, 3.5, 3.5],
}


def _motion(tmp_path, moving: dict | None) -> str:
    raw = yaml.safe_load(resolve_config_path("grutrack_nusc").read_text())
    raw["classes"]["motorcycle"].pop("moving", None)  # the shipped one's (docs/results/default_tracker.md)
    if moving is not None:
        raw["classes"]["motorcycle"]["moving"] = moving
    path = tmp_path / "motion.yaml"
    path.write_text(yaml.safe_dump(raw))
    return str(path)


def _preset(tmp_path, motion: str) -> str:
    raw = yaml.safe_load(preset_path("ekf").read_text())
    raw["motion"]["config"] = motion
    path = tmp_path / "preset.yaml"
    path.write_text(yaml.safe_dump(raw))
    return str(path)


def test_the_moving_model_is_loaded_with_its_noise_and_speed(tmp_path):
    cfg = load_motion_config(_motion(tmp_path, {"speed": 2.0, "model": "cv", **CV_NOISE}))
    moving = cfg["motorcycle"]["moving"]
    assert moving["model"] == "CV" and moving["speed"] == 2.0 and moving["Q"].shape == (9, 9)
    np.testing.assert_array_equal(np.diag(moving["R"]), CV_NOISE["R"])
    assert cfg["motorcycle"]["model"] == "Bicycle" and "moving" not in cfg["car"]
    # a preset's model_override sets the class's one model
    assert (
        "moving"
        not in load_motion_config(_motion(tmp_path, {"speed": 2.0, "model": "CV", **CV_NOISE}), "CTRA")["motorcycle"]
    )


@pytest.mark.parametrize(
    ("moving", "key"),
    [
        ({"speed": 2.0, "model": "Bicycle", **CV_NOISE}, "classes.motorcycle.moving.model"),
        ({"model": "CV", **CV_NOISE}, "classes.motorcycle.moving"),
        ({"speed": 0.0, "model": "CV", **CV_NOISE}, "classes.motorcycle.moving.speed"),
        ({"speed": 2.0, "model": "CV", **CV_NOISE, "P0": [1, 1, 1]}, "classes.motorcycle.moving.P0"),
    ],
    ids=["its-own-model", "no-speed", "zero-speed", "wrong-size"],
)
def test_a_bad_moving_block_names_its_key(tmp_path, moving, key):
    path = _motion(tmp_path, moving)
    with pytest.raises(ConfigError) as info:
        load_motion_config(path)
    assert path in str(info.value) and key in str(info.value)


def _step(tracker, velocities, t: int):
    """One frame: a motorcycle per velocity (m/s), 20 m apart, moved by its velocity over t half-seconds."""
    boxes = np.array(
        [
            [20.0 * i + 0.5 * t * vx, 0.5 * t * vy, 0.0, 0.8, 2.2, 1.5, 0.0, vx, vy]
            for i, (vx, vy) in enumerate(velocities)
        ]
    )
    tracker.step(BoxSet(boxes, np.full(len(boxes), 0.9), np.full(len(boxes), MOTO)), 1_000_000 + 500_000 * t)


def _owners(tracker) -> dict[str, list[int]]:
    """Model name -> ids of the motorcycle tracks its group holds."""
    return {g.backend.model.name: sorted(g.ids[g.labels == MOTO].tolist()) for g in tracker.groups}


@pytest.mark.parametrize("with_moving", [True, False])
def test_a_track_born_moving_lives_in_the_moving_model(tmp_path, with_moving):
    moving = {"speed": 2.0, "model": "CV", **CV_NOISE} if with_moving else None
    tracker = build_tracker("ekf", _preset(tmp_path, _motion(tmp_path, moving)))
    riding, parked = (6.0, 0.0), (0.3, 0.1)
    for t in range(4):  # the parked one's detected speed later above 2 m/s: it stays where it was born
        _step(tracker, [riding, parked if t == 0 else (2.5, 0.0)], t)
    owners = _owners(tracker)
    if with_moving:
        assert owners["CV"] == [0] and owners["Bicycle"] == [1]
    else:
        assert owners["Bicycle"] == [0, 1] and owners.get("CV", []) == []
