"""Argoverse 2 (sensor dataset layout, ``<root>/<split>/<log_id>/``): logs as scenes at ``rate_hz``, boxes in the
city frame, LT3D detections (ego frame, .feather/.csv/pickled DataFrame), the tracking-challenge pickle as the
submission (with the same tracks as a feather table beside it), and the official AV2 tracking evaluation (HOTA,
TrackEval)."""

from __future__ import annotations

from pathlib import Path

from grutrack.data.scene import BoxSet, Scene, Vocabulary
from grutrack.datasets.base import DatasetOptions, Detections, config_entry
from grutrack.documents import MetricsDocument
from grutrack.errors import ConfigError


class AV2Dataset:
    """The AV2 sensor data at ``options.dataroot``, tracked at ``options.rate_hz``."""

    name = "av2"
    submission_suffix = ".pkl"
    detections_suffix = ".feather"
    evaluators = ("official",)
    parallel_evaluation = True
    dataroot_folder = "{split}"
    dataroot_hint = (
        "the Argoverse 2 sensor-dataset root, i.e. the folder that holds {split}/<log_id>/ with "
        "annotations.feather, city_SE3_egovehicle.feather and map/"
    )
    leaderboard_zip = False
    validates_training = True
    validation_metric = "HOTA"
    #: workflow config kinds this class reads -> the JSON schema of such a ``datasets:`` entry
    config_kinds = {
        "av2": config_entry(
            "av2",
            dataroot={"type": ["string", "null"], "minLength": 1},
            version={"type": "null"},
            rate_hz={
                "type": "number",
                "exclusiveMinimum": 0,
                "description": "the rate the logs are tracked at, Hz (the lidar sweeps at 10)",
            },
        )
    }

    @staticmethod
    def config_version(entry: dict, split: str) -> None:
        """AV2 has no versions."""
        return None

    @staticmethod
    def config_options(entry: dict) -> list[str]:
        """``--rate`` from the entry's ``rate_hz``."""
        return ["--rate", str(entry["rate_hz"])]

    def __init__(self, options: DatasetOptions):
        self.options = options
        self._labels: dict[str, dict] = {}  # split -> the evaluation's labels (score_tracks)

    def describe(self) -> str:
        """``av2 at <rate> Hz``, for messages."""
        return f"{self.name} at {self.options.rate_hz:g} Hz"

    @property
    def vocabulary(self) -> Vocabulary:
        from grutrack.data.av2 import vocabulary

        return vocabulary(self.options.all_categories)

    def is_synthetic(self) -> bool:
        """AV2 logs are real data."""
        return False

    def scenes(self, split: str, with_gt: bool = False) -> list[Scene]:
        from grutrack.data.av2 import load_scenes

        return load_scenes(
            self.options.dataroot,
            split,
            rate_hz=self.options.rate_hz,
            with_gt=with_gt,
            all_categories=self.options.all_categories,
        )

    def load_detections(
        self, path: str | Path, split: str, scenes: list[Scene], measured_yaw: str = "euler_z"
    ) -> Detections:
        """LT3D rows at the tracked frames, moved to the city frame; rows of other categories or of sweeps
        that are not tracked frames are counted and dropped (``measured_yaw`` does not apply: LT3D rows carry
        a yaw-only quaternion)."""
        from grutrack.data.lt3d_detections import load_detections

        boxes, stats = load_detections(path, self.options.dataroot, split, scenes, self.vocabulary)
        warnings = []
        if stats.empty_logs:
            warnings.append(
                f"{path}: {len(stats.empty_logs)} of {len(scenes)} logs have no detection of a "
                f"tracked category (first: {stats.empty_logs[0]}); their tracks are empty (is this "
                f"the detection file of split '{split}'?)"
            )
        summary = (
            f"detections: {stats.rows} rows, {stats.kept} tracked, {stats.other_category} of untracked "
            f"categories, {stats.off_frame} at sweeps that are not tracked frames (dropped)"
        )
        return Detections(boxes, summary, warnings)

    def simulate_detections(self, split: str, profile, seed: int, out: str | Path) -> dict[str, int]:
        """SYNTHETIC LT3D detections of the split's frames at ``rate_hz``, sampled from its ground truth with a
        detector profile (each Table I class simulated as its :data:`~grutrack.data.av2.SIMULATOR_CLASS`),
        written as a feather table in each sweep's ego frame."""
        from grutrack.data.av2 import SIMULATOR_CLASS
        from grutrack.data.detection_sim import simulate_scenes
        from grutrack.data.lt3d_detections import detection_table, write_detection_table

        if self.options.all_categories:
            raise ConfigError(
                "--all-categories: simulated AV2 detections cover the 7 classes of Table I (the "
                "detector profiles describe 10 nuScenes classes); drop --all-categories"
            )
        scenes = self.scenes(split, with_gt=True)
        sim_class = tuple(SIMULATOR_CLASS[n] for n in self.vocabulary.names)
        boxes = simulate_scenes(scenes, sim_class, profile, seed)
        table = detection_table(scenes, boxes)
        write_detection_table(out, table)
        return {"detections": len(table), "frames": sum(len(s) for s in scenes), "logs": len(scenes)}

    def gt_statistics(self, splits: list[str]) -> dict[str, dict]:
        """Over the vocabulary's classes, from the annotations at the tracked frames (``rate_hz``)."""
        from grutrack.data.gt_stats import scene_statistics

        return scene_statistics([s for split in splits for s in self.scenes(split, with_gt=True)])

    def write_tracks(
        self,
        path: str | Path,
        scenes: list[Scene],
        results: dict[str, BoxSet],
        max_boxes: int,
        meta: dict[str, bool] | None = None,
    ) -> dict[str, int]:
        """The challenge pickle at ``path`` and a feather table of the same tracks beside it (``.feather``);
        the pickle has no meta (``meta`` is None for LT3D detections and ignored)."""
        from grutrack.export.av2_tracks import write_tracks

        seqs = write_tracks(path, Path(path).with_suffix(".feather"), scenes, results, self.vocabulary)
        return {
            "logs": len(scenes),
            "frames": sum(len(s) for s in scenes),
            "boxes": sum(len(f["track_id"]) for fs in seqs.values() for f in fs),
        }

    def write_submission(self, tracks: str | Path, split: str, out: str | Path) -> dict[str, int]:
        """The pickle checked against the official layout for exactly the split's frames at ``rate_hz`` (as the
        evaluation checks it), then copied to ``out`` atomically."""
        from grutrack.export.av2_tracks import expected_frames, read_valid_tracks, write_tracks_pickle

        expected = expected_frames(self.scenes(split))
        seqs = read_valid_tracks(tracks, expected)  # an error names the tracks file, not the output
        write_tracks_pickle(out, seqs, expected)
        return {
            "logs": len(seqs),
            "frames": sum(len(v) for v in seqs.values()),
            "boxes": sum(len(f["track_id"]) for v in seqs.values() for f in v),
        }

    def check_submission(self, path: str | Path, split: str) -> dict[str, int]:
        """The official layout, for exactly the split's frames at ``rate_hz``."""
        from grutrack.export.av2_tracks import expected_frames, read_tracks_pickle, validate_sequences

        seqs = read_tracks_pickle(path)
        validate_sequences(seqs, expected_frames(self.scenes(split)), where=str(path))
        return {
            "logs": len(seqs),
            "frames": sum(len(v) for v in seqs.values()),
            "boxes": sum(len(f["track_id"]) for v in seqs.values() for f in v),
        }

    def evaluate(
        self,
        submission: str | Path,
        split: str,
        evaluator: str | None = None,
        max_range_m: int | None = None,
        workers: int | None = None,
        trackeval_dir: str | Path | None = None,
        **_ignored,
    ) -> MetricsDocument:
        """The official AV2 tracking evaluation (HOTA, drivable-area ROI when the maps are there)."""
        from grutrack.evaluation import av2_eval

        if evaluator not in (None, *self.evaluators):
            raise ConfigError(f"--evaluator {evaluator} is for nuScenes; AV2 has the official evaluator only")
        if workers is not None and workers < 1:
            raise ConfigError("--workers must be at least 1")
        return av2_eval.evaluate_submission(
            self.options.dataroot,
            split,
            submission,
            rate_hz=self.options.rate_hz,
            max_range_m=max_range_m or av2_eval.DEFAULT_RANGE_M,
            workers=workers,
            trackeval_dir=trackeval_dir,
        )

    def score_tracks(self, split: str, scenes: list[Scene], results: dict[str, BoxSet], max_boxes: int) -> float:
        """HOTA, the Table I average over the classes with ground truth (NaN when none has), of the tracks on the
        logs ``scenes`` by the official AV2 evaluation in this process (the labels of those logs alone; the
        drivable-area ROI when every log has its map); ``max_boxes`` does not apply (the pickle has no limit)."""
        from grutrack.data.av2 import load_scenes, split_dir, vocabulary
        from grutrack.evaluation import av2_eval
        from grutrack.export.av2_tracks import build_sequences, gt_sequences

        if split not in self._labels:
            every = load_scenes(
                self.options.dataroot, split, rate_hz=self.options.rate_hz, with_gt=True, all_categories=True
            )
            self._labels[split] = gt_sequences(every, vocabulary(all_categories=True))
        names = {s.name for s in scenes}
        labels = {log: frames for log, frames in self._labels[split].items() if log in names}
        ddir = split_dir(self.options.dataroot, split)
        out = av2_eval.evaluate_sequences(
            build_sequences(scenes, results, self.vocabulary),
            labels,
            ddir if av2_eval.has_maps(ddir, list(labels)) else None,
            workers=1,
        )
        hota = av2_eval.metrics_from_result(out)[0]["hota"]
        return float("nan") if hota is None else float(hota)

    def format_summary(self, doc: MetricsDocument) -> str:
        from grutrack.evaluation.av2_eval import format_summary

        return format_summary(doc)
