"""Conversion of a downloaded LT3D detection table (Argoverse 2; feather, CSV or pickled DataFrame) into a
feather table of one split's detections: the table checked against its description (columns, numbers, sizes,
quaternions, scores, categories, timestamps: ``lt3d_detections.schema.yaml``), rows restricted to the split's logs,
written atomically. Whether each timestamp is a sweep of its log is checked when ``grutrack track --dataset av2``
loads the table."""

from __future__ import annotations

from pathlib import Path

from grutrack.data.av2 import list_logs
from grutrack.data.lt3d_detections import read_detection_table
from grutrack.errors import InputFormatError
from grutrack.io import atomic_path


def convert_lt3d_detections(raw: str | Path, dataroot: str | Path, split: str, out: str | Path) -> dict:
    """Keep the rows of the split's logs and write them as feather; returns counts."""
    df = read_detection_table(raw)
    logs = set(list_logs(dataroot, split))
    keep = df["log_id"].astype(str).isin(logs)
    if not keep.any():
        raise InputFormatError(
            f"{raw}: none of its {len(df)} rows belongs to a log of split '{split}' under {dataroot} ({len(logs)} logs)"
        )
    sub = df[keep].reset_index(drop=True)
    with atomic_path(out) as tmp:
        sub.to_feather(tmp)
    return {"rows": int(len(sub)), "logs": int(sub["log_id"].nunique()), "dropped_rows": int((~keep).sum())}


def describe(stats: dict) -> str:
    """One line about a conversion."""
    return f"{stats['rows']} rows on {stats['logs']} logs ({stats['dropped_rows']} rows of other logs dropped)"
