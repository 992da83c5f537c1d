"""nuScenes-val size, beside a reference commit: a SYNTHETIC demo dataset of 150 scenes x 40 keyframes
(6,000 frames, nuScenes val has 150 scenes / 6,019 samples) with ~75 detections per frame made from its ground
truth (noise, misses, duplicates, false positives: benchmarks/bench_tracking.py's model, CenterPoint's density);
the whole commands ``grutrack track`` (EKF and GRU-KF) and ``grutrack evaluate`` (fast and devkit), wall time,
CPU time and peak memory of each, for the reference commit (temporary git worktree) and the current checkout.

    .venv/bin/python benchmarks/bench_valsize.py --reference c9e955d [--scenes 150 --repeat 1]

Inputs are made once by the current checkout (``grutrack demo-data``, the detections) and read by both checkouts;
each checkout trains its own GRU-KF checkpoint (2 steps on the same data: a checkpoint's format may differ between
commits) and tracks the ``demo_val`` split once, untimed, before the measurements (its compiled kernels are then
cached on disk, as after a user's first run). Thread variables are removed from the children's environment. A
script, not a test: at full size it runs for tens of minutes on two cores (the devkit evaluation dominates).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _reference import REPO, concurrent, interleaved, python, reference_checkout, run_measured  # noqa: E402

DENSE_DRIVER = """
import sys
sys.path.insert(0, sys.argv[3])
from bench_commands import write_dense_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
scenes = load_scenes(open_nuscenes(sys.argv[1], "v1.0-demo"), "demo_all", with_gt=True)
write_dense_detections(scenes, __import__("pathlib").Path(sys.argv[2]))
"""


def make_inputs(py: str, tmp: Path, scenes: int, frames: int) -> dict:
    """Demo dataset and ~75 detections per frame made from its ground truth (bench_tracking's noise model), by the
    current checkout in child processes."""
    data, dets = tmp / "demo", tmp / "dets_demo_all.json"
    run_measured(
        [
            py,
            "-m",
            "grutrack",
            "demo-data",
            "--out",
            str(data),
            "--scenes",
            str(scenes),
            "--frames-per-scene",
            str(frames),
        ],
        REPO,
    )
    run_measured([py, "-", str(data), str(dets), str(Path(__file__).resolve().parent)], REPO, stdin=DENSE_DRIVER)
    return {"data": data, "dets": dets}


def prepare_checkout(py: str, root: Path, paths: dict, out: Path) -> Path:
    """A GRU-KF checkpoint trained by checkout ``root`` (2 steps) and one untimed EKF run of ``demo_val`` there
    (fills its compiled-kernel cache); returns the checkpoint."""
    run_measured([py, "-", str(paths["data"]), str(paths["dets"]), str(out)], root, stdin=TRAIN_DRIVER)
    run_measured(
        [
            py,
            "-m",
            "grutrack",
            "track",
            "--dataroot",
            str(paths["data"]),
            "--version",
            "v1.0-demo",
            "--split",
            "demo_val",
            "--detections",
            str(paths["dets"]),
            "--out",
            str(out / "warm.json"),
            "--no-progress",
        ],
        root,
    )
    return out / "bench.pt"


TRAIN_DRIVER = """
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
scenes = load_scenes(open_nuscenes(root, "v1.0-demo"), "demo_all", with_gt=True)[:2]
d = load_detections(dets, [f.token for s in scenes for f in s.frames])
t = Trainer(bench_config(device="cpu", checkpoint_every=0), scenes, d, out, progress=False)
t.run(max_steps=2)
t.save("bench.pt")
"""


def _row(label: str, s) -> str:
    """One table line: reference and current medians (wall s, CPU s, peak MiB) and the wall-time ratio."""
    cur = s["current"]
    line = f"{label:<21}"
    if "reference" in s:
        r = s["reference"]
        line += f"{r.median('wall'):>10.1f}{r.median('cpu'):>10.1f}{r.median('rss_mib'):>10.0f}   |"
        ratio = r.median("wall") / cur.median("wall")
    else:
        line += f"{'':>30}   |"
        ratio = float("nan")
    return line + f"{cur.median('wall'):>10.1f}{cur.median('cpu'):>10.1f}{cur.median('rss_mib'):>10.0f}{ratio:>7.2f}x"


def _done(rows: list, label: str, s) -> None:
    """Keep a measured row and show it at once (stderr): a full-size run takes long."""
    rows.append((label, s))
    print("measured: " + _row(label, s), file=sys.stderr, flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reference", default="c9e955d", help="commit to measure beside the current checkout")
    ap.add_argument("--scenes", type=int, default=150)
    ap.add_argument("--frames-per-scene", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument(
        "--skip",
        action="append",
        default=[],
        choices=("grukf", "fast", "devkit"),
        help="skip a row (the EKF tracks are needed by the evaluation rows)",
    )
    ap.add_argument(
        "--concurrent",
        action="append",
        default=[],
        choices=("ekf", "grukf", "fast", "devkit"),
        help="run the two checkouts' commands of this row (ekf, grukf, fast, devkit) at the same time, "
        "one per core, instead of one after the other (the devkit at full size: hours otherwise)",
    )
    args = ap.parse_args(argv)
    py = python()
    with tempfile.TemporaryDirectory(prefix="grutrack-valsize-") as tmp_, reference_checkout(args.reference) as ref:
        tmp = Path(tmp_)
        paths = make_inputs(py, tmp, args.scenes, args.frames_per_scene)
        n_dets = sum(len(v) for v in json.loads(paths["dets"].read_text())["results"].values())
        roots = {"reference": ref, "current": REPO} if ref else {"current": REPO}
        checkpoint = {r: prepare_checkout(py, r, paths, tmp / f"train_{name}") for name, r in roots.items()}
        common = ["--dataroot", str(paths["data"]), "--version", "v1.0-demo", "--split", "demo_all"]

        def out(r, name):
            return str(tmp / f"{name}_{'ref' if r == ref else 'cur'}.json")

        rows = []

        def measured(row):
            return concurrent if row in args.concurrent else interleaved

        s = measured("ekf")(
            lambda r: run_measured(
                [
                    py,
                    "-m",
                    "grutrack",
                    "track",
                    *common,
                    "--detections",
                    str(paths["dets"]),
                    "--out",
                    out(r, "ekf"),
                    "--no-progress",
                ],
                r,
            ),
            roots,
            args.repeat,
        )
        _done(rows, "track, EKF", s)
        if "grukf" not in args.skip:
            s = measured("grukf")(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "track",
                        *common,
                        "--detections",
                        str(paths["dets"]),
                        "--tracker",
                        "grukf",
                        "--checkpoint",
                        str(checkpoint[r]),
                        "--device",
                        "cpu",
                        "--out",
                        out(r, "grukf"),
                        "--no-progress",
                    ],
                    r,
                ),
                roots,
                args.repeat,
            )
            _done(rows, "track, GRU-KF", s)
        for ev in ("fast", "devkit"):
            if ev in args.skip:
                continue
            s = measured(ev)(
                lambda r: run_measured(
                    [
                        py,
                        "-m",
                        "grutrack",
                        "evaluate",
                        *common,
                        "--submission",
                        out(r, "ekf"),
                        "--out",
                        out(r, f"m_{ev}"),
                        "--evaluator",
                        ev,
                    ],
                    r,
                ),
                roots,
                args.repeat,
            )
            _done(rows, f"evaluate, {ev}", s)
        amota = (
            {name: json.loads(Path(out(r, "m_fast")).read_text())["overall"]["amota"] for name, r in roots.items()}
            if "fast" not in args.skip
            else {}
        )

    frames = args.scenes * args.frames_per_scene
    print(
        f"\nSYNTHETIC demo split: {args.scenes} scenes, {frames} frames, {n_dets} SIMULATED detections "
        f"({n_dets / frames:.1f} per frame); medians of {args.repeat} run(s); thread variables unset"
        + (f"; run side by side (one per core): {', '.join(args.concurrent)}" if args.concurrent else "")
    )
    print(
        f"{'command':<18}{'':>3}{'wall s':>10}{'CPU s':>10}{'peak MiB':>10}   |{'wall s':>10}{'CPU s':>10}"
        f"{'peak MiB':>10}{'wall x':>8}"
    )
    print(f"{'':<21}{'reference ' + (args.reference or '-'):>30}   |{'current':>30}")
    for label, s in rows:
        print(_row(label, s))
    if amota:
        print("AMOTA of the EKF tracks (fast evaluator): " + ", ".join(f"{k} {v:.4f}" for k, v in amota.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
