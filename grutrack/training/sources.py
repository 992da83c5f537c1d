"""Training sources: one GRU-KF training over several datasets, splits and detection sets.

A source is a split with ground truth and its detections: a dataset on disk (``nuscenes``, ``av2``) or a
SYNTHETIC demo dataset generated for the run (``demo``, nuScenes-format, any size: e.g. the size of nuScenes
train, 700 scenes of 40 frames), with a detection file or detections simulated with a detector profile and
seed. ``grutrack train`` takes its split (``--dataroot/--split/--detections``) as the first source and adds the
training config's ``sources`` and every ``--source``. Their scenes make one epoch; each scene keeps its own
vocabulary (nuScenes classes, AV2 categories), so the tracker's per-class parameters and the network's class
gain follow each dataset. With ``resample_profiles`` every source's detections are simulated afresh each epoch.

A source entry (training config ``sources:`` item, or ``--source`` as a YAML flow mapping)::

    {dataset: nuscenes, dataroot: D, version: v1.0-mini, split: mini_train, detections: DET.json}
    {dataset: av2, dataroot: AV2, split: val, rate_hz: 2, profile: centerpoint, seed: 3}
    {dataset: demo, scenes: 700, frames_per_scene: 40, demo_seed: 1, split: demo_all, profile: centerpoint}

Generated data (demo datasets, simulated detections) is written under ``<out>/sources/`` and reused by a
resumed run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from grutrack.data.scene import BoxSet, Scene
from grutrack.errors import ConfigError

#: keys of a source entry and what each must be (the schema: grutrack/configs/schemas/training.schema.yaml)
_REQUIRED = {
    "nuscenes": ("dataroot", "version", "split"),
    "av2": ("dataroot", "split"),
    "demo": ("scenes", "frames_per_scene", "split"),
}


@dataclass
class LoadedSource:
    """A source read: its scenes (with ground truth), detections by frame token, a resampler (``callable(profile,
    seed) -> detections``) and a description for the training log."""

    scenes: list[Scene]
    dets: dict[str, BoxSet]
    resampler: Callable[[str, int], dict[str, BoxSet]]
    description: dict


def check_source(entry: dict, where: str) -> None:
    """What the schema cannot state: the keys each dataset needs, and detections given either as a file or as a
    profile to simulate with. ``where`` names the entry in errors (``--source 2``, ``config sources[0]``)."""
    for key in _REQUIRED[entry["dataset"]]:
        if key not in entry:
            raise ConfigError(f"{where}: '{key}' is required for a {entry['dataset']} source")
    if ("detections" in entry) == ("profile" in entry):
        raise ConfigError(
            f"{where}: give either 'detections' (a file) or 'profile' (simulate them), not "
            f"{'both' if 'detections' in entry else 'neither'}"
        )
    if entry["dataset"] == "demo" and "dataroot" in entry:
        raise ConfigError(f"{where}: a demo source is generated for the run; it takes no 'dataroot'")


def load_source(entry: dict, measured_yaw: str, cache: Path, where: str) -> LoadedSource:
    """Read (or generate) one source. ``cache``: the folder for generated data (``<out>/sources``)."""
    from grutrack.datasets import DatasetOptions, open_dataset
    from grutrack.training.resample import DetectionResampler

    check_source(entry, where)
    dataset, root = entry["dataset"], entry.get("dataroot")
    version = entry.get("version")
    if dataset == "demo":
        root, version = _demo(entry, cache)
        dataset = "nuscenes"
    ds = open_dataset(dataset, DatasetOptions(dataroot=root, version=version, rate_hz=entry.get("rate_hz", 2.0)))
    scenes = ds.scenes(entry["split"], with_gt=True)
    resampler = DetectionResampler(ds, entry["split"], scenes, measured_yaw)
    if "detections" in entry:
        dets = ds.load_detections(entry["detections"], entry["split"], scenes, measured_yaw).boxes
    else:
        dets = resampler(entry["profile"], int(entry.get("seed", 0)))
    description = {k: (str(Path(v).resolve()) if k in ("dataroot", "detections") else v) for k, v in entry.items()}
    return LoadedSource(scenes, dets, resampler, description)


def _demo(entry: dict, cache: Path) -> tuple[str, str]:
    """The demo dataset of a source, generated under ``cache`` unless already there: (dataroot, version)."""
    from grutrack.data.demo import generate_demo
    from grutrack.data.demo_defaults import VERSION

    n, frames, seed = int(entry["scenes"]), int(entry["frames_per_scene"]), int(entry.get("demo_seed", 0))
    root = cache / f"demo_n{n}_f{frames}_s{seed}"
    generate_demo(root, scenes=n, frames=frames, seed=seed, version=VERSION)  # unchanged when already there
    return str(root), VERSION


def parse_source(text: str, index: int) -> dict:
    """A ``--source`` value (a YAML flow mapping) checked against the training schema's source entry."""
    from grutrack.config_loader import schema
    from grutrack.io import parse_yaml

    where = f"--source {index}"
    try:
        entry = parse_yaml(text)
    except Exception as exc:  # noqa: BLE001 - any YAML error is bad input here
        raise ConfigError(f"{where}: not a YAML mapping ({exc.__class__.__name__}): {text!r}") from None
    if not isinstance(entry, dict):
        raise ConfigError(
            f"{where}: expected a mapping such as '{{dataset: av2, dataroot: D, split: val, "
            f"profile: centerpoint}}', got {text!r}"
        )
    _validate_entry(entry, schema("training")["properties"]["sources"]["items"], where)
    check_source(entry, where)
    return entry


def _validate_entry(entry: dict, node: dict, where: str) -> None:
    """One source entry against its schema node; the first error names the key."""
    import jsonschema

    errors = sorted(jsonschema.Draft202012Validator(node).iter_errors(entry), key=lambda e: list(e.path))
    if errors:
        err = errors[0]
        key = ".".join(str(p) for p in err.path)
        raise ConfigError(f"{where}{'.' + key if key else ''}: {err.message}")


def merge(sources: list[LoadedSource]) -> tuple[list[Scene], dict[str, BoxSet]]:
    """The scenes of every source in order and their detections; a frame token seen in two sources is an
    error (the same split given twice)."""
    scenes, dets = [], {}
    for src in sources:
        overlap = dets.keys() & src.dets.keys()
        if overlap:
            raise ConfigError(
                f"training source {src.description} repeats frames of an earlier source "
                f"({len(overlap)} frames, e.g. {next(iter(overlap))})"
            )
        scenes += src.scenes
        dets.update(src.dets)
    return scenes, dets


def merged_resampler(sources: list[LoadedSource]) -> Callable[[str, int], dict[str, BoxSet]]:
    """``callable(profile, seed)``: fresh detections of every source, merged."""

    def resample(profile: str, seed: int) -> dict[str, BoxSet]:
        out: dict[str, BoxSet] = {}
        for src in sources:
            out.update(src.resampler(profile, seed))
        return out

    return resample
