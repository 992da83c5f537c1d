"""The nuScenes submission ``meta`` (use_camera, use_lidar, use_radar, use_map, use_external: what the detector
used, hence the leaderboard category) is the detection file's: checked when detections are read or converted,
carried by ``convert-detections``, ``track``, ``submit`` and ``leaderboard-zip``; simulated detections declare
lidar only."""

from __future__ import annotations

import json
import zipfile

import pytest

from grutrack.cli import main
from grutrack.data.nusc_detections import LIDAR_META

#: a camera detector trained with external data: another leaderboard category than lidar-only
CAMERA_META = {"use_camera": True, "use_lidar": False, "use_radar": False, "use_map": False, "use_external": True}


def _with_meta(src, dest, meta):
    """The detection file ``src`` written to ``dest`` with ``meta`` (any JSON value; ``...``: no meta at all)."""
    data = json.loads(src.read_text())
    data.pop("meta")
    if meta is not ...:
        data["meta"] = meta
    dest.write_text(json.dumps(data))
    return dest


@pytest.fixture()
def mini_val(nusc_root):
    """The dataset arguments of mini_val."""
    return ["--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val"]


def _run(argv) -> None:
    assert main([str(a) for a in argv]) == 0


def test_detection_meta_reaches_the_leaderboard_zip(mini_val, pointpillars_mini_val, tmp_path):
    raw = _with_meta(pointpillars_mini_val, tmp_path / "raw.json", dict(CAMERA_META, note="kept out"))
    dets, tracks, sub, zipped = (tmp_path / n for n in ("dets.json", "tracks.json", "sub.json", "sub.zip"))
    _run(["convert-detections", "--format", "nuscenes_json", "--raw", raw, *mini_val, "--out", dets])
    assert json.loads(dets.read_text())["meta"] == CAMERA_META  # the five booleans, nothing else
    _run(["track", *mini_val, "--detections", dets, "--out", tracks, "--no-progress"])
    assert json.loads(tracks.read_text())["meta"] == CAMERA_META
    _run(["submit", *mini_val, "--tracks", tracks, "--out", sub, "--detections", dets, "--tracker", "ekf"])
    _run(["leaderboard-zip", "--submission", sub, *mini_val, "--out", zipped])
    with zipfile.ZipFile(zipped) as zf:
        assert json.loads(zf.read("sub.json"))["meta"] == CAMERA_META


def test_simulated_detections_declare_lidar_and_tracks_keep_it(mini_val, tmp_path):
    dets, tracks = tmp_path / "sim.json", tmp_path / "tracks.json"
    _run(["simulate-detections", *mini_val, "--profile", "centerpoint", "--seed", "1", "--out", dets])
    assert json.loads(dets.read_text())["meta"] == LIDAR_META
    _run(["track", *mini_val, "--detections", dets, "--out", tracks, "--no-progress"])
    assert json.loads(tracks.read_text())["meta"] == LIDAR_META


BAD_META = {
    "missing_field": (
        {k: v for k, v in CAMERA_META.items() if k != "use_camera"},
        "field 'meta.use_camera' is missing; expected true or false",
    ),
    "string": (dict(CAMERA_META, use_external="yes"), "field 'meta.use_external' must be true or false, got 'yes'"),
    "number": (dict(CAMERA_META, use_lidar=1), "field 'meta.use_lidar' must be true or false, got 1"),
    "null": (dict(CAMERA_META, use_map=None), "field 'meta.use_map' must be true or false, got None"),
    "no_meta": (
        ...,
        "field 'meta' is missing; expected an object with the booleans use_camera, use_lidar, use_radar, use_map, "
        "use_external",
    ),
    "meta_list": ([True], "field 'meta' must be an object with the booleans"),
    "no_sensor": (dict(CAMERA_META, use_camera=False), "field 'meta' declares no sensor"),
}


#: cases of a kind another quick case has (a non-boolean flag: string; no meta: test_bad_formats' meta_missing)
SLOW_META = {"number", "null", "no_meta"}


@pytest.mark.parametrize(
    "case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_META else c for c in sorted(BAD_META)]
)
def test_bad_meta_is_one_line_naming_the_field(mini_val, pointpillars_mini_val, tmp_path, capsys, case):
    meta, message = BAD_META[case]
    dets = _with_meta(pointpillars_mini_val, tmp_path / "d.json", meta)
    for argv in (
        ["track", *mini_val, "--detections", dets, "--out", tmp_path / "t.json", "--no-progress"],
        ["convert-detections", "--format", "nuscenes_json", "--raw", dets, *mini_val, "--out", tmp_path / "c.json"],
    ):
        assert main([str(a) for a in argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "Traceback" not in err[0], err
        assert f"{dets}: {message}" in err[0], err[0]
    assert not (tmp_path / "t.json").exists() and not (tmp_path / "c.json").exists()
