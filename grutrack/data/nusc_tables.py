"""The nuScenes tables without the devkit's ``NuScenes`` class: the same records, reverse indexes and lookups
(``get``, ``getind``, ``field2token``, ``box_velocity``) for the code that only reads tables.

Importing ``nuscenes`` (any of its modules: the package imports ``NuScenes``, which imports matplotlib, OpenCV
and scikit-learn) costs 2-3 s; tracking and the fast evaluator read tables only. The predefined split lists
are read from the devkit's own ``nuscenes/utils/splits.py`` source (its list literals), not copied, so they
always match the installed devkit (tests/test_nusc_tables.py compares both against the devkit).
"""

from __future__ import annotations

import ast
import functools
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np

#: table bytes above which reading shows a progress bar (on a terminal)
PROGRESS_BYTES = 200 * 2**20
#: the tables ``NuScenes.__init__`` loads, in its order
TABLE_NAMES = (
    "category",
    "attribute",
    "visibility",
    "instance",
    "sensor",
    "calibrated_sensor",
    "ego_pose",
    "log",
    "scene",
    "sample",
    "sample_data",
    "sample_annotation",
    "map",
)


class NuScenesTables:
    """The tables of ``<dataroot>/<version>/`` with the devkit's reverse indexes (``sample['data']``,
    ``sample['anns']``, ``sample_annotation['category_name']``, ``sample_data['channel']`` and
    ``['sensor_modality']``, ``log['map_token']``), record for record as ``nuscenes.NuScenes`` builds them;
    map records lack the devkit's ``mask`` (the map image is never loaded)."""

    def __init__(self, version: str, dataroot: str | Path, progress: bool | None = None):
        """``progress``: a bar on stderr over the table bytes read (None: when the tables exceed
        :data:`PROGRESS_BYTES` and stderr is a terminal; v1.0-trainval reads ~1.3 GB for tens of seconds)."""
        self.version, self.dataroot = version, str(dataroot)
        self.table_names = list(TABLE_NAMES)
        root = Path(dataroot) / version
        sizes = {name: (root / f"{name}.json").stat().st_size for name in TABLE_NAMES}
        if progress is None:
            progress = sum(sizes.values()) > PROGRESS_BYTES and sys.stderr.isatty()
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(
                total=sum(sizes.values()), unit="B", unit_scale=True, desc=f"reading {version} tables", file=sys.stderr
            )
        for name in TABLE_NAMES:
            setattr(self, name, json.loads((root / f"{name}.json").read_text()))
            if bar is not None:
                bar.update(sizes[name])
        if bar is not None:
            bar.close()
        self._token2ind = {name: {rec["token"]: i for i, rec in enumerate(getattr(self, name))} for name in TABLE_NAMES}
        self._reverse_index()

    def _reverse_index(self) -> None:
        """The short-cuts of ``NuScenes.__make_reverse_index__`` (same fields, same order of ``anns``)."""
        for rec in self.sample_annotation:
            inst = self.get("instance", rec["instance_token"])
            rec["category_name"] = self.get("category", inst["category_token"])["name"]
        for rec in self.sample_data:
            sensor = self.get("sensor", self.get("calibrated_sensor", rec["calibrated_sensor_token"])["sensor_token"])
            rec["sensor_modality"], rec["channel"] = sensor["modality"], sensor["channel"]
        for rec in self.sample:
            rec["data"], rec["anns"] = {}, []
        for rec in self.sample_data:
            if rec["is_key_frame"]:
                self.get("sample", rec["sample_token"])["data"][rec["channel"]] = rec["token"]
        for rec in self.sample_annotation:
            self.get("sample", rec["sample_token"])["anns"].append(rec["token"])
        log_to_map = {log: m["token"] for m in self.map for log in m.get("log_tokens", ())}
        for rec in self.log:
            if rec["token"] in log_to_map:
                rec["map_token"] = log_to_map[rec["token"]]

    def get(self, table_name: str, token: str) -> dict:
        """The record of ``table_name`` with ``token`` (KeyError when absent)."""
        return getattr(self, table_name)[self._token2ind[table_name][token]]

    def getind(self, table_name: str, token: str) -> int:
        """Index of the record with ``token`` in ``table_name``."""
        return self._token2ind[table_name][token]

    def field2token(self, table_name: str, field: str, query) -> list[str]:
        """Tokens of the records whose ``field`` equals ``query`` (linear time, as in the devkit)."""
        return [rec["token"] for rec in getattr(self, table_name) if rec[field] == query]

    def box_velocity(self, sample_annotation_token: str, max_time_diff: float = 1.5) -> np.ndarray:
        """(3,) float64 m/s: the devkit's ``NuScenes.box_velocity`` (centred difference of the neighbouring
        annotations of the instance, one-sided at the ends; NaN when alone or the gap exceeds
        ``max_time_diff`` s, doubled for a centred difference)."""
        current = self.get("sample_annotation", sample_annotation_token)
        has_prev, has_next = current["prev"] != "", current["next"] != ""
        if not has_prev and not has_next:
            return np.array([np.nan, np.nan, np.nan])
        first = self.get("sample_annotation", current["prev"]) if has_prev else current
        last = self.get("sample_annotation", current["next"]) if has_next else current
        pos_diff = np.array(last["translation"]) - np.array(first["translation"])
        time_last = 1e-6 * self.get("sample", last["sample_token"])["timestamp"]
        time_first = 1e-6 * self.get("sample", first["sample_token"])["timestamp"]
        time_diff = time_last - time_first
        if has_next and has_prev:
            max_time_diff *= 2
        if time_diff > max_time_diff:
            return np.array([np.nan, np.nan, np.nan])
        return pos_diff / time_diff


@functools.lru_cache(maxsize=1)
def predefined_split_scenes() -> dict[str, list[str]]:
    """The devkit's ``create_splits_scenes()`` (train, val, test, mini_train, mini_val, train_detect,
    train_track -> scene names), read from the list literals of the installed ``nuscenes/utils/splits.py``."""
    spec = importlib.util.find_spec("nuscenes")  # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("nuscenes-devkit is not installed")
    source = Path(next(iter(spec.submodule_search_locations))) / "utils" / "splits.py"
    lists: dict[str, list[str]] = {}
    for node in ast.parse(source.read_text()).body:
        if (
            isinstance(node, ast.Assign)
            and len(node.targets) == 1
            and isinstance(node.targets[0], ast.Name)
            and isinstance(node.value, ast.List)
        ):
            lists[node.targets[0].id] = ast.literal_eval(node.value)
    lists["train"] = sorted(set(lists["train_detect"] + lists["train_track"]))  # splits.py: train = sorted(set(...))
    names = ("train", "val", "test", "mini_train", "mini_val", "train_detect", "train_track")
    if any(n not in lists for n in names) or len(set(lists["train"] + lists["val"] + lists["test"])) != 1000:
        raise ImportError(f"{source}: unexpected layout of the split lists")
    return {n: lists[n] for n in names}
