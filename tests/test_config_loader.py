"""The one config loader: the name-or-path rule, schema errors that name the file, the key path and the
expectation, and numbers that must be finite."""

from __future__ import annotations

import math

import pytest
import yaml

from grutrack.config_loader import KINDS, config_path, load_config, merge, shipped_names
from grutrack.errors import ConfigError


@pytest.mark.parametrize("kind", sorted(k for k in KINDS if KINDS[k].folder))
def test_every_shipped_config_is_valid_under_its_schema(kind):
    assert shipped_names(kind)
    for name in shipped_names(kind):
        raw, source = load_config(kind, name)
        assert source.endswith(f"{name}.yaml") and isinstance(raw, dict)


def test_the_papers_numbers_are_valid_and_given_by_path_only(tmp_path):
    from grutrack.report.paper import default_paper_path, load_paper

    assert set(load_paper()["tables"]) == {"I", "II", "III", "IV"}
    with pytest.raises(ConfigError, match="paper numbers file paper does not exist"):
        config_path("paper", "paper")  # no shipped names: a path only
    bad = tmp_path / "paper.yaml"
    bad.write_text(default_paper_path().read_text().replace("tolerance: ", "tolerance: -", 1))
    with pytest.raises(
        ConfigError, match=r"paper.yaml: 'tables\.[IV]+\.columns\.\w+\.tolerance' must be a number >= 0, got -"
    ):
        load_paper(bad)


def test_name_or_path_rule(tmp_path):
    assert config_path("tracker", "ekf").name == "ekf.yaml"
    with pytest.raises(ConfigError, match=r"unknown tracker preset 'ekff' \(available: ab3dmot, ekf,"):
        config_path("tracker", "ekff")
    with pytest.raises(ConfigError, match="training config .*nope.yaml does not exist"):
        config_path("training", tmp_path / "nope.yaml")
    own = tmp_path / "mine"  # an existing file is a path even without a suffix
    own.write_text(config_path("training", "grukf").read_text())
    assert load_config("training", own)[1] == str(own)


def _tracker_with(tmp_path, edit) -> str:
    raw = yaml.safe_load(config_path("tracker", "ekf").read_text())
    edit(raw)
    p = tmp_path / "t.yaml"
    p.write_text(yaml.safe_dump(raw))
    return str(p)


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            lambda r: r["lifecycle"]["max_age"].__setitem__("car", 0),
            r"'lifecycle.max_age.car' must be an integer >= 1, got 0",
        ),
        (
            lambda r: r["lifecycle"]["max_age"].__setitem__("car", float("nan")),
            r"'lifecycle.max_age.car' must be an integer",
        ),
        (
            lambda r: r["association"]["first_threshold"].__setitem__("bus", math.inf),
            r"'association.first_threshold.bus' must be a cost threshold in \[0, 3\]",
        ),
        (lambda r: r["association"]["first_threshold"].pop("bus"), r"missing key 'association.first_threshold.bus'"),
        (
            lambda r: r["motion"].__setitem__("speed", 1),
            r"unknown key 'motion.speed' \(expected one of: motion.config,",
        ),
        (
            lambda r: r["preprocessing"].__setitem__("score_threshold", 0.1),
            r"'preprocessing.score_threshold' must be a mapping over the tracking classes bicycle, bus,",
        ),
        (lambda r: r["motion"].__setitem__("time_step", -1), r"'motion.time_step' must be 'timestamps' or a positive"),
    ],
)
def test_tracker_errors_name_file_key_and_expectation(tmp_path, edit, message):
    path = _tracker_with(tmp_path, edit)
    with pytest.raises(ConfigError, match=message) as e:
        load_config("tracker", path)
    assert str(e.value).startswith(path + ": ")


def test_an_error_inside_a_list_is_stated_for_the_list_and_overrides_name_their_flag():
    with pytest.raises(ConfigError, match=r"grukf.yaml: 'loss_weights' must be 9 non-negative numbers, got \[1, -1,"):
        load_config("training", "grukf", {"loss_weights": [1, -1, 1, 1, 1, 1, 1, 1, 1]})
    with pytest.raises(
        ConfigError,
        match=r"^--epochs must be an integer >= 0 \(0: no step, the initialised "
        r"network\), got -1$",
    ):
        load_config("training", "grukf", {"epochs": -1}, flags={"epochs": "--epochs"})


def test_merge_is_key_by_key_and_copies():
    base = {"a": {"x": [1]}, "b": 1}
    out = merge(base, {"a": {"y": 2}})
    out["a"]["x"].append(2)
    assert base == {"a": {"x": [1]}, "b": 1} and out == {"a": {"x": [1, 2], "y": 2}, "b": 1}


def test_registry_formats_on_the_command_line_are_the_schemas(tmp_path):
    from grutrack.config_loader import schema
    from grutrack.data.registry import FORMATS, REGISTRY_PATH, load_registry

    entry = schema("registry")["properties"]["sources"]["additionalProperties"]["properties"]["format"]
    assert tuple(entry["enum"]) == FORMATS
    text = REGISTRY_PATH.read_text()
    bad = tmp_path / "reg.yaml"
    bad.write_text(text.replace("host: browser", "host: ftp", 1))
    with pytest.raises(ConfigError, match=r"reg.yaml: 'sources\.\w+\.host' must be one of direct, browser, got 'ftp'"):
        load_registry(bad)
