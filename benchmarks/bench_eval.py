"""Time the official nuScenes tracking evaluation against the fast exact one, on the same input.

    python benchmarks/bench_eval.py                       # default: ../shared/data nuScenes v1.0-mini, mini_val,
                                                          # ground truth corrupted into a realistic tracker output
    python benchmarks/bench_eval.py --dataroot /data/nuscenes --version v1.0-trainval --split val \
        --submission tracks_val.json

Reported (medians over the repeats, seconds of wall-clock and of CPU time of this process):
  * accumulation + metrics: the devkit's ``TrackingEval.evaluate()`` vs our ``evaluate_tracks`` on the same
    loaded tracks (what the devkit reports as eval_time);
  * loading + filtering: the devkit's loaders vs the fast exact re-implementation (``load_tracks``);
  * whole pipeline: ``TrackingEval(...).main(render_curves=False)`` (it loads NuScenes itself; that load is also
    timed on its own) vs ``fast_tracking_eval(nusc, ...)`` with a loaded NuScenes, and the devkit's own pipeline
    with the fast accumulation (``FastTrackingEval(...).main()``, grutrack.evaluation.devkit_plugin).
The two results are compared number by number (max |difference|, NaN == NaN).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))  # support.fast_synth / support.compare: test helpers, not the package


class _Timing:
    """Wall-clock and CPU (process) time of repeated runs; medians. The CPU time is the robust figure on a
    shared machine (other processes steal wall-clock time, not this process's CPU time)."""

    def __init__(self, wall, cpu):
        self.wall, self.cpu = wall, cpu
        self.wall_med, self.cpu_med = statistics.median(wall), statistics.median(cpu)

    def runs(self, fmt="%.2f"):
        return ", ".join(fmt % t for t in self.wall)


def _median_time(fn, repeat: int):
    wall, cpu, result = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        result = fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - t0)
    return _Timing(wall, cpu), result


def _max_diff(a: dict, b: dict) -> float:
    """Largest entry difference of two summaries (inf when their entries differ)."""
    from support.compare import entry_differences

    try:
        return max(entry_differences(a, b).values(), default=0.0)
    except ValueError:
        return math.inf


def main(argv=None) -> int:
    default_root = Path(os.environ.get("GRUTRACK_TEST_DATA", REPO.parent / "shared" / "data")) / "nuscenes"
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", default=str(default_root))
    ap.add_argument("--version", default="v1.0-mini")
    ap.add_argument("--split", default="mini_val")
    ap.add_argument(
        "--submission",
        default=None,
        help="tracking-submission JSON; default: the split's ground truth, corrupted (seed 0)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=5, help="repeats of the fast evaluator")
    ap.add_argument("--repeat-devkit", type=int, default=3, help="repeats of the devkit")
    ap.add_argument(
        "--skip-devkit-whole",
        action="store_true",
        help="time only the devkit's evaluate() (not TrackingEval(...).main)",
    )
    args = ap.parse_args(argv)

    from nuscenes import NuScenes
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking.evaluate import TrackingEval

    from grutrack.evaluation.nuscenes_fast import evaluate_tracks, fast_tracking_eval, load_tracks

    t0 = time.perf_counter()
    nusc = NuScenes(version=args.version, dataroot=args.dataroot, verbose=False)
    t_nusc = time.perf_counter() - t0
    cfg = config_factory("tracking_nips_2019")

    with tempfile.TemporaryDirectory() as tmp:
        if args.submission:
            sub_path = args.submission
            what = sub_path
        else:
            from support.fast_synth import corrupt_submission

            sub_path = os.path.join(tmp, "submission.json")
            with open(sub_path, "w") as f:
                json.dump(corrupt_submission(nusc, args.split, seed=args.seed), f)
            what = (
                "ground truth of %s corrupted (seed %d: noise, id switches, fragments, drops, "
                "false positives, class changes, shadow tracks)" % (args.split, args.seed)
            )
        with open(sub_path) as f:
            n_boxes = sum(len(v) for v in json.load(f)["results"].values())
        print("input: %s; %d boxes; %s %s (NuScenes load %.2fs)" % (what, n_boxes, args.version, args.split, t_nusc))

        # Loading + filtering: the devkit's loaders vs the fast exact re-implementation.
        n_load = max(1, min(args.repeat, 3))
        t_load_dev, (tracks_gt, tracks_pred, meta) = _median_time(
            lambda: load_tracks(nusc, sub_path, args.split, cfg, loader="devkit"), n_load
        )
        t_load_fast, _ = _median_time(lambda: load_tracks(nusc, sub_path, args.split, cfg, loader="fast"), n_load)

        # Accumulation + metrics, on the devkit-loaded tracks.
        def devkit_evaluate():
            ev = object.__new__(TrackingEval)
            ev.cfg, ev.eval_set, ev.output_dir, ev.verbose, ev.render_classes = cfg, args.split, tmp, False, None
            ev.tracks_gt, ev.tracks_pred, ev.meta = tracks_gt, tracks_pred, meta
            metrics, _ = ev.evaluate()
            return dict(metrics.serialize(), meta=meta)

        t_dev_acc, dev_summary = _median_time(devkit_evaluate, args.repeat_devkit)
        t_fast_acc, (fast_metrics, _) = _median_time(lambda: evaluate_tracks(tracks_gt, tracks_pred, cfg), args.repeat)
        diff_acc = _max_diff(dev_summary, dict(fast_metrics.serialize(), meta=meta))

        # Whole pipeline.
        t_fast_whole, fast_summary = _median_time(
            lambda: fast_tracking_eval(nusc, sub_path, args.split, cfg), args.repeat
        )
        from grutrack.evaluation.devkit_plugin import FastTrackingEval

        def whole(cls, folder):
            """``cls(...).main()``: the devkit's pipeline (it loads NuScenes itself) with its or our accumulation."""

            def run():
                with contextlib.redirect_stderr(io.StringIO()):
                    ev = cls(
                        cfg, sub_path, args.split, os.path.join(tmp, folder), args.version, args.dataroot, verbose=False
                    )
                    return ev.main(render_curves=False)

            return run

        t_dev_whole = None
        if not args.skip_devkit_whole:
            t_dev_whole, dev_whole_summary = _median_time(whole(TrackingEval, "devkit"), args.repeat_devkit)
            diff_whole = _max_diff(dev_whole_summary, fast_summary)
        t_plugin_whole, plugin_summary = _median_time(whole(FastTrackingEval, "plugin"), args.repeat)
        diff_plugin = _max_diff(plugin_summary, fast_summary)

    def line(label, t, fmt="%.2f"):
        print("  %-34s %9.3f s wall  %9.3f s CPU   (wall runs: %s)" % (label, t.wall_med, t.cpu_med, t.runs(fmt)))

    def ratio(label, slow, fast):
        print("  %-34s %9.1f x wall  %9.1f x CPU" % (label, slow.wall_med / fast.wall_med, slow.cpu_med / fast.cpu_med))

    print()
    print(
        "accumulation + metrics (same loaded tracks; medians of %d devkit / %d fast runs)"
        % (args.repeat_devkit, args.repeat)
    )
    line("devkit TrackingEval.evaluate()", t_dev_acc)
    line("fast evaluate_tracks()", t_fast_acc, "%.3f")
    ratio("ratio", t_dev_acc, t_fast_acc)
    print("  max |difference| of the results    %9.3g" % diff_acc)
    print("loading + filtering (medians of %d)" % n_load)
    line("devkit loaders (TrackingBox)", t_load_dev)
    line("fast exact loader", t_load_fast, "%.3f")
    ratio("ratio", t_load_dev, t_load_fast)
    print("whole pipeline")
    line("fast_tracking_eval() (loaded nusc)", t_fast_whole, "%.3f")
    print("    ~ loading %.3f + accumulation %.3f s CPU" % (t_load_fast.cpu_med, t_fast_acc.cpu_med))
    if t_dev_whole is not None:
        line("devkit TrackingEval(...).main()", t_dev_whole)
        print(
            "    ~ its NuScenes load %.3f + loading %.3f + accumulation %.3f s CPU"
            % (t_nusc, t_load_dev.cpu_med, t_dev_acc.cpu_med)
        )
        ratio("ratio", t_dev_whole, t_fast_whole)
        print("  max |difference| of the results    %9.3g" % diff_whole)
    line("FastTrackingEval(...).main()", t_plugin_whole, "%.3f")
    print("    (the devkit's TrackingEval with the fast accumulation; max |difference| %.3g)" % diff_plugin)
    if t_dev_whole is not None:
        ratio("ratio devkit / FastTrackingEval", t_dev_whole, t_plugin_whole)
    else:
        print(
            "  devkit loading + evaluate()        %9.3f s CPU   ratio %.1f x"
            % (t_load_dev.cpu_med + t_dev_acc.cpu_med, (t_load_dev.cpu_med + t_dev_acc.cpu_med) / t_fast_whole.cpu_med)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
