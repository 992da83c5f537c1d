"""Tracking-loop throughput (frames/s) on CenterPoint-like detection density, one core.

Input: the real nuScenes mini_val ground truth (../shared/data, 81 frames, ~54 tracked boxes per frame)
turned into detector-like output: centre/size/yaw/velocity noise, 10 % misses, duplicates and false positives,
so that a frame has about 75 raw detections (CenterPoint's density after its score threshold). The frames
are tracked --repeat times; the figure is the median frames/s of the tracking loop alone (no I/O).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_tracking.py [--repeat 3] [--config ekf]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from grutrack.data.nuscenes import load_scenes, open_nuscenes  # noqa: E402
from grutrack.data.scene import BoxSet  # noqa: E402
from grutrack.tracking.factory import build_tracker  # noqa: E402
from grutrack.tracking.tracker import track_scenes  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nuscenes"


def noisy_detections(gt: BoxSet, rng: np.random.Generator, target: int = 75) -> BoxSet:
    """Detector-like boxes from GT (N, 9): noise, 10 % misses, then duplicates / false positives up to ``target``."""
    keep = rng.random(len(gt)) > 0.1
    b = gt.boxes[keep].copy()
    b[:, :3] += rng.normal(0, 0.25, (len(b), 3))
    b[:, 3:6] *= rng.normal(1, 0.05, (len(b), 3)).clip(0.7, 1.3)
    b[:, 6] += rng.normal(0, 0.1, len(b))
    b[:, 7:9] += rng.normal(0, 0.5, (len(b), 2))
    labels, scores = gt.labels[keep], rng.uniform(0.3, 1.0, len(b))
    extra = max(target - len(b), 0)
    if len(b) and extra:
        src = rng.integers(0, len(b), extra)
        fp = b[src].copy()
        fp[:, :2] += rng.normal(0, 3.0, (extra, 2))
        b = np.concatenate([b, fp])
        labels = np.concatenate([labels, labels[src]])
        scores = np.concatenate([scores, rng.uniform(0.0, 0.5, extra)])
    return BoxSet(b, scores, labels)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", default=str(DEFAULT_DATA))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--config", default="ekf")
    ap.add_argument("--tracker", default="ekf")
    ap.add_argument("--checkpoint", default=None, help="GRU-KF model for --tracker grukf")
    ap.add_argument("--scene-copies", type=int, default=3, help="track the scenes this many times per run")
    args = ap.parse_args()

    nusc = open_nuscenes(args.dataroot, "v1.0-mini")
    scenes = load_scenes(nusc, "mini_val", with_gt=True) * args.scene_copies
    rng = np.random.default_rng(0)
    dets = {f.token: noisy_detections(f.gt, rng) for s in scenes for f in s.frames}
    density = np.mean([len(d) for d in dets.values()])
    fps, cpu_fps = [], []
    for _ in range(args.repeat):
        tracker = build_tracker(args.tracker, args.config, checkpoint=args.checkpoint, device="cpu")
        c0 = time.process_time()
        run = track_scenes(tracker, scenes, dets)
        cpu_fps.append(run.frames / (time.process_time() - c0))
        fps.append(run.fps)
    print(
        f"tracker {args.tracker} (config {args.config}), {run.frames} frames per run, "
        f"{density:.1f} raw detections per frame, OMP_NUM_THREADS={os.environ['OMP_NUM_THREADS']}"
    )
    print(f"frames/s per run: {', '.join(f'{v:.1f}' for v in fps)}")
    print(f"median frames/s (wall clock): {statistics.median(fps):.1f}")
    print(f"median frames/s (process CPU time, robust to other load on the machine): {statistics.median(cpu_fps):.1f}")


if __name__ == "__main__":
    sys.exit(main())
