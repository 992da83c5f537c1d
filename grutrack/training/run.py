"""One training run, what ``grutrack train`` does once its arguments are parsed (:func:`train`): the training split of
a dataset (any :class:`~grutrack.datasets.base.Dataset`) and its detections, the config's and the command's extra
sources, validation on a validation split or on scenes held out of the training split (scored by the dataset,
:mod:`grutrack.training.validation`), the trainer, training.yaml beside the checkpoints.

Only light imports at module level: the command line imports this module to build its parser."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from grutrack.errors import ConfigError


@dataclass
class TrainingResult:
    """What a finished run left: the final checkpoint (``model.pt``), the steps taken, the last step's loss and,
    with validation, its record (``validation.json``) and the name of its score."""

    final: Path
    steps: int
    last_loss: float | None
    validation: object | None = None  # documents.ValidationRecord
    metric: str | None = None


def train(
    cfg,
    dataset,
    split: str,
    detections: str | Path,
    out: str | Path,
    *,
    config_arg: str = "grukf",
    val_split: str | None = None,
    val_detections: str | Path | None = None,
    sources: list[dict] = (),
    resume: bool = False,
    progress: bool = True,
) -> TrainingResult:
    """Train the GRU-KF with the training config ``cfg`` (:class:`~grutrack.training.config.TrainConfig`) on
    ``split`` of ``dataset`` with ``detections`` (a file the dataset reads), plus the config's ``sources`` and
    ``sources`` (more source entries, checked: ``grutrack.training.sources``); checkpoints and logs into ``out``.

    Validation: on ``val_split`` with ``val_detections`` (both or neither), else on ``cfg.validation_scenes``
    scenes held out of ``split``; a dataset that does not ``validates_training`` trains without (one line on
    stderr). ``config_arg``: the config as given (a name or path; errors name its file). ``resume``: continue
    from ``out/last.pt``. Raises :class:`~grutrack.training.trainer.TrainingInterrupted` on Ctrl-C (after
    saving last.pt). A run that starts from the beginning writes training.yaml before it reads the data (and
    again with what it read), so that, stopped at any moment, it leaves a folder ``--resume`` continues (from the
    beginning where it saved no last.pt)."""
    from grutrack.tracking.config import load_tracker_config
    from grutrack.training.resample import DetectionResampler, ResamplingTrainer
    from grutrack.training.sources import LoadedSource, check_source, load_source, merge, merged_resampler
    from grutrack.training.trainer import Trainer
    from grutrack.training.validation import DatasetValidator

    if (val_split is None) != (val_detections is None):
        raise ConfigError("--val-split and --val-detections go together")
    extra = [(e, f"{cfg_name(config_arg)} sources[{i}]") for i, e in enumerate(cfg.sources)]
    extra += [(e, f"--source {i + 1}") for i, e in enumerate(sources)]
    for e, where in extra:
        check_source(e, where)  # before any data is read
    if val_split and not dataset.validates_training:
        raise ConfigError(
            f"--val-split: grutrack train cannot validate on {dataset.name} data; train without it "
            f"(or validate a checkpoint with grutrack track + evaluate)"
        )
    out = Path(out)
    resume_from = _resume_from(out) if resume else None  # before training.yaml is written
    source = {
        "dataset": dataset.name,
        # absolute as given, links not followed: a package writes them relative to the workflow's folder
        "dataroot": os.path.abspath(dataset.options.dataroot),
        "version": dataset.options.version,
        "split": split,
        "detections": os.path.abspath(detections),
    }
    if resume_from is None:  # a resumed run's training.yaml stays until its last.pt has accepted these settings
        out.mkdir(parents=True, exist_ok=True)
        write_training_yaml(cfg, config_arg, out / "training.yaml", source)
    scenes = dataset.scenes(split, with_gt=True)
    yaw = load_tracker_config(cfg.tracker_preset).measured_yaw  # the preset's measured-yaw definition
    loaded_dets = dataset.load_detections(detections, split, scenes, yaw)
    dets = loaded_dets.boxes
    held = [] if val_split else _held_out(cfg, config_arg, dataset, split, scenes)
    if held:
        names = {sc.name for sc in held}
        scenes = [sc for sc in scenes if sc.name not in names]
        source["validation_scenes"] = sorted(names)
        print(f"validating on {len(held)} scenes held out of {split}: {', '.join(sorted(names))}")
    if dataset.name != "nuscenes":  # the rate the logs are read at (nuScenes keyframes have one)
        source["rate_hz"] = dataset.options.rate_hz
    resampler = DetectionResampler(dataset, split, scenes, yaw)
    if extra:
        loaded = [LoadedSource(scenes, dets, resampler, source)]
        loaded += [load_source(e, yaw, out / "sources", where) for e, where in extra]
        scenes, dets = merge(loaded)
        resampler = merged_resampler(loaded)
        source = {**source, "sources": [src.description for src in loaded[1:]]}
        print(f"training on {len(scenes)} scenes, {sum(len(sc) for sc in scenes)} frames from {len(loaded)} sources")
    if cfg.resample_profiles:
        trainer = ResamplingTrainer(cfg, scenes, dets, out, resampler, progress=progress, source=source)
    else:
        trainer = Trainer(cfg, scenes, dets, out, progress=progress, source=source)
    if val_split:
        val_scenes = dataset.scenes(val_split)
        val_dets = dataset.load_detections(val_detections, val_split, val_scenes, yaw).boxes
        trainer.validate = DatasetValidator(dataset, val_split, val_scenes, val_dets, cfg)
    elif held:
        trainer.validate = DatasetValidator(
            dataset,
            split,
            held,
            _validation_sets(cfg, dataset, split, held, dets, yaw),
            cfg,
            held_out=True,
            reference_name=f"tracker preset '{cfg.tracker_preset}' (its EKF)",
        )
    if resume_from is not None:
        trainer.resume(resume_from)
    source["synthetic"] = synthetic_inputs(dataset, loaded_dets, cfg, [e for e, _ in extra])
    write_training_yaml(cfg, config_arg, out / "training.yaml", source)
    final = trainer.run()
    last = trainer.log.steps[-1] if trainer.log.steps else None
    result = TrainingResult(final, trainer.state.step, last.loss if last else None)
    if trainer.validate is not None and final.name == "model.pt":
        from grutrack.documents import ValidationRecord

        result.validation, result.metric = ValidationRecord.read(out / "validation.json"), trainer.validate.metric
    return result


def _held_out(cfg, config_arg: str, dataset, split: str, scenes: list) -> list:
    """The training split's scenes held out for validation (``validation_scenes``), or [] when there are none:
    the config asks for none, or the dataset cannot validate (said in one line on stderr)."""
    import sys

    from grutrack.training.validation import held_out_scenes

    n = cfg.validation_scenes
    if n == 0:
        return []
    if not dataset.validates_training:
        print(
            f"grutrack train: note: grutrack train cannot validate on {dataset.name} data; training on every "
            f"scene of {split} without validation (model.pt: the last step)",
            file=sys.stderr,
        )
        return []
    if n >= len(scenes):
        raise ConfigError(
            f"{cfg_name(config_arg)}: validation_scenes {n} would leave no training scene (split "
            f"'{split}' has {len(scenes)}); expected fewer, or 0 with --val-split"
        )
    return held_out_scenes(scenes, n)


def _validation_sets(cfg, dataset, split: str, held: list, dets: dict, yaw: str) -> dict:
    """Detection sets of the held-out scenes: the command's detections and, with ``resample_profiles``,
    ``validation_draws`` sets simulated with each profile (seeds :func:`~grutrack.training.resample.validation_seed`,
    which training never draws), so that validation sees every kind of detector error the training does, each
    over several draws of its noise. Names: the profile's (its first draw), then ``<profile>_<draw>``."""
    from grutrack.training.resample import DetectionResampler, validation_seed

    sets = {"given": dets}
    sim = DetectionResampler(dataset, split, held, yaw)
    for profile in cfg.resample_profiles:
        for draw in range(cfg.validation_draws):
            name = Path(profile).stem + (f"_{draw}" if draw else "")
            sets[name] = sim(profile, validation_seed(cfg.seed, draw))
    return sets


def cfg_name(config_arg: str) -> str:
    """How errors name the training config: its file name or preset name."""
    return Path(config_arg).name


def synthetic_inputs(dataset, dets, cfg, sources: list[dict]) -> list[str]:
    """What of the training's data is SYNTHETIC, one phrase each (empty: none), for the ``# data`` line of
    training.yaml, which reports read to flag every number that depends on it: the grutrack demo's scenes, a
    simulated detection file (its ``synthetic`` entry), detections resampled from the ground truth each epoch
    (``resample_profiles``), and extra sources that are demo scenes or simulated detections."""
    out = []
    if dataset.is_synthetic():
        out.append("scenes of the SYNTHETIC grutrack demo dataset")
    if dets.synthetic:
        out.append(
            f"simulated detections ({dets.synthetic.get('profile', '?')} profile, seed "
            f"{dets.synthetic.get('seed', '?')})"
        )
    if cfg.resample_profiles and cfg.epochs > 1:
        out.append(f"detections simulated afresh every epoch after the first ({', '.join(cfg.resample_profiles)})")
    synthetic_sources = [e for e in sources if e.get("dataset") == "demo" or "profile" in e]
    if synthetic_sources:
        out.append(
            f"{len(synthetic_sources)} SYNTHETIC training source(s) "
            f"({sum(e.get('scenes', 0) for e in synthetic_sources if e.get('dataset') == 'demo')} demo scenes)"
        )
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
    head = (
        f"# Resolved training config, written by grutrack {__version__} train: --config '{config_arg}' with "
        f"the command line's overrides.\n# config hash {config_hash(d)}\n{data}\n"
    )
    write_text_atomic(path, head + yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=120))


def _resume_from(out: Path) -> Path | None:
    """``--resume``: the checkpoint to continue from, ``out/last.pt``; None for a run stopped before it saved one
    (its training.yaml is there, its last.pt not: stopped while it read its data or aborted during its start-up
    validation), which starts from the beginning and says so; a folder with neither is refused (a mistyped
    --out), before any data is read."""
    import sys

    last = out / "last.pt"
    if last.is_file():
        return last
    if (out / "training.yaml").is_file():
        print(
            f"grutrack train: --resume: {last} does not exist (the run stopped before its first step was "
            f"saved); starting from the beginning",
            file=sys.stderr,
        )
        return None
    raise ConfigError(
        f"--resume: nothing to resume in {out} (no last.pt, no training.yaml of a run); expected "
        f"the --out folder of the interrupted run"
    )
