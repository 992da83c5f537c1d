"""Argoverse 2 tracking output: the official tracking-challenge pickle and the same tracks as a feather table.

Pickle (what ``av2.evaluation.tracking.eval.evaluate`` and the leaderboard read): ``{log_id: [frame, ...]}``,
the frames of a log exactly those of the labels at the evaluated rate, in time order. Each frame is a dict:

=====================  ====================  =====================================================================
key                    type                  meaning
=====================  ====================  =====================================================================
``seq_id``             str                   the log id
``timestamp_ns``       int                   sweep time, nanoseconds
``track_id``           (N,) int64            track identity (GT: (N,) object, the track_uuid strings)
``translation_m``      (N, 3) float64        box centre, CITY frame, metres
``size``               (N, 3) float64        [length, width, height], metres
``yaw``                (N,) float64          heading about city +z, radians
``velocity_m_per_s``   (N, 3) float64        [vx, vy, 0], city frame
``label``              (N,) int64            index into the 26 competition categories
``name``               (N,) object (str)     AV2 category
``score``              (N,) float64          track confidence (tracks only)
``ego_translation_m``  list of 3 float       ego position, city frame (a list: the evaluator's array indexing
                                             must not touch it)
=====================  ====================  =====================================================================

Logs are ordered by their first timestamp (then log id): the evaluator pairs prediction and label frames by
position after regrouping the labels in that order, so this order makes the pairing right by construction.

Feather table (one per split): one row per box with ``log_id, timestamp_ns, track_uuid, category, tx_m, ty_m,
tz_m, length_m, width_m, height_m, qw, qx, qy, qz, vx_m_per_s, vy_m_per_s, score`` (city frame).
Both files are written atomically after validation. The pickle's layout is described once, by
``grutrack/configs/schemas/formats/av2_tracks.schema.yaml`` (:mod:`grutrack.formats`), and checked by
:func:`validate_sequences` wherever a pickle is read or written.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pandas as pd

from grutrack import formats
from grutrack.boxes import quaternion_from_yaw, yaw_from_quaternion
from grutrack.data.av2 import COMPETITION_CATEGORIES, token_timestamp_ns
from grutrack.data.scene import BoxSet, Scene, Vocabulary
from grutrack.errors import InputFormatError
from grutrack.io import atomic_path

#: the format's description (grutrack/configs/schemas/formats/<FORMAT>.schema.yaml)
FORMAT = "av2_tracks"
ARRAY_KEYS = ("track_id", "translation_m", "size", "yaw", "velocity_m_per_s", "label", "name")
TABLE_COLUMNS = (
    "log_id",
    "timestamp_ns",
    "track_uuid",
    "category",
    "tx_m",
    "ty_m",
    "tz_m",
    "length_m",
    "width_m",
    "height_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "vx_m_per_s",
    "vy_m_per_s",
    "score",
)
_CATEGORY_INDEX = {c: i for i, c in enumerate(COMPETITION_CATEGORIES)}


def frame_dict(
    log_id: str,
    timestamp_ns: int,
    ego_translation: np.ndarray,
    boxes: BoxSet | None,
    vocab: Vocabulary,
    with_score: bool = True,
) -> dict:
    """One frame of the official format from canonical boxes (city frame; labels index ``vocab``).

    ``boxes.ids`` become ``track_id`` (int64 when integer, else object); None or empty gives (0, ...) arrays.
    """
    b = boxes if boxes is not None and len(boxes) else BoxSet.empty()
    names = np.asarray(vocab.names, dtype=object)[b.labels]
    label = np.array([_CATEGORY_INDEX[n] for n in vocab.names], dtype=np.int64)[b.labels]
    if len(b) == 0 or b.ids is None:
        ids = np.zeros(len(b), dtype=np.int64 if with_score else object)
    elif np.issubdtype(np.asarray(b.ids).dtype, np.integer):
        ids = np.asarray(b.ids, dtype=np.int64)
    else:
        ids = np.asarray(b.ids, dtype=object)
    out = {
        "seq_id": log_id,
        "timestamp_ns": int(timestamp_ns),
        "track_id": ids,
        "translation_m": b.boxes[:, 0:3].copy(),
        "size": b.boxes[:, [4, 3, 5]].copy(),
        "yaw": b.boxes[:, 6].copy(),
        "velocity_m_per_s": np.column_stack([b.boxes[:, 7:9], np.zeros(len(b))]),
        "label": label,
        "name": names,
        "ego_translation_m": [float(v) for v in np.asarray(ego_translation, dtype=np.float64)[:3]],
    }
    if with_score:
        out["score"] = b.scores.astype(np.float64).copy()
    return out


def _log_order(scenes: list[Scene]) -> list[Scene]:
    """Scenes sorted by (first timestamp, log id), the order the evaluator regroups labels in."""
    return sorted(scenes, key=lambda s: (token_timestamp_ns(s.frames[0].token) if s.frames else 0, s.name))


def build_sequences(scenes: list[Scene], results: dict[str, BoxSet], vocab: Vocabulary) -> dict[str, list[dict]]:
    """The tracking pickle object: every frame of every scene, tracks from ``results`` (token -> BoxSet)."""
    return {
        s.name: [
            frame_dict(s.name, token_timestamp_ns(f.token), f.ego_translation, results.get(f.token), vocab)
            for f in s.frames
        ]
        for s in _log_order(scenes)
    }


def gt_sequences(scenes: list[Scene], vocab: Vocabulary) -> dict[str, list[dict]]:
    """The labels object (same layout, no score) from scenes loaded with ground truth."""
    return {
        s.name: [
            frame_dict(s.name, token_timestamp_ns(f.token), f.ego_translation, f.gt, vocab, with_score=False)
            for f in s.frames
        ]
        for s in _log_order(scenes)
    }


def expected_frames(scenes: list[Scene]) -> dict[str, list[int]]:
    """Log id -> frame timestamps (ns) in time order: what a submission must hold exactly."""
    return {s.name: [token_timestamp_ns(f.token) for f in s.frames] for s in scenes}


# ------------------------------------------------------------------------------------------------------------
# validation
# ------------------------------------------------------------------------------------------------------------


def validate_sequences(seqs, expected: dict[str, list[int]], where: str = "tracks") -> None:
    """Check a tracking object against the format's description (``av2_tracks.schema.yaml``, frame by frame, naming
    the first failing field) and the expected frames (``expected``: log id -> frame timestamps in time order);
    raises :class:`InputFormatError` naming the file (``where``) and the field."""
    formats.require_type(FORMAT, seqs, where, ())
    missing, extra = sorted(set(expected) - set(seqs)), sorted(set(seqs) - set(expected), key=str)
    if missing or extra:
        raise InputFormatError(
            f"{where}: logs must be exactly the {len(expected)} logs of the split "
            f"(missing {missing[:3]}, not in the split {extra[:3]})"
        )
    for log_id, frames in seqs.items():
        formats.require_type(FORMAT, frames, where, (log_id,))
        ts = [f.get("timestamp_ns") if isinstance(f, dict) else None for f in frames]
        if ts != list(expected[log_id]):
            raise InputFormatError(
                f"{where}: log {log_id}: frames must be exactly the {len(expected[log_id])} "
                f"label frames in time order (timestamp_ns), got {len(frames)} frames"
                f"{'' if len(frames) != len(expected[log_id]) else ' with other timestamps'}"
            )
        for i, f in enumerate(frames):
            formats.check(FORMAT, f, where, at=(log_id, i))
            if f["seq_id"] != log_id:
                raise InputFormatError(
                    f"{where}: field '{formats.field_path(FORMAT, (log_id, i, 'seq_id'))}' is {f['seq_id']!r}, "
                    f"expected the log id it is listed under"
                )


# ------------------------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------------------------


def write_tracks_pickle(path: str | Path, seqs: dict, expected: dict[str, list[int]]) -> None:
    """Validate and write the tracking pickle atomically."""
    validate_sequences(seqs, expected, where=str(path))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            pickle.dump(seqs, fh, protocol=pickle.HIGHEST_PROTOCOL)


def read_tracks_pickle(path: str | Path) -> dict:
    """Load a tracking pickle (format checked later against the expected frames)."""
    path = Path(path)
    if not path.is_file():
        raise InputFormatError(f"{path}: tracking pickle does not exist")
    try:
        with open(path, "rb") as fh:
            return pickle.load(fh)
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, ValueError) as exc:
        raise InputFormatError(f"{path}: not a readable pickle ({exc})") from exc


def read_valid_tracks(path: str | Path, expected: dict[str, list[int]]) -> dict:
    """A tracking pickle checked against the format's description and the expected frames; an error names
    ``path`` and the field."""
    seqs = read_tracks_pickle(path)
    validate_sequences(seqs, expected, where=str(path))
    return seqs


def sequences_to_table(seqs: dict[str, list[dict]]) -> pd.DataFrame:
    """One row per box (city frame, AV2 quaternion convention); columns :data:`TABLE_COLUMNS`."""
    frames = [f for fs in seqs.values() for f in fs]
    n = np.array([len(f["track_id"]) for f in frames], dtype=np.int64)

    def cat(key: str, width: int | None = None) -> np.ndarray:
        parts = [np.asarray(f[key]) for f in frames]
        if not parts:
            return np.zeros((0, width) if width else 0)
        return np.concatenate([p.reshape(-1, width) if width else p.reshape(-1) for p in parts])

    trans, size, vel = cat("translation_m", 3), cat("size", 3), cat("velocity_m_per_s", 3)
    q = quaternion_from_yaw(cat("yaw"))
    table = {
        "log_id": np.repeat([f["seq_id"] for f in frames], n).astype(object),
        "timestamp_ns": np.repeat([f["timestamp_ns"] for f in frames], n).astype(np.int64),
        "track_uuid": cat("track_id").astype(str).astype(object),
        "category": cat("name").astype(object),
        "tx_m": trans[:, 0],
        "ty_m": trans[:, 1],
        "tz_m": trans[:, 2],
        "length_m": size[:, 0],
        "width_m": size[:, 1],
        "height_m": size[:, 2],
        "qw": q[:, 0],
        "qx": q[:, 1],
        "qy": q[:, 2],
        "qz": q[:, 3],
        "vx_m_per_s": vel[:, 0],
        "vy_m_per_s": vel[:, 1],
        "score": cat("score").astype(np.float64),
    }
    return pd.DataFrame(table, columns=list(TABLE_COLUMNS))


def table_to_sequences(table: pd.DataFrame, expected: dict[str, list[int]]) -> dict[str, list[dict]]:
    """The tracking object of a feather table for the given frames (frames without rows are empty).

    ``ego_translation_m`` is not in the table and is left out (the evaluator copies it from the labels).
    """
    missing = [c for c in TABLE_COLUMNS if c not in table.columns]
    if missing:
        raise InputFormatError(f"tracks table: missing column(s) {missing}")
    t = table.reset_index(drop=True)
    ids = t["track_uuid"].astype(str).to_numpy()
    ids = ids.astype(np.int64) if all(s.lstrip("-").isdigit() for s in ids) else ids.astype(object)
    yaw = yaw_from_quaternion(t[["qw", "qx", "qy", "qz"]].to_numpy(np.float64))
    names = t["category"].astype(str).to_numpy(dtype=object)
    groups = t.groupby([t["log_id"].astype(str), t["timestamp_ns"].astype(np.int64)], sort=False).indices
    empty = np.zeros(0, dtype=np.int64)
    out = {}
    for log_id, times in expected.items():
        out[log_id] = []
        for ts in times:
            i = groups.get((log_id, int(ts)), empty)
            out[log_id].append(_table_frame(t.iloc[i], ids[i], yaw[i], names[i], log_id, ts))
    return out


def _table_frame(rows: pd.DataFrame, ids, yaw, names, log_id: str, ts: int) -> dict:
    """One frame dict from its table rows."""
    n = len(rows)
    return {
        "seq_id": log_id,
        "timestamp_ns": int(ts),
        "track_id": ids,
        "translation_m": rows[["tx_m", "ty_m", "tz_m"]].to_numpy(np.float64).reshape(n, 3),
        "size": rows[["length_m", "width_m", "height_m"]].to_numpy(np.float64).reshape(n, 3),
        "yaw": yaw,
        "velocity_m_per_s": np.column_stack(
            [rows[["vx_m_per_s", "vy_m_per_s"]].to_numpy(np.float64).reshape(n, 2), np.zeros(n)]
        ),
        "label": pd.Series(names, dtype=object).map(_CATEGORY_INDEX).to_numpy(np.int64),
        "name": names,
        "score": rows["score"].to_numpy(np.float64),
    }


def write_tracks_feather(path: str | Path, table: pd.DataFrame) -> None:
    """Write the tracks table atomically."""
    with atomic_path(path) as tmp:
        table.reset_index(drop=True).to_feather(tmp)


def write_tracks(
    pkl_path: str | Path,
    feather_path: str | Path | None,
    scenes: list[Scene],
    results: dict[str, BoxSet],
    vocab: Vocabulary,
) -> dict:
    """Build, validate and write the pickle (and the feather table when a path is given); returns the object."""
    seqs = build_sequences(scenes, results, vocab)
    write_tracks_pickle(pkl_path, seqs, expected_frames(scenes))
    if feather_path is not None:
        write_tracks_feather(feather_path, sequences_to_table(seqs))
    return seqs
