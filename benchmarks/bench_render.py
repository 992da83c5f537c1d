"""Benchmark of ``grutrack render``, timed as a user runs it (a fresh ``grutrack render`` process: dataset loading,
evaluation matching, drawing, files).

- ``--dataset nuscenes`` (default): both nuScenes mini_val scenes (81 frames: PNG each, one GIF per scene,
  counts.json) for the real PointPillars detections tracked by the EKF.
- ``--dataset av2``: both AV2 val logs of the fixture at 2 Hz (64 frames, 2 GIFs, counts.json; the official AV2
  evaluation runs inside, one worker) for SIMULATED detections (the centerpoint profile, seed 0, as in
  grutrack simulate-detections --dataset av2; the fixture has no real AV2 detections) tracked by the EKF.

    .venv/bin/python benchmarks/bench_render.py [--dataset nuscenes|av2] [--data ../shared/data] [--repeat 3]
                                                [--keep DIR]

Target (issue 16): both mini_val scenes under 30 s on the 2-core machine. Prints the command and the wall and CPU
time of each repeat (the CPU time does not grow when other jobs share the cores; the wall time does).
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", choices=("nuscenes", "av2"), default="nuscenes")
    parser.add_argument("--data", default=str(REPO.parent / "shared" / "data"), help="real data fragments")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--keep", help="keep the submission and renders here instead of a temporary folder")
    args = parser.parse_args()

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="grutrack-bench-render-"))
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    grutrack = [sys.executable, "-m", "grutrack"]
    try:
        if args.dataset == "nuscenes":
            nusc = Path(args.data) / "nuscenes"
            dets = nusc / "detections" / "pointpillars_mini_val.json"
            common = ["--dataset", "nuscenes", "--dataroot", str(nusc), "--version", "v1.0-mini", "--split", "mini_val"]
            sub = work / "ekf_pointpillars_mini_val.json"
            scenes, what = ["scene-0103", "scene-0916"], "81 frames, 2 GIFs, counts.json"
        else:
            root = Path(args.data) / "av2" / "sensor"
            dets = work / "simulated_av2_val.feather"
            _simulated_av2(root, dets)
            common = ["--dataset", "av2", "--dataroot", str(root), "--split", "val"]
            sub = work / "ekf_simulated_av2_val.pkl"
            scenes = ["7fab2350-7eaf-3b7e-a39d-6937a4c1bede", "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"]
            what = "64 frames, 2 GIFs, counts.json, official AV2 evaluation"
        subprocess.run(
            [
                *grutrack,
                "track",
                *common,
                "--detections",
                str(dets),
                "--tracker",
                "ekf",
                "--out",
                str(sub),
                "--no-progress",
            ],
            check=True,
            env=env,
            stdout=subprocess.DEVNULL,
        )
        cmd = [
            *grutrack,
            "render",
            *common,
            "--submission",
            str(sub),
            "--detections",
            str(dets),
            "--scene",
            *scenes,
            "--out",
            str(work / "render"),
        ]
        print("command:", shlex.join(cmd))
        times = []
        for i in range(args.repeat):
            shutil.rmtree(work / "render", ignore_errors=True)
            ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
            times.append(time.perf_counter() - t0)
            ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
            print(f"repeat {i + 1}: {times[-1]:6.1f} s wall, {cpu:5.1f} s CPU ({what})")
        print(
            f"best {min(times):.1f} s, median {sorted(times)[len(times) // 2]:.1f} s; target < 30 s; "
            f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
        )
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


def _simulated_av2(root: Path, out: Path) -> None:
    """SIMULATED LT3D detections of the AV2 val logs (`grutrack simulate-detections --dataset av2`, centerpoint
    profile, seed 0) written to ``out``."""
    sys.path.insert(0, str(REPO))
    from grutrack.data.detection_sim import load_profile
    from grutrack.datasets import DatasetOptions, open_dataset

    open_dataset("av2", DatasetOptions(root)).simulate_detections("val", load_profile("centerpoint"), 0, out)


if __name__ == "__main__":
    main()
