"""Tracker presets side by side over many detection sets: per set AMOTA / AMOTP / IDS of each preset and its AMOTA
difference from the first, then per preset the mean, lowest and highest difference and on how many sets it is
higher / lower. This is how the figures in grutrack/configs/trackers/ekf.yaml were measured. Simulated sets are
SYNTHETIC (`grutrack simulate-detections`); official metrics via the exact fast evaluator (equal to the devkit).

    PYTHONPATH=. .venv/bin/python scripts/preset_sweep.py --dataroot ../shared/data/nuscenes --version v1.0-mini \
        --split mini_val --profile centerpoint --seeds 100-119 --presets polymot,ekf --cache /tmp/sweep

A preset is a shipped name or a YAML path (e.g. written by `grutrack resolve-config tracker --base ekf --overrides
'{"lifecycle": {"punish_num": 1}}' --out v.yaml`). ``--detections FILE`` adds a detection file (e.g. the real
PointPillars file) to the sets. Simulated detections and per-set results are cached under ``--cache`` (results are
keyed by the preset file's and its motion config's content). Sets run one after another, on one core.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import sys
from pathlib import Path

import numpy as np


def _seeds(text: str) -> list[int]:
    """'100-119' or '7,11,12' -> seeds."""
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out += list(range(int(a), int(b or a) + 1))
    return out


def _preset_key(preset: str) -> str:
    """Content hash of a preset and its motion config (a shipped name or a path)."""
    import yaml

    from grutrack.motion.config import resolve_config_path
    from grutrack.tracking.config import preset_path

    path = preset_path(preset)
    raw = yaml.safe_load(path.read_text())
    h = hashlib.sha1(path.read_bytes())
    h.update(resolve_config_path(raw["motion"]["config"]).read_bytes())
    return f"{Path(preset).stem}-{h.hexdigest()[:12]}"


def _score(nusc, scenes, split: str, detections: Path, preset: str) -> dict:
    """AMOTA, AMOTP, IDS of one preset on one detection file."""
    from grutrack.data.nusc_detections import load_detections
    from grutrack.evaluation.nuscenes_fast import fast_tracking_eval
    from grutrack.export.nuscenes_json import build_submission
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.tracker import track_scenes

    tokens = [f.token for s in scenes for f in s.frames]
    tracker = build_tracker("ekf", preset)
    dets = load_detections(detections, tokens, tracker.cfg.measured_yaw)
    sub = build_submission(track_scenes(tracker, scenes, dets).results, tokens, tracker.cfg.max_boxes_per_sample)
    with contextlib.redirect_stdout(io.StringIO()):
        s = fast_tracking_eval(nusc, sub, split)
    return {"amota": s["amota"], "amotp": s["amotp"], "ids": int(s["ids"])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataroot", required=True)
    p.add_argument("--version", required=True)
    p.add_argument("--split", required=True)
    p.add_argument("--profile", action="append", default=[], help="detector profile (name or YAML); repeatable")
    p.add_argument("--seeds", default="", help="simulation seeds, e.g. 100-119 or 7,11")
    p.add_argument("--detections", action="append", default=[], help="a detection file of the split; repeatable")
    p.add_argument("--presets", required=True, help="comma-separated; differences are taken from the first")
    p.add_argument("--cache", required=True, help="folder for simulated detections and per-set results")
    a = p.parse_args(argv)

    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.threads import apply_thread_policy

    apply_thread_policy(torch_too=False)
    cache = Path(a.cache)
    cache.mkdir(parents=True, exist_ok=True)
    nusc = open_nuscenes(a.dataroot, a.version, devkit=True)
    scenes = load_scenes(nusc, a.split)
    sets = [(Path(f).stem, Path(f)) for f in a.detections]
    for profile in a.profile:
        for seed in _seeds(a.seeds) if a.seeds else []:
            name = f"{a.split}_{Path(profile).stem}_s{seed}"
            path = cache / f"{name}.json"
            if not path.exists():
                simulate_nuscenes(None, a.version, a.split, profile, seed=seed, out=path, nusc=nusc)
            sets.append((name, path))
    presets = a.presets.split(",")
    keys = {q: _preset_key(q) for q in presets}
    rows = []
    for name, path in sets:
        res = {}
        for q in presets:
            f = cache / f"{name}__{keys[q]}.json"
            if not f.exists():
                f.write_text(json.dumps(_score(nusc, scenes, a.split, path, q)))
            res[q] = json.loads(f.read_text())
        base = res[presets[0]]
        line = f"{name:36s} {presets[0]} {base['amota']:.4f} / {base['amotp']:.3f} / {base['ids']:3d}"
        for q in presets[1:]:
            r = res[q]
            line += f" | {q} {r['amota']:.4f} ({r['amota'] - base['amota']:+.4f}) / {r['amotp']:.3f} / {r['ids']:3d}"
        print(line, flush=True)
        rows.append(res)
    for q in presets[1:]:
        d = np.array([r[q]["amota"] - r[presets[0]]["amota"] for r in rows])
        print(
            f"{q} - {presets[0]}: mean {d.mean():+.4f}, lowest {d.min():+.4f}, highest {d.max():+.4f}, "
            f"higher on {(d > 0).sum()}, lower on {(d < 0).sum()} of {len(d)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
