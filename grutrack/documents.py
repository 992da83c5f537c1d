"""The documents that pass between stages, as typed records with their file format (the contract between the
stage that writes a file and every stage or tool that reads it, as the nuScenes devkit's ``DetectionMetrics``
is between its evaluation and rendering).

- :class:`MetricsDocument`: what ``grutrack evaluate`` writes (``reports/metrics/...json``); read by the reports,
  ``grutrack check`` and ``grutrack render``. Layout (kept stable; other tools read it)::

      {"dataset", "version", "split", "evaluator", "submission",
       "overall": {metric: value}, "per_class": {class: {metric: value}},
       ["seconds"], ["settings"], ["logs"], ["frames"], ["devkit_summary"]}

  A class the evaluated ground truth does not hold is marked ``per_class[c]["absent"] = true`` (AV2, with its
  ``gt_boxes``); its numbers stay as the evaluator gave them but are in no average, and reports and the check show
  it as absent (:meth:`MetricsDocument.is_absent`).

- :class:`Manifest`: the provenance record ``grutrack submit`` writes beside a submission
  (``x.json`` -> ``x.manifest.json``).
- :class:`TrainingLog`: ``train_log.csv`` of ``grutrack train``, one :class:`TrainingStep` per optimiser step.
- :class:`ValidationRecord`: ``validation.json`` beside it: what was validated, the reference tracker's AMOTA on
  the same scenes and which step ``model.pt`` holds.
- :class:`CrossCheckDocument`: what ``grutrack cross-check`` writes: the devkit and the fast evaluator on the
  same submission (or an evenly spaced subset of its scenes), the largest difference of any metric entry.
- :class:`Checkpoint`: a GRU-KF checkpoint of ``grutrack train`` (``model.pt``, ``last.pt``, ``best.pt``): the
  network's weights and architecture, the training config, the state a run resumes from and provenance; read by
  ``grutrack track`` and by a resumed training.

Readers raise :class:`~grutrack.errors.InputFormatError` naming the file and what was expected.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import MISSING as dataclasses_MISSING
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from grutrack import __version__
from grutrack.errors import InputFormatError
from grutrack.io import read_json, write_json_atomic, write_text_atomic
from grutrack.provenance import sha256_file

# -- metrics -----------------------------------------------------------------------------------------------

#: how reports and ``grutrack check`` show a class without ground truth instead of its number
ABSENT_TEXT = "absent (no ground truth)"

#: AV2 ``overall`` columns that documents written before absent classes were left out of the averages kept twice:
#: ``hota`` (mean over the 7 Table I classes, absent ones at their 0 / -FP) and ``hota_present`` (mean over the
#: classes with ground truth, the average now written as ``hota``)
_PRESENT_AVERAGES = ("hota", "mota", "idf1")


def _upgraded(d: dict) -> dict:
    """A metrics JSON in the current layout: an AV2 document written before absent classes were left out of the
    averages (``overall`` has ``hota_present``) gets the averages over the classes with ground truth as ``hota`` /
    ``mota`` / ``idf1`` (the ``*_present`` values it holds; nothing is recomputed), ``absent_classes``, and
    ``absent`` per class from its ``present``. Other documents are returned as they are."""
    overall = d["overall"]
    if "hota_present" not in overall:
        return d
    overall = {k: v for k, v in overall.items() if not (k.endswith("_present") and k[:-8] in _PRESENT_AVERAGES)}
    overall.update({k: d["overall"][f"{k}_present"] for k in _PRESENT_AVERAGES if f"{k}_present" in d["overall"]})
    per_class = {
        c: ({**m, "absent": not m["present"]} if isinstance(m.get("present"), bool) and "absent" not in m else m)
        for c, m in d["per_class"].items()
    }
    if isinstance(overall.get("classes"), list):
        overall["absent_classes"] = [c for c in overall["classes"] if per_class.get(c, {}).get("absent") is True]
    settings = d.get("settings")
    if isinstance(settings, dict) and "average" in settings:
        settings = {
            **settings,
            "average": "Table I: mean over the Table I classes with ground truth (absent "
            "classes are left out; read from the document's *_present averages)",
        }
    return {**d, "overall": overall, "per_class": per_class, **({"settings": settings} if settings else {})}


@dataclass
class MetricsDocument:
    """Official metrics of one submission: overall and per class (metric names as the evaluator gives them,
    lower case: ``amota``, ``amotp`` (m), ``ids``, ... for nuScenes; ``hota``, ``mota``, ``idf1`` for AV2)."""

    dataset: str
    version: str | None
    split: str
    evaluator: str
    submission: str
    overall: dict[str, Any]
    per_class: dict[str, dict[str, Any]]
    seconds: float | None = None
    settings: dict[str, Any] | None = None  # AV2: rate, range, ROI, workers, how the average is taken
    logs: int | None = None  # AV2: logs and frames evaluated
    frames: int | None = None
    devkit_summary: dict[str, Any] | None = None  # nuScenes: the devkit's metrics_summary.json, NaN as null

    OPTIONAL = ("seconds", "settings", "logs", "frames", "devkit_summary")

    @property
    def classes(self) -> list[str]:
        """Class names in the evaluator's order."""
        return list(self.per_class)

    def is_absent(self, cls: str) -> bool:
        """Whether the evaluated ground truth holds no box of ``cls`` (``absent: true``; documents that only say
        ``present`` or ``gt_boxes`` are read from those). A class the document does not list is not absent."""
        m = self.per_class.get(cls)
        if not isinstance(m, dict):
            return False
        if "absent" in m:
            return m["absent"] is True
        if isinstance(m.get("present"), bool):
            return not m["present"]
        gt = m.get("gt_boxes")
        return isinstance(gt, int) and not isinstance(gt, bool) and gt == 0

    @property
    def absent_classes(self) -> list[str]:
        """The classes without ground truth, in the evaluator's order."""
        return [c for c in self.per_class if self.is_absent(c)]

    def is_absent_path(self, dotted: str) -> bool:
        """Whether a dotted path names a per-class value of an absent class (``per_class.BUS.hota``)."""
        parts = dotted.split(".")
        return len(parts) >= 3 and parts[0] == "per_class" and self.is_absent(parts[1])

    def value(self, dotted: str) -> float | None:
        """The number at a dotted path (``overall.amota``, ``per_class.car.amotp``); None when absent, not a
        number or not finite (the devkit reports a class without ground truth as NaN)."""
        node: Any = self.to_dict()
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                return None
            node = node[part]
        if isinstance(node, bool) or not isinstance(node, (int, float)) or not math.isfinite(node):
            return None
        return float(node)

    def class_value(self, cls: str, key: str) -> float | None:
        """``per_class[cls][key]`` as a finite float, or None."""
        return self.value(f"per_class.{cls}.{key}")

    def to_dict(self) -> dict[str, Any]:
        """The JSON object; optional fields that are unset are left out."""
        d = asdict(self)
        return {k: v for k, v in d.items() if not (k in self.OPTIONAL and v is None)}

    @classmethod
    def from_dict(cls, d: Any, where: str = "metrics JSON") -> MetricsDocument:
        """Parse and check the layout against its description (``grutrack/configs/schemas/formats/metrics.schema.yaml``;
        an error names the field, ``per_class.car.amota``); unknown top-level keys are ignored (newer writers may add
        some). An AV2
        document written before absent classes were left out of the averages is read in the current layout
        (see :func:`_upgraded`)."""
        from grutrack import formats

        formats.check("metrics", d, where)  # the layout's one description (metrics.schema.yaml)
        d = _upgraded(d)
        names = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in names}
        for key in ("dataset", "split", "evaluator", "submission"):
            kw.setdefault(key, "")
        kw.setdefault("version", None)
        return cls(**kw)

    def write(self, path: str | Path) -> None:
        """Write the JSON atomically (indented: a small file people read)."""
        write_json_atomic(path, self.to_dict(), indent=2)

    @classmethod
    def read(cls, path: str | Path) -> MetricsDocument:
        """Read a metrics JSON written by :meth:`write`."""
        return cls.from_dict(read_json(path, "metrics JSON"), where=str(path))


# -- submission manifest -----------------------------------------------------------------------------------


@dataclass
class FileRecord:
    """A file an output was made from: its path and content hash (sha256, hex)."""

    path: str
    sha256: str | None = None
    config_hash: str | None = None  # tracker configs: the hash of the resolved configuration

    @classmethod
    def of(cls, path: str | Path | None, config_hash: str | None = None) -> FileRecord | None:
        """The record of an existing file (its sha256 read now); None for no file."""
        if path is None:
            return None
        return cls(path=str(path), sha256=sha256_file(path), config_hash=config_hash)

    @classmethod
    def from_dict(cls, d: Any, where: str) -> FileRecord | None:
        if d is None:
            return None
        if not isinstance(d, dict) or not isinstance(d.get("path"), str):
            raise InputFormatError(f"{where}: expected {{\"path\": ..., \"sha256\": ...}} or null")
        return cls(path=d["path"], sha256=d.get("sha256"), config_hash=d.get("config_hash"))

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if not (k == "config_hash" and v is None)}


@dataclass
class Manifest:
    """What produced a submission: dataset and split, the submission's hash and counts, the tracker, its
    configuration (hash of the resolved config), the detections and the checkpoint, package and code version."""

    dataset: str
    split: str
    submission: FileRecord
    tracker: str
    tracker_config: FileRecord
    dataroot: str | None = None
    version: str | None = None
    detections: FileRecord | None = None
    checkpoint: FileRecord | None = None
    code_version: str | None = None
    counts: dict[str, int] = field(default_factory=dict)  # samples/boxes (nuScenes), logs/frames/boxes (AV2)
    grutrack_version: str = __version__

    RECORDS = ("submission", "tracker_config", "detections", "checkpoint")

    def to_dict(self) -> dict[str, Any]:
        """The JSON object (counts flattened to the top level, as readers have always found them)."""
        d: dict[str, Any] = {
            "grutrack_version": self.grutrack_version,
            "code_version": self.code_version,
            "dataset": self.dataset,
            "dataroot": self.dataroot,
            "version": self.version,
            "split": self.split,
            **self.counts,
            "tracker": self.tracker,
        }
        for key in self.RECORDS:
            rec = getattr(self, key)
            d[key] = rec.to_dict() if rec is not None else None
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "manifest") -> Manifest:
        if not isinstance(d, dict):
            raise InputFormatError(f"{where}: not a manifest of grutrack submit (expected a JSON object)")
        recs = {k: FileRecord.from_dict(d.get(k), f"{where}: {k}") for k in cls.RECORDS}
        for key in ("submission", "tracker_config"):
            if recs[key] is None:
                raise InputFormatError(f"{where}: not a manifest of grutrack submit (no '{key}' record)")
        plain = {"dataset", "split", "tracker", "dataroot", "version", "code_version", "grutrack_version"}
        counts = {k: v for k, v in d.items() if k not in plain | set(cls.RECORDS) and isinstance(v, int)}
        return cls(
            dataset=str(d.get("dataset", "")),
            split=str(d.get("split", "")),
            tracker=str(d.get("tracker", "")),
            dataroot=d.get("dataroot"),
            version=d.get("version"),
            code_version=d.get("code_version"),
            grutrack_version=str(d.get("grutrack_version", "")),
            counts=counts,
            **recs,
        )

    @staticmethod
    def path_for(submission: str | Path) -> Path:
        """The manifest beside a submission: ``x.json`` -> ``x.manifest.json``."""
        p = Path(submission)
        return p.with_name(p.stem + ".manifest.json")

    def write(self, path: str | Path) -> None:
        write_json_atomic(path, self.to_dict(), indent=2)

    @classmethod
    def read(cls, path: str | Path) -> Manifest | None:
        """The manifest at ``path``, or None when there is none."""
        if not Path(path).is_file():
            return None
        return cls.from_dict(read_json(path, "manifest"), where=str(path))


# -- training log ------------------------------------------------------------------------------------------


@dataclass
class TrainingStep:
    """One optimiser step of ``grutrack train``: its loss and how many terms of each kind made it, the learning
    rate it ran with, the validation AMOTA when validated after it (else None), wall seconds of the step, and the
    AMOTA of each validation detection set (``val_amota_sets``, in ``validation.json``'s ``detection_sets`` order;
    ``val_amota`` is their mean; written ``a;b;c`` in the CSV), and the L2 norm of the step's gradient over all
    parameters before clipping (``grad_norm``, see ``grad_clip_norm``; NaN where the step had none)."""

    step: int
    epoch: int
    scene: str
    loss: float
    gt_terms: int = 0
    pseudo_terms: int = 0
    prediction_terms: int = 0
    lr: float = math.nan
    val_amota: float | None = None
    seconds: float = math.nan
    val_amota_sets: tuple[float, ...] | None = None
    grad_norm: float = math.nan

    @classmethod
    def from_row(cls, row: dict[str, str], where: str) -> TrainingStep:
        try:
            return cls(
                step=int(row["step"]),
                epoch=int(row["epoch"]),
                scene=row.get("scene") or "",
                loss=float(row["loss"]),
                gt_terms=int(row.get("gt_terms") or 0),
                pseudo_terms=int(row.get("pseudo_terms") or 0),
                prediction_terms=int(row.get("prediction_terms") or 0),
                lr=float(row.get("lr") or "nan"),
                val_amota=float(row["val_amota"]) if row.get("val_amota") not in ("", None) else None,
                seconds=float(row.get("seconds") or "nan"),
                val_amota_sets=tuple(float(x) for x in row["val_amota_sets"].split(";"))
                if row.get("val_amota_sets")
                else None,
                grad_norm=float(row.get("grad_norm") or "nan"),
            )
        except (TypeError, ValueError) as exc:
            raise InputFormatError(
                f"{where}: step {row.get('step')!r}: not a number where one is expected ({exc})"
            ) from exc

    def to_row(self) -> dict[str, Any]:
        row = asdict(self)
        row["val_amota"] = "" if self.val_amota is None else self.val_amota
        row["val_amota_sets"] = "" if self.val_amota_sets is None else ";".join(map(str, self.val_amota_sets))
        return row


@dataclass
class TrainingLog:
    """``train_log.csv``: the steps of one training run, in order."""

    steps: list[TrainingStep] = field(default_factory=list)

    FIELDS = tuple(f.name for f in fields(TrainingStep))
    REQUIRED = ("step", "epoch", "loss", "val_amota")

    def to_csv(self) -> str:
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=self.FIELDS)
        w.writeheader()
        w.writerows(s.to_row() for s in self.steps)
        return buf.getvalue()

    def write(self, path: str | Path) -> None:
        write_text_atomic(path, self.to_csv())

    @classmethod
    def read(cls, path: str | Path) -> TrainingLog:
        path = Path(path)
        try:
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
        except OSError as exc:
            raise InputFormatError(f"{path}: cannot read the training log ({exc})") from exc
        if rows and any(k not in rows[0] for k in cls.REQUIRED):
            raise InputFormatError(f"{path}: a training log needs the columns {', '.join(cls.REQUIRED)}")
        return cls([TrainingStep.from_row(r, str(path)) for r in rows])

    def validated(self) -> list[TrainingStep]:
        """The steps after which validation ran."""
        return [s for s in self.steps if s.val_amota is not None]


# select_checkpoint rules of the training config and validation.json -> how messages and reports name the step
SELECTION_RULES = {
    "last": "the last step",
    "best_val_amota": "the step of best validation AMOTA",
    "best_val_amota_1se": "the latest step within one standard error of the best validation AMOTA",
}


@dataclass
class ValidationRecord:
    """``validation.json`` of ``grutrack train``: the validation scenes (a split, or scenes held out of the
    training split: ``held_out``) and detection sets, the AMOTA of the reference tracker (the training's tracker
    preset with its own EKF) on them, the selection rule and the step whose network ``model.pt`` holds with its
    validation AMOTA. Without validation only ``rule`` ("last") and ``selected_step`` are set."""

    rule: str
    selected_step: int
    split: str | None = None
    scenes: list[str] = field(default_factory=list)
    held_out: bool = False  # the scenes are part of the training split, held out of training
    detection_sets: list[str] = field(default_factory=list)  # AMOTA is the mean over these detection sets
    reference: str | None = None
    reference_amota: float | None = None
    selected_amota: float | None = None
    reference_amota_sets: list[float] | None = None  # per detection set, in detection_sets order
    selected_amota_sets: list[float] | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def write(self, path: str | Path) -> None:
        write_json_atomic(path, self.to_dict(), indent=2)

    @classmethod
    def read(cls, path: str | Path) -> ValidationRecord:
        d = read_json(path, "validation record")
        if not isinstance(d, dict) or "rule" not in d or "selected_step" not in d:
            raise InputFormatError(f"{path}: a validation record needs the fields 'rule' and 'selected_step'")
        if d["rule"] not in SELECTION_RULES or not isinstance(d["selected_step"], int):
            raise InputFormatError(
                f"{path}: 'rule' must be one of {', '.join(map(repr, SELECTION_RULES))} and "
                f"'selected_step' an integer, got {d['rule']!r} and {d['selected_step']!r}"
            )
        for key in ("reference_amota", "selected_amota"):
            if not isinstance(d.get(key), (int, float, type(None))) or isinstance(d.get(key), bool):
                raise InputFormatError(f"{path}: '{key}' must be a number or null, got {d.get(key)!r}")
        for key in ("reference_amota_sets", "selected_amota_sets"):
            v = d.get(key)
            if v is not None and not (
                isinstance(v, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
            ):
                raise InputFormatError(f"{path}: '{key}' must be a list of numbers or null, got {v!r}")
        try:
            return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})
        except TypeError as exc:
            raise InputFormatError(f"{path}: not a validation record ({exc})") from exc


# -- evaluator cross-check ---------------------------------------------------------------------------------


@dataclass
class CrossCheckDocument:
    """What ``grutrack cross-check`` writes (``reports/metrics/<experiment>/<detector>/<run>.crosscheck.json``):
    the devkit's ``TrackingEval`` and the fast evaluator on the same submission, restricted to ``scenes`` of the
    split's ``split_scenes`` (all of them, or evenly spaced ones), every one of the summary's ``entries``
    compared; ``equal`` when the largest absolute difference is at most ``tolerance`` (``max_abs_difference``
    null: an entry differs in kind, e.g. NaN against a number; ``worst_entry`` names it). ``amota`` and
    ``seconds`` per evaluator."""

    dataset: str
    version: str | None
    split: str
    submission: str
    scenes: list[str]
    split_scenes: int
    samples: int
    entries: int
    max_abs_difference: float | None
    worst_entry: str
    tolerance: float
    equal: bool
    amota: dict[str, float | None] = field(default_factory=dict)
    seconds: dict[str, float | None] = field(default_factory=dict)

    def __post_init__(self):
        if self.max_abs_difference is not None and not math.isfinite(self.max_abs_difference):
            self.max_abs_difference = None  # JSON has no infinity

    @property
    def subset(self) -> bool:
        """Whether fewer scenes than the split's were compared."""
        return len(self.scenes) < self.split_scenes

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def write(self, path: str | Path) -> None:
        """Write the JSON atomically."""
        write_json_atomic(path, self.to_dict(), indent=2)

    @classmethod
    def read(cls, path: str | Path) -> CrossCheckDocument:
        """Read a cross-check JSON written by :meth:`write`."""
        d = read_json(path, "cross-check JSON")
        need = [
            f.name for f in fields(cls) if f.default is dataclasses_MISSING and f.default_factory is dataclasses_MISSING
        ]
        if not isinstance(d, dict) or any(k not in d for k in need):
            raise InputFormatError(
                f"{path}: not a cross-check JSON of grutrack cross-check (it needs the fields {', '.join(need)})"
            )
        if not isinstance(d["equal"], bool) or not isinstance(d["scenes"], list):
            raise InputFormatError(f"{path}: 'equal' must be true or false and 'scenes' a list")
        return cls(**{f.name: d[f.name] for f in fields(cls) if f.name in d})


# -- GRU-KF checkpoint -------------------------------------------------------------------------------------

#: the format tag every grutrack GRU-KF checkpoint carries (the layout below; checkpoints of every grutrack version
#: so far have it)
CHECKPOINT_FORMAT = "grutrack-grukf/1"

#: the checkpoint fields a run resumes from (``last.pt``, and ``model.pt`` of the trainer); ``best.pt`` and a
#: network saved outside a training have none of them
RESUME_FIELDS = ("train_state", "train_config", "optimizer", "scheduler", "rng", "log")


@dataclass
class TrainingPosition:
    """Where a training run stands: optimizer steps taken, the epoch, the position within the epoch's scene order
    and that order (None: the epoch's order is not drawn yet)."""

    step: int = 0
    epoch: int = 0
    index: int = 0
    order: list[int] | None = None


@dataclass
class TrainingState:
    """What resumes a run exactly: its position, the optimizer's and the learning-rate scheduler's state dicts,
    the states of the run's own generators (``{"numpy": bit-generator state, "torch": ByteTensor}``) and its
    log so far."""

    position: TrainingPosition
    optimizer: dict[str, Any]
    scheduler: dict[str, Any]
    rng: dict[str, Any]
    log: list[TrainingStep]


@dataclass
class CheckpointSelection:
    """Which validated step a checkpoint's network is: ``step`` and its validation ``val_amota`` (the mean over
    the detection sets; the dataset's metric); ``rule``: the ``select_checkpoint`` rule that chose it (model.pt;
    None in best.pt, the candidate the rule holds so far)."""

    step: int
    val_amota: float | None = None
    rule: str | None = None


@dataclass
class Checkpoint:
    """A GRU-KF checkpoint (``model.pt``, ``last.pt``, ``best.pt`` of ``grutrack train``): the network's weights
    (``weights``: tensor name -> tensor) and architecture (``arch``: the ``GRUKFConfig`` fields), the training
    config the run had (``train_config``: the ``TrainConfig`` fields; what ``grutrack track`` reads its
    ``matched_box`` from), the state a run resumes from (``training``), the selected step (``selected``) and
    provenance: the package version that wrote it, a fingerprint of the training data (``data_fingerprint``,
    SHA-256 hex: a resumed run must see the same data) and where that data came from (``data_source``).

    One writer (:meth:`write`) and one reader (:meth:`read`); a torch file of the layout every version so far wrote::

        {"format": "grutrack-grukf/1", "grutrack_version", "arch", "model", ["selected"], ["optimizer",
         "scheduler", "rng", "train_state", "train_config", "log", "data_fingerprint", "data_source"]}

    Fields a version did not write read as None (a checkpoint without its training state loads as a network
    but cannot be resumed: :meth:`require_resumable`)."""

    arch: dict[str, Any]
    weights: dict[str, Any]
    train_config: dict[str, Any] | None = None
    training: TrainingState | None = None
    selected: CheckpointSelection | None = None
    data_fingerprint: str | None = None
    data_source: dict[str, Any] | None = None
    grutrack_version: str = __version__
    #: the resume fields the file lacks (set by :meth:`from_dict`; empty for a document made in memory)
    absent: tuple[str, ...] = field(default=(), repr=False, compare=False)

    @property
    def matched_box(self) -> str:
        """The box a tracker running this network writes for a matched track by default: the training config's
        ``matched_box`` ("filter" or "detection"); "detection" for a checkpoint without one (written before that
        key, or a network saved outside a training)."""
        return (self.train_config or {}).get("matched_box", "detection")

    def require_resumable(self, where: str) -> TrainingState:
        """The training state, or :class:`InputFormatError` naming the first resume field the file lacks."""
        if self.training is None or self.train_config is None:
            missing = next((k for k in RESUME_FIELDS if k in self.absent), "train_state")
            raise InputFormatError(
                f"{where}: not a resumable checkpoint (no '{missing}'; model.pt files of old "
                f"versions cannot be resumed: train again with another --out)"
            )
        return self.training

    def to_dict(self) -> dict[str, Any]:
        """The file's object (fields that are None are left out)."""
        d: dict[str, Any] = {
            "format": CHECKPOINT_FORMAT,
            "grutrack_version": self.grutrack_version,
            "arch": self.arch,
            "model": self.weights,
        }
        if self.selected is not None:
            s = self.selected
            d["selected"] = ({"rule": s.rule} if s.rule is not None else {}) | {
                "step": s.step,
                "val_amota": s.val_amota,
            }
        t = self.training
        if t is not None:
            d.update(optimizer=t.optimizer, scheduler=t.scheduler, rng=t.rng, train_state=asdict(t.position))
        if self.train_config is not None:
            d["train_config"] = self.train_config
        if t is not None:
            d["log"] = [s.to_row() for s in t.log]
        for key in ("data_fingerprint", "data_source"):
            if getattr(self, key) is not None:
                d[key] = getattr(self, key)
        return d

    @classmethod
    def from_dict(cls, d: Any, where: str = "checkpoint") -> Checkpoint:
        """Parse and check the layout (InputFormatError naming ``where`` and the field)."""
        if not isinstance(d, dict) or d.get("format") != CHECKPOINT_FORMAT:
            raise InputFormatError(
                f"{where}: not a grutrack GRU-KF checkpoint (expected format {CHECKPOINT_FORMAT}; "
                f"train one with `grutrack train`)"
            )
        if not isinstance(d.get("arch"), dict):
            raise InputFormatError(f"{where}: field 'arch' must be the network's architecture (a mapping)")
        if not isinstance(d.get("model"), dict):
            raise InputFormatError(f"{where}: field 'model' must hold the network's tensors")
        for key in ("train_config", "data_source", "optimizer", "scheduler", "rng", "train_state", "selected"):
            if d.get(key) is not None and not isinstance(d[key], dict):
                raise InputFormatError(f"{where}: field '{key}' must be a mapping, got {type(d[key]).__name__}")
        if d.get("log") is not None and not isinstance(d["log"], list):
            raise InputFormatError(f"{where}: field 'log' must be a list of training-log rows")
        absent = tuple(k for k in RESUME_FIELDS if d.get(k) is None)
        training = None
        if not (set(absent) - {"train_config"}):
            try:
                position = TrainingPosition(**d["train_state"])
            except TypeError as exc:
                raise InputFormatError(f"{where}: field 'train_state' is not a training position ({exc})") from exc
            training = TrainingState(
                position, d["optimizer"], d["scheduler"], d["rng"], [TrainingStep.from_row(r, where) for r in d["log"]]
            )
        selected = None
        if d.get("selected") is not None:
            s = d["selected"]
            if not isinstance(s.get("step"), int):
                raise InputFormatError(f"{where}: field 'selected.step' must be an integer, got {s.get('step')!r}")
            selected = CheckpointSelection(step=s["step"], val_amota=s.get("val_amota"), rule=s.get("rule"))
        return cls(
            arch=d["arch"],
            weights=d["model"],
            train_config=d.get("train_config"),
            training=training,
            selected=selected,
            data_fingerprint=d.get("data_fingerprint"),
            data_source=d.get("data_source"),
            grutrack_version=str(d.get("grutrack_version", "")),
            absent=absent,
        )

    def write(self, path: str | Path) -> None:
        """Write the checkpoint atomically (torch's file format). Saved through a file object, so the archive's
        inner folder is torch's fixed ``archive`` rather than the temporary file's random name: the same checkpoint
        gives the same bytes (and SHA-256) wherever and whenever it is written."""
        import torch

        from grutrack.io import atomic_path

        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            torch.save(self.to_dict(), f)

    @classmethod
    def read(cls, path: str | Path, map_location: Any = "cpu") -> Checkpoint:
        """Read a checkpoint (tensors onto ``map_location``); a missing, unreadable or foreign file is an
        :class:`InputFormatError` naming it."""
        import torch

        path = Path(path)
        if not path.is_file():
            raise InputFormatError(f"{path}: checkpoint does not exist (train one with `grutrack train`)")
        try:
            d = torch.load(path, map_location=map_location, weights_only=False)
        except Exception as exc:  # torch raises many types for a corrupt file
            raise InputFormatError(f"{path}: not a readable torch checkpoint ({exc})") from exc
        return cls.from_dict(d, where=str(path))
