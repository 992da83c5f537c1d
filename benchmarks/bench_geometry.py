"""Timing of the pairwise overlap measures of grutrack.geometry (a plain script, not a test).

Usage: ``python benchmarks/bench_geometry.py [--repeats N] [--seed S]``

Two workloads:

* 60 x 75: a busy nuScenes frame, 60 tracks against 75 detections within 50 m of the ego vehicle,
  a class mix of cars, pedestrians, trucks, cyclists and cones, most detections close to a track;
* 500 x 500: two large sets spread over 200 m x 200 m.

Prints, for each pairwise function, the median (and min / max) over the timing runs in ms and the
median throughput in pairs/s. numpy runs these element-wise operations on one core. The machine may
be shared, so compare medians, not single runs.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time

import numpy as np

from grutrack import geometry

# (w, l, h) in metres and relative frequency of a few nuScenes classes.
_SIZES = np.array([[1.95, 4.6, 1.75], [0.7, 0.75, 1.8], [2.5, 7.5, 3.0], [0.6, 1.8, 1.4], [0.45, 0.45, 1.0]])
_FREQ = np.array([0.45, 0.25, 0.1, 0.1, 0.1])

FUNCTIONS = {
    "pairwise_bev_iou": geometry.pairwise_bev_iou,
    "pairwise_bev_giou": geometry.pairwise_bev_giou,
    "pairwise_iou_3d": geometry.pairwise_iou_3d,
    "pairwise_giou_3d": geometry.pairwise_giou_3d,
    "pairwise_centre_distance": geometry.pairwise_centre_distance,
}


def random_boxes(rng: np.random.Generator, n: int, half_span: float) -> np.ndarray:
    """``(n, 9)`` boxes of the class mix, centres uniform in a square of side ``2 * half_span`` m."""
    kind = rng.choice(len(_SIZES), size=n, p=_FREQ)
    boxes = np.zeros((n, 9))
    boxes[:, :2] = rng.uniform(-half_span, half_span, (n, 2))
    boxes[:, 3:6] = _SIZES[kind] * rng.uniform(0.85, 1.15, (n, 3))
    boxes[:, 2] = boxes[:, 5] / 2 + rng.normal(0.0, 0.1, n)
    boxes[:, 6] = rng.uniform(-np.pi, np.pi, n)
    boxes[:, 7:9] = rng.normal(0.0, 3.0, (n, 2))
    return boxes


def frame_workload(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """60 tracks and 75 detections: 55 detections jittered from tracks, 20 new ones."""
    tracks = random_boxes(rng, 60, 50.0)
    near = tracks[rng.choice(60, size=55, replace=False)].copy()
    near[:, :2] += rng.normal(0.0, 0.5, (55, 2))
    near[:, 6] += rng.normal(0.0, 0.1, 55)
    dets = np.concatenate([near, random_boxes(rng, 20, 50.0)])
    return tracks, dets


def time_runs(fn, a: np.ndarray, b: np.ndarray, repeats: int) -> list[float]:
    """Wall-clock seconds of ``repeats`` calls of ``fn(a, b)`` after one warm-up call."""
    fn(a, b)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn(a, b)
        times.append(time.perf_counter() - start)
    return times


def report(label: str, a: np.ndarray, b: np.ndarray, repeats: int) -> None:
    """Print one table of timings for all pairwise functions on ``a`` x ``b``."""
    pairs = a.shape[0] * b.shape[0]
    overlap = float((geometry.pairwise_bev_iou(a, b) > 0).mean())
    print(
        f"\n{label}: {a.shape[0]} x {b.shape[0]} = {pairs} pairs "
        f"({overlap:.1%} overlapping in BEV), {repeats} runs each"
    )
    print(f"  {'function':26s} {'median ms':>10s} {'min ms':>9s} {'max ms':>9s} {'pairs/s':>12s}")
    for name, fn in FUNCTIONS.items():
        times = time_runs(fn, a, b, repeats)
        med = statistics.median(times)
        print(f"  {name:26s} {med * 1e3:10.3f} {min(times) * 1e3:9.3f} {max(times) * 1e3:9.3f} {pairs / med:12.3g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--repeats", type=int, default=30, help="timing runs for 60 x 75 (500 x 500 gets a fifth, at least 3)"
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    tracks, dets = frame_workload(rng)
    report("busy nuScenes frame", tracks, dets, args.repeats)
    big_a, big_b = random_boxes(rng, 500, 100.0), random_boxes(rng, 500, 100.0)
    report("large sets", big_a, big_b, max(3, args.repeats // 5))


if __name__ == "__main__":
    main()
