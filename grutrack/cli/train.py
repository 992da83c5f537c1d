"""``grutrack train``: semi-supervised training of the GRU-Kalman filter."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from grutrack.cli.common import add_dataset_args
from grutrack.errors import ConfigError

# Only argument definitions at module level: building the parser must not import numpy or torch
# (tests/test_cli_imports.py).


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grutrack train``."""
    p = sub.add_parser("train", help="train the GRU-Kalman filter (semi-supervised, EKF pseudo-labels)",
                       description="Run the tracker online over the training scenes with the GRU-KF, associate "
                                   "tracks with ground truth, use a parallel EKF's posterior as pseudo-label "
                                   "where a track has none, one AdamW step per scene. Writes model.pt, last.pt "
                                   "(resumable) and train_log.csv into --out.")
    add_dataset_args(p, "training split with ground truth (train, mini_train, ...; AV2: train, val, ...)")
    p.add_argument("--detections", required=True,
                   help="detections of the training split (real or simulated): nuScenes detection JSON, or an "
                        "LT3D table for AV2")
    p.add_argument("--config", default="grukf", help="training config name or YAML path (default: grukf)")
    p.add_argument("--out", required=True, help="output folder for checkpoints and the CSV log")
    p.add_argument("--val-split", default=None,
                   help="validation split for AMOTA every val_every steps (nuScenes-format data)")
    p.add_argument("--val-detections", default=None, help="detection JSON of the validation split")
    p.add_argument("--mode", choices=("semi_supervised", "supervised"), default=None,
                   help="override the config's mode")
    p.add_argument("--epochs", type=int, default=None, help="override the config's epochs")
    p.add_argument("--val-every", type=int, default=None, help="override the config's val_every")
    p.add_argument("--seed", type=int, default=None, help="override the config's seed")
    p.add_argument("--source", action="append", default=[], metavar="MAPPING",
                   help="one more training source, a YAML mapping such as '{dataset: av2, dataroot: AV2, split: "
                        "val, profile: centerpoint, seed: 1}' or '{dataset: demo, scenes: 700, "
                        "frames_per_scene: 40, split: demo_all, profile: centerpoint}' (repeatable; added to the "
                        "config's sources; see grutrack/training/sources.py)")
    p.add_argument("--no-config-sources", action="store_true",
                   help="leave out the config's sources (the default recipe's 700-scene SYNTHETIC demo): train on "
                        "--split and any --source only, e.g. a quick run or real data at the paper's scale")
    p.add_argument("--resume", action="store_true", help="continue from --out/last.pt")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Train; prints the final checkpoint and the last logged figures."""
    from grutrack.cli.common import dataset_of
    from grutrack.threads import apply_thread_policy
    from grutrack.tracking.config import load_tracker_config
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer, TrainingInterrupted
    from grutrack.training.validation import Validator, make_validator

    overrides = {k: v for k, v in (("mode", args.mode), ("epochs", args.epochs), ("val_every", args.val_every),
                                   ("seed", args.seed)) if v is not None}
    if args.no_config_sources:
        overrides["sources"] = []
    cfg = load_train_config(args.config, overrides, flags={k: "--" + k.replace("_", "-") for k in overrides})
    apply_thread_policy()
    if (args.val_split is None) != (args.val_detections is None):
        raise ConfigError("--val-split and --val-detections go together")
    extra = [(e, f"{cfg_name(args.config)} sources[{i}]") for i, e in enumerate(cfg.sources)]
    extra += [(e, f"--source {i + 1}") for i, e in enumerate(_parsed_sources(args.source))]
    if extra:
        from grutrack.training.sources import check_source

        for e, where in extra:
            check_source(e, where)      # before any data is read
    ds = dataset_of(args)
    if args.val_split and ds.name != "nuscenes":
        raise ConfigError(f"--val-split: validation AMOTA is scored on nuScenes-format data; train on {ds.name} "
                          f"without it (or validate a checkpoint with grutrack track + evaluate)")
    scenes = ds.scenes(args.split, with_gt=True)
    yaw = load_tracker_config(cfg.tracker_preset).measured_yaw  # the preset's measured-yaw definition
    loaded_dets = ds.load_detections(args.detections, args.split, scenes, yaw)
    dets = loaded_dets.boxes
    validate = None
    source = {"dataset": ds.name, "dataroot": str(Path(args.dataroot).resolve()), "version": args.version,
              "split": args.split, "detections": str(Path(args.detections).resolve())}
    held = _held_out(cfg, args, ds.name, scenes) if not args.val_split else []
    if held:
        names = {sc.name for sc in held}
        scenes = [sc for sc in scenes if sc.name not in names]
        source["validation_scenes"] = sorted(names)
        print(f"validating on {len(held)} scenes held out of {args.split}: {', '.join(sorted(names))}")
    if ds.name != "nuscenes":
        source["rate_hz"] = args.rate
    from grutrack.training.resample import DetectionResampler

    resampler = DetectionResampler(ds, args.split, scenes, yaw)
    if extra:
        from grutrack.training.sources import LoadedSource, load_source, merge, merged_resampler

        loaded = [LoadedSource(scenes, dets, resampler, source)]
        loaded += [load_source(e, yaw, Path(args.out) / "sources", where) for e, where in extra]
        scenes, dets = merge(loaded)
        resampler = merged_resampler(loaded)
        source = {**source, "sources": [src.description for src in loaded[1:]]}
        print(f"training on {len(scenes)} scenes, {sum(len(sc) for sc in scenes)} frames from {len(loaded)} "
              f"sources")
    if cfg.resample_profiles:
        from grutrack.training.resample import ResamplingTrainer

        trainer = ResamplingTrainer(cfg, scenes, dets, args.out, resampler, progress=not args.no_progress,
                                    source=source)
    else:
        trainer = Trainer(cfg, scenes, dets, args.out, progress=not args.no_progress, source=source)
    val_cfg = replace(trainer.tracker_cfg, matched_box=cfg.matched_box)
    if args.val_split:
        val_scenes = ds.scenes(args.val_split)
        val_dets = ds.load_detections(args.val_detections, args.val_split, val_scenes, yaw).boxes
        validate = make_validator(ds.tables, args.val_split, val_scenes, val_dets, val_cfg, cfg.device)
    elif held:
        validate = Validator(ds.tables, args.split, held, _validation_sets(cfg, ds, args.split, held, dets, yaw),
                             val_cfg, cfg.device, held_out=True,
                             reference_name=f"tracker preset '{cfg.tracker_preset}' (its EKF)")
    trainer.validate = validate
    if args.resume:
        trainer.resume(Path(args.out) / "last.pt")
    source["synthetic"] = synthetic_inputs(ds, loaded_dets, cfg, [e for e, _ in extra])
    write_training_yaml(cfg, args.config, Path(args.out) / "training.yaml", source)
    try:
        final = trainer.run()
    except TrainingInterrupted as exc:
        print(f"grutrack train: {exc}", file=sys.stderr)
        return 130
    last = trainer.log.steps[-1] if trainer.log.steps else None
    print(f"wrote {final} after {trainer.state.step} steps (last loss {last.loss if last else None}); log: "
          f"{Path(args.out) / 'train_log.csv'}")
    if validate is not None and final.name == "model.pt":
        from grutrack.documents import SELECTION_RULES, ValidationRecord

        rec = ValidationRecord.read(Path(args.out) / "validation.json")
        chosen = SELECTION_RULES[rec.rule]
        amota = "n/a" if rec.selected_amota is None else f"{rec.selected_amota:.4f}"
        print(f"model.pt holds step {rec.selected_step} ({chosen}): validation AMOTA {amota}; "
              f"{rec.reference} on the same scenes: {rec.reference_amota:.4f}")
    return 0


def _held_out(cfg, args: argparse.Namespace, dataset: str, scenes: list) -> list:
    """The training split's scenes held out for validation (``validation_scenes``), or [] when there are none:
    the config asks for none, or the data is not nuScenes-format (said in one line on stderr)."""
    from grutrack.training.validation import held_out_scenes

    n = cfg.validation_scenes
    if n == 0:
        return []
    if dataset != "nuscenes":
        print(f"grutrack train: note: validation_scenes {n} is for nuScenes-format data; training on every "
              f"{dataset} scene of {args.split} without validation (model.pt: the last step)", file=sys.stderr)
        return []
    if n >= len(scenes):
        raise ConfigError(f"{cfg_name(args.config)}: validation_scenes {n} would leave no training scene (split "
                          f"'{args.split}' has {len(scenes)}); expected fewer, or 0 with --val-split")
    return held_out_scenes(scenes, n)


def _validation_sets(cfg, ds, split: str, held: list, dets: dict, yaw: str) -> dict:
    """Detection sets of the held-out scenes: the command's detections and, with ``resample_profiles``, one set
    simulated with each profile (seed ``resample_seed(seed, 0)``, which training never draws: epoch 0 trains on the
    command's detections), so that validation sees every kind of detector error the training does."""
    from grutrack.training.resample import DetectionResampler, resample_seed

    sets = {"given": dets}
    sim = DetectionResampler(ds, split, held, yaw)
    for profile in cfg.resample_profiles:
        sets[Path(profile).stem] = sim(profile, resample_seed(cfg.seed, 0))
    return sets


def cfg_name(config_arg: str) -> str:
    """How errors name the training config: its file name or preset name."""
    return Path(config_arg).name


def _parsed_sources(values: list[str]) -> list[dict]:
    """The ``--source`` mappings, each checked (exit 2 naming the flag and key)."""
    from grutrack.training.sources import parse_source

    return [parse_source(v, i + 1) for i, v in enumerate(values)]


def synthetic_inputs(ds, dets, cfg, sources: list[dict]) -> list[str]:
    """What of the training's data is SYNTHETIC, one phrase each (empty: none), for the ``# data`` line of
    training.yaml, which reports read to flag every number that depends on it: the grutrack demo's scenes, a
    simulated detection file (its ``synthetic`` entry), detections resampled from the ground truth each epoch
    (``resample_profiles``), and extra sources that are demo scenes or simulated detections."""
    from grutrack.data.demo import is_demo_tables

    out = []
    if ds.name == "nuscenes" and is_demo_tables(ds.tables):
        out.append("scenes of the SYNTHETIC grutrack demo dataset")
    if dets.synthetic:
        out.append(f"simulated detections ({dets.synthetic.get('profile', '?')} profile, seed "
                   f"{dets.synthetic.get('seed', '?')})")
    if cfg.resample_profiles and cfg.epochs > 1:
        out.append(f"detections simulated afresh every epoch after the first ({', '.join(cfg.resample_profiles)})")
    synthetic_sources = [e for e in sources if e.get("dataset") == "demo" or "profile" in e]
    if synthetic_sources:
        out.append(f"{len(synthetic_sources)} SYNTHETIC training source(s) "
                   f"({sum(e.get('scenes', 0) for e in synthetic_sources if e.get('dataset') == 'demo')} demo scenes)")
    return out


def write_training_yaml(cfg, config_arg: str, path: Path, source: dict) -> None:
    """The resolved training config beside the checkpoint, with a ``# data {...}`` line naming what it trains
    on. When --config is that very file (the workflow resolves it there first), its header is kept."""
    import json
    from dataclasses import asdict

    import yaml

    from grutrack import __version__
    from grutrack.io import write_text_atomic
    from grutrack.provenance import config_hash

    data = f"# data {json.dumps(source, sort_keys=True)}"
    if Path(config_arg).is_file() and Path(config_arg).resolve() == path.resolve():
        lines = [ln for ln in path.read_text().splitlines() if not ln.startswith("# data ")]
        n_head = next((i for i, ln in enumerate(lines) if not ln.startswith("#")), len(lines))
        write_text_atomic(path, "\n".join([*lines[:n_head], data, *lines[n_head:]]) + "\n")
        return
    d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(cfg).items()}
    head = (f"# Resolved training config, written by grutrack {__version__} train: --config '{config_arg}' with "
            f"the command line's overrides.\n# config hash {config_hash(d)}\n{data}\n")
    write_text_atomic(path, head + yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=120))
