"""A Rerun recording (``.rrd``) of rendered frames, for interactive 3D viewing (``rerun DIR/<scene>.rrd``): the
boxes and the evaluator's decisions of :class:`grutrack.render.views.FrameView` frames, in the same colours as the
bird's-eye PNGs, on a ``frame`` timeline.

Two halves, so that the recording's content is testable without rerun-sdk: :func:`frame_layers` (numpy only)
turns a frame into the arrays of each entity; :func:`write_recording` logs them with rerun-sdk (the optional
extra ``pip install grutrack[rerun]``, imported inside the function).

Entities (world frame = the dataset's global / city frame shifted by ``origin``, the scene's first ego position,
metres; z up): ``world/ego`` (one box), ``world/ground_truth``, ``world/tracks``, ``world/detections``
(``Boxes3D``), ``world/trails`` (``LineStrips3D``), ``world/id_switches`` (``Points3D`` at the switched ground
truth), ``counts`` (``TextDocument``, the frame's counts in markdown). Time: timeline ``frame`` (1-based, as the
PNGs are numbered) and ``time`` (seconds since the scene's first frame).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from grutrack.render.views import GT_IGNORED, GT_MISS, GT_SWITCH, TR_FP, TR_MATCH, TR_SWITCH, FrameView

EGO_SIZE = (4.6, 1.9, 1.7)  # length, width, height of the ego box, metres (the PNGs' ego rectangle)
DEFAULT_HEIGHT = 1.5  # height of a box whose height is not known, metres
INSTALL_HINT = "pip install grutrack[rerun]"


def _rgba(hex_colour: str, alpha: float = 1.0) -> np.ndarray:
    h = hex_colour.lstrip("#")
    return np.array([int(h[i : i + 2], 16) for i in (0, 2, 4)] + [int(round(alpha * 255))], dtype=np.uint8)


def _zh(zh: np.ndarray | None, n: int, ego_z: float) -> np.ndarray:
    """``(n, 2) [z of the centre, height]``: the given one, or on the ego's ground at the default height."""
    if zh is not None and len(zh) == n:
        return np.asarray(zh, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([np.full(n, ego_z + DEFAULT_HEIGHT / 2), np.full(n, DEFAULT_HEIGHT)])


def _boxes(b5: np.ndarray, zh: np.ndarray, origin: np.ndarray) -> dict:
    """``(N, 5) [x, y, w, l, yaw]`` + ``(N, 2) [z, h]`` -> centres (N, 3), half sizes (N, 3) [l/2, w/2, h/2]
    (box x along its heading), yaw (N,) radians; float32 centres relative to ``origin`` (3,)."""
    b5 = np.asarray(b5, dtype=np.float64).reshape(-1, 5)
    centres = np.column_stack([b5[:, :2], zh[:, 0]]) - origin
    half = np.column_stack([b5[:, 3], b5[:, 2], zh[:, 1]]) / 2
    return {"centers": centres.astype(np.float32), "half_sizes": half.astype(np.float32), "yaw": b5[:, 4].copy()}


def frame_layers(v: FrameView, origin: np.ndarray) -> dict[str, dict]:
    """What one frame logs: ``{entity path: arrays}``.

    Box entities: ``centers (N, 3)`` float32 metres (global minus ``origin``), ``half_sizes (N, 3)`` float32,
    ``yaw (N,)`` radians, ``colors (N, 4)`` uint8 RGBA, ``labels`` (N,) str. ``world/trails``: ``strips``
    (list of (K, 3) float32) and ``colors``; ``world/id_switches``: ``positions (M, 3)``, ``colors``, ``labels``;
    ``counts``: ``text`` (markdown).
    """
    from grutrack.render.draw import DET_COLOR, FP_COLOR, GT_COLOR, IDS_COLOR, IGNORED_COLOR, MISS_COLOR, track_color

    origin = np.asarray(origin, dtype=np.float64).reshape(3)
    out: dict[str, dict] = {}
    ego = np.array([[v.ego_xy[0], v.ego_xy[1], EGO_SIZE[1], EGO_SIZE[0], v.ego_yaw]])
    out["world/ego"] = {
        **_boxes(ego, np.array([[v.ego_z + EGO_SIZE[2] / 2, EGO_SIZE[2]]]), origin),
        "colors": np.array([_rgba("#404040")]),
        "labels": ["ego"],
    }

    gt_col = {GT_MISS: _rgba(MISS_COLOR), GT_IGNORED: _rgba(IGNORED_COLOR), GT_SWITCH: _rgba(IDS_COLOR)}
    out["world/ground_truth"] = {
        **_boxes(v.gt_boxes, _zh(v.gt_zh, len(v.gt_boxes), v.ego_z), origin),
        "colors": np.array([gt_col.get(int(s), _rgba(GT_COLOR)) for s in v.gt_state], dtype=np.uint8).reshape(-1, 4),
        "labels": [
            f"{c} {'FN' if s == GT_MISS else 'IDS' if s == GT_SWITCH else ''}".strip()
            for c, s in zip(v.gt_cls, v.gt_state)
        ],
    }

    scored = np.isin(v.tr_state, (TR_MATCH, TR_SWITCH, TR_FP))
    tr_colors = [
        _rgba(FP_COLOR) if s == TR_FP else _rgba(track_color(t)) if ok else _rgba(IGNORED_COLOR)
        for t, s, ok in zip(v.tr_ids, v.tr_state, scored)
    ]
    out["world/tracks"] = {
        **_boxes(v.tr_boxes, _zh(v.tr_zh, len(v.tr_boxes), v.ego_z), origin),
        "colors": np.array(tr_colors, dtype=np.uint8).reshape(-1, 4),
        "labels": [
            f"{t} {c}" + (" FP" if s == TR_FP else "" if ok else " (not scored)")
            for t, c, s, ok in zip(v.tr_ids, v.tr_cls, v.tr_state, scored)
        ],
    }

    out["world/detections"] = {
        **_boxes(v.det_boxes, _zh(v.det_zh, len(v.det_boxes), v.ego_z), origin),
        "colors": np.tile(_rgba(DET_COLOR, 0.5), (len(v.det_boxes), 1)),
        "labels": [""] * len(v.det_boxes),
    }

    tz = dict(zip(v.tr_ids, _zh(v.tr_zh, len(v.tr_boxes), v.ego_z)[:, 0]))
    strips, colors = [], []
    for tid, t in zip(v.tr_ids, v.trails):
        if len(t) > 1:
            strips.append((np.column_stack([t, np.full(len(t), tz[tid])]) - origin).astype(np.float32))
            colors.append(_rgba(track_color(tid)))
    out["world/trails"] = {"strips": strips, "colors": np.array(colors, dtype=np.uint8).reshape(-1, 4)}

    gz = dict(zip(v.gt_ids, _zh(v.gt_zh, len(v.gt_boxes), v.ego_z)[:, 0]))
    pos = [[*sw["xy"], gz.get(sw["instance"], v.ego_z)] for sw in v.id_switches]
    out["world/id_switches"] = {
        "positions": (np.asarray(pos, dtype=np.float64).reshape(-1, 3) - origin).astype(np.float32),
        "colors": np.tile(_rgba(IDS_COLOR), (len(pos), 1)),
        "labels": [f"IDS {sw['previous_track_id']} \u2192 {sw['track_id']}" for sw in v.id_switches],
    }

    rows = [
        f"| {c} | {k['tp']} | {'-' if k['fp'] is None else k['fp']} | {k['fn']} | "
        f"{'-' if k['ids'] is None else k['ids']} |"
        for c, k in v.counts.items()
        if any(k.values())
    ]
    tot = v.totals()
    out["counts"] = {
        "text": "\n".join(
            [
                f"**{v.scene}**, frame {v.index + 1}: TP {tot['tp']}, FP {tot['fp']}, FN {tot['fn']}, IDS {tot['ids']}",
                "",
                "| class | TP | FP | FN | IDS |",
                "|---|---|---|---|---|",
                *rows,
            ]
        )
    }
    return out


def scene_origin(views: list[FrameView]) -> np.ndarray:
    """``(3,)`` the first frame's ego position: the recording's world origin."""
    return np.array([views[0].ego_xy[0], views[0].ego_xy[1], views[0].ego_z])


def import_rerun():
    """rerun-sdk, or :class:`ConfigError` with the install line when it is not installed."""
    from grutrack.errors import ConfigError

    try:
        import rerun
    except ImportError as exc:
        raise ConfigError(f"--rerun needs the optional rerun-sdk package: {INSTALL_HINT}") from exc
    return rerun


def write_recording(path: str | Path, views: list[FrameView]) -> dict:
    """Write one scene's frames as a Rerun recording at ``path`` (atomically); returns ``{"frames", "origin"}``."""
    from grutrack.io import atomic_path

    rr = import_rerun()
    origin = scene_origin(views)
    t0 = views[0].timestamp
    with atomic_path(path) as tmp:
        rec = rr.new_recording(application_id="grutrack", recording_id=f"{views[0].scene}", spawn=False)
        rec.save(str(tmp))
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        rec.log(
            "about",
            rr.TextDocument(
                f"grutrack render of {views[0].scene}: world = global frame minus ({origin[0]:.3f}, {origin[1]:.3f}, "
                f"{origin[2]:.3f}) m (the first ego position); "
                "colours as in the PNGs (tracks by id, false positives red, missed ground truth orange, id switches "
                "magenta, not scored / not evaluated grey)",
                media_type="text/markdown",
            ),
            static=True,
        )
        for v in views:
            _set_time(rec, v.index + 1, (v.timestamp - t0) / 1e6)
            for entity, d in frame_layers(v, origin).items():
                rec.log(entity, _archetype(rr, entity, d))
        rec.flush(blocking=True)
        rec.disconnect()
    return {"frames": len(views), "origin": [float(x) for x in origin]}


def _set_time(rec, frame: int, seconds: float) -> None:
    """Timeline ``frame`` and ``time`` (rerun-sdk 0.22 names; 0.23+ has ``set_time``)."""
    if hasattr(rec, "set_time"):
        rec.set_time("frame", sequence=frame)
        rec.set_time("time", duration=seconds)
    else:
        rec.set_time_sequence("frame", frame)
        rec.set_time_seconds("time", seconds)


def _archetype(rr, entity: str, d: dict):
    """The rerun archetype of one entity's arrays (see :func:`frame_layers`)."""
    if entity == "counts":
        return rr.TextDocument(d["text"], media_type="text/markdown")
    if entity == "world/trails":
        return rr.LineStrips3D(d["strips"], colors=d["colors"], radii=0.08)
    if entity == "world/id_switches":
        return rr.Points3D(d["positions"], colors=d["colors"], labels=d["labels"], radii=1.2)
    rot = [rr.RotationAxisAngle(axis=[0.0, 0.0, 1.0], radians=float(y)) for y in d["yaw"]]
    return rr.Boxes3D(
        centers=d["centers"],
        half_sizes=d["half_sizes"],
        rotation_axis_angles=rot,
        colors=d["colors"],
        labels=d["labels"] if any(d["labels"]) else None,
    )
