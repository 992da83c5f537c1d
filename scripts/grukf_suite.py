"""The GRU-KF evaluation suite on nuScenes mini: EKF, GRU-KF variants and the constant-gain ablation on real
mini_val motion with detections from several generating processes (SYNTHETIC simulated sets) and the real
PointPillars file. Official AMOTA / AMOTP via the exact fast evaluator.

    PYTHONPATH=. .venv/bin/python scripts/grukf_suite.py --out reports/grukf_suite --more-sets \
        --train paper=config:paper --constant-gain constant_gain --checkpoint default=CK/model.pt

Training: mini_train GT with simulated CenterPoint-like detections (seed 1), a shipped training config (``config:``
NAME, default grukf) with the given overrides (``key:value`` pairs, YAML values), every step kept (no validation
here: a default-recipe checkpoint with its held-out validation and selection comes from ``grutrack train`` and
``--checkpoint``). ``--constant-gain NAME``: the paper's network before any step, with no gain table (K = the
EKF's mean gain on the training data, the same for every track and frame). Evaluation sets
(mini_val, seeds never used in training): centerpoint seed 11, pointpillars seed 12, the heavy-tail profile
(docs/results/grukf_eval/heavytail.yaml) seed 13, and the real PointPillars detections. Writes suite.csv and
suite.md (a markdown table) into --out; trained checkpoints go to --out/<name>/.

``--cp-seeds N``: N more CenterPoint-like sets on mini_val (seeds 21 .. 20 + N). Two sets decide little: one
association event in a row of parked motorcycles or one bus ID switch moves a set's 6-class AMOTP by 0.03 m.
suite.md then also gives, for every model, the mean difference to the ``ekf`` row over all CenterPoint-like sets
with its standard error (differences taken set by set, so the detection draw cancels) and per class.
``--cp-seed-list 2-11,21-30``: these CenterPoint-like seeds on mini_val (a comma list of seeds and inclusive
ranges; seeds the suite already has are not repeated), with the same difference table. The twenty draws of issue
14's bars (docs/results/pretrained.md#twenty-draws) are ``--cp-seed-list 2-11,21-30``.
``--profile-seeds PROFILE:SEEDS`` (repeatable): sets of another profile on mini_val (a built-in profile name such as
pointpillars, centerpoint_velfail, centerpoint_drift, or a profile file; SEEDS as above), named
``<profile>_s<seed>``, with a difference table per profile.
``--drift-seeds N``: N sets of the drift profile (docs/results/grukf_eval/drift.yaml: centerpoint plus a centre
error correlated over time) on mini_val (seeds 41 .. 40 + N), with the same difference table over them.

``--holdout scene-0655,scene-1094``: recipe selection on the training side. Training uses the other mini_train
scenes; the evaluation sets are simulated on mini_train (centerpoint seeds 31, 34; pointpillars 32, 35; heavy-tail
33) and scored on the held-out scenes only (their tracks, official metric); mini_val and the real file are not
read.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
EVAL_SETS = (
    ("centerpoint_s11", "centerpoint", 11),
    ("pointpillars_s12", "pointpillars", 12),
    ("heavytail_s13", str(ROOT / "docs/results/grukf_eval/heavytail.yaml"), 13),
)
MORE_SETS = (
    ("centerpoint_s2", "centerpoint", 2),
    ("pointpillars_s3", "pointpillars", 3),
    ("velfail_s14", "centerpoint_velfail", 14),
)
SEED_BASE = 20  # --cp-seeds N: centerpoint seeds SEED_BASE + 1 .. SEED_BASE + N
DRIFT_PROFILE, DRIFT_BASE = str(ROOT / "docs/results/grukf_eval/drift.yaml"), 40  # --drift-seeds N: 41 .. 40 + N
HOLDOUT_SETS = (
    ("centerpoint_s31", "centerpoint", 31),
    ("pointpillars_s32", "pointpillars", 32),
    ("heavytail_s33", str(ROOT / "docs/results/grukf_eval/heavytail.yaml"), 33),
    ("centerpoint_s34", "centerpoint", 34),
    ("pointpillars_s35", "pointpillars", 35),
)


def seed_list(text: str) -> list[int]:
    """``2-4,21`` -> [2, 3, 4, 21]: a comma list of seeds (>= 0) and inclusive ranges, in order, each once."""
    seeds: list[int] = []
    for part in text.split(","):
        lo, dash, hi = part.strip().partition("-")
        hi = hi if dash else lo
        if not lo.isdigit() or not hi.isdigit() or int(hi) < int(lo):
            raise ValueError(f"expected seeds and ranges like 2-11,21-30, got {part.strip()!r}")
        seeds += [s for s in range(int(lo), int(hi) + 1) if s not in seeds]
    return seeds


def profile_sets(specs: list[str]) -> dict[str, tuple[str, int]]:
    """``["pointpillars:2-3"]`` -> {"pointpillars_s2": ("pointpillars", 2), "pointpillars_s3": (...)}: the sets of
    ``--profile-seeds`` by name (``<profile stem>_s<seed>``). Raises ValueError naming the spec for a malformed one,
    an unknown profile, or ``centerpoint`` (whose sets are ``--cp-seed-list``'s)."""
    from grutrack.data.detection_sim import load_profile
    from grutrack.errors import ConfigError

    sets: dict[str, tuple[str, int]] = {}
    for spec in specs:
        prof, _, seeds = spec.rpartition(":")
        if not prof or Path(prof).stem == "centerpoint":
            raise ValueError(f"{spec!r}: expected PROFILE:SEEDS with a profile other than centerpoint (--cp-seed-list)")
        try:
            load_profile(prof)
            sets.update({f"{Path(prof).stem}_s{seed}": (prof, seed) for seed in seed_list(seeds)})
        except (ValueError, ConfigError) as e:
            raise ValueError(f"{spec!r}: {e}") from None
    return sets


def _overrides(text: str) -> dict:
    """``a:1,b:[x,y]`` -> {a: 1, b: [x, y]} (YAML values; commas inside brackets kept)."""
    out, depth, cur = {}, 0, ""
    for ch in text + ",":
        if ch == "," and depth == 0:
            if cur.strip():
                k, v = cur.split(":", 1)
                out[k.strip()] = yaml.safe_load(v)
            cur = ""
            continue
        depth += (ch == "[") - (ch == "]")
        cur += ch
    return out


def _dets(nusc, split, profile, seed, tokens, tmp: Path):
    from grutrack.data.detection_sim import simulate_nuscenes
    from grutrack.data.nusc_detections import load_detections

    p = tmp / f"{split}_{Path(profile).stem}_s{seed}.json"
    if not p.exists():
        simulate_nuscenes(None, "v1.0-mini", split, profile, seed=seed, out=p, nusc=nusc)
    return load_detections(p, tokens)


def paired_difference(values: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
    """Mean and standard error of ``values - reference`` (both (S,), one entry per detection set, same sets in
    the same order); the standard error is 0 for a single set."""
    d = np.asarray(values, float) - np.asarray(reference, float)
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0


def _score(
    nusc, tracker, scenes, dets, tokens, split: str = "mini_val", split_tokens=None, per_class: dict | None = None
) -> tuple[float, float]:
    """AMOTA, AMOTP of ``tracker`` on ``scenes``; with ``split_tokens`` (every sample of ``split``) the scenes
    are part of the split and only their tracks are scored. ``per_class``: filled with {class: AMOTP (m)}
    (classes without ground truth left out; mini_val only)."""
    from grutrack.evaluation.nuscenes_fast import evaluate_tracks, fast_tracking_eval, load_tracks
    from grutrack.export.nuscenes_json import build_submission
    from grutrack.tracking.tracker import track_scenes

    results = track_scenes(tracker, scenes, dets).results
    if split_tokens is None:
        with contextlib.redirect_stdout(io.StringIO()):
            s = fast_tracking_eval(nusc, build_submission(results, tokens), split)
        if per_class is not None:
            per_class.update(
                {c: float(v) for c, v in s["label_metrics"]["amotp"].items() if v is not None and not np.isnan(v)}
            )
        return float(s["amota"]), float(s["amotp"])
    sub = build_submission(results, tokens)
    sub["results"].update({t: [] for t in split_tokens if t not in sub["results"]})
    with contextlib.redirect_stdout(io.StringIO()):
        gt, pred, _ = load_tracks(nusc, sub, split)
        keep = {s.token for s in scenes}
        m, _ = evaluate_tracks({k: v for k, v in gt.items() if k in keep}, {k: v for k, v in pred.items() if k in keep})
        s = m.serialize()
    return float(s["amota"]), float(s["amotp"])


def _difference_table(rows: list[dict], classes: dict, sets: list[str], kind: str = "CenterPoint-like") -> list[str]:
    """Markdown lines: every model's mean difference to the ``ekf`` row over ``sets`` (AMOTA, AMOTP m, and AMOTP
    per class), with standard errors; ``classes[(model, set)]`` = {class: AMOTP}; ``kind`` names the sets."""
    ref = next(r for r in rows if r["model"] == "ekf")
    names = sorted({c for pc in classes.values() if pc for c in pc})
    lines = [
        f"Difference to ekf over {len(sets)} {kind} sets (mean +- standard error; SYNTHETIC "
        "detections, real mini_val motion):",
        "",
        "| model | AMOTA | AMOTP (m) | " + " | ".join(f"{c} AMOTP" for c in names) + " |",
        "|---" * (len(names) + 3) + "|",
    ]
    for r in rows:
        cells = []
        for what in ("amota", "amotp"):
            m, se = paired_difference([r[f"{s}_{what}"] for s in sets], [ref[f"{s}_{what}"] for s in sets])
            cells.append(f"{m:+.4f} +- {se:.4f}")
        for c in names:
            pairs = [(classes[(r["model"], s)].get(c), classes[("ekf", s)].get(c)) for s in sets]
            pairs = [(a, b) for a, b in pairs if a is not None and b is not None]
            m, _ = paired_difference([a for a, _ in pairs], [b for _, b in pairs]) if pairs else (float("nan"), 0)
            cells.append(f"{m:+.3f}")
        lines.append(f"| {r['model']} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--dataroot", default=str(ROOT / "../shared/data/nuscenes"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--train", action="append", default=[], help="NAME=key:value,... (training config overrides)")
    ap.add_argument("--constant-gain", default=None, help="name of the constant-gain ablation row")
    ap.add_argument("--checkpoint", action="append", default=[], help="NAME=PATH: also evaluate a trained model")
    ap.add_argument(
        "--untrained",
        action="append",
        default=[],
        help="NAME=key:value,...: the network of that training config before any step (e.g. "
        "gain_prior:ekf, which is then the EKF with the GRU-KF's SS model)",
    )
    ap.add_argument("--no-ekf", action="store_true", help="leave out the ekf preset's row")
    ap.add_argument(
        "--holdout",
        default=None,
        help="SCENE,SCENE: train without these mini_train scenes and score "
        "on them (recipe selection; mini_val is not read)",
    )
    ap.add_argument(
        "--more-sets",
        action="store_true",
        help="also centerpoint seed 2, pointpillars seed 3 (the sets options were compared on) and "
        "centerpoint_velfail seed 14 (velocity failing over whole tracks)",
    )
    ap.add_argument(
        "--cp-seeds",
        type=int,
        default=0,
        metavar="N",
        help=f"also N CenterPoint-like sets on mini_val, seeds {SEED_BASE + 1}..{SEED_BASE} + N, and the "
        "mean difference to the ekf row with its standard error (needs the ekf row)",
    )
    ap.add_argument(
        "--cp-seed-list",
        default="",
        metavar="SEEDS",
        help="also CenterPoint-like sets on mini_val at these seeds (e.g. 2-11,21-30; those the suite has are "
        "not repeated), and the difference table (needs the ekf row)",
    )
    ap.add_argument(
        "--profile-seeds",
        action="append",
        default=[],
        metavar="PROFILE:SEEDS",
        help="also sets of this detector profile on mini_val at these seeds (e.g. pointpillars:2-11), and a "
        "difference table for them (needs the ekf row); repeatable",
    )
    ap.add_argument(
        "--drift-seeds",
        type=int,
        default=0,
        metavar="N",
        help=f"also N sets of the drift profile on mini_val, seeds {DRIFT_BASE + 1}..{DRIFT_BASE} + N, "
        "and the mean difference to the ekf row over them (needs the ekf row)",
    )
    args = ap.parse_args()
    try:
        extra_cp = seed_list(args.cp_seed_list) if args.cp_seed_list else []
    except ValueError as e:
        ap.error(f"--cp-seed-list: {e}")
    if extra_cp and (args.holdout or args.no_ekf):
        ap.error("--cp-seed-list: expected without --holdout and --no-ekf (it compares with the ekf row on mini_val)")
    try:
        by_profile = profile_sets(args.profile_seeds)
    except ValueError as e:
        ap.error(f"--profile-seeds {e}")
    if by_profile and (args.holdout or args.no_ekf):
        ap.error("--profile-seeds: expected without --holdout and --no-ekf (it compares with the ekf row on mini_val)")
    for flag, n in (("--cp-seeds", args.cp_seeds), ("--drift-seeds", args.drift_seeds)):
        if n < 0 or (n and (args.holdout or args.no_ekf)):
            ap.error(
                f"{flag}: expected a count >= 0, without --holdout and --no-ekf (it compares with the ekf "
                "row on mini_val)"
            )

    from grutrack.data.nusc_detections import load_detections
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.datasets import DatasetOptions
    from grutrack.datasets.nuscenes import NuScenesDataset
    from grutrack.tracking.factory import build_tracker
    from grutrack.training.config import load_train_config
    from grutrack.training.resample import DetectionResampler, ResamplingTrainer

    out = Path(args.out)
    (out / "detections").mkdir(parents=True, exist_ok=True)
    nusc = open_nuscenes(args.dataroot, "v1.0-mini")
    tr_scenes = load_scenes(nusc, "mini_train", with_gt=True)
    tr_tokens = [f.token for s in tr_scenes for f in s.frames]
    tr_dets = _dets(nusc, "mini_train", "centerpoint", 1, tr_tokens, out / "detections")
    split, split_tokens = "mini_val", None
    if args.holdout:
        held = set(args.holdout.split(","))
        unknown = held - {s.name for s in tr_scenes}
        if unknown:
            ap.error(f"--holdout: {sorted(unknown)} are not mini_train scenes")
        va_scenes = [s for s in tr_scenes if s.name in held]
        tr_scenes = [s for s in tr_scenes if s.name not in held]
        split, split_tokens, eval_sets = "mini_train", tr_tokens, HOLDOUT_SETS
        va_tokens = [f.token for s in va_scenes for f in s.frames]
        sets = {
            name: _dets(nusc, "mini_train", prof, seed, tr_tokens, out / "detections") for name, prof, seed in eval_sets
        }
    else:
        va_scenes = load_scenes(nusc, "mini_val")
        va_tokens = [f.token for s in va_scenes for f in s.frames]
        eval_sets = (
            EVAL_SETS
            + (MORE_SETS if args.more_sets else ())
            + tuple(
                (f"centerpoint_s{SEED_BASE + i}", "centerpoint", SEED_BASE + i) for i in range(1, args.cp_seeds + 1)
            )
            + tuple((f"drift_s{DRIFT_BASE + i}", DRIFT_PROFILE, DRIFT_BASE + i) for i in range(1, args.drift_seeds + 1))
        )
        have = {name for name, _, _ in eval_sets}
        eval_sets += tuple((f"centerpoint_s{s}", "centerpoint", s) for s in extra_cp if f"centerpoint_s{s}" not in have)
        eval_sets += tuple((name, prof, seed) for name, (prof, seed) in by_profile.items())
        sets = {
            name: _dets(nusc, "mini_val", prof, seed, va_tokens, out / "detections") for name, prof, seed in eval_sets
        }
        sets["real_pointpillars"] = load_detections(
            Path(args.dataroot) / "detections/pointpillars_mini_val.json", va_tokens
        )

    models: list[tuple[str, dict, object]] = [] if args.no_ekf else [("ekf", {}, None)]
    resampler = DetectionResampler(NuScenesDataset(DatasetOptions(args.dataroot, "v1.0-mini")), "mini_train", tr_scenes)
    if args.constant_gain:
        cfg = load_train_config("paper", {"device": "cpu", "gap_bins": 0, "class_gain": False, "age_bins": 0})
        t = ResamplingTrainer(cfg, tr_scenes, tr_dets, out / args.constant_gain, resampler, progress=False)
        models.append((args.constant_gain, {"gap_bins": 0, "steps": 0}, t.save("model.pt")))
    for spec in args.untrained:
        name, _, over = spec.partition("=")
        over = _overrides(over)
        cfg = load_train_config(
            over.get("config", "grukf"), {"device": "cpu", **{k: v for k, v in over.items() if k != "config"}}
        )
        t = ResamplingTrainer(cfg, tr_scenes, tr_dets, out / name, resampler, progress=False)
        models.append((name, {**over, "steps": 0}, t.save("model.pt")))
    for spec in args.train:
        name, _, over = spec.partition("=")
        over = _overrides(over)
        cfg = load_train_config(
            over.get("config", "grukf"), {"device": "cpu", **{k: v for k, v in over.items() if k != "config"}}
        )
        t0 = time.perf_counter()
        ck = ResamplingTrainer(cfg, tr_scenes, tr_dets, out / name, resampler, progress=False).run()
        print(f"trained {name} {over} in {time.perf_counter() - t0:.0f} s", flush=True)
        models.append((name, over, ck))

    for spec in args.checkpoint:
        name, _, path = spec.partition("=")
        models.append((name, {"checkpoint": path}, Path(path)))
    rows, classes = [], {}
    for name, over, ck in models:
        row = {"model": name, "overrides": json.dumps(over)}
        for sname, dets in sets.items():
            tracker = build_tracker("ekf") if ck is None else build_tracker("grukf", checkpoint=ck, device="cpu")
            pc = {} if split_tokens is None else None
            a, p = _score(nusc, tracker, va_scenes, dets, va_tokens, split, split_tokens, per_class=pc)
            row[f"{sname}_amota"], row[f"{sname}_amotp"] = round(a, 4), round(p, 4)
            classes[(name, sname)] = pc
        rows.append(row)
        print(row, flush=True)
        with open(out / "rows.jsonl", "a") as f:  # rows as they come (a long run can be read before it ends)
            f.write(json.dumps(row) + "\n")
    with open(out / "suite.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        "| model | " + " | ".join(sets) + " | mean simulated AMOTA / AMOTP | mean CenterPoint-like |",
        "|---" * (len(sets) + 3) + "|",
    ]
    sim = [n for n, _, _ in eval_sets if n not in by_profile]  # the suite's own sets
    cp_like = [n for n, prof, _ in eval_sets if prof == "centerpoint"]  # the acceptance's held-out kind

    def mean(r, names, what):
        return np.mean([r[f"{s}_{what}"] for s in names])

    for r in rows:
        cells = [f"{r[f'{s}_amota']:.4f} / {r[f'{s}_amotp']:.3f}" for s in sets]
        lines.append(
            f"| {r['model']} | " + " | ".join(cells) + f" | {mean(r, sim, 'amota'):.4f} / "
            f"{mean(r, sim, 'amotp'):.3f} | {mean(r, cp_like, 'amota'):.4f} / "
            f"{mean(r, cp_like, 'amotp'):.3f} |"
        )
    if args.cp_seeds or extra_cp:
        lines += ["", *_difference_table(rows, classes, cp_like)]
    for prof in dict.fromkeys(prof for prof, _ in by_profile.values()):
        names = [name for name, (p, _) in by_profile.items() if p == prof]
        lines += ["", *_difference_table(rows, classes, names, Path(prof).stem)]
    if args.drift_seeds:
        lines += [
            "",
            *_difference_table(
                rows,
                classes,
                [n for n, prof, _ in eval_sets if prof == DRIFT_PROFILE],
                "drift (time-correlated centre error)",
            ),
        ]
    (out / "suite.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
