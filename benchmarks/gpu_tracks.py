"""The shipped GRU-KF's tracks on two devices, box for box: mini_val with the real PointPillars file and a SYNTHETIC
CenterPoint-like set (seed 11), tracked on each device of ``--devices`` (default cpu,cuda); prints each run's
tracking-loop frames/s, then per set the boxes, how many track ids are equal and the largest box difference
between the first and the last device. Figures: docs/results/lockstep.md#gpu.

    python benchmarks/gpu_tracks.py --dataroot ../shared/data/nuscenes [--devices cpu,cuda]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from grutrack.data.detection_sim import simulate_nuscenes
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.threads import apply_thread_policy
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes
from grutrack.training.pretrained import pretrained_dir

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nuscenes"


def compare(runs: list, tokens: list[str]) -> tuple[int, int, float]:
    """(boxes, equal ids, largest |box difference|) between the first and the last run, frame by frame."""
    n = same = 0
    dmax = 0.0
    for tok in tokens:
        a, b = runs[0].results[tok], runs[-1].results[tok]
        if len(a) != len(b):
            raise SystemExit(f"gpu_tracks.py: frame {tok}: {len(a)} boxes against {len(b)}")
        n += len(a)
        if len(a):
            same += int(np.sum(np.asarray(a.ids) == np.asarray(b.ids)))
            dmax = max(dmax, float(np.abs(np.asarray(a.boxes) - np.asarray(b.boxes)).max()))
    return n, same, dmax


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--devices", default="cpu,cuda")
    args = ap.parse_args()
    apply_thread_policy()
    devices = args.devices.split(",")
    nusc = open_nuscenes(args.dataroot, "v1.0-mini")
    scenes = load_scenes(nusc, "mini_val")
    tokens = [f.token for s in scenes for f in s.frames]
    with tempfile.TemporaryDirectory(prefix="grutrack-gpu-tracks-") as tmp:
        sim = Path(tmp) / "centerpoint_s11.json"
        sim.write_text(json.dumps(simulate_nuscenes(None, "v1.0-mini", "mini_val", "centerpoint", 11, nusc=nusc)))
        sets = {
            "real PointPillars": args.dataroot / "detections" / "pointpillars_mini_val.json",
            "SYNTHETIC CenterPoint-like s11": sim,
        }
        track_on_devices(sets, devices, scenes, tokens)


def track_on_devices(sets: dict[str, Path], devices: list[str], scenes: list, tokens: list[str]) -> None:
    """Track each detection file of ``sets`` with the shipped GRU-KF on every device; print frames/s and the
    box-for-box comparison of the first and the last device."""
    checkpoint = pretrained_dir("grukf_default") / "model.pt"
    for name, path in sets.items():
        runs = []
        for device in devices:
            tracker = build_tracker("grukf", checkpoint=checkpoint, device=device)
            runs.append(track_scenes(tracker, scenes, load_detections(path, tokens, tracker.cfg.measured_yaw)))
            print(f"{name}, {device}: {runs[-1].fps:.1f} frames/s (tracking loop)", flush=True)
        n, same, dmax = compare(runs, tokens)
        print(f"{name}: {n} boxes, ids equal {same}/{n}, largest |box difference| {dmax:.3g}", flush=True)


if __name__ == "__main__":
    main()
