"""The official nuScenes tracking-submission JSON.

``{"meta": {use_camera, use_lidar, use_radar, use_map, use_external: booleans}, "results": {sample_token:
[box, ...]}}``; the meta is the detection file's (what the detector used), lidar-only by default. Each box has
sample_token, translation [x, y, z], size [w, l, h], rotation [w, x, y, z], velocity [vx, vy] (global frame,
m/s), tracking_id (string), tracking_name (one of the 7 tracking classes) and tracking_score.
Every sample token of the split is present and no sample has more than 500 boxes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from grutrack.boxes import quaternion_from_yaw
from grutrack.classes import TRACKING_CLASSES
from grutrack.data.nusc_detections import LIDAR_META, META_KEYS, SENSOR_KEYS
from grutrack.data.scene import BoxSet
from grutrack.errors import InputFormatError
from grutrack.io import write_json_atomic

MAX_BOXES_PER_SAMPLE = 500
#: the meta of a submission built with no detection meta (the tracker's own evaluations: validation, scripts)
META = dict(LIDAR_META)
BOX_KEYS = (
    "sample_token",
    "translation",
    "size",
    "rotation",
    "velocity",
    "tracking_id",
    "tracking_name",
    "tracking_score",
)


def sample_boxes(token: str, tracks: BoxSet, max_boxes: int = MAX_BOXES_PER_SAMPLE) -> list[dict]:
    """Submission dicts of one sample's tracked boxes (highest scores first, at most ``max_boxes``).

    tracks: boxes (N, 9) global frame, scores (N,), labels (N,), ids (N,) track ids.
    """
    order = np.argsort(-tracks.scores, kind="stable")[:max_boxes]
    b = tracks.boxes[order].copy()
    b[:, 3:6] = np.maximum(b[:, 3:6], 1e-3)  # a filter may shrink a size to ~0; the format needs > 0
    q = quaternion_from_yaw(b[:, 6])
    names = [TRACKING_CLASSES[i] for i in tracks.labels[order]]
    ids = tracks.ids[order]
    return [
        {
            "sample_token": token,
            "translation": b[i, 0:3].tolist(),
            "size": b[i, 3:6].tolist(),
            "rotation": q[i].tolist(),
            "velocity": b[i, 7:9].tolist(),
            "tracking_id": str(ids[i]),
            "tracking_name": names[i],
            "tracking_score": float(tracks.scores[order[i]]),
        }
        for i in range(len(order))
    ]


def build_submission(
    results: dict[str, BoxSet],
    sample_tokens: list[str],
    max_boxes: int = MAX_BOXES_PER_SAMPLE,
    meta: dict[str, bool] | None = None,
) -> dict:
    """The submission dict for the given samples (a sample with no tracks gets an empty list); ``meta``: the
    detection file's (:func:`grutrack.data.nusc_detections.detection_meta`), None: :data:`META`."""
    out = {}
    for token in sample_tokens:
        r = results.get(token)
        out[token] = sample_boxes(token, r, max_boxes) if r is not None and len(r) else []
    return {"meta": dict(META if meta is None else meta), "results": out}


def validate_submission(sub: dict, sample_tokens: list[str], where: str = "submission") -> None:
    """Check a tracking submission against the official format; raises :class:`InputFormatError`."""
    if not isinstance(sub, dict) or set(sub) != {"meta", "results"}:
        raise InputFormatError(f"{where}: expected exactly the keys 'meta' and 'results'")
    meta = sub["meta"]
    if not isinstance(meta, dict) or not all(isinstance(meta.get(k), bool) for k in META_KEYS):
        raise InputFormatError(f"{where}: 'meta' must have boolean {', '.join(META_KEYS)}")
    if not any(meta[k] for k in SENSOR_KEYS):
        raise InputFormatError(f"{where}: 'meta' must declare at least one sensor (use_lidar true for lidar)")
    res = sub["results"]
    missing = [t for t in sample_tokens if t not in res]
    extra = set(res) - set(sample_tokens)
    if missing or extra:
        raise InputFormatError(
            f"{where}: 'results' must hold exactly the {len(sample_tokens)} samples of the "
            f"split ({len(missing)} missing, {len(extra)} not in the split)"
        )
    for token, boxes in res.items():
        if len(boxes) > MAX_BOXES_PER_SAMPLE:
            raise InputFormatError(f"{where}: sample {token} has {len(boxes)} boxes (max {MAX_BOXES_PER_SAMPLE})")
        for i, box in enumerate(boxes):
            _validate_box(where, token, i, box)


_BOX_KEY_SET = frozenset(BOX_KEYS)
_CLASS_SET = frozenset(TRACKING_CLASSES)
_VECTORS = (("translation", 3), ("size", 3), ("rotation", 4), ("velocity", 2))


def _validate_box(where: str, token: str, i: int, box: dict) -> None:
    if box.keys() != _BOX_KEY_SET:
        raise InputFormatError(f"{where}: sample {token} box {i}: keys must be {', '.join(BOX_KEYS)}")
    if box["sample_token"] != token:
        raise InputFormatError(f"{where}: sample {token} box {i}: sample_token is {box['sample_token']}")
    if box["tracking_name"] not in _CLASS_SET:
        raise InputFormatError(
            f"{where}: sample {token} box {i}: tracking_name '{box['tracking_name']}' is not "
            f"one of {', '.join(TRACKING_CLASSES)}"
        )
    if not isinstance(box["tracking_id"], str):
        raise InputFormatError(f"{where}: sample {token} box {i}: tracking_id must be a string")
    for key, n in _VECTORS:
        v = box[key]
        if not _numbers(v, n):
            raise InputFormatError(f"{where}: sample {token} box {i}: '{key}' must be {n} finite numbers, got {v!r}")
    if min(box["size"]) <= 0:
        raise InputFormatError(f"{where}: sample {token} box {i}: 'size' must be positive, got {box['size']}")
    if abs(math.sqrt(sum(q * q for q in box["rotation"])) - 1) > 1e-6:
        raise InputFormatError(f"{where}: sample {token} box {i}: 'rotation' must be a unit quaternion")
    s = box["tracking_score"]
    if not _finite(s) or not 0 <= s <= 1:
        raise InputFormatError(f"{where}: sample {token} box {i}: tracking_score must be a number in [0, 1], got {s!r}")


def _numbers(v, n: int) -> bool:
    """Whether ``v`` is a list of ``n`` finite JSON numbers (not strings, not booleans); plain Python, since
    numpy calls on 2-4 numbers cost more than the check itself (a float, what JSON gives, is tested first)."""
    if type(v) is not list or len(v) != n:
        return False
    for x in v:
        if not (math.isfinite(x) if type(x) is float else _finite(x)):
            return False
    return True


def _finite(x) -> bool:
    """A finite real number (bool excluded)."""
    return isinstance(x, (int, float, np.floating, np.integer)) and not isinstance(x, bool) and math.isfinite(x)


def write_submission(path: str | Path, sub: dict, sample_tokens: list[str]) -> None:
    """Validate ``sub`` and write it to ``path`` atomically."""
    validate_submission(sub, sample_tokens, where=str(path))
    write_json_atomic(path, sub, compact=True)
