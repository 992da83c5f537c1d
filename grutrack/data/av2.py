"""Argoverse 2 (sensor dataset) adapter: the logs of a split as canonical scenes in the CITY frame.

Layout read (``<root>/<split>/<log_id>/``): ``annotations.feather`` (ego-frame cuboids at 10 Hz: timestamp_ns,
track_uuid, category, length_m, width_m, height_m, qw..qz, tx_m..tz_m, num_interior_pts) and
``city_SE3_egovehicle.feather`` (ego poses: timestamp_ns, qw..qz, tx_m..tz_m). A log without annotations (the
test split) takes its frame times from the lidar sweeps ``sensors/lidar/<timestamp_ns>.feather``.

Frames: the 10 Hz annotation timestamps sub-sampled to ``rate_hz`` (2 Hz by default, the rate at which LT3D and
Table I evaluate AV2 val): every k-th timestamp from the first, k = round(period / median native interval).
Frame token ``"<log_id>:<timestamp_ns>"`` (:func:`frame_token`); ``Frame.timestamp`` is in MICROseconds like
every canonical frame (the exact nanoseconds are in the token, :func:`token_timestamp_ns`).

Labels index an AV2 category :class:`Vocabulary` (AV2 names are kept for output). By default it holds the 7
classes of Table I; ``all_categories=True`` gives the 26 categories of the AV2 sensor competition (the only
ones the official evaluator accepts). Each category has the nuScenes tracking class whose tracker parameters
it uses (:data:`PARAM_CLASS`), passed to ``build_tracker(param_classes=...)``. Ground-truth ids are the
``track_uuid`` strings; GT velocity is the centred difference of consecutive 10 Hz annotations of the same
track in the city frame (one-sided at the ends of a track, 0 for a track seen once).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from grutrack.boxes import wrap_angle
from grutrack.data.scene import BoxSet, Frame, Scene, Vocabulary
from grutrack.errors import ConfigError, DatasetError, InputFormatError

#: Table I classes, in the paper's column order.
TABLE_I_CLASSES: tuple[str, ...] = (
    "REGULAR_VEHICLE",
    "PEDESTRIAN",
    "BICYCLE",
    "LARGE_VEHICLE",
    "BUS",
    "BOX_TRUCK",
    "TRUCK",
)
#: The 26 categories of the AV2 sensor competition (``av2.evaluation.SensorCompetitionCategories``, same order);
#: the official tracking evaluator indexes this list, so no other name may appear in its inputs.
COMPETITION_CATEGORIES: tuple[str, ...] = (
    "ARTICULATED_BUS",
    "BICYCLE",
    "BICYCLIST",
    "BOLLARD",
    "BOX_TRUCK",
    "BUS",
    "CONSTRUCTION_BARREL",
    "CONSTRUCTION_CONE",
    "DOG",
    "LARGE_VEHICLE",
    "MESSAGE_BOARD_TRAILER",
    "MOBILE_PEDESTRIAN_CROSSING_SIGN",
    "MOTORCYCLE",
    "MOTORCYCLIST",
    "PEDESTRIAN",
    "REGULAR_VEHICLE",
    "SCHOOL_BUS",
    "SIGN",
    "STOP_SIGN",
    "STROLLER",
    "TRUCK",
    "TRUCK_CAB",
    "VEHICULAR_TRAILER",
    "WHEELCHAIR",
    "WHEELED_DEVICE",
    "WHEELED_RIDER",
)
#: Annotation categories outside the competition (``av2.datasets.sensor.constants.AnnotationCategories``).
OTHER_ANNOTATION_CATEGORIES: tuple[str, ...] = (
    "ANIMAL",
    "OFFICIAL_SIGNALER",
    "RAILED_VEHICLE",
    "TRAFFIC_LIGHT_TRAILER",
)
#: nuScenes tracking class whose tracker parameters each competition category uses (grutrack choice: the
#: nuScenes class of the most similar size and motion; small static objects take pedestrian parameters).
PARAM_CLASS: dict[str, str] = {
    "REGULAR_VEHICLE": "car",
    "PEDESTRIAN": "pedestrian",
    "BICYCLE": "bicycle",
    "BICYCLIST": "bicycle",
    "MOTORCYCLE": "motorcycle",
    "MOTORCYCLIST": "motorcycle",
    "WHEELED_RIDER": "bicycle",
    "WHEELED_DEVICE": "bicycle",
    "BUS": "bus",
    "SCHOOL_BUS": "bus",
    "ARTICULATED_BUS": "bus",
    "BOX_TRUCK": "truck",
    "TRUCK": "truck",
    "LARGE_VEHICLE": "truck",
    "TRUCK_CAB": "truck",
    "VEHICULAR_TRAILER": "trailer",
    "MESSAGE_BOARD_TRAILER": "trailer",
    "BOLLARD": "pedestrian",
    "CONSTRUCTION_CONE": "pedestrian",
    "CONSTRUCTION_BARREL": "pedestrian",
    "SIGN": "pedestrian",
    "STOP_SIGN": "pedestrian",
    "MOBILE_PEDESTRIAN_CROSSING_SIGN": "pedestrian",
    "WHEELCHAIR": "pedestrian",
    "STROLLER": "pedestrian",
    "DOG": "pedestrian",
}
#: The nuScenes detection class whose detector-profile statistics simulate each Table I class
#: (``grutrack simulate-detections --dataset av2``): distinct, so a simulated box's class maps back to exactly
#: one AV2 category; the two AV2 truck-like classes take the two large nuScenes classes nearest in size and
#: motion (LARGE_VEHICLE: construction_vehicle; TRUCK, the tractor units: trailer).
SIMULATOR_CLASS: dict[str, str] = {
    "REGULAR_VEHICLE": "car",
    "PEDESTRIAN": "pedestrian",
    "BICYCLE": "bicycle",
    "LARGE_VEHICLE": "construction_vehicle",
    "BUS": "bus",
    "BOX_TRUCK": "truck",
    "TRUCK": "trailer",
}
DEFAULT_RATE_HZ = 2.0
ANNOTATION_COLUMNS = (
    "timestamp_ns",
    "track_uuid",
    "category",
    "length_m",
    "width_m",
    "height_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "tx_m",
    "ty_m",
    "tz_m",
)
POSE_COLUMNS = ("timestamp_ns", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")


def vocabulary(all_categories: bool = False) -> Vocabulary:
    """The 7 Table I classes (default) or the 26 competition categories."""
    names = COMPETITION_CATEGORIES if all_categories else TABLE_I_CLASSES
    return Vocabulary(names, tuple(PARAM_CLASS[n] for n in names))


def frame_token(log_id: str, timestamp_ns: int) -> str:
    """Canonical frame token of an AV2 sweep."""
    return f"{log_id}:{int(timestamp_ns)}"


def token_timestamp_ns(token: str) -> int:
    """The exact nanosecond timestamp of a frame token made by :func:`frame_token`."""
    return int(token.rsplit(":", 1)[1])


# ------------------------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------------------------


def split_dir(root: str | Path, split: str) -> Path:
    """``<root>/<split>``, checked to exist and to hold at least one log."""
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"AV2 dataroot {root} does not exist (expected a folder holding <split>/<log_id>/)")
    d = root / split
    if not d.is_dir():
        found = sorted(p.name for p in root.iterdir() if p.is_dir())
        raise DatasetError(f"AV2 dataroot {root} has no split folder '{split}' (found: {', '.join(found) or 'none'})")
    return d


def list_logs(root: str | Path, split: str) -> list[str]:
    """Sorted log ids of a split: the sub-folders that hold ``city_SE3_egovehicle.feather``."""
    d = split_dir(root, split)
    logs = sorted(p.name for p in d.iterdir() if (p / "city_SE3_egovehicle.feather").is_file())
    if not logs:
        raise DatasetError(f"{d}: no log folder with city_SE3_egovehicle.feather")
    return logs


def _read_feather(path: Path, table: str) -> pd.DataFrame:
    """A feather table checked against its description (``table``: ``av2_poses`` or ``av2_annotations``, schemas
    in grutrack/configs/schemas/formats/); InputFormatError naming the file, the row and the column otherwise."""
    from grutrack import formats

    try:
        df = pd.read_feather(path)
    except (OSError, ValueError) as exc:
        raise InputFormatError(f"{path}: not a readable feather table ({exc})") from exc
    formats.check_table(table, df, path)
    return df


@dataclass
class Poses:
    """Ego poses of one log, sorted by time: ``timestamps (T,)`` int64 ns, ``rotation (T, 3, 3)`` and
    ``quaternion (T, 4)`` [w, x, y, z] ego -> city, ``translation (T, 3)`` metres, city frame."""

    timestamps: np.ndarray
    rotation: np.ndarray
    quaternion: np.ndarray
    translation: np.ndarray

    def index(self, timestamps_ns: np.ndarray) -> np.ndarray:
        """(N,) row of each timestamp; -1 where a timestamp has no pose."""
        ts = np.asarray(timestamps_ns, dtype=np.int64).reshape(-1)
        if len(self.timestamps) == 0:
            return np.full(len(ts), -1, dtype=np.int64)
        i = np.searchsorted(self.timestamps, ts).clip(0, len(self.timestamps) - 1)
        return np.where(self.timestamps[i] == ts, i, -1)


def read_poses(log_dir: str | Path) -> Poses:
    """The ego poses of a log (``city_SE3_egovehicle.feather``)."""
    path = Path(log_dir) / "city_SE3_egovehicle.feather"
    if not path.is_file():
        raise DatasetError(f"{path} does not exist (every AV2 log needs its ego poses)")
    df = _read_feather(path, "av2_poses").sort_values("timestamp_ns", kind="stable")
    q = df[["qw", "qx", "qy", "qz"]].to_numpy(np.float64)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return Poses(
        df["timestamp_ns"].to_numpy(np.int64), quat_to_matrix(q), q, df[["tx_m", "ty_m", "tz_m"]].to_numpy(np.float64)
    )


def read_annotations(log_dir: str | Path) -> pd.DataFrame | None:
    """``annotations.feather`` of a log, or None when the log has none (test split)."""
    path = Path(log_dir) / "annotations.feather"
    if not path.is_file():
        return None
    return _read_feather(path, "av2_annotations")


# ------------------------------------------------------------------------------------------------------------
# geometry
# ------------------------------------------------------------------------------------------------------------


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of unit quaternions (N, 4) [w, x, y, z]."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def ego_to_city(
    poses: Poses, rows: np.ndarray, centre: np.ndarray, quat: np.ndarray, velocity: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ego-frame cuboids to the city frame.

    rows (N,) pose row of each box; centre (N, 3) metres, ego frame; quat (N, 4) [w, x, y, z] box -> ego;
    velocity (N, 2) m/s in ego axes or None. Returns centre (N, 3) city, yaw (N,) radians about city +z,
    velocity (N, 2) m/s in city axes (zeros when None).
    """
    R = poses.rotation[rows]
    c = np.einsum("nij,nj->ni", R, centre) + poses.translation[rows]
    heading = np.einsum("nij,nj->ni", R, quat_to_matrix(quat)[:, :, 0])  # box +x axis in the city frame
    yaw = wrap_angle(np.arctan2(heading[:, 1], heading[:, 0]))
    v = np.zeros((len(rows), 2))
    if velocity is not None:
        v3 = np.column_stack([velocity, np.zeros(len(rows))])
        v = np.einsum("nij,nj->ni", R, v3)[:, :2]
    return c, yaw, v


def track_velocity(track_ids: np.ndarray, timestamps_ns: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Ground-plane velocity (N, 2) m/s of boxes from their track's neighbours in time.

    track_ids (N,), timestamps_ns (N,) int64, xy (N, 2) city metres. Centred difference inside a track,
    one-sided at its ends, 0 for a track with one box.
    """
    n = len(track_ids)
    v = np.zeros((n, 2))
    if n == 0:
        return v
    order = np.lexsort((timestamps_ns, track_ids))
    ids, t, p = track_ids[order], timestamps_ns[order].astype(np.float64) * 1e-9, xy[order]
    same_prev = np.r_[False, ids[1:] == ids[:-1]]
    same_next = np.r_[ids[1:] == ids[:-1], False]
    prev = np.where(same_prev, np.arange(n) - 1, np.arange(n))
    nxt = np.where(same_next, np.arange(n) + 1, np.arange(n))
    dt = t[nxt] - t[prev]
    ok = dt > 0
    v_sorted = np.zeros((n, 2))
    v_sorted[ok] = (p[nxt[ok]] - p[prev[ok]]) / dt[ok, None]
    v[order] = v_sorted
    return v


# ------------------------------------------------------------------------------------------------------------
# frames and scenes
# ------------------------------------------------------------------------------------------------------------


def subsample(timestamps_ns: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Sorted unique timestamps (T,) int64 ns kept at ``rate_hz``: every k-th from the first, k = round(period /
    median interval); all of them when ``rate_hz`` is None or not below the native rate."""
    ts = np.unique(np.asarray(timestamps_ns, dtype=np.int64))
    if rate_hz is None or len(ts) < 2:
        return ts
    if rate_hz <= 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    step = max(1, int(round(1e9 / rate_hz / float(np.median(np.diff(ts))))))
    return ts[::step]


def _lidar_timestamps(log_dir: Path) -> np.ndarray:
    """Timestamps of the lidar sweeps ``sensors/lidar/<timestamp_ns>.feather`` (empty when there are none)."""
    d = log_dir / "sensors" / "lidar"
    names = [p.stem for p in d.glob("*.feather")] if d.is_dir() else []
    return np.array(sorted(int(s) for s in names if s.isdigit()), dtype=np.int64)


def log_frame_times(log_dir: Path, ann: pd.DataFrame | None, rate_hz: float | None) -> np.ndarray:
    """Frame timestamps (F,) int64 ns of a log: annotation times (else lidar sweep times) at ``rate_hz``."""
    native = ann["timestamp_ns"].to_numpy(np.int64) if ann is not None and len(ann) else _lidar_timestamps(log_dir)
    if len(native) == 0:
        why = "its annotations.feather has no rows" if ann is not None else "it has no annotations.feather"
        raise DatasetError(
            f"log {log_dir.name}: cannot determine its frames: {why} and it has no lidar sweeps under sensors/lidar/"
        )
    return subsample(native, rate_hz)


def _gt_boxsets(
    ann: pd.DataFrame, poses: Poses, frame_ts: np.ndarray, vocab: Vocabulary, log_dir: Path
) -> list[BoxSet]:
    """Ground truth of each frame (city frame, vocabulary categories only), velocity from the 10 Hz track."""
    ann = ann[ann["category"].isin(vocab.names)]
    ts = ann["timestamp_ns"].to_numpy(np.int64)
    rows = poses.index(ts)
    if (rows < 0).any():
        bad = int(ts[np.argmax(rows < 0)])
        raise DatasetError(
            f"{log_dir}/annotations.feather: timestamp_ns {bad} has no ego pose in city_SE3_egovehicle.feather"
        )
    centre, yaw, _ = ego_to_city(
        poses,
        rows,
        ann[["tx_m", "ty_m", "tz_m"]].to_numpy(np.float64),
        ann[["qw", "qx", "qy", "qz"]].to_numpy(np.float64),
    )
    uuids = ann["track_uuid"].to_numpy(dtype=object)
    vel = track_velocity(uuids.astype(str), ts, centre[:, :2])
    boxes = np.column_stack([centre, ann[["width_m", "length_m", "height_m"]].to_numpy(np.float64), yaw, vel])
    labels = vocab.labels(ann["category"].to_numpy(dtype=object))
    pts = ann["num_interior_pts"].to_numpy(np.int64) if "num_interior_pts" in ann else np.zeros(len(ann), np.int64)
    order = np.argsort(ts, kind="stable")
    starts = np.searchsorted(ts[order], frame_ts, side="left")
    stops = np.searchsorted(ts[order], frame_ts, side="right")
    return [
        BoxSet(boxes[order[a:b]], np.ones(b - a), labels[order[a:b]], uuids[order[a:b]], {"num_pts": pts[order[a:b]]})
        for a, b in zip(starts, stops)
    ]


def load_log(
    root: str | Path,
    split: str,
    log_id: str,
    *,
    rate_hz: float | None = DEFAULT_RATE_HZ,
    with_gt: bool = False,
    vocab: Vocabulary | None = None,
) -> Scene:
    """One log as a canonical scene (frames in time order, ego poses, optional ground truth)."""
    log_dir = split_dir(root, split) / log_id
    if not log_dir.is_dir():
        raise DatasetError(f"log {log_id} is not in {log_dir.parent}")
    vocab = vocab or vocabulary()
    poses = read_poses(log_dir)
    ann = read_annotations(log_dir)
    frame_ts = log_frame_times(log_dir, ann, rate_hz)
    rows = poses.index(frame_ts)
    if (rows < 0).any():
        raise DatasetError(
            f"{log_dir}: frame timestamp {int(frame_ts[np.argmax(rows < 0)])} has no ego pose in "
            f"city_SE3_egovehicle.feather"
        )
    if with_gt and ann is None:
        raise DatasetError(f"{log_dir}: no annotations.feather, ground truth requested")
    gts = _gt_boxsets(ann, poses, frame_ts, vocab, log_dir) if with_gt else [None] * len(frame_ts)
    frames = [
        Frame(
            token=frame_token(log_id, t),
            timestamp=int(t) // 1000,
            ego_translation=poses.translation[r].copy(),
            ego_rotation=poses.quaternion[r].copy(),
            gt=g,
        )
        for t, r, g in zip(frame_ts, rows, gts)
    ]
    return Scene(name=log_id, token=log_id, frames=frames, vocabulary=vocab)


def load_scenes(
    root: str | Path,
    split: str,
    *,
    rate_hz: float | None = DEFAULT_RATE_HZ,
    with_gt: bool = False,
    all_categories: bool = False,
    log_ids: list[str] | None = None,
) -> list[Scene]:
    """Canonical scenes of the logs of ``split`` (sorted by log id, or the given ``log_ids``).

    Labels of the GT index :func:`vocabulary` (``all_categories``); boxes are in the city frame.
    """
    if rate_hz is not None and not (isinstance(rate_hz, (int, float)) and np.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(
            f"--rate: the frame rate must be a positive number of frames per second (the "
            f"annotations are at 10 Hz), got {rate_hz}"
        )
    known = list_logs(root, split)
    if log_ids is not None:
        unknown = [lg for lg in log_ids if lg not in known]
        if unknown:
            raise DatasetError(f"log(s) {unknown} not in {split_dir(root, split)} (found {len(known)} logs)")
    vocab = vocabulary(all_categories)
    return [load_log(root, split, lg, rate_hz=rate_hz, with_gt=with_gt, vocab=vocab) for lg in (log_ids or known)]
