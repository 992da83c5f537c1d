"""The pretrained GRU-KF shipped with the package (``grutrack/pretrained/<name>/``): a checkpoint of a shipped
training recipe, trained by ``scripts/pretrain_grukf.sh``, with its training config, log, validation record and
``provenance.json`` (the command, the package version and commit, the detections' and the model's SHA-256, the
training data's fingerprint).

The files are what ``grutrack train`` wrote; :func:`package` copies them in and writes the provenance, with a
digest of each section of the tracker preset and motion config the recipe trained with (:func:`pipeline_digest`).
:func:`recipe_differences` and :func:`pipeline_differences` say whether the checkpoint still is the shipped recipe
on the shipped tracker (tests/test_grukf_real.py fails, naming the keys or sections, when the recipe, the default
tracker preset or its motion config changed and the checkpoint was not re-trained).

    python -m grutrack.training.pretrained --from CK_DIR --detections DET.json --out grutrack/pretrained/grukf_default
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import subprocess
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

#: the shipped pretrained networks: name -> the training recipe (grutrack/configs/training/<recipe>.yaml) it is
PRETRAINED = {"grukf_default": "grukf"}
#: the files of a training folder a pretrained network keeps (model.pt without the state a resume needs)
FILES = ("model.pt", "training.yaml", "train_log.csv", "validation.json")
#: training-config keys that do not change what is learned
IGNORED_KEYS = ("device", "checkpoint_every")
#: tracker-config fields that say where the preset was read from, not how it tracks
IGNORED_TRACKER_FIELDS = ("source",)
#: the keys of a training's data record (a checkpoint's ``data_source``, training.yaml's ``# data`` line) that hold
#: paths: written relative to the workflow's folder in a package, so the record names no machine's folders
PATH_KEYS = ("dataroot", "detections")


def pretrained_dir(name: str) -> Path:
    """The folder of the shipped pretrained network ``name`` (a key of :data:`PRETRAINED`)."""
    return Path(__file__).resolve().parents[1] / "pretrained" / name


def _canonical(value: Any) -> Any:
    """JSON-comparable form of a config value (a training config, a resolved preset): dataclasses as dicts,
    arrays and tuples as lists, numpy scalars as Python numbers, keys as strings (nested)."""
    import dataclasses

    import numpy as np

    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_canonical(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def recipe_differences(train_config: dict, recipe: str) -> list[str]:
    """Keys (dotted) whose value in a checkpoint's training config differs from the shipped recipe ``recipe``
    as loaded today; empty when the checkpoint is that recipe (:data:`IGNORED_KEYS` left out)."""
    from grutrack.training.config import load_train_config

    shipped = _canonical(asdict(load_train_config(recipe)))
    have = _canonical(train_config)
    out = []
    for key in sorted(set(shipped) | set(have)):
        if key in IGNORED_KEYS:
            continue
        a, b = shipped.get(key), have.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out += [f"{key}.{k}" for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            out.append(key)
    return out


def pipeline_digest(train_config: dict) -> dict[str, dict[str, str]]:
    """SHA-256 of each field of the tracker preset (but :data:`IGNORED_TRACKER_FIELDS`) and of each class of the
    motion config that ``train_config`` (a checkpoint's training config, a dict) names, as they load today:
    ``{"tracker_preset": {field: hex}, "motion_config": {class: hex}}``. The network learns on that tracker (its
    association, lifecycle and the parallel EKF's noise), so a change there makes a shipped network stale."""
    import hashlib

    from grutrack.motion.config import load_motion_config
    from grutrack.tracking.config import load_tracker_config

    def digests(resolved: dict) -> dict[str, str]:
        return {
            key: hashlib.sha256(json.dumps(val, sort_keys=True).encode()).hexdigest()
            for key, val in sorted(_canonical(resolved).items())
            if key not in IGNORED_TRACKER_FIELDS
        }

    return {
        "tracker_preset": digests(load_tracker_config(train_config["tracker_preset"])),
        "motion_config": digests(load_motion_config(train_config["motion_config"])),
    }


def pipeline_differences(recorded: dict, train_config: dict) -> list[str]:
    """Sections (``tracker_preset.<field>``, ``motion_config.<class>``) whose digest in ``recorded`` (a
    provenance's ``trained_with``) differs from :func:`pipeline_digest` of ``train_config`` today; empty when the
    network was trained on the tracker as it is. A preset field the record predates counts only when its value
    today is not the field's default: an option added later and left at its default (off) leaves the tracker the
    network was trained on as it was."""
    today = pipeline_digest(train_config)
    unset = _default_digests()
    out = []
    for part in sorted(set(today) | set(recorded)):
        a, b = today.get(part, {}), recorded.get(part, {})
        for k in sorted(set(a) | set(b)):
            added_off = part == "tracker_preset" and k not in b and a.get(k) == unset.get(k)
            if a.get(k) != b.get(k) and not added_off:
                out.append(f"{part}.{k}")
    return out


def _default_digests() -> dict[str, str]:
    """SHA-256 (as :func:`pipeline_digest`) of the default of each tracker-preset field that has one."""
    import dataclasses
    import hashlib

    from grutrack.tracking.config import TrackerConfig

    out = {}
    for f in dataclasses.fields(TrackerConfig):
        if f.default is not dataclasses.MISSING:
            value = f.default
        elif f.default_factory is not dataclasses.MISSING:
            value = f.default_factory()
        else:
            continue
        out[f.name] = hashlib.sha256(json.dumps(_canonical(value), sort_keys=True).encode()).hexdigest()
    return out


def _git_commit() -> str | None:
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True, check=True
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def portable_source(source: dict | None, root: Path) -> dict | None:
    """``source`` (a training's data record) with each absolute path of :data:`PATH_KEYS` written relative to
    ``root``; for root ``/home/me/grutrack``: ``/home/me/grutrack/detections/x.json`` -> ``detections/x.json``,
    ``/home/me/shared/data/nuscenes`` -> ``../shared/data/nuscenes``. Relative paths and other keys are kept."""
    if source is None:
        return None
    out = dict(source)
    for key in PATH_KEYS:
        value = out.get(key)
        if isinstance(value, str) and Path(value).is_absolute():
            out[key] = Path(os.path.relpath(value, root)).as_posix()
    return out


def portable_training_yaml(text: str, root: Path) -> str:
    """training.yaml's ``text`` with its ``# data {...}`` line's paths made relative to ``root``
    (:func:`portable_source`); the rest byte for byte."""
    lines = text.split("\n")
    for i, line in enumerate(lines):
        if line.startswith("# data "):
            record = portable_source(json.loads(line[len("# data ") :]), root)
            lines[i] = f"# data {json.dumps(record, sort_keys=True)}"
    return "\n".join(lines)


def package(src: Path, detections: Path, out: Path, command: str, root: Path | None = None) -> dict:
    """Copy :data:`FILES` of the training folder ``src`` into ``out`` and write ``provenance.json``; returns it.
    Paths of the data record are written relative to ``root`` (default: the working folder, the workflow's)."""
    from grutrack import __version__
    from grutrack.documents import Checkpoint
    from grutrack.io import atomic_path, write_json_atomic, write_text_atomic
    from grutrack.provenance import sha256_file

    root = Path.cwd() if root is None else root
    ck = Checkpoint.read(src / "model.pt")
    source = portable_source(ck.data_source, root)
    out.mkdir(parents=True, exist_ok=True)
    # the network, its config, the selected step and provenance; not the optimizer and log a resume needs
    replace(ck, training=None, data_source=source).write(out / "model.pt")
    write_text_atomic(out / "training.yaml", portable_training_yaml((src / "training.yaml").read_text(), root))
    for name in FILES[2:]:
        with atomic_path(out / name) as tmp:
            shutil.copyfile(src / name, tmp)
    prov = {
        "command": command,
        "grutrack_version": __version__,
        "git_commit": _git_commit(),
        "written": datetime.date.today().isoformat(),
        "model_sha256": sha256_file(out / "model.pt"),
        "selected_step": ck.selected.step if ck.selected else None,
        "detections": {"file": Path(detections).name, "sha256": sha256_file(detections)},
        "data_fingerprint": ck.data_fingerprint,
        "data_source": source,
        "trained_with": pipeline_digest(ck.train_config),
    }
    write_json_atomic(out / "provenance.json", prov, indent=2)
    return prov


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Package a training folder as a shipped pretrained GRU-KF.")
    p.add_argument("--from", dest="src", required=True, help="the --out folder of grutrack train")
    p.add_argument("--detections", required=True, help="the training detections (their SHA-256 is recorded)")
    p.add_argument("--out", required=True, help="grutrack/pretrained/<name>")
    p.add_argument("--command", required=True, help="the command that made it (recorded)")
    args = p.parse_args(argv)
    prov = package(Path(args.src), Path(args.detections), Path(args.out), args.command)
    print(f"wrote {args.out}: model.pt sha256 {prov['model_sha256'][:12]}, step {prov['selected_step']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
