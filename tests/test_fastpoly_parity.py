"""Box-for-box parity of ``--tracker ekf --config fastpoly`` with Fast-Poly's own code (lixiaoyu2000/FastPoly @
694dec3, default nuScenes config, Multiprocessing False) on the four reference sets of
../shared/data/nuscenes/reference (three SYNTHETIC detection sets kept as files, and the real PointPillars file).

On every set: every reference box paired within 1e-6 m (centre and size) with a box of ours of the same class,
score and yaw; the same box count in every sample; the same partition of boxes into tracks (ids may differ;
Fast-Poly's restart per scene); and the devkit metrics of the reference (``*.metrics_summary.json``) equal to
ours to 1e-9 (the fast evaluator, itself equal to the devkit to 1e-9).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes
from grutrack.evaluation.compare import entry_differences
from grutrack.evaluation.fast_amota import fast_tracking_eval
from grutrack.evaluation.track_parity import compare_tracks
from grutrack.export.nuscenes_json import build_submission
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes

#: reference set -> (split, detection file relative to nuscenes/reference)
SETS = {
    "mini_val_centerpoint_sim_s7": ("mini_val", "mini_val_centerpoint_sim_s7.json"),
    "mini_val_pointpillars_sim_s7": ("mini_val", "mini_val_pointpillars_sim_s7.json"),
    "pointpillars_mini_val": ("mini_val", "../detections/pointpillars_mini_val.json"),
    "mini_train_centerpoint_sim_s7": ("mini_train", "mini_train_centerpoint_sim_s7.json"),
}


def _file(root: Path, name: str) -> Path:
    path = root / name
    if not path.is_file():
        pytest.fail(f"reference file missing: {path}")
    return path


@pytest.mark.parametrize("name", list(SETS))
def test_fastpoly_box_for_box(nusc_mini, nusc_reference, name):
    split, det = SETS[name]
    scenes = load_scenes(nusc_mini, split)
    tokens = [f.token for s in scenes for f in s.frames]
    tracker = build_tracker("ekf", "fastpoly")
    dets = load_detections(_file(nusc_reference, det), tokens, tracker.cfg.measured_yaw)
    ours = build_submission(track_scenes(tracker, scenes, dets).results, tokens, tracker.cfg.max_boxes_per_sample)
    ref = json.loads(_file(nusc_reference, f"fastpoly_{name}.json").read_text())

    parity = compare_tracks(ref, ours, {f.token: s.token for s in scenes for f in s.frames}, tolerance=1e-6)
    assert parity.ref_boxes > 1000, parity.summary()
    assert parity.paired == parity.ref_boxes == parity.our_boxes, parity.summary()
    assert parity.count_mismatch == [], parity.summary()
    assert parity.score_mismatch == 0 and parity.yaw_mismatch == 0, parity.summary()
    assert parity.partition_breaks == 0, parity.summary()

    summary = fast_tracking_eval(nusc_mini, ours, split)
    expected = json.loads(_file(nusc_reference, f"fastpoly_{name}.metrics_summary.json").read_text())
    expected.pop("meta"), summary.pop("meta")   # use_camera differs by convention (Fast-Poly writes true)
    diffs = entry_differences(expected, summary)
    worst = max(diffs, key=diffs.get)
    assert diffs[worst] <= 1e-9, f"{worst}: {diffs[worst]}"
    assert math.isclose(summary["amota"], expected["amota"], abs_tol=1e-9)
