"""The official nuScenes tracking-submission JSON.

``{"meta": {use_camera, use_lidar, use_radar, use_map, use_external: booleans}, "results": {sample_token:
[box, ...]}}``; the meta is the detection file's (what the detector used), lidar-only by default. Each box has
sample_token, translation [x, y, z], size [w, l, h], rotation [w, x, y, z], velocity [vx, vy] (global frame,
m/s), tracking_id (string), tracking_name (one of the 7 tracking classes) and tracking_score.
Every sample token of the split is present and no sample has more than 500 boxes. The format is described once, by
``grutrack/configs/schemas/formats/nusc_tracking.schema.yaml`` (:mod:`grutrack.formats`); every command that reads
a submission checks it with :func:`validate_submission` (or :func:`check_document` where the split is not known).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grutrack import formats
from grutrack.boxes import quaternion_from_yaw
from grutrack.classes import TRACKING_CLASSES
from grutrack.data.nusc_detections import LIDAR_META, SENSOR_KEYS, results_chunks
from grutrack.data.scene import BoxSet
from grutrack.errors import InputFormatError
from grutrack.io import write_json_atomic

#: the format's description (grutrack/configs/schemas/formats/<FORMAT>.schema.yaml)
FORMAT = "nusc_tracking"
#: boxes per sample the official format allows (the schema's ``maxItems``)
MAX_BOXES_PER_SAMPLE = formats.node(FORMAT, ("results", "*"))["maxItems"]
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
    """Check a tracking submission against the format's description (``nusc_tracking.schema.yaml``: the boxes
    array by array, the schema naming the first failing field) and for exactly the split's samples
    (``sample_tokens``); raises :class:`InputFormatError` naming the file (``where``) and the field."""
    check_document(sub, where)
    res = sub["results"]
    missing = [t for t in sample_tokens if t not in res]
    extra = set(res) - set(sample_tokens)
    if missing or extra:
        raise InputFormatError(
            f"{where}: 'results' must hold exactly the {len(sample_tokens)} samples of the "
            f"split ({len(missing)} missing, {len(extra)} not in the split)"
        )


def check_document(sub, where: str) -> None:
    """The submission's top level, ``meta`` and every sample's boxes against the format's description (whatever
    its samples); raises :class:`InputFormatError` naming the file and the first failing field."""
    formats.require_type(FORMAT, sub, where, ())
    for key in ("meta", "results"):
        formats.require_key(FORMAT, sub, key, where)
    extra = next((k for k in sub if k not in ("meta", "results")), None)
    if extra is not None:
        raise InputFormatError(
            f"{where}: the document has the unknown field {extra!r}; expected exactly the fields 'meta' and 'results'"
        )
    formats.check(FORMAT, sub["meta"], where, at=("meta",))
    if not any(sub["meta"][k] for k in SENSOR_KEYS):
        raise InputFormatError(
            f"{where}: field 'meta' declares no sensor ({', '.join(SENSOR_KEYS)} all false); expected at least one "
            f"true (use_lidar for lidar)"
        )
    formats.require_type(FORMAT, sub["results"], where, ("results",))
    for _ in results_chunks(FORMAT, where, sub["results"], list(sub["results"])):
        pass


def write_submission(path: str | Path, sub: dict, sample_tokens: list[str]) -> None:
    """Validate ``sub`` and write it to ``path`` atomically."""
    validate_submission(sub, sample_tokens, where=str(path))
    write_json_atomic(path, sub, compact=True)
