"""GRU-Kalman filter throughput: training (frames/s and scenes/s, one optimizer step per scene) and tracking.

Input: real nuScenes mini_train ground truth (../shared/data) with simulated CenterPoint-like detections
(labelled simulated), mini_val for tracking. Prints medians over --repeat runs of --steps training steps, and
the tracking loop's frames/s with the trained network. Threads: the toolkit's policy (``grutrack/threads.py``: one
intra-op thread, ``GRUTRACK_THREADS`` to change it).

    .venv/bin/python benchmarks/bench_grukf.py [--steps 8 --repeat 3 --device auto]

``--paper-scale``: training on the paper-scale source mix instead, the real mini_train motion (simulated
CenterPoint-like detections) plus a SYNTHETIC demo_all of 700 scenes x 40 frames (nuScenes train's size, detections
simulated with the same profile), as ``grutrack train --source`` builds it; prints the time to prepare the data,
the training throughput over --steps steps (one per scene, scenes in the run's shuffled order) and the time an
epoch of the mix takes at that throughput.

    .venv/bin/python benchmarks/bench_grukf.py --paper-scale --steps 40 --repeat 1

``--scenes-per-step K``: K scenes per optimizer step, the network batched over them (training config
``scenes_per_step``; a step is then K scenes, frames/s counts the frames of all of them).

``--lockstep``: one table of training throughput for several scenes per step on several devices in one run:
every k of ``--scenes-per-step`` (a comma list, default 1,8,32) on every device of ``--device`` (a comma list:
cpu, cuda, cpu,cuda; a device this machine lacks is refused in one line, exit 2), the default recipe
(``--config``, default grukf: training_classes own_model, two network groups) on the same SYNTHETIC demo scenes
(``--lockstep-scenes``, default the largest k, of 40 frames; simulated CenterPoint-like detections), each k over
those scenes once (scenes / k steps, after one untimed warm-up step), medians over ``--repeat`` runs; then the
GRU-KF tracking loop's frames/s on mini_val (real motion, simulated detections) on each device.

    .venv/bin/python benchmarks/bench_grukf.py --lockstep --device cpu,cuda --repeat 1
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

from grutrack.data.detection_sim import simulate_nuscenes
from grutrack.data.nusc_detections import load_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.errors import ConfigError
from grutrack.threads import apply_thread_policy
from grutrack.tracking.factory import build_tracker
from grutrack.tracking.tracker import track_scenes
from grutrack.training.config import load_train_config
from grutrack.training.trainer import Trainer

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
        default=None,
        help="training config (default: paper, with the 5-bin gap table; grukf: the default recipe, "
        "whose network filters only the CTRA classes; with --lockstep the default is grukf)",
    )
    ap.add_argument(
        "--paper-scale",
        action="store_true",
        help="train on mini_train + a 700-scene SYNTHETIC demo (the paper's scale), see the docstring",
    )
    ap.add_argument("--demo-scenes", type=int, default=700, help=argparse.SUPPRESS)
    ap.add_argument(
        "--scenes-per-step",
        default=None,
        help="training config scenes_per_step (default 1); with --lockstep a comma list (default 1,8,32)",
    )
    ap.add_argument(
        "--lockstep",
        action="store_true",
        help="a table of training throughput for each k of --scenes-per-step on each device of --device",
    )
    ap.add_argument(
        "--lockstep-scenes", type=int, default=None, help="SYNTHETIC demo scenes per k (default: the largest k)"
    )
    args = ap.parse_args()
    args.config = args.config or ("grukf" if args.lockstep else "paper")
    devices = _devices(args.device)
    apply_thread_policy()
    if args.lockstep:
        lockstep(args)
        return
    if len(devices) != 1:
        print(f"bench_grukf.py: --device: one device without --lockstep, got {args.device!r}", file=sys.stderr)
        raise SystemExit(2)
    ks = _ks(args.scenes_per_step or "1")
    if len(ks) != 1:
        print(
            f"bench_grukf.py: --scenes-per-step: one k without --lockstep, got {args.scenes_per_step!r}",
            file=sys.stderr,
        )
        raise SystemExit(2)
    args.scenes_per_step = ks[0]
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
                **_fixed(args.config),
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


def _fixed(config: str) -> dict:
    """Overrides of a training config: "paper" runs with the 5-bin gap table, the configuration the figures in
    the README were measured with (the default of earlier versions)."""
    return {"gap_bins": 5} if config == "paper" else {}


def _devices(arg: str) -> list[str]:
    """The devices of ``--device`` (a comma list), each checked here: one this machine lacks stops the run with
    one line and exit status 2."""
    from grutrack.tracking.grukf_backend import resolve_device

    names = [d.strip() for d in arg.split(",") if d.strip()]
    try:
        for d in names:
            resolve_device(d, "--device")
    except ConfigError as exc:
        print(f"bench_grukf.py: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    return names


def _ks(arg: str | None) -> list[int]:
    """The k of ``--scenes-per-step`` (a comma list; default 1, 8, 32); a bad one exits 2 in one line."""
    try:
        ks = [int(k) for k in (arg or "1,8,32").split(",")]
        if any(k < 1 for k in ks):
            raise ValueError
    except ValueError:
        print(
            f"bench_grukf.py: --scenes-per-step must be positive integers (a comma list), got {arg!r}", file=sys.stderr
        )
        raise SystemExit(2) from None
    return ks


def _sync(device) -> None:
    """Wait for the device's queued work (a GPU runs asynchronously)."""
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize()


def lockstep(args) -> None:
    """Training throughput for k scenes per step on each device, and GRU-KF tracking frames/s on each device (see
    the module docstring)."""
    from grutrack.tracking.config import load_tracker_config
    from grutrack.tracking.grukf_backend import resolve_device
    from grutrack.training.sources import load_source

    devices, ks = _devices(args.device), _ks(args.scenes_per_step)
    n_scenes = args.lockstep_scenes or max(ks)
    yaw = load_tracker_config(load_train_config(args.config).tracker_preset).measured_yaw
    entry = {"dataset": "demo", "scenes": n_scenes, "frames_per_scene": 40, "demo_seed": 700, "split": "demo_all"}
    rows, tracking = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        src = load_source({**entry, "profile": "centerpoint", "seed": 1}, yaw, Path(tmp) / "sources", "demo")
        scenes, dets = src.scenes, src.dets
        prepare = time.perf_counter() - t0
        length = {s.name: len(s) for s in scenes}
        for device in devices:
            for k in ks:
                over = {**_fixed(args.config), "device": device, "checkpoint_every": 0, "epochs": 3}
                cfg = load_train_config(args.config, {**over, "scenes_per_step": k})
                runs = []
                for r in range(args.repeat):
                    t = Trainer(cfg, scenes, dets, Path(tmp) / f"{device}-{k}-{r}", progress=False)
                    t.run(max_steps=1)  # warm-up: first operators, kernels, caches (not timed)
                    t.state.epoch, t.state.index, t.state.order = 1, 0, None  # then every scene once, timed
                    cpu = time.process_time()
                    t.run(max_steps=-(-len(scenes) // k))
                    cpu = time.process_time() - cpu  # the process's CPU seconds (all threads; with last.pt's save)
                    timed = [row for row in t.log.steps if row.epoch == 1]
                    # a step's seconds: its tracking, loss, backward and optimizer step (ends in a device sync)
                    dt = sum(row.seconds for row in timed)
                    names = [name for row in timed for name in row.scene.split("+")]
                    f = sum(length[n] for n in names)
                    runs.append((f / dt, len(names) / dt, len(timed) / dt, f / cpu))
                fps, sps, steps, per_cpu = (statistics.median(v) for v in zip(*runs))
                rows.append((str(t.device), k, len(timed), fps, sps, steps, per_cpu, [r[0] for r in runs]))
                print(f"  {t.device} k={k}: {fps:.1f} frames/s", file=sys.stderr, flush=True)
        ckpt = t.save("bench.pt")
        nusc = open_nuscenes(args.dataroot, "v1.0-mini")
        val = load_scenes(nusc, "mini_val")
        dval = _dets(nusc, "mini_val", 2, val, tmp)
        for device in devices:
            runs = [
                track_scenes(build_tracker("grukf", checkpoint=ckpt, device=device), val, dval).fps
                for _ in range(args.repeat)
            ]
            tracking[device] = (resolve_device(device), statistics.median(runs), runs)
    print(
        f"training config {args.config} on {n_scenes} SYNTHETIC demo scenes x 40 frames ({sum(length.values())} "
        f"frames, simulated CenterPoint-like detections, prepared in {prepare:.1f} s); torch threads "
        f"{torch.get_num_threads()}; medians over {args.repeat} run(s), each k over every scene once after one "
        f"warm-up step"
    )
    print(
        "| device | scenes per step k | steps | training frames/s | scenes/s | steps/s | frames per CPU s "
        "| runs (frames/s) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for device, k, n_steps, f, sc, st, per_cpu, runs in rows:
        each = ", ".join(f"{v:.1f}" for v in runs)
        print(f"| {device} | {k} | {n_steps} | {f:.1f} | {sc:.2f} | {st:.3f} | {per_cpu:.1f} | {each} |")
    print(f"GRU-KF tracking loop, mini_val ({sum(len(s) for s in val)} frames, real motion, simulated detections):")
    for device, (used, f, runs) in tracking.items():
        print(f"  --device {device} ({used}): {f:.1f} frames/s (runs: {', '.join(f'{v:.1f}' for v in runs)})")


def paper_scale(args) -> None:
    """Training throughput and time per epoch on the paper-scale source mix (see the module docstring)."""
    from grutrack.tracking.config import load_tracker_config
    from grutrack.training.sources import load_source, merge

    cfg = load_train_config(
        args.config,
        {
            **_fixed(args.config),
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
