"""GRU-Kalman filter throughput: training (frames/s and scenes/s, one optimizer step per scene) and tracking.

Input: real nuScenes mini_train ground truth (../shared/data) with simulated CenterPoint-like detections
(labelled simulated), mini_val for tracking. Prints medians over --repeat runs of --steps training steps, and
the tracking loop's frames/s with the trained network.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_grukf.py [--steps 8 --repeat 3 --device auto]

``--paper-scale``: training on the paper-scale source mix instead, the real mini_train motion (simulated
CenterPoint-like detections) plus a SYNTHETIC demo_all of 700 scenes x 40 frames (nuScenes train's size, detections
simulated with the same profile), as ``grutrack train --source`` builds it; prints the time to prepare the data,
the training throughput over --steps steps (one per scene, scenes in the run's shuffled order) and the time an
epoch of the mix takes at that throughput.

    .venv/bin/python benchmarks/bench_grukf.py --paper-scale --steps 40 --repeat 1

``--scenes-per-step K``: K scenes per optimizer step, the network batched over them (training config
``scenes_per_step``; a step is then K scenes, frames/s counts the frames of all of them).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

from grutrack.data.detection_sim import simulate_nuscenes  # noqa: E402
from grutrack.data.nusc_detections import load_detections  # noqa: E402
from grutrack.data.nuscenes import load_scenes, open_nuscenes  # noqa: E402
from grutrack.tracking.factory import build_tracker  # noqa: E402
from grutrack.tracking.tracker import track_scenes  # noqa: E402
from grutrack.training.config import load_train_config  # noqa: E402
from grutrack.training.trainer import Trainer  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "nuscenes"


def _dets(nusc, split, seed, scenes, tmp):
    path = Path(tmp) / f"{split}.json"
    path.write_text(json.dumps(simulate_nuscenes(None, "v1.0-mini", split, "centerpoint", seed, nusc=nusc)))
    return load_detections(path, [f.token for s in scenes for f in s.frames])


def _frames_of_steps(t: Trainer, scenes) -> int:
    """The frames of the scenes of the steps trainer ``t`` has taken (its log names them, ``a+b`` for several)."""
    length = {s.name: len(s) for s in scenes}
    return sum(length[name] for row in t.log.steps for name in row.scene.split("+"))


def _timed_trainings(cfg, scenes, dets, tmp, args) -> tuple[Trainer, list[float], list[float]]:
    """``args.repeat`` fresh trainings of ``args.steps`` steps: the last trainer, frames/s and scenes/s of each."""
    fps, sps = [], []
    for r in range(args.repeat):
        t = Trainer(cfg, scenes, dets, Path(tmp) / f"run{r}", progress=False)
        t0 = time.perf_counter()
        t.run(max_steps=args.steps)
        dt = time.perf_counter() - t0
        fps.append(_frames_of_steps(t, scenes) / dt)
        sps.append(sum(len(row.scene.split("+")) for row in t.log.steps) / dt)
    return t, fps, sps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", default=str(DEFAULT_DATA))
    ap.add_argument("--steps", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--device", default="auto")
    ap.add_argument(
        "--config",
        default="paper",
        help="training config (default: paper, with the 5-bin gap table; grukf: the default recipe, "
        "whose network filters only the CTRA classes)",
    )
    ap.add_argument(
        "--paper-scale",
        action="store_true",
        help="train on mini_train + a 700-scene SYNTHETIC demo (the paper's scale), see the docstring",
    )
    ap.add_argument("--demo-scenes", type=int, default=700, help=argparse.SUPPRESS)
    ap.add_argument("--scenes-per-step", type=int, default=1, help="training config scenes_per_step")
    args = ap.parse_args()
    torch.set_num_threads(int(os.environ["OMP_NUM_THREADS"]))
    if args.paper_scale:
        paper_scale(args)
        return
    nusc = open_nuscenes(args.dataroot, "v1.0-mini")
    train = load_scenes(nusc, "mini_train", with_gt=True)
    val = load_scenes(nusc, "mini_val")
    with tempfile.TemporaryDirectory() as tmp:
        dtrain, dval = _dets(nusc, "mini_train", 1, train, tmp), _dets(nusc, "mini_val", 2, val, tmp)
        cfg = load_train_config(
            args.config,
            {
                **_fixed(args.config, args.scenes_per_step),
                "device": args.device,
                "checkpoint_every": 0,
                "epochs": 100,
                "scenes_per_step": args.scenes_per_step,
            },
        )
        t, fps, sps = _timed_trainings(cfg, train, dtrain, tmp, args)
        ckpt = t.save("bench.pt")
        track_fps = []
        for _ in range(args.repeat):
            run = track_scenes(build_tracker("grukf", checkpoint=ckpt, device=args.device), val, dval)
            track_fps.append(run.fps)
    print(
        f"device {t.device}, torch threads {torch.get_num_threads()}, {args.steps} training steps per run, "
        f"{args.scenes_per_step} scene(s) per step"
    )
    print(
        f"training: median {statistics.median(fps):.1f} frames/s, {statistics.median(sps):.2f} scenes/s "
        f"(runs: {', '.join(f'{v:.1f}' for v in fps)} frames/s)"
    )
    print(
        f"tracking with the GRU-KF: median {statistics.median(track_fps):.1f} frames/s "
        f"(runs: {', '.join(f'{v:.1f}' for v in track_fps)})"
    )


def _fixed(config: str, scenes_per_step: int = 1) -> dict:
    """Overrides of a training config: "paper" runs with the 5-bin gap table, the configuration the figures in
    the README were measured with (the default of earlier versions); several scenes per step train the network
    on the tracked classes only (``training_classes: own_model`` needs one scene per step)."""
    return {
        **({"gap_bins": 5} if config == "paper" else {}),
        **({"training_classes": "tracked"} if scenes_per_step > 1 else {}),
    }


def paper_scale(args) -> None:
    """Training throughput and time per epoch on the paper-scale source mix (see the module docstring)."""
    from grutrack.tracking.config import load_tracker_config
    from grutrack.training.sources import load_source, merge

    cfg = load_train_config(
        args.config,
        {
            **_fixed(args.config, args.scenes_per_step),
            "device": args.device,
            "checkpoint_every": 0,
            "epochs": 100,
            "scenes_per_step": args.scenes_per_step,
        },
    )
    yaw = load_tracker_config(cfg.tracker_preset).measured_yaw
    entries = [
        {
            "dataset": "nuscenes",
            "dataroot": args.dataroot,
            "version": "v1.0-mini",
            "split": "mini_train",
            "profile": "centerpoint",
            "seed": 1,
        },
        {
            "dataset": "demo",
            "scenes": args.demo_scenes,
            "frames_per_scene": 40,
            "split": "demo_all",
            "profile": "centerpoint",
            "seed": 1,
        },
    ]
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        loaded = [load_source(e, yaw, Path(tmp) / "sources", f"source {i}") for i, e in enumerate(entries)]
        scenes, dets = merge(loaded)
        prepare = time.perf_counter() - t0
        frames_per_epoch = sum(len(s) for s in scenes)
        t, fps, _ = _timed_trainings(cfg, scenes, dets, tmp, args)
    f = statistics.median(fps)
    print(
        f"paper-scale source mix: {len(scenes)} scenes, {frames_per_epoch} frames per epoch (mini_train, real motion, "
        f"simulated detections; demo_all, SYNTHETIC); data prepared in {prepare:.1f} s"
    )
    print(
        f"device {t.device}, torch threads {torch.get_num_threads()}: training median {f:.1f} frames/s over "
        f"{args.steps} steps of {args.scenes_per_step} scene(s) (runs: {', '.join(f'{v:.1f}' for v in fps)}); an "
        f"epoch ({t.total_steps // cfg.epochs} steps) "
        f"{frames_per_epoch / f / 60:.1f} min"
    )


if __name__ == "__main__":
    main()
