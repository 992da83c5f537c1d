"""Bird's-eye drawing of :class:`grutrack.render.views.FrameView` frames: PNG per frame, one GIF per scene, and
a strip of key frames for the reports.

The view is ego-centred with the ego heading pointing up, at a fixed scale (``HALF_RANGE`` metres from the ego
to each edge, range rings every 10 m). Layout is fixed in pixels (:class:`Layout`), so a point of the scene maps
to a known pixel (:meth:`Layout.pixel`). matplotlib and Pillow are imported inside the functions.

Drawing code (one colour per meaning; track colours avoid them):
ground truth: thin dark outline; missed ground truth (FN): thick orange dashed outline; ground truth the
evaluator drops (nuScenes: outside the class range, no points; AV2: beyond the range, off the drivable area):
light grey. Tracks: filled in their id's colour with a trail of their last centres and a heading mark;
false-positive tracks: filled red; tracks that are not scored (nuScenes: below their class's best-MOTA threshold,
class without a threshold, outside the range; AV2: below the tuned threshold, beyond the range, off the drivable
area): grey outline.
Id switch: magenta ring on the ground truth, labelled with the old and new track. Raw detections: dotted
dark outline over the tracks.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grutrack.render.views import GT_IGNORED, GT_MISS, TR_FP, TR_MATCH, TR_SWITCH, FrameView

HALF_RANGE = 55.0  # metres from the ego to each edge of the view
RINGS = (10.0, 20.0, 30.0, 40.0, 50.0)  # range rings, metres
TRAIL_FRAMES = 6
CLASS_CHARS = 15  # class names longer than this are cut in the text panel

#: what the text panel says about the matching (nuScenes: the devkit's; AV2: TrackEval's CLEAR, see render.av2)
NUSC_NOTES = (
    "- : class without an achieved",
    "    threshold (only misses count)",
    "thr: track-score threshold of the",
    "     class (best MOTA); match within",
    "     2 m centre distance",
)

FP_COLOR = "#e6194b"  # false-positive track (fill and edge)
MISS_COLOR = "#ff8c00"  # missed ground truth (FN)
IDS_COLOR = "#c000c0"  # id switch ring
GT_COLOR = "#1a1a1a"  # evaluated ground truth
IGNORED_COLOR = "#a8a8a8"  # not evaluated / not scored
DET_COLOR = "#404040"  # raw detections (dotted, over the tracks)
#: track colours by id: blues, greens, purples, browns, teals (no red, orange or magenta)
TRACK_PALETTE = (
    "#1f77b4",
    "#2ca02c",
    "#9467bd",
    "#8c564b",
    "#17becf",
    "#7f7f00",
    "#393b79",
    "#637939",
    "#5254a3",
    "#3182bd",
    "#31a354",
    "#756bb1",
    "#0b6e4f",
    "#4a6fa5",
    "#6a3d9a",
    "#005f73",
)


@dataclass(frozen=True)
class Layout:
    """Figure geometry in pixels: a square BEV panel at (``margin``, ``margin``) from the top-left corner and a
    text / legend panel on its right."""

    width: int = 1060
    height: int = 760
    panel: int = 740
    margin: int = 10
    dpi: int = 100

    def pixel(self, uv: np.ndarray) -> np.ndarray:
        """Plot coordinates ``(N, 2)`` (metres, ego at 0, heading up) -> pixel ``(N, 2)`` (column, row) from
        the image's top-left corner, float."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        s = self.panel / (2 * HALF_RANGE)
        col = self.margin + (uv[:, 0] + HALF_RANGE) * s
        row = self.margin + (HALF_RANGE - uv[:, 1]) * s
        return np.column_stack([col, row])


LAYOUT = Layout()


def to_plot(xy: np.ndarray, ego_xy: np.ndarray, ego_yaw: float) -> np.ndarray:
    """Global ``(..., 2)`` metres -> plot coordinates ``(..., 2)``: ego at 0, ego heading up (+v), its left
    to the left (-u). ``u = -y_ego``, ``v = x_ego`` with ``p_ego = R(-yaw_ego) (p - t_ego)``."""
    d = np.asarray(xy, dtype=np.float64) - ego_xy
    c, s = np.cos(ego_yaw), np.sin(ego_yaw)
    x_ego = c * d[..., 0] + s * d[..., 1]
    y_ego = -s * d[..., 0] + c * d[..., 1]
    return np.stack([-y_ego, x_ego], axis=-1)


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """``(N, 5) [x, y, w, l, yaw]`` -> ``(N, 4, 2)`` corners, global metres (length along the heading)."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)
    half_l, half_w = boxes[:, 3:4] / 2, boxes[:, 2:3] / 2
    lx = np.array([1, 1, -1, -1]) * half_l  # (N, 4) along the heading
    ly = np.array([1, -1, -1, 1]) * half_w  # (N, 4) to the left
    c, s = np.cos(boxes[:, 4:5]), np.sin(boxes[:, 4:5])
    return np.stack([boxes[:, 0:1] + c * lx - s * ly, boxes[:, 1:2] + s * lx + c * ly], axis=-1)


def heading_segments(boxes: np.ndarray) -> np.ndarray:
    """``(N, 5)`` boxes -> ``(N, 2, 2)`` segments from the centre to the middle of the front edge."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 5)
    front = boxes[:, :2] + boxes[:, 3:4] / 2 * np.column_stack([np.cos(boxes[:, 4]), np.sin(boxes[:, 4])])
    return np.stack([boxes[:, :2], front], axis=1)


def track_color(track_id) -> str:
    """A stable colour for a track id (CRC32 of its text into :data:`TRACK_PALETTE`)."""
    return TRACK_PALETTE[zlib.crc32(str(track_id).encode()) % len(TRACK_PALETTE)]


class BevCanvas:
    """One reusable figure: static parts (rings, ego, legend) drawn once, the frame's artists replaced per frame."""

    def __init__(
        self,
        layout: Layout = LAYOUT,
        thresholds: dict | None = None,
        notes: tuple[str, ...] = NUSC_NOTES,
        banner: str = "",
    ):
        import matplotlib

        matplotlib.use("Agg", force=False)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.lines import Line2D
        from matplotlib.patches import Circle, Patch, Rectangle

        self.layout = L = layout
        self.fig = Figure(figsize=(L.width / L.dpi, L.height / L.dpi), dpi=L.dpi, facecolor="white")
        self.canvas = FigureCanvasAgg(self.fig)
        ax = self.ax = self.fig.add_axes(
            [L.margin / L.width, 1 - (L.margin + L.panel) / L.height, L.panel / L.width, L.panel / L.height]
        )
        ax.set_xlim(-HALF_RANGE, HALF_RANGE)
        ax.set_ylim(-HALF_RANGE, HALF_RANGE)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_facecolor("white")
        for r in RINGS:
            ax.add_patch(Circle((0, 0), r, fill=False, lw=0.6, color="#d9d9d9", zorder=0))
            ax.text(r * 0.7071 + 0.6, r * 0.7071 + 0.6, f"{r:.0f} m", color="#a0a0a0", fontsize=7, zorder=0)
        ax.add_patch(Rectangle((-0.95, -2.3), 1.9, 4.6, color="#404040", zorder=6))
        ax.plot([0, 0], [2.3, 4.0], color="#404040", lw=1.5, zorder=6)
        x0 = (L.margin * 2 + L.panel) / L.width
        handles = [
            Patch(facecolor="#9ecae1", edgecolor=TRACK_PALETTE[0], label="track (colour = id), trail, heading"),
            Patch(facecolor=FP_COLOR, edgecolor=FP_COLOR, label="false-positive track (FP)"),
            Patch(facecolor="none", edgecolor=GT_COLOR, label="ground truth"),
            Patch(facecolor="none", edgecolor=MISS_COLOR, linestyle="--", lw=2, label="missed ground truth (FN)"),
            Line2D(
                [],
                [],
                marker="o",
                ls="",
                markersize=12,
                markerfacecolor="none",
                markeredgecolor=IDS_COLOR,
                markeredgewidth=2.5,
                label="id switch (IDS)",
            ),
            Patch(facecolor="none", edgecolor=IGNORED_COLOR, label="track not scored / GT not evaluated (grey)"),
            Patch(facecolor="none", edgecolor=DET_COLOR, linestyle=":", label="raw detection (dotted)"),
        ]
        self.fig.legend(
            handles=handles,
            loc="lower left",
            bbox_to_anchor=(x0 - 0.005, 10 / L.height),
            fontsize=8,
            frameon=False,
            handlelength=1.6,
        )
        self.thresholds = thresholds or {}
        self.notes = tuple(notes)
        self.banner = banner  # the first line under every title, e.g. that the scenes are SYNTHETIC
        self._dynamic: list = []
        # Static parts are drawn once; each frame restores them and draws only its own artists (blitting). The
        # frame's text panel is drawn with Pillow (matplotlib's text rendering would dominate the frame time).
        from matplotlib import font_manager
        from PIL import ImageFont

        self._font = ImageFont.truetype(font_manager.findfont("DejaVu Sans Mono"), 12)
        self._font_title = ImageFont.truetype(font_manager.findfont("DejaVu Sans:bold"), 15)
        self.canvas.draw()
        self._background = self.canvas.copy_from_bbox(self.fig.bbox)

    # -- one frame ---------------------------------------------------------------------------------------------

    def draw(self, v: FrameView, n_frames: int, t0: int) -> np.ndarray:
        """Draw one frame; returns its pixels ``(H, W, 3)`` uint8."""
        from matplotlib.collections import LineCollection, PolyCollection

        for a in self._dynamic:
            a.remove()
        self._dynamic = []
        self.canvas.restore_region(self._background)
        ax = self.ax
        P = lambda xy: to_plot(xy, v.ego_xy, v.ego_yaw)  # noqa: E731

        if len(v.det_boxes):
            self._add(
                ax.add_collection(
                    PolyCollection(
                        P(box_corners(v.det_boxes)),
                        facecolors="none",
                        edgecolors=DET_COLOR,
                        linewidths=0.8,
                        alpha=0.8,
                        linestyles=(0, (1, 1.5)),
                        zorder=4.5,
                    )
                )
            )
        # Trails below the boxes.
        segs = [P(t) for t in v.trails if len(t) > 1]
        cols = [track_color(tid) for tid, t in zip(v.tr_ids, v.trails) if len(t) > 1]
        if segs:
            self._add(ax.add_collection(LineCollection(segs, colors=cols, linewidths=1.3, alpha=0.8, zorder=2)))
        if len(v.gt_boxes):
            corners = P(box_corners(v.gt_boxes))
            edge = [MISS_COLOR if s == GT_MISS else IGNORED_COLOR if s == GT_IGNORED else GT_COLOR for s in v.gt_state]
            lw = [2.2 if s == GT_MISS else 0.6 if s == GT_IGNORED else 1.0 for s in v.gt_state]
            ls = [(0, (3, 2)) if s == GT_MISS else "solid" for s in v.gt_state]
            self._add(
                ax.add_collection(
                    PolyCollection(corners, facecolors="none", edgecolors=edge, linewidths=lw, linestyles=ls, zorder=3)
                )
            )
        if len(v.tr_boxes):
            corners = P(box_corners(v.tr_boxes))
            scored = np.isin(v.tr_state, (TR_MATCH, TR_SWITCH, TR_FP))
            idc = [track_color(t) for t in v.tr_ids]
            face = [FP_COLOR if s == TR_FP else c if ok else "none" for s, c, ok in zip(v.tr_state, idc, scored)]
            edge = [FP_COLOR if s == TR_FP else c if ok else IGNORED_COLOR for s, c, ok in zip(v.tr_state, idc, scored)]
            alpha_face = [0.9 if s == TR_FP else 0.35 for s in v.tr_state]
            from matplotlib.colors import to_rgba

            fc = [(0, 0, 0, 0) if f == "none" else to_rgba(f, a) for f, a in zip(face, alpha_face)]
            order = np.argsort(v.tr_state == TR_FP, kind="stable")  # false positives on top
            self._add(
                ax.add_collection(
                    PolyCollection(
                        corners[order],
                        facecolors=[fc[i] for i in order],
                        edgecolors=[edge[i] for i in order],
                        linewidths=[1.8 if scored[i] else 0.8 for i in order],
                        zorder=4,
                    )
                )
            )
            heads = P(heading_segments(v.tr_boxes))
            self._add(ax.add_collection(LineCollection(heads, colors=edge, linewidths=1.6, zorder=5)))
            for fp in v.false_positives:
                uv = P(np.asarray(fp["xy"]))
                if np.all(np.abs(uv) < HALF_RANGE - 4):
                    self._add(
                        ax.text(
                            uv[0] + 1.8,
                            uv[1] + 1.2,
                            f"FP {fp['class']} {_short(fp['track_id'])}",
                            color=FP_COLOR,
                            fontsize=7,
                            weight="bold",
                            zorder=7,
                            bbox=_HALO,
                        )
                    )
        for sw in v.id_switches:
            uv = P(np.asarray(sw["xy"]))
            if sw["previous_track_id"] in v.tr_ids:  # where the track that lost the object is now
                old = P(v.tr_boxes[v.tr_ids.index(sw["previous_track_id"]), :2])
                self._add(
                    ax.plot([uv[0], old[0]], [uv[1], old[1]], color=IDS_COLOR, lw=1.4, ls=(0, (2, 2)), zorder=7)[0]
                )
            self._add(
                ax.scatter([uv[0]], [uv[1]], s=420, facecolors="none", edgecolors=IDS_COLOR, linewidths=2.8, zorder=7)
            )
            self._add(
                ax.text(
                    uv[0] + 3.2,
                    uv[1] - 1.0,
                    f"IDS {_short(sw['previous_track_id'])} \u2192 {_short(sw['track_id'])}",
                    color=IDS_COLOR,
                    fontsize=8,
                    weight="bold",
                    zorder=7,
                    bbox=_HALO,
                )
            )

        for a in self._dynamic:
            ax.draw_artist(a)
        from PIL import Image, ImageDraw

        im = Image.fromarray(np.asarray(self.canvas.buffer_rgba())[:, :, :3])
        d = ImageDraw.Draw(im)
        x = 2 * self.layout.margin + self.layout.panel
        name = v.scene if len(v.scene) <= 16 else v.scene[:8] + "\u2026"  # an AV2 log id: in full below
        d.text((x, 12), f"{name}   frame {v.index + 1}/{n_frames}", fill="black", font=self._font_title)
        d.multiline_text((x, 40), self._info(v, t0), fill="black", font=self._font, spacing=3)
        return np.asarray(im)

    def _add(self, artist) -> None:
        artist.set_animated(True)
        self._dynamic.append(artist)

    def _info(self, v: FrameView, t0: int) -> str:
        tot = v.totals()
        shown = [(c, k) for c, k in v.counts.items() if any(k[x] for x in k)]
        w = max([11] + [min(len(c), CLASS_CHARS) + 1 for c, _ in shown])
        lines = [self.banner, ""] if self.banner else []
        lines += [
            f"t = {(v.timestamp - t0) / 1e6:5.1f} s   {v.caption or 'sample ' + v.sample_token[:8]}",
            "",
            "this frame (evaluator's decisions)",
            f"  TP {tot['tp']:3d}   FP {tot['fp']:3d}",
            f"  FN {tot['fn']:3d}   IDS {tot['ids']:2d}",
            "",
            f"{'class':<{w}}{'TP':>4}{'FP':>4}{'FN':>4}{'IDS':>4}  thr",
        ]
        for c, k in shown:
            thr = self.thresholds.get(c)
            name = c if len(c) <= CLASS_CHARS else c[: CLASS_CHARS - 1] + "\u2026"
            lines.append(
                f"{name:<{w}}{k['tp']:>4}{_n(k['fp']):>4}{k['fn']:>4}{_n(k['ids']):>4}  "
                + (f"{thr:.2f}" if thr is not None else "none")
            )
        lines += [
            "",
            *self.notes,
            "",
            "ego heading up, rings every 10 m",
            f"trail: last {TRAIL_FRAMES} frames",
            "IDS old \u2192 new track (dashed: old",
            "     track's position)",
        ]
        return "\n".join(lines)


_HALO = {"facecolor": "white", "alpha": 0.75, "edgecolor": "none", "pad": 0.8}


def _n(v) -> str:
    return "-" if v is None else str(v)


def _short(track_id) -> str:
    s = "none" if track_id is None else str(track_id)
    return s if len(s) <= 8 else s[:7] + "\u2026"


# ----------------------------------------------------------------------------------------------------------------
# Files
# ----------------------------------------------------------------------------------------------------------------


def write_png(path: Path, rgb: np.ndarray) -> None:
    """Write ``(H, W, 3)`` uint8 as PNG atomically."""
    from PIL import Image

    from grutrack.io import atomic_path

    with atomic_path(path) as tmp:
        Image.fromarray(rgb).save(tmp, format="PNG", compress_level=1)


def gif_frame(rgb: np.ndarray, scale: float = 0.75):
    """One animation frame: ``(H, W, 3)`` uint8 resized by ``scale`` and reduced to a 64-colour palette (a
    Pillow image of about 0.4 MB, so a scene's animation is held in memory at that size, not at full size)."""
    from PIL import Image

    im = Image.fromarray(rgb)
    if scale != 1:
        im = im.resize((int(im.width * scale), int(im.height * scale)), Image.BILINEAR)
    return im.quantize(colors=64, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)


def write_gif(path: Path, frames: list, seconds_per_frame: float = 0.5) -> None:
    """One looping animated GIF of :func:`gif_frame` images, written atomically."""
    from grutrack.io import atomic_path

    with atomic_path(path) as tmp:
        frames[0].save(
            tmp, format="GIF", save_all=True, append_images=frames[1:], loop=0, duration=int(seconds_per_frame * 1000)
        )


def render_scene(
    views: list[FrameView], out_dir: Path, thresholds: dict, canvas: BevCanvas | None = None, animation: bool = True
) -> tuple[list[Path], Path | None]:
    """PNG per frame (``out_dir/<scene>/frame_NNN.png``, NNN from 001 as in the title) and
    ``out_dir/<scene>.gif``; returns their paths."""
    canvas = canvas or BevCanvas(thresholds=thresholds)
    scene = views[0].scene
    folder = Path(out_dir) / scene
    folder.mkdir(parents=True, exist_ok=True)
    pngs, frames = [], []
    t0 = views[0].timestamp
    for v in views:
        rgb = canvas.draw(v, len(views), t0)
        path = folder / f"frame_{v.index + 1:03d}.png"  # the frame number of the title, from 1
        write_png(path, rgb)
        pngs.append(path)
        if animation:
            frames.append(gif_frame(rgb))
    gif = None
    if animation:
        gif = Path(out_dir) / f"{scene}.gif"
        write_gif(gif, frames)
    return pngs, gif


def key_frames(frames: list[dict], k: int = 4) -> list[dict]:
    """Up to ``k`` frame records of counts.json to show: the id-switch moments first, then the frames with the
    most FP + FN; returned in time order."""
    switch = [f for f in frames if f["id_switches"]]
    rest = sorted(
        (f for f in frames if not f["id_switches"]),
        key=lambda f: (-(f["totals"]["fp"] + f["totals"]["fn"]), f["index"]),
    )
    return sorted((switch + rest)[:k], key=lambda f: f["index"])


def strip_from_counts(
    counts_json: str | Path, out_png: str | Path, k: int = 4, scale: float = 0.45, layout: Layout = LAYOUT
) -> dict:
    """A strip of ``k`` key frames (BEV panels of the rendered PNGs, resized by ``scale``, side by side) of the
    rendered scene with the most IDS + FP + FN, from a ``grutrack render`` folder; written as one PNG.

    :return: ``{"scene", "frames": [frame number, 1-based], "totals": {tp, fp, fn, ids} over the shown frames,
        "id_switches": [(old, new), ...]}``.
    """
    from PIL import Image

    from grutrack.errors import InputFormatError
    from grutrack.io import read_json

    counts_json = Path(counts_json)
    doc = read_json(counts_json, "render counts")
    scenes = doc.get("scenes") if isinstance(doc, dict) else None
    if not scenes or not all(s.get("frames") for s in scenes):
        raise InputFormatError(f"{counts_json}: no rendered scene with frames (a grutrack render counts.json)")
    scene = max(scenes, key=lambda s: s.get("errors", 0))
    picks = key_frames(scene["frames"], k)
    side = int(layout.panel * scale)
    panels = []
    for f in picks:
        png = counts_json.parent / f["png"]
        if not png.is_file():
            raise InputFormatError(f"{counts_json}: frame image {png} is missing")
        with Image.open(png) as im:
            crop = im.convert("RGB").crop(
                (layout.margin, layout.margin, layout.margin + layout.panel, layout.margin + layout.panel)
            )
        panels.append(np.asarray(crop.resize((side, side), Image.LANCZOS)))
    from matplotlib import font_manager
    from PIL import ImageDraw, ImageFont

    font = ImageFont.truetype(font_manager.findfont("DejaVu Sans"), 13)
    gap = np.full((side + 24, 6, 3), 255, dtype=np.uint8)
    labelled = []
    for f, p in zip(picks, panels):
        im = Image.new("RGB", (side, side + 24), "white")
        im.paste(Image.fromarray(p), (0, 24))
        t = f["totals"]
        sw = ", ".join(f"{_short(s['previous_track_id'])}\u2192{_short(s['track_id'])}" for s in f["id_switches"])
        ImageDraw.Draw(im).text(
            (4, 4),
            f"frame {f['index'] + 1}: " + (f"IDS {sw}  " if sw else "") + f"FP {t['fp']}  FN {t['fn']}",
            fill="black",
            font=font,
        )
        labelled.append(np.asarray(im))
    write_png(Path(out_png), np.concatenate([x for p in labelled for x in (p, gap)][:-1], axis=1))
    totals = {key: sum(f["totals"][key] for f in picks) for key in ("tp", "fp", "fn", "ids")}
    return {
        "scene": scene["name"],
        "frames": [f["index"] + 1 for f in picks],
        "totals": totals,
        "id_switches": [(s["previous_track_id"], s["track_id"]) for f in picks for s in f["id_switches"]],
    }
