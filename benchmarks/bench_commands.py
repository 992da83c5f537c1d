"""Whole commands as a user runs them, beside a reference commit: ``grutrack --help``, ``grutrack track`` (EKF,
CenterPoint-like density on the real mini_val), ``grutrack evaluate`` with the fast and the devkit evaluator,
GRU-KF tracking frames/s and GRU-KF training frames/s. Thread variables (OMP_NUM_THREADS, ...) are removed from
the children's environment: the figures are what a user gets without setting them.

    .venv/bin/python benchmarks/bench_commands.py --reference c9e955d [--repeat 5 --repeat-devkit 1]
    .venv/bin/python benchmarks/bench_commands.py --reference c9e955d --only grukf_track --only grukf_train

The GRU-KF tracking row is the loop's frames/s as ``grutrack track`` prints it. A checkout whose tracker pays its
one-time start before the loop (``Tracker.warm_up``: numba loading its compiled kernels, torch's first operators)
prints that separately; the row below it, the whole command's wall time, includes everything the user waits for.

Each measurement runs in a child process per checkout (the reference in a temporary git worktree), the
checkouts alternating run by run; medians are printed with the ratio reference / current (> 1: faster now).
Inputs (made once by the current checkout, the same files for both): mini_val ground truth turned into ~75
detections per frame (benchmarks/bench_tracking.py), SIMULATED CenterPoint-profile detections of mini_train and
mini_val for the GRU-KF; each checkout trains its own GRU-KF checkpoint (2 steps) for the tracking row.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _reference import REPO, interleaved, python, reference_checkout, run_measured  # noqa: E402

DEFAULT_DATA = REPO.parent / "shared" / "data" / "nuscenes"

#: GRU-KF training in the child: what ``grutrack train`` does (its thread policy where the checkout has one)
TRAIN_DRIVER = """
import json, sys, time
from pathlib import Path
try:
    from grutrack.threads import apply_thread_policy
    apply_thread_policy()
except ImportError:
    pass
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.training.config import load_train_config
from grutrack.training.trainer import Trainer
from pathlib import Path
import grutrack
# the configuration every figure was measured with (the paper's network with the 5-bin gap table); older
# checkouts have it as their default "grukf"
_paper = (Path(grutrack.__file__).parent / "configs/training/paper.yaml").is_file()
def bench_config(**over):
    return load_train_config("paper" if _paper else "grukf", {**({"gap_bins": 5} if _paper else {}), **over})
root, dets, out, steps = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
scenes = load_scenes(open_nuscenes(root, "v1.0-mini"), "mini_train", with_gt=True)
d = load_detections(dets, [f.token for s in scenes for f in s.frames])
cfg = bench_config(device="cpu", checkpoint_every=0, epochs=100)
t = Trainer(cfg, scenes, d, out, progress=False)
frames = []
step = Trainer._step
# both checkouts have it: one scene (older commits) or the step's list of scenes
Trainer._step = lambda self, sc: (frames.append(sum(map(len, sc)) if isinstance(sc, list) else len(sc)),
                                  step(self, sc))[1]
t0 = time.perf_counter()
t.run(max_steps=steps)
dt = time.perf_counter() - t0
print(f"training frames/s {sum(frames) / dt:.3f}")
"""


#: a 2-step GRU-KF checkpoint made by the checkout that reads it (a checkpoint's format may differ between commits)
CHECKPOINT_DRIVER = """
import sys
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.training.config import load_train_config
from grutrack.training.trainer import Trainer
from pathlib import Path
import grutrack
# the configuration every figure was measured with (the paper's network with the 5-bin gap table); older
# checkouts have it as their default "grukf"
_paper = (Path(grutrack.__file__).parent / "configs/training/paper.yaml").is_file()
def bench_config(**over):
    return load_train_config("paper" if _paper else "grukf", {**({"gap_bins": 5} if _paper else {}), **over})
root, dets, out = sys.argv[1:4]
scenes = load_scenes(open_nuscenes(root, "v1.0-mini"), "mini_train", with_gt=True)
d = load_detections(dets, [f.token for s in scenes for f in s.frames])
t = Trainer(bench_config(device="cpu", checkpoint_every=0), scenes, d, out, progress=False)
t.run(max_steps=2)
t.save("bench.pt")
"""


def write_dense_detections(scenes, path: Path, target: int = 75, seed: int = 0) -> int:
    """Detector-like boxes from the scenes' ground truth (``bench_tracking.noisy_detections``: noise, misses,
    duplicates and false positives up to ``target`` per frame, CenterPoint's density) as a detection JSON."""
    import numpy as np
    from bench_tracking import noisy_detections

    from grutrack.boxes import quaternion_from_yaw
    from grutrack.classes import TRACKING_CLASSES

    rng = np.random.default_rng(seed)
    results, n = {}, 0
    for f in (f for s in scenes for f in s.frames):
        d = noisy_detections(f.gt, rng, target)
        q = quaternion_from_yaw(d.boxes[:, 6])
        results[f.token] = [
            {
                "sample_token": f.token,
                "translation": b[:3].tolist(),
                "size": b[3:6].tolist(),
                "rotation": qq.tolist(),
                "velocity": b[7:9].tolist(),
                "detection_name": TRACKING_CLASSES[int(lab)],
                "detection_score": float(sc),
                "attribute_name": "",
            }
            for b, qq, lab, sc in zip(d.boxes, q, d.labels, d.scores)
        ]
        n += len(d)
    meta = {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False}
    path.write_text(json.dumps({"meta": meta, "results": results}))
    return n


def make_inputs(root: Path, tmp: Path) -> dict:
    """Dense mini_val detections and simulated CenterPoint-profile detections of mini_train and mini_val (current
    checkout); the GRU-KF checkpoints are made by each checkout (:data:`CHECKPOINT_DRIVER`)."""
    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.data.nuscenes import load_scenes, open_nuscenes

    nusc = open_nuscenes(root, "v1.0-mini")
    val = load_scenes(nusc, "mini_val", with_gt=True)
    paths = {"dense": tmp / "dense_mini_val.json"}
    write_dense_detections(val, paths["dense"])
    for split, seed in (("mini_train", 1), ("mini_val", 2)):
        paths[split] = tmp / f"sim_{split}.json"
        paths[split].write_text(json.dumps(simulate_nuscenes(None, "v1.0-mini", split, "centerpoint", seed, nusc=nusc)))
    return paths


def _fps(run, pattern: str) -> float:
    m = re.search(pattern + r"\s*\(?([0-9.]+) frames/s" if "loop" in pattern else pattern + r" ([0-9.]+)", run.stdout)
    if not m:
        raise RuntimeError(f"no '{pattern}' figure in:\n{run.stdout[-2000:]}")
    return float(m.group(1))


def _line(label, unit, s, fig, higher) -> str:
    cur = fig(s["current"])
    ref_v = fig(s["reference"]) if "reference" in s else float("nan")
    ratio = (cur / ref_v if higher else ref_v / cur) if ref_v == ref_v else float("nan")
    return f"{label:<48}{unit:>9}{ref_v:>12.3f}{cur:>12.3f}{ratio:>9.2f}x"


class _Rows(list):
    """The table's rows; each is shown on stderr as soon as it is measured (a full run takes minutes)."""

    def append(self, row) -> None:
        super().append(row)
        print("measured: " + _line(*row), file=sys.stderr, flush=True)


#: the measurements, as --skip and --only name them
MEASUREMENTS = ("help", "track", "fast", "devkit", "grukf_track", "grukf_train")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", default=str(DEFAULT_DATA))
    ap.add_argument("--reference", default="c9e955d", help="commit to measure beside the current checkout")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--repeat-devkit", type=int, default=1, help="runs of the devkit evaluate command")
    ap.add_argument("--repeat-grukf", type=int, default=3, help="runs of GRU-KF tracking and training")
    ap.add_argument(
        "--train-steps",
        type=int,
        default=8,
        help="GRU-KF training steps timed (8 = one epoch of mini_train: every scene once)",
    )
    ap.add_argument("--make-inputs", default=None, help=argparse.SUPPRESS)  # internal: build inputs into DIR
    ap.add_argument("--skip", action="append", default=[], choices=MEASUREMENTS, help="skip a measurement")
    ap.add_argument(
        "--only",
        action="append",
        default=[],
        choices=MEASUREMENTS,
        help="run only this measurement (repeatable), e.g. --only grukf_track --only grukf_train",
    )
    args = ap.parse_args(argv)
    if args.only:
        args.skip = [m for m in MEASUREMENTS if m not in args.only]
    root = Path(args.dataroot)
    if args.make_inputs:
        paths = make_inputs(root, Path(args.make_inputs))
        print(json.dumps({k: str(v) for k, v in paths.items()}))
        return 0
    py = python()
    with tempfile.TemporaryDirectory(prefix="grutrack-bench-") as tmp_, reference_checkout(args.reference) as ref:
        tmp = Path(tmp_)
        # in a child: this process stays small, so the children's peak RSS (inherited at fork) is their own
        made = run_measured([py, __file__, "--dataroot", str(root), "--make-inputs", str(tmp)], REPO)
        paths = {k: Path(v) for k, v in json.loads(made.stdout.splitlines()[-1]).items()}
        roots = {"reference": ref, "current": REPO} if ref else {"current": REPO}
        common = ["--dataroot", str(root), "--version", "v1.0-mini", "--split", "mini_val"]

        def out(root_, name):
            return str(tmp / f"{name}_{'ref' if root_ == ref else 'cur'}.json")

        rows = _Rows()  # (label, unit, series per checkout, figure, higher_is_better), shown as measured
        if "help" not in args.skip:
            s = interleaved(lambda r: run_measured([py, "-m", "grutrack", "--help"], r), roots, args.repeat)
            rows.append(("grutrack --help", "s", s, lambda x: x.median("wall"), False))
            rows.append(("  its CPU time", "s", s, lambda x: x.median("cpu"), False))
        # the track output of each checkout is what its evaluate commands read
        need_track = {"track", "fast", "devkit"} - set(args.skip)
        s = (
            None
            if not need_track
            else interleaved(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "track",
                        *common,
                        "--detections",
                        str(paths["dense"]),
                        "--out",
                        out(r, "tracks"),
                        "--no-progress",
                    ],
                    r,
                ),
                roots,
                args.repeat,
            )
        )
        if "track" not in args.skip:
            rows.append(("grutrack track (EKF, ~75 dets/frame)", "s", s, lambda x: x.median("wall"), False))
            rows.append(("  its CPU time", "s", s, lambda x: x.median("cpu"), False))
            rows.append(("  its peak memory", "MiB", s, lambda x: x.median("rss_mib"), False))
        fast = None
        if "fast" not in args.skip:
            fast = interleaved(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "evaluate",
                        *common,
                        "--submission",
                        out(r, "tracks"),
                        "--out",
                        out(r, "m_fast"),
                        "--evaluator",
                        "fast",
                    ],
                    r,
                ),
                roots,
                args.repeat,
            )
            rows.append(("grutrack evaluate --evaluator fast", "s", fast, lambda x: x.median("wall"), False))
            rows.append(("  its CPU time", "s", fast, lambda x: x.median("cpu"), False))
        devkit = None
        if "devkit" not in args.skip:
            devkit = interleaved(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "evaluate",
                        *common,
                        "--submission",
                        out(r, "tracks"),
                        "--out",
                        out(r, "m_devkit"),
                        "--evaluator",
                        "devkit",
                    ],
                    r,
                ),
                roots,
                args.repeat_devkit,
            )
            rows.append(("grutrack evaluate --evaluator devkit", "s", devkit, lambda x: x.median("wall"), False))
            rows.append(("  its CPU time", "s", devkit, lambda x: x.median("cpu"), False))
        if "grukf_track" not in args.skip:
            checkpoint = {}
            for name, r in roots.items():
                run_measured(
                    [py, "-", str(root), str(paths["mini_train"]), str(tmp / f"ck_{name}")], r, stdin=CHECKPOINT_DRIVER
                )
                checkpoint[r] = str(tmp / f"ck_{name}" / "bench.pt")
            s = interleaved(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "track",
                        *common,
                        "--detections",
                        str(paths["mini_val"]),
                        "--tracker",
                        "grukf",
                        "--checkpoint",
                        checkpoint[r],
                        "--device",
                        "cpu",
                        "--out",
                        out(r, "grukf"),
                        "--no-progress",
                    ],
                    r,
                ),
                roots,
                args.repeat_grukf,
            )
            for r in (x for v in s.values() for x in v.runs):
                r.fps = _fps(r, "tracking loop: [0-9]+ frames in [0-9.]+ s")
            rows.append(("GRU-KF tracking loop (grutrack track)", "frames/s", s, lambda x: x.median("fps"), True))
            rows.append(("  the whole command's wall time", "s", s, lambda x: x.median("wall"), False))
        if "grukf_train" not in args.skip:
            s = interleaved(
                lambda r: run_measured(
                    [
                        py,
                        "-",
                        str(root),
                        str(paths["mini_train"]),
                        str(tmp / f"train_{'ref' if r == ref else 'cur'}"),
                        str(args.train_steps),
                    ],
                    r,
                    stdin=TRAIN_DRIVER,
                ),
                roots,
                args.repeat_grukf,
            )
            for r in (x for v in s.values() for x in v.runs):
                r.fps = _fps(r, "training frames/s")
            rows.append(
                (
                    f"GRU-KF training ({args.train_steps} steps, one per scene)",
                    "frames/s",
                    s,
                    lambda x: x.median("fps"),
                    True,
                )
            )

    cpu_note = f"{__import__('os').cpu_count()} cores; thread variables unset in the children"
    print(f"\nmedians; reference {args.reference or '-'} vs current checkout; {cpu_note}")
    print(f"{'measurement':<48}{'unit':>9}{'reference':>12}{'current':>12}{'speed-up':>10}")
    for row in rows:
        print(_line(*row))
    if fast and devkit:
        for name in fast:
            print(
                f"fast vs devkit evaluate command ({name}): "
                f"{devkit[name].median('wall') / fast[name].median('wall'):.1f}x wall, "
                f"{devkit[name].median('cpu') / fast[name].median('cpu'):.1f}x CPU time"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
