"""Small GRU-KF training inputs for tests: the first scenes of mini_train (cut to a few frames) with SYNTHETIC
CenterPoint-like detections simulated from their ground truth."""

from __future__ import annotations

import json


def mini_train_scenes_and_dets(nusc, folder, n_scenes: int, n_frames: int, seed: int = 5):
    """``n_scenes`` mini_train scenes (first ``n_frames`` frames, with ground truth) and their simulated detections
    by frame token (the detection JSON written into ``folder``)."""
    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes
    from grutrack.data.scene import Scene

    scenes = [
        Scene(s.name, s.token, s.frames[:n_frames]) for s in load_scenes(nusc, "mini_train", with_gt=True)[:n_scenes]
    ]
    p = folder / "dets.json"
    p.write_text(json.dumps(simulate_nuscenes(None, "v1.0-mini", "mini_train", "centerpoint", seed=seed, nusc=nusc)))
    return scenes, load_detections(p, [f.token for s in scenes for f in s.frames])
