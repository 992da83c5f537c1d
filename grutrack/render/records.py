"""The ``counts.json`` entries of a render (one per scene, one per frame) and, on request, the scene's Rerun
recording (:mod:`grutrack.render.rerun_log`). Kept apart from :mod:`grutrack.render.views`, which the recording
code itself imports, so that the render modules import one another without a cycle."""

from __future__ import annotations

from pathlib import Path

from grutrack.render.views import FrameView


def frame_record(v: FrameView, png: Path, out: Path) -> dict:
    """The counts.json entry of one frame."""
    return {
        "index": v.index,
        "frame": v.index + 1,
        "sample_token": v.sample_token,
        "timestamp": v.timestamp,
        "png": str(png.relative_to(out)),
        "ego": {"xy": [round(float(x), 4) for x in v.ego_xy], "yaw": round(v.ego_yaw, 6)},
        "totals": v.totals(),
        "per_class": v.counts,
        "false_positives": v.false_positives,
        "missed": v.missed,
        "id_switches": v.id_switches,
    }


def scene_record(
    scene, errors: int, views: list[FrameView], pngs: list[Path], gif: Path | None, out: Path, rerun: bool
) -> dict:
    """The counts.json entry of one rendered scene (``scene``: a canonical scene; ``errors``: its IDS + FP + FN);
    writes ``out/<scene>.rrd`` too when ``rerun``."""
    return {
        "name": scene.name,
        "token": scene.token,
        "errors": errors,
        "animation": str(gif.relative_to(out)) if gif else None,
        "rerun": _recording(out, views) if rerun else None,
        "frames": [frame_record(v, p, out) for v, p in zip(views, pngs)],
    }


def _recording(out: Path, views: list[FrameView]) -> str:
    """Write ``out/<scene>.rrd`` (:mod:`grutrack.render.rerun_log`); returns its path relative to ``out``."""
    from grutrack.render.rerun_log import write_recording

    path = out / f"{views[0].scene}.rrd"
    write_recording(path, views)
    return str(path.relative_to(out))
