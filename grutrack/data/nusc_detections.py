"""Loader of the official nuScenes detection-submission JSON into canonical per-sample box sets.

The format is described once, by ``grutrack/configs/schemas/formats/nusc_detections.schema.yaml``
(:mod:`grutrack.formats`): a file is checked against it before use (the boxes array by array, the schema naming
the first failing field: ``d.json: field 'results['3e87…'][2].size' must be a list of 3 positive finite numbers
…``), then for what a schema cannot state: every sample of the split present, each box listed under its own
sample. The 10 detection classes map to the
7 tracking classes; boxes of the 3 untracked classes (barrier, traffic_cone, construction_vehicle) are dropped.
The file's ``meta`` (the devkit's detection-submission meta: which sensors, map and external data the detector
used) is checked by :func:`detection_meta`; a tracking submission made from the file declares the same meta.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from grutrack import formats
from grutrack.boxes import MEASURED_YAW
from grutrack.classes import CLASS_INDEX, DETECTION_TO_TRACKING
from grutrack.data.scene import BoxSet
from grutrack.errors import InputFormatError
from grutrack.io import read_json

#: the format's description (grutrack/configs/schemas/formats/<FORMAT>.schema.yaml)
FORMAT = "nusc_detections"
_BOX = formats.node(FORMAT, ("results", "*", 0))
#: |‖q‖ - 1| allowed (the schema's ``unitNorm``); JSON writers round quaternions to a few digits
QUATERNION_TOLERANCE = _BOX["properties"]["rotation"]["unitNorm"]
#: boxes per sample the official detection format allows (the devkit's ``max_boxes_per_sample``, the schema's
#: ``maxItems``); it also bounds the tracker's per-frame work (NMS compares every pair of a frame's boxes)
MAX_BOXES_PER_SAMPLE = formats.node(FORMAT, ("results", "*"))["maxItems"]
#: the booleans of the official submission ``meta`` (detection and tracking alike), in the devkit's order
META_KEYS = ("use_camera", "use_lidar", "use_radar", "use_map", "use_external")
#: the keys of :data:`META_KEYS` that are sensors; a submission declares at least one
SENSOR_KEYS = ("use_camera", "use_lidar", "use_radar")
#: the meta of lidar-only detections with no map and no external data (what simulated detections declare)
LIDAR_META = {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False}


def read_detection_json(path: str | Path) -> dict:
    """Parse a detection JSON and check its top level (an object whose ``results`` is an object)."""
    path = Path(path)
    data = read_json(path, "detection file")
    formats.require_type(FORMAT, data, path, ())
    formats.require_key(FORMAT, data, "results", path)
    formats.require_type(FORMAT, data["results"], path, ("results",))
    return data


def detection_meta(data: dict, path: str | Path) -> dict[str, bool]:
    """The ``meta`` of a parsed detection file (:func:`read_detection_json`) as ``{key: bool}`` over
    :data:`META_KEYS` (other keys are dropped): each key present and a JSON boolean, at least one sensor true.
    Raises :class:`InputFormatError` naming the file and the field (``meta.use_camera``)."""
    formats.require_key(FORMAT, data, "meta", path)
    meta = data["meta"]
    formats.check(FORMAT, meta, path, at=("meta",))
    if not any(meta[k] for k in SENSOR_KEYS):
        raise InputFormatError(
            f"{path}: field 'meta' declares no sensor ({', '.join(SENSOR_KEYS)} all false); expected at least one true"
        )
    return {k: meta[k] for k in META_KEYS}


def load_detection_file(
    path: str | Path, sample_tokens: list[str], measured_yaw: str = "euler_z"
) -> tuple[dict[str, BoxSet], dict[str, bool], dict | None]:
    """:func:`load_detections`, the file's checked meta (:func:`detection_meta`) and its ``synthetic`` entry
    (what ``grutrack simulate-detections`` writes: generator, profile, seed; None for a detector's file), the file
    parsed once: ``(boxes by sample token, meta, synthetic)``; what tracking and training read, since the
    tracking submission declares the same meta and reports flag numbers made from simulated detections."""
    path = Path(path)
    data = read_detection_json(path)
    boxes = results_boxes(path, data["results"], sample_tokens, measured_yaw)
    synthetic = data.get("synthetic")
    return boxes, detection_meta(data, path), synthetic if isinstance(synthetic, dict) else None


def load_detections(path: str | Path, sample_tokens: list[str], measured_yaw: str = "euler_z") -> dict[str, BoxSet]:
    """Detections of the given samples as canonical box sets (tracking classes only); the ``meta`` is not read
    (:func:`load_detection_file` checks it too).

    ``measured_yaw``: how a box's quaternion becomes its yaw, a key of :data:`grutrack.boxes.MEASURED_YAW`
    (``euler_z``: the Euler yaw; ``rotation_angle``: the whole rotation angle, as Poly-MOT).

    Every token in ``sample_tokens`` must be a key of ``results`` (an empty list is fine); extra samples
    in the file are ignored. Raises :class:`InputFormatError` naming the file and the field path.
    """
    path = Path(path)
    return results_boxes(path, read_detection_json(path)["results"], sample_tokens, measured_yaw)


def results_boxes(
    path: Path, results: dict, sample_tokens: list[str], measured_yaw: str = "euler_z"
) -> dict[str, BoxSet]:
    """The ``results`` object of the detection file ``path`` (for messages) as box sets of ``sample_tokens``,
    validated as :func:`load_detections` says."""
    missing = [t for t in sample_tokens if t not in results]
    if missing:
        raise InputFormatError(
            f"{path}: {len(missing)} of {len(sample_tokens)} sample tokens of the split are missing from "
            f"'results' (first: {missing[:3]}); every sample must be present, with [] when it has no boxes"
        )
    yaw_of = MEASURED_YAW[measured_yaw]
    out = {}
    for tokens, counts, cols in results_chunks(FORMAT, path, results, sample_tokens):
        names = cols["detection_name"]
        keep = np.array([DETECTION_TO_TRACKING[n] is not None for n in names], dtype=bool)
        labels = np.array([CLASS_INDEX[DETECTION_TO_TRACKING[n]] for n, k in zip(names, keep) if k], dtype=np.int64)
        quaternion = cols["rotation"][keep]
        boxes = np.column_stack(
            [cols["translation"][keep], cols["size"][keep], yaw_of(quaternion), cols["velocity"][keep]]
        )
        scores = cols["detection_score"][keep]
        # each sample's slice of the kept boxes; the file's unit quaternion [w, x, y, z], pitch and roll included, is
        # kept beside the box (Fast-Poly's footprints use the whole rotation)
        kept_before = np.r_[0, np.cumsum(keep)]
        offsets = np.r_[0, np.cumsum(counts)]
        for token, a, b in zip(tokens, kept_before[offsets[:-1]].tolist(), kept_before[offsets[1:]].tolist()):
            if a == b:
                out[token] = BoxSet.empty()
            else:
                out[token] = BoxSet(boxes[a:b], scores[a:b], labels[a:b], extra={"quaternion": quaternion[a:b]})
    return out


def results_chunks(name: str, path, results: dict, tokens: list[str]) -> Iterator[tuple[list[str], list[int], dict]]:
    """The boxes of the samples ``tokens`` of a ``results`` object (format ``name``: ``nusc_detections`` or
    ``nusc_tracking``, both list boxes per sample), checked against the format's description and for every box
    listed under its own sample, in chunks of samples: ``(their tokens, their box counts, arrays of their boxes one
    after the other)`` (:meth:`grutrack.formats.RecordPlan.iter_arrays`). Raises :class:`InputFormatError` naming
    the first failing field (``results['3e87…'][2].size``)."""
    plan = formats.record_plan(name, ("results", "*"))
    lists = [results[t] for t in tokens]
    for i, j, cols in plan.iter_arrays(lists, "sample_token", tokens):
        if cols is None:
            _name_the_failure(name, path, plan, tokens[i:j], lists[i:j])
        yield tokens[i:j], [len(b) for b in lists[i:j]], cols


def _name_the_failure(name: str, path, plan, tokens: list[str], lists: list) -> None:
    """Raise the error of the first sample of a chunk that does not fit (the schema names its field)."""
    for token, boxes in zip(tokens, lists):
        if plan.arrays(boxes) is None:
            formats.check(name, boxes, path, at=("results", token))
            raise AssertionError(f"{path}: results[{token!r}]: the array check and the schema of {name} disagree")
        other = next((i for i, b in enumerate(boxes) if b["sample_token"] != token), None)
        if other is not None:
            raise InputFormatError(
                f"{path}: field '{formats.field_path(name, ('results', token, other, 'sample_token'))}' is "
                f"{boxes[other]['sample_token']!r}, expected the sample it is listed under ({token!r})"
            )
    raise AssertionError(f"{path}: the array check of {name} fails on a chunk and on none of its samples")
