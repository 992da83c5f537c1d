"""Benchmark of ``grutrack render``: both nuScenes mini_val scenes (81 frames: PNG each, one GIF per scene,
counts.json) for the real PointPillars detections tracked by the EKF, timed as a user runs it (a fresh
``grutrack render`` process: dataset loading, evaluation matching, drawing, files).

    .venv/bin/python benchmarks/bench_render.py [--data ../shared/data] [--repeat 3] [--keep DIR]

Target (issue 16): under 30 s on the 2-core machine. Prints the command and the wall and CPU time of each
repeat (the CPU time does not grow when other jobs share the cores; the wall time does).
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
    parser.add_argument("--data", default=str(REPO.parent / "shared" / "data"), help="real data fragments")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--keep", help="keep the submission and renders here instead of a temporary folder")
    args = parser.parse_args()

    nusc = Path(args.data) / "nuscenes"
    dets = nusc / "detections" / "pointpillars_mini_val.json"
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="grutrack-bench-render-"))
    work.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    grutrack = [sys.executable, "-m", "grutrack"]
    common = ["--dataset", "nuscenes", "--dataroot", str(nusc), "--version", "v1.0-mini", "--split", "mini_val"]
    try:
        sub = work / "ekf_pointpillars_mini_val.json"
        subprocess.run([*grutrack, "track", *common, "--detections", str(dets), "--tracker", "ekf", "--out",
                        str(sub), "--no-progress"], check=True, env=env, stdout=subprocess.DEVNULL)
        cmd = [*grutrack, "render", *common, "--submission", str(sub), "--detections", str(dets),
               "--scene", "scene-0103", "scene-0916", "--out", str(work / "render")]
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
            print(f"repeat {i + 1}: {times[-1]:6.1f} s wall, {cpu:5.1f} s CPU (81 frames, 2 GIFs, counts.json)")
        print(f"best {min(times):.1f} s, median {sorted(times)[len(times) // 2]:.1f} s; target < 30 s; "
              f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
