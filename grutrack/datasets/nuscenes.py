"""nuScenes (v1.0-trainval, -test, -mini, and the synthetic v1.0-demo in the same format): scenes and ground
truth from the JSON tables, detections in the official detection-submission JSON, the tracking submission
JSON (``tracking_nips_2019``), and evaluation by nuscenes-devkit's TrackingEval (``devkit``) or grutrack's
exact re-implementation of it (``fast``)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from grutrack.data.scene import NUSCENES_VOCABULARY, BoxSet, Scene, Vocabulary
from grutrack.datasets.base import DatasetOptions, Detections, config_entry
from grutrack.documents import MetricsDocument
from grutrack.errors import ConfigError


class NuScenesDataset:
    """The nuScenes dataset at ``options.dataroot`` / ``options.version``."""

    name = "nuscenes"
    submission_suffix = ".json"
    detections_suffix = ".json"
    evaluators = ("devkit", "fast")
    parallel_evaluation = False
    dataroot_folder = "{version}"
    dataroot_hint = (
        "the nuScenes dataroot, i.e. the folder that holds {version}/ (the JSON tables; v1.0-test/ "
        "too for the test split)"
    )
    leaderboard_zip = True
    validates_training = True
    validation_metric = "AMOTA"
    #: workflow config kinds (``datasets: {<name>: {kind: ...}}``) this class reads -> the JSON schema of such an
    #: entry; the demo is nuScenes-format data that the workflow generates (rule demo_data)
    config_kinds = {
        "nuscenes": config_entry(
            "nuscenes",
            dataroot={"type": ["string", "null"], "minLength": 1},
            version={"type": "string", "minLength": 1},
            test_version={"type": ["string", "null"], "minLength": 1},
        ),
        "demo": config_entry(
            "demo",
            dataroot={"type": "string", "minLength": 1},
            version={"type": "string", "minLength": 1},
            scenes={"type": "integer", "minimum": 2},
            frames_per_scene={"type": "integer", "minimum": 2},
            seed={"type": "integer", "minimum": 0, "maximum": 4294967295},  # as --seed (cli/common.py MAX_SEED)
        ),
    }

    @staticmethod
    def config_version(entry: dict, split: str) -> str | None:
        """The version a split of a workflow config entry lives in (nuScenes test: ``test_version``)."""
        if split == "test" and entry.get("test_version"):
            return entry["test_version"]
        return entry["version"]

    @staticmethod
    def config_options(entry: dict) -> list[str]:
        """Command-line options besides ``--dataset/--dataroot/--version/--split`` for a config entry: none."""
        return []

    def __init__(self, options: DatasetOptions):
        if not options.version:
            raise ConfigError("--version is required with --dataset nuscenes (e.g. v1.0-trainval, v1.0-mini)")
        self.options = options
        self._nusc = None
        self._split_samples: dict[str, set[str]] = {}  # split -> its sample tokens (score_tracks of a subset)

    def describe(self) -> str:
        """``<name> <version>``, for messages."""
        return f"{self.name} {self.options.version}"

    @property
    def vocabulary(self) -> Vocabulary:
        return NUSCENES_VOCABULARY

    def is_synthetic(self) -> bool:
        """Whether the tables are the grutrack demo's (SYNTHETIC)."""
        from grutrack.data.demo_defaults import is_demo_tables

        return is_demo_tables(self.tables)

    @property
    def tables(self):
        """The version's tables (read once; without the devkit's NuScenes class)."""
        if self._nusc is None:
            from grutrack.data.nuscenes import open_nuscenes

            self._nusc = open_nuscenes(self.options.dataroot, self.options.version)
        return self._nusc

    def scenes(self, split: str, with_gt: bool = False) -> list[Scene]:
        from grutrack.data.nuscenes import load_scenes

        return load_scenes(self.tables, split, with_gt=with_gt)

    def sample_tokens(self, split: str) -> list[str]:
        """The split's sample tokens, scene by scene in time order."""
        return [f.token for s in self.scenes(split) for f in s.frames]

    def load_detections(
        self, path: str | Path, split: str, scenes: list[Scene], measured_yaw: str = "euler_z"
    ) -> Detections:
        """The official detection-submission JSON: boxes of every sample of ``scenes`` and the file's meta
        (checked; the tracking submission declares it)."""
        from grutrack.data.nusc_detections import load_detection_file

        tokens = [f.token for s in scenes for f in s.frames]
        boxes, meta, synthetic = load_detection_file(path, tokens, measured_yaw)
        return Detections(boxes, meta=meta, synthetic=synthetic)

    def simulate_detections(self, split: str, profile, seed: int, out: str | Path) -> dict[str, int]:
        """SYNTHETIC detections of the split's samples (the 10 detection classes), sampled from its ground truth
        with a detector profile, as an official detection-submission JSON."""
        from grutrack.data.detection_sim import simulate_nuscenes

        sub = simulate_nuscenes(
            self.options.dataroot, self.options.version, split, profile, seed, out, nusc=self.tables
        )
        return {"detections": sum(len(v) for v in sub["results"].values()), "samples": len(sub["results"])}

    def gt_statistics(self, splits: list[str]) -> dict[str, dict]:
        """Over the 7 tracking classes, from every annotation of the 10 detection classes (lidar points)."""
        from grutrack.data.gt_stats import nuscenes_statistics

        return nuscenes_statistics(self.options.dataroot, self.options.version, splits, nusc=self.tables)

    def write_tracks(
        self,
        path: str | Path,
        scenes: list[Scene],
        results: dict[str, BoxSet],
        max_boxes: int,
        meta: dict[str, bool] | None = None,
    ) -> dict[str, int]:
        """The tracking JSON declaring the detections' ``meta`` (None: lidar-only)."""
        from grutrack.export.nuscenes_json import build_submission, write_submission

        tokens = [f.token for s in scenes for f in s.frames]
        sub = build_submission(results, tokens, max_boxes, meta)
        write_submission(path, sub, tokens)
        return {"samples": len(tokens), "boxes": sum(len(v) for v in sub["results"].values()), "scenes": len(scenes)}

    def write_submission(self, tracks: str | Path, split: str, out: str | Path) -> dict[str, int]:
        from grutrack.export.leaderboard import write_validated

        return write_validated(tracks, self.sample_tokens(split), out)

    def check_submission(self, path: str | Path, split: str) -> dict[str, int]:
        """grutrack's field-by-field checks for exactly the split's samples, then the devkit's loader."""
        from grutrack.export.leaderboard import counts, devkit_check, load_valid_submission

        sub = load_valid_submission(path, self.sample_tokens(split))
        devkit_check(path)
        return counts(sub)

    def evaluate(
        self, submission: str | Path, split: str, evaluator: str | None = None, progress: bool | None = None, **_ignored
    ) -> MetricsDocument:
        """``devkit``: nuscenes-devkit TrackingEval (the reference, default); ``fast``: the exact vectorised
        re-implementation (equal to 1e-9). The submission is checked first as ``leaderboard-zip`` checks it."""
        from grutrack.data.nuscenes import split_scene_names
        from grutrack.evaluation.nuscenes_eval import devkit_tracking_eval, metrics_document
        from grutrack.export.leaderboard import load_valid_submission

        evaluator = evaluator or self.evaluators[0]
        if evaluator not in self.evaluators:
            raise ConfigError(f"--evaluator {evaluator}: nuScenes has {' and '.join(self.evaluators)}")
        split_scene_names(self.tables, split)  # clear error for an unknown split before the devkit asserts
        t0 = time.perf_counter()
        sub = load_valid_submission(submission, self.sample_tokens(split))
        if evaluator == "devkit":
            summary = devkit_tracking_eval(
                self.options.dataroot,
                self.options.version,
                split,
                submission,
                progress=sys.stderr.isatty() if progress is None else progress,
            )
        else:
            from grutrack.evaluation.nuscenes_fast import fast_tracking_eval

            summary = fast_tracking_eval(self.tables, sub, split)
        doc = metrics_document(
            summary,
            dataset=self.name,
            version=self.options.version,
            split=split,
            evaluator=evaluator,
            submission=str(submission),
        )
        doc.seconds = round(time.perf_counter() - t0, 3)
        return doc

    def score_tracks(self, split: str, scenes: list[Scene], results: dict[str, BoxSet], max_boxes: int) -> float:
        """AMOTA (official semantics, the exact fast evaluator) of the tracks on ``scenes``: the split's evaluation
        when they are the whole split, else that of their samples alone (the split's other samples given no
        tracks, and only the scenes' ground truth and tracks scored)."""
        import contextlib
        import io

        from grutrack.data.nuscenes import split_scene_names
        from grutrack.evaluation.nuscenes_fast import evaluate_tracks, fast_tracking_eval, load_tracks
        from grutrack.export.nuscenes_json import build_submission

        tokens = [f.token for s in scenes for f in s.frames]
        sub = build_submission(results, tokens, max_boxes)
        with contextlib.redirect_stdout(io.StringIO()):
            if {s.name for s in scenes} == set(split_scene_names(self.tables, split)):
                return float(fast_tracking_eval(self.tables, sub, split)["amota"])
            if split not in self._split_samples:
                names = set(split_scene_names(self.tables, split))
                in_split = {s["token"] for s in self.tables.scene if s["name"] in names}
                self._split_samples[split] = {s["token"] for s in self.tables.sample if s["scene_token"] in in_split}
            sub["results"].update({t: [] for t in self._split_samples[split] - set(tokens)})  # every sample of it
            gt, pred, _ = load_tracks(self.tables, sub, split)
            keep = {sc.token for sc in scenes}
            metrics, _ = evaluate_tracks(
                {k: v for k, v in gt.items() if k in keep}, {k: v for k, v in pred.items() if k in keep}
            )
        return float(metrics.serialize()["amota"])

    def format_summary(self, doc: MetricsDocument) -> str:
        from grutrack.evaluation.nuscenes_eval import format_summary

        return format_summary(doc)
