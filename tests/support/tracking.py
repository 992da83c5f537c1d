"""A detection file tracked with a tracker preset into a nuScenes tracking submission, for the parity tests."""

from __future__ import annotations

from pathlib import Path

from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes
from grutrack.export.nuscenes_json import build_submission
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes


def track(nusc, preset: str, split: str, detections: Path) -> tuple[dict, dict[str, str]]:
    """The preset's submission dict for a split (``--tracker ekf --config preset``), and sample token -> scene
    token."""
    scenes = load_scenes(nusc, split)
    tokens = [f.token for s in scenes for f in s.frames]
    tracker = build_tracker("ekf", preset)
    dets = load_detections(detections, tokens, tracker.cfg.measured_yaw)
    run = track_scenes(tracker, scenes, dets)
    return (
        build_submission(run.results, tokens, tracker.cfg.max_boxes_per_sample),
        {f.token: s.token for s in scenes for f in s.frames},
    )
