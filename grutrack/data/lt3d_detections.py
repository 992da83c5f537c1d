"""LT3D detections (Argoverse 2) into canonical city-frame detections.

Input: LT3D's detection table (``AV2Dataset.format_results`` of github.com/neeharperi/LT3D, the AV2 detection
format), one row per box in the EGO frame of its sweep: ``tx_m, ty_m, tz_m`` (box centre, metres),
``length_m, width_m, height_m``, ``qw, qx, qy, qz`` (box -> ego rotation), ``score``, ``log_id``,
``timestamp_ns``, ``category`` (AV2 name) and optionally ``vx, vy`` (object velocity in ego axes, m/s; 0 when
absent). Accepted files: feather (``.feather`` / ``.arrow``), CSV (LT3D writes ``val_detections.csv``) and a
pickled pandas DataFrame of the same columns (``.pkl`` / ``.pickle``, what ``format_results`` returns).

Validation (an :class:`InputFormatError` names the file, the row, the column and what was expected): against the
table's one description, ``grutrack/configs/schemas/formats/lt3d_detections.schema.yaml`` (:mod:`grutrack.formats`:
required columns present; numbers finite; sizes positive; unit quaternions; scores in [0, 1]; category an AV2
category; integer timestamps), then ``log_id`` one of the split's logs and ``timestamp_ns`` one of that log's
ego-pose timestamps.

Policy for detections at valid sweep times that are not tracked frames (the tracker runs at the evaluated
rate, 2 Hz by default, on the label timestamps): they are DROPPED and counted in
:class:`DetectionStats.off_frame`. Boxes of categories outside the tracking vocabulary (e.g. BOLLARD with the 7
Table I classes) are dropped likewise (``other_category``). A frame without detections gets an empty box set.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from grutrack import formats
from grutrack.data.av2 import ego_to_city, quat_to_matrix, read_poses, split_dir, token_timestamp_ns
from grutrack.data.scene import BoxSet, Scene, Vocabulary
from grutrack.errors import InputFormatError
from grutrack.io import atomic_path

#: the table's description (grutrack/configs/schemas/formats/<FORMAT>.schema.yaml): one row
FORMAT = "lt3d_detections"
_ROW = formats.node(FORMAT, (0,))
REQUIRED_COLUMNS = tuple(_ROW["required"])
NUMERIC_COLUMNS = ("tx_m", "ty_m", "tz_m", "length_m", "width_m", "height_m", "qw", "qx", "qy", "qz", "score")
VELOCITY_COLUMNS = ("vx", "vy")
#: LT3D writes OTHER for a label outside its class list; such boxes are dropped like untracked categories
KNOWN_CATEGORIES = frozenset(_ROW["properties"]["category"]["enum"])
QUATERNION_TOLERANCE = _ROW["unitNormOf"]["tolerance"]


#: detections per sweep accepted: NMS compares every pair of a frame's boxes (memory grows with its square)
MAX_DETECTIONS_PER_SWEEP = 5000


@dataclass
class DetectionStats:
    """What happened to the rows of a detection file."""

    rows: int = 0
    kept: int = 0
    other_category: int = 0  # category valid but not tracked
    off_frame: int = 0  # valid sweep time, not a tracked frame (dropped, see module docstring)
    empty_logs: list = field(default_factory=list)  # logs without any tracked detection


def read_detection_table(path: str | Path) -> pd.DataFrame:
    """The detection table of a feather, CSV or pickled-DataFrame file, with the required columns."""
    path = Path(path)
    if not path.is_file():
        raise InputFormatError(f"{path}: detection file does not exist")
    suffix = path.suffix.lower()
    try:
        if suffix in (".feather", ".arrow"):
            df = pd.read_feather(path)
        elif suffix == ".csv":
            df = pd.read_csv(path)
        elif suffix in (".pkl", ".pickle"):
            with open(path, "rb") as fh:
                df = pickle.load(fh)
        else:
            raise InputFormatError(
                f"{path}: unknown detection file type '{suffix}' (expected .feather, .csv or "
                f".pkl holding a pandas DataFrame)"
            )
    except (OSError, ValueError, pickle.UnpicklingError, EOFError) as exc:
        raise InputFormatError(f"{path}: cannot read the detection table ({exc})") from exc
    if not isinstance(df, pd.DataFrame):
        raise InputFormatError(f"{path}: expected a pandas DataFrame of LT3D detections, got {type(df).__name__}")
    formats.check_table(FORMAT, df, path)  # the table's one description: columns, types, ranges, quaternions
    return df.reset_index(drop=True)


def load_detections(
    path: str | Path, root: str | Path, split: str, scenes: list[Scene], vocab: Vocabulary
) -> tuple[dict[str, BoxSet], DetectionStats]:
    """Detections of every frame of ``scenes`` as canonical city-frame box sets, and what was dropped.

    ``root``/``split``: the AV2 dataset the scenes come from (ego poses are read per log). Labels index
    ``vocab``; the boxes are ``(N, 9) [x, y, z, w, l, h, yaw, vx, vy]`` in the city frame (metres, radians, m/s).
    """
    path = Path(path)
    df = read_detection_table(path)
    num = df[list(NUMERIC_COLUMNS)].to_numpy(dtype=np.float64)
    has_vel = all(c in df.columns for c in VELOCITY_COLUMNS)
    vel = df[list(VELOCITY_COLUMNS)].to_numpy(dtype=np.float64) if has_vel else np.zeros((len(df), 2))
    ts = df["timestamp_ns"].to_numpy().astype(np.int64)
    logs = df["log_id"].astype(str).to_numpy()
    _check_sweep_counts(path, logs, ts)
    known = {s.name for s in scenes}
    outside = set(logs) - known  # logs of the split that are not tracked now (a held-out subset) are ignored
    ddir = split_dir(root, split)
    unknown = sorted(outside - {p.name for p in ddir.iterdir() if p.is_dir()}) if outside else []
    if unknown:
        raise InputFormatError(
            f"{path}: field 'log_id' has {len(unknown)} log(s) that are not logs of split "
            f"'{split}' under {root} (first: {unknown[0]}); expected one of the {len(known)} "
            f"logs being tracked"
        )
    tracked = np.isin(logs, list(known)) if outside else np.ones(len(df), dtype=bool)
    stats = DetectionStats(rows=int(tracked.sum()))
    labels = vocab.labels(df["category"].astype(str).to_numpy())
    stats.other_category = int(((labels < 0) & tracked).sum())
    out: dict[str, BoxSet] = {}
    for scene in scenes:
        rows = np.flatnonzero(logs == scene.name)
        kept = stats.kept
        out.update(_log_boxes(path, ddir / scene.name, scene, rows, ts, num, vel, labels, stats))
        if stats.kept == kept:
            stats.empty_logs.append(scene.name)
    return out, stats


def _check_sweep_counts(path: Path, logs: np.ndarray, ts: np.ndarray) -> None:
    """Refuse a sweep with more than :data:`MAX_DETECTIONS_PER_SWEEP` rows before any per-frame work."""
    if len(ts) <= MAX_DETECTIONS_PER_SWEEP or np.unique(ts, return_counts=True)[1].max() <= MAX_DETECTIONS_PER_SWEEP:
        return  # no timestamp has that many rows, so no (log, sweep) has
    codes = pd.factorize(logs)[0]
    order = np.lexsort((ts, codes))  # rows of one (log, sweep) are now adjacent
    c, t = codes[order], ts[order]
    starts = np.flatnonzero(np.r_[True, (c[1:] != c[:-1]) | (t[1:] != t[:-1])])
    counts = np.diff(np.r_[starts, len(order)])
    if counts.max() > MAX_DETECTIONS_PER_SWEEP:
        i = int(order[starts[np.argmax(counts)]])
        raise InputFormatError(
            f"{path}: log {logs[i]}, timestamp_ns {ts[i]} has {int(counts.max())} detections; at "
            f"most {MAX_DETECTIONS_PER_SWEEP} per sweep are accepted (the tracker compares "
            f"every pair of a frame's boxes; keep the highest-scoring ones)"
        )


def _log_boxes(
    path: Path,
    log_dir: Path,
    scene: Scene,
    rows: np.ndarray,
    ts: np.ndarray,
    num: np.ndarray,
    vel: np.ndarray,
    labels: np.ndarray,
    stats: DetectionStats,
) -> dict[str, BoxSet]:
    """The frames of one log: pose check, ego -> city, binning to the tracked frames."""
    poses = read_poses(log_dir)
    prow = poses.index(ts[rows])
    if (prow < 0).any():
        i = int(rows[np.argmax(prow < 0)])
        raise InputFormatError(
            f"{path}: row {i} (log {scene.name}): field 'timestamp_ns' {ts[i]} is not a sweep "
            f"time of this log (no ego pose at it in {log_dir}/city_SE3_egovehicle.feather)"
        )
    frame_ts = np.array([token_timestamp_ns(f.token) for f in scene.frames], dtype=np.int64)
    fidx = np.searchsorted(frame_ts, ts[rows]).clip(0, max(len(frame_ts) - 1, 0))
    on_frame = (frame_ts[fidx] == ts[rows]) if len(frame_ts) else np.zeros(len(rows), dtype=bool)
    stats.off_frame += int((~on_frame).sum())
    keep = on_frame & (labels[rows] >= 0)
    r, f, p = rows[keep], fidx[keep], prow[keep]
    stats.kept += len(r)
    centre, yaw, v = ego_to_city(poses, p, num[r, 0:3], num[r, 6:10], vel[r])
    boxes = np.column_stack([centre, num[r][:, [4, 3, 5]], yaw, v])
    order = np.argsort(f, kind="stable")
    starts = np.searchsorted(f[order], np.arange(len(frame_ts)), side="left")
    stops = np.searchsorted(f[order], np.arange(len(frame_ts)), side="right")
    return {
        fr.token: BoxSet(boxes[order[a:b]], num[r[order[a:b]], 10], labels[r[order[a:b]]])
        for fr, a, b in zip(scene.frames, starts, stops)
    }


# ------------------------------------------------------------------------------------------------------------
# writing
# ------------------------------------------------------------------------------------------------------------


def detection_table(scenes: list[Scene], boxsets: dict[str, BoxSet]) -> pd.DataFrame:
    """Canonical city-frame detections of ``scenes`` as an LT3D table (the ego frame of each frame's sweep):
    the inverse of :func:`load_detections` for the frames given. Labels index each scene's vocabulary."""
    parts = []
    for s in scenes:
        names = np.asarray(s.vocabulary.names, dtype=object)
        for f in s.frames:
            b = boxsets.get(f.token)
            if b is None or len(b) == 0:
                continue
            R = quat_to_matrix(f.ego_rotation)[0]  # ego -> city
            centre = (b.boxes[:, 0:3] - f.ego_translation) @ R  # R^T (c - t), row-wise
            box_to_city = _yaw_matrices(b.boxes[:, 6])
            q = _matrix_to_quat(np.einsum("ji,njk->nik", R, box_to_city))  # box -> ego
            # (vx, vy) in ego axes that the reader maps back to the city-frame (vx, vy) exactly: it rotates
            # [vx, vy, 0] by R and keeps x, y, so solve with R's upper-left 2x2 block
            v = np.linalg.solve(R[:2, :2], b.boxes[:, 7:9].T).T
            parts.append(
                pd.DataFrame(
                    {
                        "tx_m": centre[:, 0],
                        "ty_m": centre[:, 1],
                        "tz_m": centre[:, 2],
                        "length_m": b.boxes[:, 4],
                        "width_m": b.boxes[:, 3],
                        "height_m": b.boxes[:, 5],
                        "qw": q[:, 0],
                        "qx": q[:, 1],
                        "qy": q[:, 2],
                        "qz": q[:, 3],
                        "vx": v[:, 0],
                        "vy": v[:, 1],
                        "score": b.scores,
                        "log_id": s.name,
                        "timestamp_ns": token_timestamp_ns(f.token),
                        "category": names[b.labels],
                    }
                )
            )
    if not parts:
        return pd.DataFrame(
            {
                c: pd.Series(dtype=object if c in ("log_id", "category") else float)
                for c in (*REQUIRED_COLUMNS, *VELOCITY_COLUMNS)
            }
        )
    return pd.concat(parts, ignore_index=True)


def write_detection_table(path: str | Path, table: pd.DataFrame) -> None:
    """Write an LT3D detection table atomically as feather."""
    with atomic_path(path) as tmp:
        table.reset_index(drop=True).to_feather(tmp)


def _yaw_matrices(yaw: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations about +z by ``yaw`` (N,) radians."""
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.zeros((len(yaw), 3, 3))
    m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1], m[:, 2, 2] = c, -s, s, c, 1.0
    return m


def _matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions [w, x, y, z] of rotation matrices (N, 3, 3)."""
    from scipy.spatial.transform import Rotation

    xyzw = Rotation.from_matrix(m).as_quat()
    return np.column_stack([xyzw[:, 3], xyzw[:, :3]])
