"""The dataset interface: what every stage needs from a dataset, in the canonical types of
:mod:`grutrack.data.scene` and :mod:`grutrack.documents`.

A dataset gives its splits as :class:`~grutrack.data.scene.Scene` lists (frames in time order, ego poses,
optionally ground truth; labels index the scene's :class:`~grutrack.data.scene.Vocabulary`), reads detection
files into per-frame :class:`~grutrack.data.scene.BoxSet` (global / city frame, metres, radians), writes and
validates its official tracking submission, and evaluates one with its official evaluator into a
:class:`~grutrack.documents.MetricsDocument`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

from grutrack.data.scene import BoxSet, Scene, Vocabulary
from grutrack.documents import MetricsDocument


@dataclass(frozen=True)
class DatasetOptions:
    """Where a dataset is and how it is read. ``version``: nuScenes table version (v1.0-trainval, v1.0-mini,
    v1.0-demo); ``rate_hz``: AV2 frames per second tracked (annotations are at 10 Hz); ``all_categories``: AV2's
    26 competition categories instead of the 7 classes of Table I."""

    dataroot: str | Path
    version: str | None = None
    rate_hz: float = 2.0
    all_categories: bool = False


@dataclass
class Detections:
    """Detections of a split read for tracking: ``boxes[frame token]`` (global frame), what reading them
    found worth telling (``summary``: one line; ``warnings``: lines for stderr) and the file's submission
    ``meta`` (nuScenes: ``{use_camera, use_lidar, use_radar, use_map, use_external: bool}``, which the tracking
    submission declares too; None for a format that has none, AV2's) and, for detections simulated by
    ``grutrack simulate-detections``, how they were made (``synthetic``: generator, profile, seed; None for a
    detector's output)."""

    boxes: dict[str, BoxSet]
    summary: str = ""
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, bool] | None = None
    synthetic: dict | None = None


def config_entry(kind: str, **properties: dict) -> dict:
    """The JSON schema of a workflow-config ``datasets:`` entry of ``kind`` with these properties (each a JSON
    schema), all required, no other key."""
    return {
        "type": "object",
        "additionalProperties": False,
        "required": ["kind", *properties],
        "properties": {"kind": {"const": kind}, **properties},
    }


@runtime_checkable
class Dataset(Protocol):
    """One dataset. ``name`` as on the command line; ``submission_suffix`` / ``detections_suffix``: the file
    types of its submission (``.json``, ``.pkl``) and of the detections it reads and simulates (``.json``,
    ``.feather``); ``evaluators``: its evaluators, the default first; ``parallel_evaluation``: whether its
    evaluation runs worker processes (``--workers``); ``dataroot_folder``: the folder a dataroot must hold
    (a format string of ``version`` and ``split``) and ``dataroot_hint`` what a dataroot is, for error messages;
    ``leaderboard_zip``: whether ``grutrack leaderboard-zip`` packs its submissions; ``validates_training``:
    whether ``grutrack train`` can validate on it (``--val-split``, ``validation_scenes``: :meth:`score_tracks`)
    and ``validation_metric`` the name of that score (AMOTA, HOTA); ``config_kinds``: the
    workflow config kinds it reads (``datasets: {<name>: {kind: <kind>, ...}}``), each with the JSON schema of
    such an entry; ``config_version`` / ``config_options``: the ``--version`` and other command-line options
    of a split of such an entry."""

    name: str
    submission_suffix: str
    detections_suffix: str
    evaluators: tuple[str, ...]
    parallel_evaluation: bool
    dataroot_folder: str
    dataroot_hint: str
    leaderboard_zip: bool
    validates_training: bool
    validation_metric: str
    config_kinds: dict[str, dict]
    options: DatasetOptions

    @staticmethod
    def config_version(entry: dict, split: str) -> str | None: ...

    @staticmethod
    def config_options(entry: dict) -> list[str]: ...

    def describe(self) -> str:
        """What is read, for messages (``nuscenes v1.0-mini``, ``av2 at 2 Hz``)."""
        ...

    @property
    def vocabulary(self) -> Vocabulary:
        """What the labels of its boxes mean (tracked classes and their parameter classes)."""

    def is_synthetic(self) -> bool:
        """Whether its scenes are SYNTHETIC (the grutrack demo dataset), which every number made from them says."""

    def scenes(self, split: str, with_gt: bool = False) -> list[Scene]:
        """The split's scenes in order; ground-truth boxes on each frame when ``with_gt``."""

    def load_detections(
        self, path: str | Path, split: str, scenes: list[Scene], measured_yaw: str = "euler_z"
    ) -> Detections:
        """A detection file of the split, per frame of ``scenes`` (tracked classes only)."""

    def simulate_detections(self, split: str, profile, seed: int, out: str | Path) -> dict[str, int]:
        """SYNTHETIC detections of the split sampled from its ground truth with a detector profile
        (:class:`~grutrack.data.detection_sim.DetectorProfile`), written to ``out`` in the format
        :meth:`load_detections` reads; returns counts."""

    def gt_statistics(self, splits: list[str]) -> dict[str, dict]:
        """Per-class statistics of the ground truth of the union of ``splits``
        (:mod:`grutrack.data.gt_stats`: share, size, speed, moving share, |yaw rate|, 0-point share)."""

    def write_tracks(
        self,
        path: str | Path,
        scenes: list[Scene],
        results: dict[str, BoxSet],
        max_boxes: int,
        meta: dict[str, bool] | None = None,
    ) -> dict[str, int]:
        """The tracker's output written as the official submission (validated, atomically) declaring ``meta``
        (:attr:`Detections.meta` of the detections tracked; a format without one ignores it); returns counts
        (samples/logs, frames, boxes)."""

    def write_submission(self, tracks: str | Path, split: str, out: str | Path) -> dict[str, int]:
        """A tracker output checked against the official format for exactly the split's frames and written to
        ``out`` atomically; returns counts."""

    def check_submission(self, path: str | Path, split: str) -> dict[str, int]:
        """A submission checked against the official format for exactly the split's frames (one-line
        :class:`~grutrack.errors.InputFormatError` otherwise); returns counts as :meth:`write_submission`."""

    def evaluate(self, submission: str | Path, split: str, evaluator: str | None = None, **options) -> MetricsDocument:
        """Official metrics of a submission (``evaluator`` one of :attr:`evaluators`, None: the default)."""

    def score_tracks(self, split: str, scenes: list[Scene], results: dict[str, BoxSet], max_boxes: int) -> float:
        """The dataset's headline metric (:attr:`validation_metric`) of the tracker output ``results`` (frame
        token -> tracks) on ``scenes`` of ``split`` (all of them, or a subset: only their frames are scored), by the
        dataset's evaluator in memory, with nothing written; what validation during training reads."""

    def format_summary(self, doc: MetricsDocument) -> str:
        """A table of the document's headline metrics for the terminal."""
