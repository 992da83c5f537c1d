"""Argoverse 2 at 10 Hz with the motion models' process noise Q scaled: official HOTA per SYNTHETIC detection set.

Every preset's Q comes from Poly-MOT's, tuned for nuScenes keyframes (one prediction every 0.5 s), and the tracker
adds it at every prediction step. At AV2's 10 Hz a track is predicted five times per 0.5 s, so it takes five times
the process noise per second. This script measures what scaling Q per step would give: ``--factors 1,0.2`` runs
the preset as it is (1) and with every class's Q times 0.2 (the noise of a 0.5 s step spread over five 0.1 s
steps). The scaling is applied here, from outside, to the Kalman filter's prediction (``P = F P F^T + s Q``), the
EKF's and the GRU-KF's covariance alike; no preset has such an option. A measurement, not a test:

    .venv/bin/python benchmarks/bench_av2_process_noise.py [--tracker ekf] [--factors 1,0.5,0.2] \\
        [--profiles centerpoint,centerpoint_velfail,pointpillars] [--seeds 2,3,4,5] [--cache DIR]

Detections: ``grutrack simulate-detections --dataset av2 --rate 10`` on the split's logs (the shared fragment's
two val logs by default), made once into ``--cache``. Each set is tracked with ``grutrack track`` and scored with
``grutrack evaluate`` (the official AV2 tracking evaluation), in this process.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_ROOT = REPO.parent / "shared" / "data" / "av2" / "sensor"


@contextlib.contextmanager
def process_noise_scaled(factor: float):
    """Within the block, every Kalman prediction adds ``factor * Q`` instead of Q."""
    from grutrack.motion.kalman import BatchKalmanFilter

    predict = BatchKalmanFilter.predict

    def scaled(self, x, P, Q, dt):
        return predict(self, x, P, np.asarray(Q, dtype=np.float64) * factor, dt)

    BatchKalmanFilter.predict = scaled
    try:
        yield
    finally:
        BatchKalmanFilter.predict = predict


def _cli(argv: list[str]) -> None:
    from grutrack.cli import main

    with contextlib.redirect_stdout(sys.stderr):
        status = main([str(a) for a in argv])
    if status:
        raise SystemExit(f"grutrack {argv[0]} failed (exit {status})")


def hota(args, detections: Path, factor: float, work: Path) -> float:
    """Official HOTA of the preset on ``detections`` with Q scaled by ``factor``."""
    where = ["--dataset", "av2", "--dataroot", args.dataroot, "--split", args.split, "--rate", args.rate]
    with process_noise_scaled(factor):
        _cli(["track", *where, "--detections", detections, "--tracker", args.tracker, "--config", args.config,
              "--out", work / "t.pkl", "--no-progress"])  # fmt: skip
    _cli(["evaluate", *where, "--submission", work / "t.pkl", "--out", work / "m.json"])
    return float(json.loads((work / "m.json").read_text())["overall"]["hota"])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataroot", default=str(DEFAULT_ROOT), help="AV2 sensor root (holds <split>/<log_id>/)")
    ap.add_argument("--split", default="val")
    ap.add_argument("--rate", default="10", help="tracking rate, Hz (default 10, AV2's lidar)")
    ap.add_argument("--tracker", default="ekf", choices=("ekf", "grukf"))
    ap.add_argument("--config", default="ekf", help="tracker preset (default ekf)")
    ap.add_argument("--factors", default="1,0.5,0.2", help="comma list of Q scales; the first is the reference")
    ap.add_argument("--profiles", default="centerpoint,centerpoint_velfail,pointpillars")
    ap.add_argument("--seeds", default="2,3,4,5")
    ap.add_argument("--cache", type=Path, default=None, help="folder for the simulated detections (reused)")
    args = ap.parse_args(argv)
    factors = [float(f) for f in args.factors.split(",")]
    cache = args.cache or Path(tempfile.mkdtemp(prefix="av2_q_"))
    cache.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="av2_q_run_"))
    rows = []
    print(f"official AV2 HOTA, {args.tracker} --config {args.config}, {args.split} at {args.rate} Hz, SYNTHETIC")
    print("set                         " + "".join(f"  Q x {f:<5g}" for f in factors))
    for profile in args.profiles.split(","):
        for seed in args.seeds.split(","):
            det = cache / f"{args.split}_{args.rate}hz_{profile}_s{seed}.feather"
            if not det.is_file():
                _cli(["simulate-detections", "--dataset", "av2", "--dataroot", args.dataroot, "--split", args.split,
                      "--rate", args.rate, "--profile", profile, "--seed", seed, "--out", det])  # fmt: skip
            row = [hota(args, det, f, work) for f in factors]
            rows.append(row)
            print(f"{profile + ' s' + seed:<28}" + "".join(f"  {h:9.4f}" for h in row), flush=True)
    table = np.array(rows)
    print("mean                        " + "".join(f"  {h:9.4f}" for h in table.mean(axis=0)))
    for j, f in enumerate(factors[1:], start=1):
        d = table[:, j] - table[:, 0]
        print(
            f"Q x {f:g} against Q x {factors[0]:g}: mean {d.mean():+.4f}, median {statistics.median(d):+.4f}, "
            f"higher on {(d > 1e-4).sum()} of {len(d)}, lower on {(d < -1e-4).sum()}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
