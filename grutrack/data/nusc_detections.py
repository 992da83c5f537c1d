"""Loader of the official nuScenes detection-submission JSON into canonical per-sample box sets.

Validates what a tracker relies on and says exactly what is wrong: every sample of the split present,
known class names, finite numbers, positive sizes, unit quaternions. The 10 detection classes map to the
7 tracking classes; boxes of the 3 untracked classes (barrier, traffic_cone, construction_vehicle) are dropped.
The file's ``meta`` (the devkit's detection-submission meta: which sensors, map and external data the detector
used) is checked by :func:`detection_meta`; a tracking submission made from the file declares the same meta.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grutrack.boxes import MEASURED_YAW
from grutrack.classes import CLASS_INDEX, DETECTION_CLASSES, DETECTION_TO_TRACKING
from grutrack.data.scene import BoxSet
from grutrack.errors import InputFormatError
from grutrack.io import read_json

QUATERNION_TOLERANCE = 1e-2  # |‖q‖ - 1| allowed; JSON writers round quaternions to a few digits
#: boxes per sample the official detection format allows (the devkit's ``max_boxes_per_sample``); it also bounds
#: the tracker's per-frame work (NMS compares every pair of a frame's boxes)
MAX_BOXES_PER_SAMPLE = 500
#: the booleans of the official submission ``meta`` (detection and tracking alike), in the devkit's order
META_KEYS = ("use_camera", "use_lidar", "use_radar", "use_map", "use_external")
#: the keys of :data:`META_KEYS` that are sensors; a submission declares at least one
SENSOR_KEYS = ("use_camera", "use_lidar", "use_radar")
#: the meta of lidar-only detections with no map and no external data (what simulated detections declare)
LIDAR_META = {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False}


def read_detection_json(path: str | Path) -> dict:
    """Parse a detection JSON and check its top level (``meta``, ``results``)."""
    path = Path(path)
    data = read_json(path, "detection file")
    if not isinstance(data, dict) or not isinstance(data.get("results"), dict):
        raise InputFormatError(
            f"{path}: expected a JSON object with a 'results' object "
            f"{{sample_token: [box, ...]}} (official nuScenes detection format)"
        )
    return data


def detection_meta(data: dict, path: str | Path) -> dict[str, bool]:
    """The ``meta`` of a parsed detection file (:func:`read_detection_json`) as ``{key: bool}`` over
    :data:`META_KEYS` (other keys are dropped): each key present and a JSON boolean, at least one sensor true.
    Raises :class:`InputFormatError` naming the file and the field (``meta.use_camera``)."""
    meta = data.get("meta")
    if not isinstance(meta, dict):
        got = "nothing" if meta is None else type(meta).__name__
        raise InputFormatError(
            f"{path}: field 'meta' must be an object with the booleans {', '.join(META_KEYS)} "
            f"(the official detection-submission meta: what the detector used), got {got}"
        )
    for key in META_KEYS:
        if key not in meta:
            raise InputFormatError(
                f"{path}: field 'meta.{key}' is missing; expected true or false (the official "
                f"detection-submission meta has {', '.join(META_KEYS)})"
            )
        if not isinstance(meta[key], bool):
            raise InputFormatError(f"{path}: field 'meta.{key}' must be true or false, got {meta[key]!r}")
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
    synthetic = data.get("synthetic")
    return (
        results_boxes(path, data["results"], sample_tokens, measured_yaw),
        detection_meta(data, path),
        synthetic if isinstance(synthetic, dict) else None,
    )


def load_detections(path: str | Path, sample_tokens: list[str], measured_yaw: str = "euler_z") -> dict[str, BoxSet]:
    """Detections of the given samples as canonical box sets (tracking classes only); the ``meta`` is not read
    (:func:`load_detection_file` checks it too).

    ``measured_yaw``: how a box's quaternion becomes its yaw, a key of :data:`grutrack.boxes.MEASURED_YAW`
    (``euler_z``: the Euler yaw; ``rotation_angle``: the whole rotation angle, as Poly-MOT).

    Every token in ``sample_tokens`` must be a key of ``results`` (an empty list is fine); extra samples
    in the file are ignored. Raises :class:`InputFormatError` naming the file, sample, box and field.
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
    return {token: _sample_boxes(path, token, results[token], yaw_of) for token in sample_tokens}


def _sample_boxes(path: Path, token: str, boxes: list, yaw_of) -> BoxSet:
    """Validate and convert the box dicts of one sample."""
    if not isinstance(boxes, list):
        raise InputFormatError(f"{path}: results['{token}'] must be a list of boxes, got {type(boxes).__name__}")
    if not boxes:
        return BoxSet.empty()
    if len(boxes) > MAX_BOXES_PER_SAMPLE:
        raise InputFormatError(
            f"{path}: sample {token} has {len(boxes)} boxes; the detection format allows at "
            f"most {MAX_BOXES_PER_SAMPLE} per sample (keep the highest-scoring ones)"
        )
    try:
        names = [b["detection_name"] for b in boxes]
        other = next((i for i, b in enumerate(boxes) if b.get("sample_token", token) != token), None)
        raw = np.array(
            [[*b["translation"], *b["size"], *b["rotation"], *b["velocity"][:2], b["detection_score"]] for b in boxes]
        )
    except KeyError as exc:
        raise InputFormatError(
            f"{path}: a box of sample {token} has no field {exc} (needs translation, size, "
            f"rotation, velocity, detection_name, detection_score)"
        ) from exc
    except (TypeError, ValueError, AttributeError) as exc:
        raise InputFormatError(
            f"{path}: a box of sample {token} has a malformed numeric field: translation "
            f"[x,y,z], size [w,l,h], rotation [w,x,y,z], velocity [vx,vy] and "
            f"detection_score must be numbers ({exc})"
        ) from exc
    if other is not None:
        raise InputFormatError(
            f"{path}: results['{token}'] box {other}: field 'sample_token' is "
            f"{boxes[other]['sample_token']!r}, expected the sample it is listed under"
        )
    if raw.ndim != 2 or raw.dtype.kind not in "fiu":
        raise InputFormatError(_not_numbers(path, token, boxes))
    arr = raw.astype(np.float64)
    if arr.shape[1] != 13:
        raise InputFormatError(
            f"{path}: boxes of sample {token} have wrong field lengths (expected translation 3, "
            f"size 3, rotation 4, velocity 2)"
        )
    _check_values(path, token, names, arr)
    keep = np.array([DETECTION_TO_TRACKING[n] is not None for n in names], dtype=bool)
    labels = np.array([CLASS_INDEX[DETECTION_TO_TRACKING[n]] for n, k in zip(names, keep) if k], dtype=np.int64)
    arr = arr[keep]
    yaw = yaw_of(arr[:, 6:10])
    out = np.column_stack([arr[:, 0:6], yaw, arr[:, 10:12]])
    # the file's unit quaternion [w, x, y, z], pitch and roll included (Fast-Poly's footprints use the whole rotation)
    return BoxSet(out, arr[:, 12], labels, extra={"quaternion": arr[:, 6:10]})


def _not_numbers(path: Path, token: str, boxes: list) -> str:
    """The message for a sample whose numeric fields are not all JSON numbers (strings, null, nested lists)."""
    for i, b in enumerate(boxes):
        for key in ("translation", "size", "rotation", "velocity", "detection_score"):
            vals = b[key] if isinstance(b[key], list) else [b[key]]
            bad = next((v for v in vals if not isinstance(v, (int, float)) or isinstance(v, bool)), None)
            if bad is not None or (key == "velocity" and len(vals) < 2):
                return (
                    f"{path}: sample {token}, box {i}: field '{key}' must hold JSON numbers, got {b[key]!r}"
                    f"{' (a number written as a string)' if isinstance(bad, str) else ''}"
                )
    return (
        f"{path}: boxes of sample {token} have wrong field lengths (expected translation 3, size 3, "
        f"rotation 4, velocity 2)"
    )


def _check_values(path: Path, token: str, names: list[str], arr: np.ndarray) -> None:
    """Raise on unknown class names, non-finite numbers, non-positive sizes and non-unit quaternions."""
    unknown = sorted({n for n in names if n not in DETECTION_TO_TRACKING})
    if unknown:
        raise InputFormatError(
            f"{path}: sample {token} has unknown detection_name {unknown}; expected one of "
            f"{', '.join(DETECTION_CLASSES)}"
        )
    fields = ["translation"] * 3 + ["size"] * 3 + ["rotation"] * 4 + ["velocity"] * 2 + ["detection_score"]
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputFormatError(
            f"{path}: sample {token}, box {i}: field '{fields[j]}' is not a finite number "
            f"({arr[i, j]}); NaN/inf are not allowed"
        )
    if (arr[:, 3:6] <= 0).any():
        i = int(np.argwhere((arr[:, 3:6] <= 0).any(axis=1))[0, 0])
        raise InputFormatError(
            f"{path}: sample {token}, box {i}: field 'size' must be positive [w, l, h] in "
            f"metres, got {arr[i, 3:6].tolist()}"
        )
    norm = np.linalg.norm(arr[:, 6:10], axis=1)
    if (np.abs(norm - 1.0) > QUATERNION_TOLERANCE).any():
        i = int(np.argmax(np.abs(norm - 1.0)))
        raise InputFormatError(
            f"{path}: sample {token}, box {i}: field 'rotation' must be a unit quaternion "
            f"[w, x, y, z], has norm {norm[i]:.4f}"
        )
    if ((arr[:, 12] < 0) | (arr[:, 12] > 1)).any():
        i = int(np.argwhere((arr[:, 12] < 0) | (arr[:, 12] > 1))[0, 0])
        raise InputFormatError(
            f"{path}: sample {token}, box {i}: field 'detection_score' must be in [0, 1], got {arr[i, 12]}"
        )
