"""Tracker presets: every key documented in the shipped preset loads; misspelt / missing / bad keys fail clearly."""

from __future__ import annotations

import copy

import pytest
import yaml

from grutrack.errors import ConfigError
from grutrack.tracking.config import PRESET_DIR, config_from_dict, load_tracker_config


def _raw():
    return yaml.safe_load((PRESET_DIR / "ekf.yaml").read_text())


def test_ekf_preset_values():
    cfg = load_tracker_config("ekf")
    assert cfg.nms_threshold == 0.08 and cfg.two_stage and cfg.second_metric == "giou_bev"
    assert cfg.first_metric[1] == "giou_bev" and cfg.first_metric[2] == "giou_3d"  # bus, car
    assert cfg.max_age.tolist() == [10, 10, 15, 20, 10, 10, 20] and cfg.punish_num == 1


def test_every_preset_key_has_a_comment():
    text = (PRESET_DIR / "ekf.yaml").read_text().splitlines()
    for i, line in enumerate(text):
        s = line.strip()
        if s and not s.startswith("#") and s.endswith(":") is False and ":" in s and line.startswith("  "):
            assert text[i - 1].strip().startswith("#"), f"key without a comment above it: {s}"


@pytest.mark.parametrize("mutate, message", [
    (lambda r: r["association"].__setitem__("first_treshold", r["association"].pop("first_threshold")),
     "unknown key 'association.first_treshold'"),
    (lambda r: r["lifecycle"].pop("punish_num"), "missing key 'lifecycle.punish_num'"),
    (lambda r: r["lifecycle"]["max_age"].pop("car"), "missing key 'lifecycle.max_age.car'"),
    (lambda r: r["preprocessing"].__setitem__("nms_threshold", 1.5), "'preprocessing.nms_threshold' must be a number in"),
    (lambda r: r["association"].__setitem__("second_metric", "giou"), "must be one of giou_3d"),
    (lambda r: r["motion"].__setitem__("model_override", {"car": "CTRV"}), "'motion.model_override.car' must be one of"),
    (lambda r: r["lifecycle"]["max_age"].__setitem__("bus", 2.5), "must be an integer"),
])
def test_bad_preset_keys(mutate, message):
    raw = copy.deepcopy(_raw())
    mutate(raw)
    with pytest.raises(ConfigError, match=message):
        config_from_dict(raw, "preset.yaml")


def test_unknown_preset_name_lists_available():
    with pytest.raises(ConfigError, match="unknown tracker preset 'ekff'.*ekf"):
        load_tracker_config("ekff")
