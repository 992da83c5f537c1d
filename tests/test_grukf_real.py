"""The GRU-KF against the EKF trackers, on real nuScenes mini motion: trained with the shipped training config
on mini_train ground truth with simulated CenterPoint-like detections (seed 1), evaluated on mini_val with simulated
detections of other seeds (2, 11) and with the real PointPillars detections (official semantics via the exact
fast evaluator, equal to the devkit's TrackingEval to 1e-15). The GRU-KF writes its posterior for matched tracks.

What holds (measured): on the simulated sets its mean AMOTA is above Poly-MOT's EKF (`polymot`, the paper's
baseline: 0.897 vs 0.868), and on the real file too (0.180 vs 0.168).
What does not hold: the default `ekf` preset (Fast-Poly's multiplicative score update, bicycles and motorcycles
coasting two frames, the velocity noise of grutrack_nusc) scores a higher mean AMOTA on the simulated sets (0.906
vs 0.897; the GRU-KF runs with the same preset's lifecycle), a lower mean AMOTP (0.377 vs 0.397) and a higher
AMOTA on the real file (0.184 vs 0.180); the bounds against `ekf` below are regression guards at those measured
gaps, not the paper's claim."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from grutrack.data.detection_sim import simulate_nuscenes
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes
from grutrack.evaluation.fast_amota import fast_tracking_eval
from grutrack.export.nuscenes_json import build_submission
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes


def _simulated(nusc, split, seed, tokens, tmp_path):
    sub = simulate_nuscenes(None, "v1.0-mini", split, "centerpoint", seed=seed, nusc=nusc)
    p = tmp_path / f"{split}_s{seed}.json"
    p.write_text(json.dumps(sub))
    return load_detections(p, tokens)


def _score(nusc, tracker, scenes, dets) -> dict:
    tokens = [f.token for s in scenes for f in s.frames]
    sub = build_submission(track_scenes(tracker, scenes, dets).results, tokens)
    with contextlib.redirect_stdout(io.StringIO()):
        return fast_tracking_eval(nusc, sub, "mini_val")


@pytest.fixture(scope="module")
def trained(nusc_mini, tmp_path_factory):
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    tmp = tmp_path_factory.mktemp("grukf_real")
    scenes = load_scenes(nusc_mini, "mini_train", with_gt=True)
    dets = _simulated(nusc_mini, "mini_train", 1, [f.token for s in scenes for f in s.frames], tmp)
    cfg = load_train_config("grukf", {"device": "cpu"})
    return Trainer(cfg, scenes, dets, tmp / "ck", progress=False).run(), tmp


def test_grukf_amota_at_least_the_ekf_on_simulated_detections(nusc_mini, trained):
    checkpoint, tmp = trained
    scenes = load_scenes(nusc_mini, "mini_val")
    tokens = [f.token for s in scenes for f in s.frames]
    gru_tracker = build_tracker("grukf", checkpoint=checkpoint, device="cpu")
    assert gru_tracker.cfg.matched_box == "filter"
    ekf, polymot, gru = [], [], []
    for seed in (2, 11):
        dets = _simulated(nusc_mini, "mini_val", seed, tokens, tmp)
        ekf.append(_score(nusc_mini, build_tracker("ekf"), scenes, dets))
        polymot.append(_score(nusc_mini, build_tracker("ekf", "polymot"), scenes, dets))
        gru.append(_score(nusc_mini, build_tracker("grukf", checkpoint=checkpoint, device="cpu"), scenes, dets))
    mean = lambda rows, k: sum(r[k] for r in rows) / len(rows)  # noqa: E731
    assert mean(gru, "amota") >= mean(polymot, "amota"), (gru, polymot)
    assert mean(gru, "amota") >= mean(ekf, "amota") - 0.015, (gru, ekf)
    assert mean(gru, "amotp") <= mean(ekf, "amotp") + 0.02, (gru, ekf)


def test_grukf_above_polymot_ekf_on_real_pointpillars(nusc_mini, pointpillars_mini_val, trained):
    checkpoint, _ = trained
    scenes = load_scenes(nusc_mini, "mini_val")
    tokens = [f.token for s in scenes for f in s.frames]
    dets = load_detections(pointpillars_mini_val, tokens)
    polymot = _score(nusc_mini, build_tracker("ekf", "polymot"), scenes, dets)
    ekf = _score(nusc_mini, build_tracker("ekf"), scenes, dets)
    gru = _score(nusc_mini, build_tracker("grukf", checkpoint=checkpoint, device="cpu"), scenes, dets)
    assert gru["amota"] >= polymot["amota"] + 0.005, (gru["amota"], polymot["amota"])
    assert gru["amota"] >= ekf["amota"] - 0.006, (gru["amota"], ekf["amota"])
