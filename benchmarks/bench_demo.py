"""Benchmark of the embedded default: generate a nuScenes-val-sized SYNTHETIC demo (150 scenes x 40 keyframes)
and simulate CenterPoint-like detections for all of it.

    .venv/bin/python benchmarks/bench_demo.py [--scenes 150] [--frames 40] [--profile centerpoint] [--keep DIR]

Target (issue): generation under 60 s on the 2-core CI machine. Prints one line per stage.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from grutrack.data import detection_sim as ds
from grutrack.data.demo import generate_demo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=150, help="scenes (nuScenes val has 150)")
    parser.add_argument("--frames", type=int, default=40, help="keyframes per scene")
    parser.add_argument("--profile", default="centerpoint")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keep", help="write the dataset and detections here instead of a temporary folder")
    args = parser.parse_args()

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="grutrack-bench-"))
    try:
        root = work / "demo"
        t0 = time.perf_counter()
        info = generate_demo(root, scenes=args.scenes, frames=args.frames, seed=args.seed)
        t_gen = time.perf_counter() - t0
        print(
            f"generate {args.scenes} scenes x {args.frames} frames: {t_gen:6.1f} s "
            f"({info['samples']} samples, {info['instances']} instances, {info['annotations']} annotations)"
        )

        t0 = time.perf_counter()
        nusc = ds.open_dataset(root, info["version"])
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        frames = ds.nusc_gt_frames(nusc, "demo_all")
        t_gt = time.perf_counter() - t0
        profile = ds.load_profile(args.profile)
        t0 = time.perf_counter()
        dets = ds.simulate(frames, profile, args.seed)
        t_sim = time.perf_counter() - t0
        t0 = time.perf_counter()
        ds.write_detection_json(work / f"{args.profile}.json", ds.detection_json(dets, profile, args.seed))
        t_write = time.perf_counter() - t0
        n_det = sum(len(d) for d in dets)
        total = t_load + t_gt + t_sim + t_write
        print(
            f"simulate-detections ({args.profile}, all {len(frames)} samples): {total:6.1f} s "
            f"(devkit load {t_load:.1f}, GT + box_velocity {t_gt:.1f}, sampling {t_sim:.1f}, "
            f"JSON {t_write:.1f}; {n_det} detections)"
        )
        status = "OK" if t_gen < 60.0 else "SLOWER THAN THE 60 s TARGET"
        print(f"generation target < 60 s: {status}")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
