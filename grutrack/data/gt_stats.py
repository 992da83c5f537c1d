"""Per-class statistics of a dataset's ground truth: what the synthetic demo is checked against.

Works on canonical GT frames (:class:`grutrack.data.detection_sim.GTFrame`: nuScenes and the nuScenes-format
demo, the 10 detection classes mapped to the 7 tracking classes) or on canonical scenes of any dataset
(:func:`scene_statistics`, per class of the scenes' vocabulary). For each class: box count and
share, mean size (w, l, h), mean speed, share of moving boxes, mean |yaw rate| from consecutive annotations of
the same instance, share of boxes without lidar points, instances and mean annotations per instance.
"""

from __future__ import annotations

import os
from collections.abc import Iterable

import numpy as np

from grutrack.boxes import VX, VY, YAW, wrap_angle
from grutrack.classes import DETECTION_TO_TRACKING, TRACKING_CLASSES
from grutrack.io import write_json_atomic

MAX_YAW_RATE_DT = 1.5  # s; consecutive annotations further apart are not differenced (devkit box_velocity limit)
MOVING_SPEED = 0.5  # m/s; a box faster than this counts as moving

COLUMNS = (  # (key, header, format)
    ("boxes", "boxes", "{:>7d}"),
    ("share", "share", "{:>6.3f}"),
    ("w", "w m", "{:>5.2f}"),
    ("l", "l m", "{:>6.2f}"),
    ("h", "h m", "{:>5.2f}"),
    ("speed", "speed m/s", "{:>9.2f}"),
    ("moving", "moving", "{:>6.3f}"),
    ("yaw_rate", "|yaw rate| rad/s", "{:>16.3f}"),
    ("zero_pts", "0-pts", "{:>5.3f}"),
    ("instances", "inst", "{:>5d}"),
    ("track_len", "anns/inst", "{:>9.1f}"),
)


def _flatten_scenes(scenes: Iterable) -> tuple[dict[str, np.ndarray], tuple[str, ...]]:
    """The ground-truth boxes of canonical scenes (any dataset) as the flat arrays of :func:`_flatten`, class
    names from each scene's vocabulary; returns the arrays and the vocabulary's names in order."""
    parts = {"boxes": [], "cls": [], "inst": [], "t": [], "pts": []}
    names: tuple[str, ...] = ()
    for s in scenes:
        names = names or s.vocabulary.names
        vocab = np.asarray(s.vocabulary.names, dtype=object)
        for f in s.frames:
            gt = f.gt
            parts["boxes"].append(gt.boxes)
            parts["cls"].append(vocab[gt.labels])
            parts["inst"].append(np.asarray(gt.ids if gt.ids is not None else np.arange(len(gt)), dtype=object))
            parts["t"].append(np.full(len(gt), f.timestamp * 1e-6))
            parts["pts"].append(np.asarray(gt.extra.get("num_pts", np.zeros(len(gt), np.int64))))
    if not parts["boxes"]:
        return _flatten(()), names
    return {k: np.concatenate(v) for k, v in parts.items()}, names


def scene_statistics(scenes: list) -> dict[str, dict]:
    """:func:`class_statistics` of the ground truth of canonical scenes (any dataset; ``with_gt``), per class
    of their vocabulary (AV2: its categories; lidar points from the dataset's own count)."""
    flat, names = _flatten_scenes(scenes)
    return _statistics(flat, names)


def _flatten(frames: Iterable) -> dict[str, np.ndarray]:
    """All boxes of the tracking classes as flat arrays: boxes (N, 9), class (N,), instance (N,), t (N,) s,
    lidar points (N,)."""
    parts = {"boxes": [], "cls": [], "inst": [], "t": [], "pts": []}
    for f in frames:
        names = [DETECTION_TO_TRACKING.get(str(n)) for n in f.names]
        keep = np.array([n is not None for n in names], dtype=bool)
        if not keep.any():
            continue
        parts["boxes"].append(f.boxes[keep])
        parts["cls"].append(np.array([n for n in names if n is not None], dtype=object))
        parts["inst"].append(np.asarray(f.instance_ids, dtype=object)[keep])
        parts["t"].append(np.full(int(keep.sum()), f.timestamp * 1e-6))
        parts["pts"].append(np.asarray(f.num_lidar_pts)[keep])
    if not parts["boxes"]:
        return {
            "boxes": np.zeros((0, 9)),
            "cls": np.zeros(0, object),
            "inst": np.zeros(0, object),
            "t": np.zeros(0),
            "pts": np.zeros(0, np.int64),
        }
    return {k: np.concatenate(v) for k, v in parts.items()}


def yaw_rates(inst: np.ndarray, t: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """|yaw rate| (rad/s) between consecutive annotations of the same instance, at most 1.5 s apart.

    inst (N,) ids, t (N,) seconds, yaw (N,) radians. Returns (rates (K,), index (K,) of the later box).
    """
    if len(inst) < 2:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    _, inst_code = np.unique(inst.astype(str), return_inverse=True)
    order = np.lexsort((t, inst_code))
    same = inst_code[order][1:] == inst_code[order][:-1]
    dt = np.diff(t[order])
    ok = same & (dt > 0) & (dt <= MAX_YAW_RATE_DT)
    rate = np.abs(wrap_angle(np.diff(yaw[order]))) / np.where(ok, dt, 1.0)
    return rate[ok], order[1:][ok]


def class_statistics(frames: Iterable) -> dict[str, dict]:
    """Statistics per tracking class (keys of :data:`COLUMNS`) plus an ``all`` row; classes without boxes
    get count 0 and NaN means."""
    return _statistics(_flatten(frames), TRACKING_CLASSES)


def _statistics(flat: dict[str, np.ndarray], classes: tuple[str, ...]) -> dict[str, dict]:
    """The statistics of flat box arrays (see :func:`_flatten`) per class name in ``classes`` and ``all``."""
    total = len(flat["cls"])
    rates, rate_idx = yaw_rates(flat["inst"], flat["t"], flat["boxes"][:, YAW])
    speed = np.hypot(flat["boxes"][:, VX], flat["boxes"][:, VY])
    stats = {}
    for name in (*classes, "all"):
        mask = np.ones(total, bool) if name == "all" else flat["cls"] == name
        n = int(mask.sum())
        r = rates[mask[rate_idx]] if len(rates) else np.zeros(0)
        n_inst = len(set(flat["inst"][mask].tolist()))
        stats[name] = {
            "boxes": n,
            "share": n / total if total else float("nan"),
            "w": _mean(flat["boxes"][mask, 3]),
            "l": _mean(flat["boxes"][mask, 4]),
            "h": _mean(flat["boxes"][mask, 5]),
            "speed": _mean(speed[mask]),
            "moving": _mean(speed[mask] > MOVING_SPEED),
            "yaw_rate": _mean(r),
            "zero_pts": _mean(flat["pts"][mask] == 0),
            "instances": n_inst,
            "track_len": n / n_inst if n_inst else float("nan"),
        }
    return stats


def _mean(x: np.ndarray) -> float:
    return float(np.mean(x)) if len(x) else float("nan")


def format_table(stats: dict[str, dict], title: str = "") -> str:
    """A fixed-width text table of :func:`class_statistics` output."""
    head = f"{'class':<11}" + " ".join(f"{h:>{len(fmt.format(0 if 'd}' in fmt else 0.0))}}" for _, h, fmt in COLUMNS)
    lines = [title] if title else []
    lines += [head, "-" * len(head)]
    for name, row in stats.items():
        cells = [_cell(row.get(key), fmt) for key, _, fmt in COLUMNS]
        lines.append(f"{name:<11}" + " ".join(cells))
    return "\n".join(lines)


def format_comparison(stats: dict[str, dict], reference: dict[str, dict], labels: tuple[str, str]) -> str:
    """Side-by-side table: for every column, ``stats`` value then ``reference`` value, per class."""
    keys = ("share", "w", "l", "h", "speed", "moving", "yaw_rate", "zero_pts")
    head = f"{'class':<11}" + "".join(f"{k:>18}" for k in keys)
    sub = f"{'':<11}" + "".join(f"{labels[0][:8]:>9}{labels[1][:8]:>9}" for _ in keys)
    lines = [head, sub, "-" * len(head)]
    for name in stats:
        a, b = stats[name], reference.get(name, {})
        cells = "".join(f"{_num(a.get(k)):>9}{_num(b.get(k)):>9}" for k in keys)
        lines.append(f"{name:<11}{cells}")
    return "\n".join(lines)


def _num(v) -> str:
    return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v:.3f}"


def _cell(value, fmt: str) -> str:
    width = len(fmt.format(0 if "d}" in fmt else 0.0))
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return f"{'-':>{width}}"
    return fmt.format(value)


def write_stats_json(path: str | os.PathLike, stats: dict[str, dict], meta: dict) -> None:
    """Write statistics (NaN as null) with a ``meta`` block, atomically."""
    clean = {
        c: {k: (None if isinstance(v, float) and np.isnan(v) else v) for k, v in row.items()}
        for c, row in stats.items()
    }
    write_json_atomic(path, {"meta": meta, "classes": clean}, indent=1)


def nuscenes_statistics(dataroot: str | os.PathLike, version: str, splits: list[str], nusc=None) -> dict[str, dict]:
    """:func:`class_statistics` over the union of ``splits`` of a nuScenes(-format) dataset."""
    from grutrack.data.detection_sim import nusc_gt_frames, open_dataset

    nusc = nusc if nusc is not None else open_dataset(dataroot, version)
    frames = [f for split in splits for f in nusc_gt_frames(nusc, split)]
    return class_statistics(frames)
