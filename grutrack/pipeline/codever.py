"""Code versions per workflow stage: the package version plus a hash of the package files that stage runs.

Every workflow rule carries its stage's code version as a Snakemake ``param``; Snakemake re-runs a job whose
params changed, so editing, say, ``grutrack/tracking/`` re-runs tracking and everything downstream of it, but
not the demo data or the detections. The file lists are deliberately generous (a stage lists every module it
imports from the package, and the shipped configs it reads).

What is hashed is what runs: a Python file's syntax tree without its docstrings and comments, a YAML file's
parsed data without its comments (:func:`_runs`), so a corrected docstring or config comment re-runs nothing.
"""

from __future__ import annotations

import ast
import hashlib
import json
import os
from pathlib import Path

import yaml

from grutrack import __version__

_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml's when built with it (10x faster)
PACKAGE = Path(__file__).resolve().parents[1]
#: files every stage runs (the package version itself is part of every code version)
_COMMON = (
    "errors.py",
    "io.py",
    "formats.py",
    "configs/schemas/formats",
    "provenance.py",
    "boxes.py",
    "classes.py",
    "geometry.py",
    "data/scene.py",
)
_TRACKING = (
    "tracking",
    "motion",
    "geometry.py",
    "boxes.py",
    "classes.py",
    "data/scene.py",
    "configs/trackers",
    "configs/motion",
    "motion/checkpoint.py",
    "pipeline/presets.py",
    "cli/common.py",
)
#: what every stage that goes through a dataset runs: the dataset interface, the stage documents, and the
#: datasets' readers and writers (the data and export layers whole, so a new dataset's modules count without
#: being listed here)
_DATASETS = ("datasets", "documents.py", "cli/common.py", "data", "export")

#: stage -> package paths (files or folders) whose content defines the stage's code version
STAGE_SOURCES: dict[str, tuple[str, ...]] = {
    "data": ("data/demo.py", "cli/demo.py"),
    "simulate": ("configs/detector_profiles", "cli/demo.py", *_DATASETS),
    "fetch": ("data/registry.py", "data/download.py", "configs/detections.yaml", "cli/detections.py"),
    "convert": ("data", "configs/detections.yaml", "cli/detections.py"),
    "train": (
        "training",
        "evaluation/nuscenes_fast",
        "evaluation/tracking_classes.py",
        "configs/training",
        "cli/train.py",
        *_TRACKING,
        *_DATASETS,
    ),
    "resolve": (
        "pipeline/presets.py",
        "tracking/config.py",
        "motion/config.py",
        "configs/trackers",
        "configs/motion",
        "cli/resolve.py",
    ),
    "track": ("cli/track.py", *_TRACKING, *_DATASETS),
    "submit": ("cli/submit.py", "pipeline/presets.py", *_DATASETS),  # presets: where track wrote its config
    "evaluate": ("evaluation", "cli/evaluate.py", *_DATASETS),
    "render": ("render", "evaluation", "threads.py", "cli/render.py", *_DATASETS),
    "report": ("report", "render", "documents.py", "cli/report.py"),
}


def _files(rel: str, root: Path) -> list[Path]:
    """The .py / .yaml files under one listed path (none when it does not exist)."""
    p = root / rel
    if p.is_file():
        return [p]
    if p.is_dir():
        return sorted(q for q in p.rglob("*") if q.suffix in (".py", ".yaml") and "__pycache__" not in q.parts)
    return []


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring (a leading string statement) of its module, classes and functions removed."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (
            isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and body
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)
        ):
            node.body = body[1:] or [ast.Pass()]
    return tree


#: SHA-256 of a file's content (suffix and bytes) -> SHA-256 of what of it runs (:func:`_runs`), so a file read by
#: several stages is parsed once
_DIGESTS: dict[bytes, bytes] = {}


def _content(f: Path) -> bytes:
    """32-byte digest of what of file ``f`` defines behaviour (:func:`_runs`)."""
    raw = f.read_bytes()
    key = hashlib.sha256(f.suffix.encode() + b"\0" + raw).digest()
    if key not in _DIGESTS:
        _DIGESTS[key] = hashlib.sha256(_runs(f.suffix, raw)).digest()
    return _DIGESTS[key]


def _runs(suffix: str, raw: bytes) -> bytes:
    """What of a file's bytes ``raw`` defines behaviour: for .py the dump of its syntax tree without docstrings
    (comments are not in the tree), for .yaml its data as JSON (comments, quoting and layout dropped); the bytes
    themselves when the file does not parse (so an edit that breaks it still changes the hash)."""
    try:
        if suffix == ".py":
            return ast.dump(_strip_docstrings(ast.parse(raw))).encode()
        if suffix == ".yaml":
            return json.dumps(yaml.load(raw, Loader=_YAML_LOADER), default=str).encode()
    except (SyntaxError, ValueError, yaml.YAMLError):
        pass
    return raw


def source_hash(paths: tuple[str, ...], root: Path = PACKAGE) -> str:
    """Short SHA-256 over the (relative path, :func:`_content` digest) of every file under ``paths``."""
    h = hashlib.sha256()
    files = sorted({f for rel in (*_COMMON, *paths) for f in _files(rel, root)})
    for f in files:
        h.update(f.relative_to(root).as_posix().encode() + b"\0" + _content(f) + b"\0")
    return h.hexdigest()[:12]


def code_version(stage: str, root: Path = PACKAGE) -> str:
    """``<version>+<hash>`` of a stage; ``GRUTRACK_CODE_VERSION`` in the environment pins every stage to
    that string instead (for a release build, or tests that must not see concurrent source edits)."""
    if stage not in STAGE_SOURCES:
        raise KeyError(f"unknown workflow stage '{stage}' (known: {', '.join(STAGE_SOURCES)})")
    pinned = os.environ.get("GRUTRACK_CODE_VERSION")
    if pinned:
        return pinned
    return f"{__version__}+{source_hash(STAGE_SOURCES[stage], root)}"
