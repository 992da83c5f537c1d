"""Conversion of a downloaded nuScenes detection file (official detection-submission JSON, plain or inside a
zip archive) into the detection JSON of one split: validated sample by sample, restricted to the split's
samples, its ``meta`` checked and kept, written atomically."""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path

from grutrack.data.nusc_detections import detection_meta, read_detection_json, results_boxes
from grutrack.data.nuscenes import load_scenes, open_nuscenes
from grutrack.errors import InputFormatError
from grutrack.io import atomic_path, write_json_atomic


def extract_member(archive: str | Path, member: str, out_dir: str | Path) -> Path:
    """Extract one file of a zip archive into ``out_dir``; a clear error when it is not there."""
    archive = Path(archive)
    try:
        with zipfile.ZipFile(archive) as zf:
            if member not in zf.namelist():
                raise InputFormatError(
                    f"{archive}: archive has no member '{member}' (members: {', '.join(zf.namelist()[:10])})"
                )
            target = Path(out_dir) / Path(member).name
            with atomic_path(target) as tmp, zf.open(member) as src, open(tmp, "wb") as dst:
                shutil.copyfileobj(src, dst)
    except zipfile.BadZipFile as exc:
        raise InputFormatError(f"{archive}: not a zip archive ({exc})") from exc
    return target


def convert_nuscenes_detections(
    raw: str | Path, dataroot: str | Path, version: str, split: str, out: str | Path, member: str | None = None
) -> dict:
    """Validate ``raw`` against the split and write the split's detections to ``out`` with the file's meta
    (checked: the five booleans of the official meta); returns counts."""
    nusc = open_nuscenes(dataroot, version)
    tokens = [f.token for s in load_scenes(nusc, split) for f in s.frames]
    with tempfile.TemporaryDirectory(prefix="grutrack-convert-") as tmp:
        path = extract_member(raw, member, tmp) if member else Path(raw)
        data = read_detection_json(path)
        results_boxes(path, data["results"], tokens)  # every sample present, every box valid (names sample, field)
        meta = detection_meta(data, path)
    results = {t: data["results"][t] for t in tokens}
    write_json_atomic(out, {"meta": meta, "results": results})
    return {
        "samples": len(tokens),
        "boxes": sum(len(v) for v in results.values()),
        "dropped_samples": len(data["results"]) - len(tokens),
    }


def describe(stats: dict) -> str:
    """One line about a conversion."""
    return (
        f"{stats['samples']} samples, {stats['boxes']} boxes "
        f"({stats['dropped_samples']} samples of other splits dropped)"
    )
