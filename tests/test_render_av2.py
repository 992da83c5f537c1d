"""``grutrack render --dataset av2`` on the two real AV2 val logs of ../shared/data/av2.

There are no real AV2 detections in the fixture: the detections are SIMULATED from the annotations
(grutrack.data.detection_sim, centerpoint profile, seed 0, as in test_av2.py) and tracked by the EKF with the
``ekf`` preset, its coasting Poly-MOT's (so that the id switches drawn stay as the default preset changes). The
counts drawn must be the official AV2 evaluator's CLEAR counts (CLR_TP, CLR_FP, CLR_FN, IDSW) for every category,
and the marks must be where the boxes are.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_av2 import LOG_A, LOG_B, lt3d_table, simulated_boxsets  # the simulated-detection helpers

from grutrack.cli import main
from grutrack.data import av2

FP_RGB = np.array([0xE6, 0x19, 0x4B])
FP_FILL_RGB = np.round(0.9 * FP_RGB + 0.1 * 255)  # the fill: alpha 0.9 over the white background
IDS_RGB = np.array([0xC0, 0x00, 0xC0])


@pytest.fixture(scope="module")
def rendered(av2_root, tmp_path_factory, ekf_coasting_keep):
    """(render folder, metrics JSON, submission pickle, detections) of the EKF on simulated detections, both
    logs rendered."""
    tmp = tmp_path_factory.mktemp("render_av2")
    scenes = av2.load_scenes(av2_root, "val", with_gt=True)
    vocab = av2.vocabulary()
    dets = tmp / "sim.feather"
    lt3d_table(scenes, simulated_boxsets(scenes, vocab, seed=0)).to_feather(dets)
    common = ["--dataset", "av2", "--dataroot", str(av2_root), "--split", "val"]
    sub, metrics, out = tmp / "ekf.pkl", tmp / "metrics.json", tmp / "render"
    # the ekf preset with Poly-MOT's coasting (motion.coast_*: keep, the preset before 2026-11-28): the tracks, and
    # so the errors drawn (id switches in both logs), stay put as the default preset's coasting improves
    assert (
        main(
            [
                "track",
                *common,
                "--detections",
                str(dets),
                "--tracker",
                "ekf",
                "--config",
                str(ekf_coasting_keep),
                "--out",
                str(sub),
                "--no-progress",
            ]
        )
        == 0
    )
    assert main(["evaluate", *common, "--submission", str(sub), "--out", str(metrics)]) == 0
    assert (
        main(
            [
                "render",
                *common,
                "--submission",
                str(sub),
                "--detections",
                str(dets),
                "--scene",
                LOG_A,
                LOG_B,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out, json.loads(metrics.read_text()), sub, dets


def _doc(out: Path) -> dict:
    return json.loads((out / "counts.json").read_text())


def _frames(doc: dict) -> list[tuple[str, dict]]:
    return [(s["name"], f) for s in doc["scenes"] for f in s["frames"]]


def _pixels(out: Path, rec: dict) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(out / rec["png"]).convert("RGB")).astype(int)


def _near(img: np.ndarray, rgb: np.ndarray, tol: int = 40) -> np.ndarray:
    return np.abs(img - rgb).sum(axis=-1) <= tol


def _ego(av2_root, log: str, timestamp_ns: int):
    """Ego (xy, yaw) from the log's city_SE3_egovehicle.feather (not from counts.json)."""
    from grutrack.boxes import yaw_from_quaternion

    poses = av2.read_poses(av2_root / "val" / log)
    r = int(poses.index(np.array([timestamp_ns]))[0])
    return poses.translation[r, :2], float(yaw_from_quaternion(poses.quaternion[r])[0])


def test_per_class_counts_equal_the_official_clear_counts(rendered):
    """Both logs rendered: per_class in counts.json is the official evaluator's CLR_TP / CLR_FP / CLR_FN / IDSW
    for each of the 26 categories; per-frame counts add up to it."""
    out, metrics, _, _ = rendered
    doc = _doc(out)
    assert doc["dataset"] == "av2" and doc["drivable_area_roi"] is True
    assert set(doc["per_class"]) == set(metrics["per_class"]) and len(doc["per_class"]) == 26
    for cls, counts in doc["per_class"].items():
        ref = metrics["per_class"][cls]
        assert counts == {"tp": ref["tp"], "fp": ref["fp"], "fn": ref["fn"], "ids": ref["idsw"]}, (cls, counts, ref)
        assert ref["tp"] + ref["fn"] == ref["gt_boxes"]
    # the run has every kind of decision, in several classes
    tot = {k: sum(c[k] for c in doc["per_class"].values()) for k in ("tp", "fp", "fn", "ids")}
    assert tot["tp"] > 1000 and tot["fp"] > 50 and tot["fn"] > 100 and tot["ids"] >= 2, tot
    frames = [f for _, f in _frames(doc)]
    assert len(frames) == 64
    for cls, counts in doc["per_class"].items():
        for k in ("tp", "fp", "fn", "ids"):
            assert sum(f["per_class"].get(cls, {}).get(k, 0) for f in frames) == counts[k], (cls, k)
    assert sum(len(f["false_positives"]) for f in frames) == tot["fp"]
    assert sum(len(f["missed"]) for f in frames) == tot["fn"]
    assert sum(len(f["id_switches"]) for f in frames) == tot["ids"]


def test_frames_and_animations_written(rendered):
    from PIL import Image

    out, _, _, _ = rendered
    doc = _doc(out)
    assert [s["name"] for s in doc["scenes"]] == [LOG_A, LOG_B]
    for s in doc["scenes"]:
        assert [f["frame"] for f in s["frames"]] == list(range(1, 33))
        assert all((out / f["png"]).is_file() for f in s["frames"])
        with Image.open(out / s["animation"]) as gif:
            assert gif.format == "GIF" and gif.n_frames == 32
        assert s["errors"] == sum(f["totals"][k] for f in s["frames"] for k in ("ids", "fp", "fn"))


def _box(sub_path: Path, log: str, timestamp_ns: int, track_id) -> tuple[np.ndarray, float, float]:
    """(centre xy, length, yaw) of a track's box in the submitted pickle."""
    from grutrack.export.av2_tracks import read_tracks_pickle

    frame = next(f for f in read_tracks_pickle(sub_path)[log] if f["timestamp_ns"] == timestamp_ns)
    k = list(frame["track_id"]).index(track_id)
    return frame["translation_m"][k, :2], float(frame["size"][k, 0]), float(frame["yaw"][k])


def _inside_any(xy: np.ndarray, frame: dict, mask: np.ndarray) -> bool:
    """Whether the point ``xy`` (2,) lies in the BEV box of any track of ``frame`` selected by ``mask``."""
    d = xy - frame["translation_m"][mask, :2]
    yaw = frame["yaw"][mask]
    u = d[:, 0] * np.cos(yaw) + d[:, 1] * np.sin(yaw)
    v = -d[:, 0] * np.sin(yaw) + d[:, 1] * np.cos(yaw)
    size = frame["size"][mask]
    return bool(np.any((np.abs(u) <= size[:, 0] / 2) & (np.abs(v) <= size[:, 1] / 2)))


def test_false_positive_drawn_in_fp_colour_where_its_box_is(rendered, av2_root):
    """The longest false-positive track box of the run (the evaluator's decision), taken from the pickle and
    placed with the log's own ego pose, is filled with the false-positive colour; matched tracks are not."""
    from grutrack.render.draw import HALF_RANGE, LAYOUT, to_plot

    out, _, sub, _ = rendered
    doc = _doc(out)
    cands = []
    for log, rec in _frames(doc):
        ts = int(rec["sample_token"].rsplit(":", 1)[1])
        for fp in rec["false_positives"]:
            xy, length, yaw = _box(sub, log, ts, fp["track_id"])
            ego_xy, ego_yaw = _ego(av2_root, log, ts)
            if np.all(np.abs(to_plot(xy, ego_xy, ego_yaw)) < HALF_RANGE - 5):
                cands.append((length, log, rec, fp, xy, yaw, ego_xy, ego_yaw))
    assert cands
    length, log, rec, fp, xy, yaw, ego_xy, ego_yaw = max(cands, key=lambda c: c[0])
    assert length > 3.0, "a vehicle-sized false positive"
    img = _pixels(out, rec)
    # five points inside the box (its centre, halfway to the front and rear edges, 0.4 m to each side): at least
    # three show the fill (a label, the heading line or another track's box may cover the others)
    along, across = np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])
    points = [xy, xy + length / 4 * along, xy - length / 4 * along, xy + 0.4 * across, xy - 0.4 * across]
    filled = []
    for point in points:
        col, row = np.round(LAYOUT.pixel(to_plot(point, ego_xy, ego_yaw))[0]).astype(int)
        filled.append(bool(_near(img[row - 1 : row + 2, col - 1 : col + 2], FP_FILL_RGB).sum() >= 5))
    assert sum(filled) >= 3, (filled, [p.tolist() for p in points])
    # the matched tracks' centres in that frame are not in that colour (unless a false positive's box, drawn on
    # top, covers them)
    from grutrack.export.av2_tracks import read_tracks_pickle

    ts = int(rec["sample_token"].rsplit(":", 1)[1])
    frame = next(f for f in read_tracks_pickle(sub)[log] if f["timestamp_ns"] == ts)
    fp_ids = {f["track_id"] for f in rec["false_positives"]}
    is_fp = np.array([t in fp_ids for t in frame["track_id"]])
    for tid, c in zip(frame["track_id"], frame["translation_m"]):
        if tid in fp_ids or _inside_any(c[:2], frame, is_fp):
            continue
        col, row = np.round(LAYOUT.pixel(to_plot(c[:2], ego_xy, ego_yaw))[0]).astype(int)
        if LAYOUT.margin <= row < LAYOUT.margin + LAYOUT.panel and LAYOUT.margin <= col < LAYOUT.margin + LAYOUT.panel:
            assert not _near(img[row, col], FP_FILL_RGB, 80), tid


def test_id_switch_marked_on_its_ground_truth(rendered, av2_root):
    """Each id switch of the run is ringed in magenta around its annotation (position from annotations.feather
    through the dataset adapter), and a frame without an id switch has no magenta in its view."""
    from grutrack.render.draw import LAYOUT, to_plot

    out, _, _, _ = rendered
    doc = _doc(out)
    scenes = {s.name: s for s in av2.load_scenes(av2_root, "val", with_gt=True, all_categories=True)}
    switched = [(log, rec) for log, rec in _frames(doc) if rec["id_switches"]]
    assert len(switched) >= 2
    for log, rec in switched:
        frame = next(f for f in scenes[log].frames if f.token == rec["sample_token"])
        ego_xy, ego_yaw = _ego(av2_root, log, int(rec["sample_token"].rsplit(":", 1)[1]))
        img = _pixels(out, rec)
        rr, cc = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
        magenta = _near(img, IDS_RGB, 60)
        for sw in rec["id_switches"]:
            assert sw["previous_track_id"] is not None and sw["previous_track_id"] != sw["track_id"]
            k = list(frame.gt.ids).index(sw["instance"])
            col, row = LAYOUT.pixel(to_plot(frame.gt.boxes[k, :2], ego_xy, ego_yaw))[0]
            dist = np.hypot(rr - row, cc - col)
            assert magenta[(dist > 9) & (dist < 19)].sum() >= 60, (log, rec["frame"], sw)
    quiet = next(rec for _, rec in _frames(doc) if not rec["id_switches"])
    view = _pixels(out, quiet)[
        LAYOUT.margin : LAYOUT.margin + LAYOUT.panel, LAYOUT.margin : LAYOUT.margin + LAYOUT.panel
    ]
    assert _near(view, IDS_RGB, 60).sum() == 0


@pytest.mark.slow  # a second AV2 render; --worst is quick in test_render::test_worst_scenes_rank_by_errors
def test_worst_log_ranks_by_errors(rendered, av2_root, tmp_path):
    """--worst 1 renders the log with the most IDS + FP + FN, and its counts are that log's."""
    out, _, sub, _ = rendered
    doc = _doc(out)
    errors = {s["name"]: s["errors"] for s in doc["scenes"]}
    assert errors[LOG_A] != errors[LOG_B]
    assert (
        main(
            [
                "render",
                "--dataset",
                "av2",
                "--dataroot",
                str(av2_root),
                "--split",
                "val",
                "--submission",
                str(sub),
                "--worst",
                "1",
                "--no-animation",
                "--out",
                str(tmp_path / "w"),
            ]
        )
        == 0
    )
    worst = _doc(tmp_path / "w")
    assert [s["name"] for s in worst["scenes"]] == [max(errors, key=errors.get)]
    assert worst["scenes"][0]["animation"] is None
    kept = worst["scenes"][0]["frames"]
    for cls, counts in worst["per_class"].items():
        assert counts["fn"] == sum(f["per_class"].get(cls, {}).get("fn", 0) for f in kept)


def test_clear_replay_equals_trackeval_on_random_sequences():
    """The per-frame replay sums to TrackEval's CLEAR counts on random sequences with crossings, gaps, ties
    and re-appearing ids (no data needed)."""
    import trackeval

    from grutrack.evaluation.clear_frames import clear_decisions

    rng = np.random.default_rng(7)
    metric = trackeval.metrics.CLEAR({"THRESHOLD": 0.5, "PRINT_CONFIG": False})
    for trial in range(40):
        n_gt, n_tr, T = rng.integers(1, 8), rng.integers(1, 10), rng.integers(1, 15)
        gt_pos, tr_pos = rng.uniform(0, 6, (n_gt, 2)), rng.uniform(0, 6, (n_tr, 2))
        gt_ids, tr_ids, sims = [], [], []
        for _ in range(T):
            g = np.flatnonzero(rng.random(n_gt) < 0.8)
            t = np.flatnonzero(rng.random(n_tr) < 0.7)
            gt_pos += rng.normal(0, 0.4, gt_pos.shape)
            tr_pos += rng.normal(0, 0.4, tr_pos.shape)
            d = np.linalg.norm(gt_pos[g][:, None] - tr_pos[t][None], axis=2)
            sim = np.maximum(0, 1 - d / 2)
            if trial % 5 == 0:
                sim = np.round(sim, 1)  # ties
            gt_ids.append(g)
            tr_ids.append(t)
            sims.append(sim)
        data = {
            "gt_ids": gt_ids,
            "tracker_ids": tr_ids,
            "similarity_scores": sims,
            "num_timesteps": int(T),
            "num_gt_ids": int(n_gt),
            "num_tracker_ids": int(n_tr),
            "num_gt_dets": sum(len(g) for g in gt_ids),
            "num_tracker_dets": sum(len(t) for t in tr_ids),
        }
        ref = metric.eval_sequence(data)
        steps = clear_decisions(gt_ids, tr_ids, sims, int(n_gt), 0.5)
        got = {k: sum(s.counts()[k] for s in steps) for k in ("tp", "fp", "fn", "ids")}
        assert got == {"tp": ref["CLR_TP"], "fp": ref["CLR_FP"], "fn": ref["CLR_FN"], "ids": ref["IDSW"]}, trial


@pytest.mark.parametrize("case", ["unknown_log", "other_frames", "missing_file", "max_range", "detections_log"])
def test_bad_inputs_exit_2_with_one_line(case, rendered, av2_root, tmp_path, capsys):
    import pickle

    out, _, sub, dets = rendered
    args = [
        "render",
        "--dataset",
        "av2",
        "--dataroot",
        str(av2_root),
        "--split",
        "val",
        "--submission",
        str(sub),
        "--out",
        str(tmp_path / "r"),
    ]
    expect = {
        "unknown_log": "--scene 0000",
        "other_frames": "frames must be exactly",
        "missing_file": "does not exist",
        "max_range": "--max-range",
        "detections_log": "field 'log_id'",
    }[case]
    args += ["--scene", "0000"] if case == "unknown_log" else ["--worst", "1"]
    if case == "other_frames":
        seqs = pickle.loads(sub.read_bytes())
        seqs[LOG_A] = seqs[LOG_A][1:]
        (tmp_path / "short.pkl").write_bytes(pickle.dumps(seqs))
        args[args.index("--submission") + 1] = str(tmp_path / "short.pkl")
    if case == "missing_file":
        args[args.index("--submission") + 1] = str(tmp_path / "none.pkl")
    if case == "max_range":
        args += ["--max-range", "0"]
    if case == "detections_log":
        import pandas as pd

        table = pd.read_feather(dets)
        table.loc[0, "log_id"] = "not-a-log"
        table.to_feather(tmp_path / "d.feather")
        args += ["--detections", str(tmp_path / "d.feather")]
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("grutrack render: error:") and expect in err[0], err
    assert not (tmp_path / "r" / "counts.json").exists()


def test_av2_report_embeds_key_frames_of_the_worst_log(rendered, tmp_path):
    """An av2_val report given the run's render folder shows a strip of the worst log's id-switch frames."""
    import re

    from PIL import Image

    from grutrack.render.draw import LAYOUT, key_frames

    out, metrics, _, _ = rendered
    doc = _doc(out)
    worst = max(doc["scenes"], key=lambda s: s["errors"])
    shown = [f["frame"] for f in key_frames(worst["frames"], 4)]
    assert {f["frame"] for f in worst["frames"] if f["id_switches"]} <= set(shown)
    metrics_path = tmp_path / "ekf_metrics.json"
    metrics_path.write_text(json.dumps(metrics))
    paper = Path(__file__).resolve().parents[1] / "workflow/config/paper.yaml"
    md = tmp_path / "rep" / "r.md"
    assert (
        main(
            [
                "report",
                "av2_val",
                "--out",
                str(md),
                "--paper",
                str(paper),
                "--experiment",
                "sim:av2:val:simulated",
                "--run",
                f"ekf={metrics_path}",
                "--row",
                "I:Ours=ekf",
                "--render",
                f"ekf={out / 'counts.json'}",
            ]
        )
        == 0
    )
    text = md.read_text()
    assert "## Worst log per run (key frames)" in text and "CLEAR matching" in text
    assert f"**ekf**: {worst['name']}, frames {', '.join(map(str, shown))}" in text
    link = re.search(rf"!\[ekf: key frames of {worst['name']}\]\(([^)]+)\)", text).group(1)
    with Image.open(md.parent / link) as im:
        side = int(LAYOUT.panel * 0.45)
        assert im.size == (4 * side + 3 * 6, side + 24)
        strip = np.asarray(im.convert("RGB")).astype(int)
    # the id-switch rings are in their own frame's panel: a ring drawn at 0.45 scale covers about 50 magenta pixels,
    # fewer where it overlaps a box (the worst log's two rings: 51 and 48); a panel without a switch has none
    switches = {f["frame"]: len(f["id_switches"]) for f in worst["frames"] if f["frame"] in shown}
    assert sum(switches.values()) >= 1
    for i, frame in enumerate(shown):
        panel = strip[24:, i * (side + 6) : i * (side + 6) + side]
        magenta = _near(panel, IDS_RGB, 60).sum()
        assert magenta > 40 * switches[frame] if switches[frame] else magenta == 0, (frame, switches[frame], magenta)


def test_nusc_test_report_says_it_has_no_key_frames(tmp_path, capsys):
    """nuScenes test has no ground truth: its report states that it has no key frames, and refuses --render."""
    paper = Path(__file__).resolve().parents[1] / "workflow/config/paper.yaml"
    md = tmp_path / "t.md"
    assert main(["report", "nusc_test", "--out", str(md), "--paper", str(paper)]) == 0
    text = md.read_text()
    assert "## Worst scene per run (key frames)\n\nNone: nuScenes test has no public ground truth" in text
    (tmp_path / "counts.json").write_text("{}")
    capsys.readouterr()
    assert (
        main(
            [
                "report",
                "nusc_test",
                "--out",
                str(tmp_path / "u.md"),
                "--paper",
                str(paper),
                "--render",
                f"grukf={tmp_path / 'counts.json'}",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--render" in err[0] and "no public ground truth" in err[0]
    assert not (tmp_path / "u.md").exists()


# ------------------------------------------------------------------------------------------------------------
# --rerun (rerun-sdk is an optional extra: the recording test skips when it is not installed; the rest runs)
# ------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def views_b(rendered, av2_root):
    """The frames of log B with the official decisions, as render draws them (with the detections)."""
    from grutrack.data.lt3d_detections import load_detections
    from grutrack.render.av2 import build_views, load_evaluation

    _, _, sub, dets = rendered
    ev = load_evaluation(av2_root, "val", sub)
    det, _ = load_detections(dets, av2_root, "val", ev.scenes, av2.vocabulary(all_categories=True))
    return build_views(ev, next(s for s in ev.scenes if s.name == LOG_B), det)


def test_rerun_layers_carry_the_frame_in_3d(rendered, views_b):
    """The 3D layers of a frame: every box of the frame with its height from the pickle / annotations, FP tracks
    in the FP colour, id switches where the switched ground truth is, relative to the first ego position."""
    from grutrack.export.av2_tracks import read_tracks_pickle
    from grutrack.render.rerun_log import frame_layers, scene_origin

    _, _, sub, _ = rendered
    origin = scene_origin(views_b)
    first = frame_layers(views_b[0], origin)
    assert (
        np.allclose(first["world/ego"]["centers"][0, :2], 0) and abs(first["world/ego"]["centers"][0, 2] - 0.85) < 1e-4
    )
    v = next(v for v in views_b if v.id_switches and v.false_positives)
    lay = frame_layers(v, origin)
    frame = next(f for f in read_tracks_pickle(sub)[LOG_B] if f["timestamp_ns"] == int(v.sample_token.split(":")[1]))
    tr = lay["world/tracks"]
    assert len(tr["centers"]) == len(frame["track_id"]) == len(v.tr_ids)
    np.testing.assert_allclose(tr["centers"] + origin, frame["translation_m"], atol=1e-3)
    np.testing.assert_allclose(tr["half_sizes"] * 2, frame["size"], atol=1e-5)  # [l, w, h]
    fp = {f["track_id"] for f in v.false_positives}
    for tid, col, label in zip(v.tr_ids, tr["colors"], tr["labels"]):
        assert (tuple(col[:3]) == tuple(FP_RGB)) == (tid in fp) and label.endswith(" FP") == (tid in fp)
    assert len(lay["world/ground_truth"]["centers"]) == len(v.gt_ids)
    assert len(lay["world/detections"]["centers"]) == len(v.det_boxes) > 0
    sw = lay["world/id_switches"]
    assert len(sw["positions"]) == len(v.id_switches)
    k = v.gt_ids.index(v.id_switches[0]["instance"])
    np.testing.assert_allclose(sw["positions"][0], lay["world/ground_truth"]["centers"][k], atol=1e-2)
    assert "| REGULAR_VEHICLE |" in lay["counts"]["text"]


def test_rerun_recording_written(rendered, av2_root, tmp_path):
    """--rerun writes <log>.rrd: 32 frames on the 'frame' timeline, each with the frame's tracks in their colours."""
    pytest.importorskip("rerun", reason="rerun-sdk is optional (pip install grutrack[rerun])")
    import warnings

    import rerun.dataframe as rdf
    from rerun.error_utils import RerunWarning

    out, _, sub, _ = rendered
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert (
            main(
                [
                    "render",
                    "--dataset",
                    "av2",
                    "--dataroot",
                    str(av2_root),
                    "--split",
                    "val",
                    "--submission",
                    str(sub),
                    "--scene",
                    LOG_A,
                    "--no-animation",
                    "--rerun",
                    "--out",
                    str(tmp_path / "r"),
                ]
            )
            == 0
        )
    assert not [w for w in caught if issubclass(w.category, RerunWarning)]  # rerun drops what it warns about
    doc = _doc(tmp_path / "r")
    assert doc["scenes"][0]["rerun"] == f"{LOG_A}.rrd"
    rec = rdf.load_recording(tmp_path / "r" / f"{LOG_A}.rrd")
    table = rec.view(index="frame", contents="/world/tracks").select().read_all()
    assert table.column("frame").to_pylist() == list(range(1, 33))
    colors = table.column("/world/tracks:Color").to_pylist()
    fp_packed = (int(FP_RGB[0]) << 24) | (int(FP_RGB[1]) << 16) | (int(FP_RGB[2]) << 8) | 0xFF
    ref = _doc(out)["scenes"][0]["frames"]
    for f, c in zip(ref, colors):
        assert sum(x == fp_packed for x in (c or [])) == len(f["false_positives"]), f["frame"]


def test_rerun_without_the_package_exits_2(rendered, av2_root, tmp_path, monkeypatch, capsys):
    import sys

    _, _, sub, _ = rendered
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun raises ImportError
    capsys.readouterr()
    assert (
        main(
            [
                "render",
                "--dataset",
                "av2",
                "--dataroot",
                str(av2_root),
                "--split",
                "val",
                "--submission",
                str(sub),
                "--worst",
                "1",
                "--rerun",
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install grutrack[rerun]" in err[0], err
    assert not (tmp_path / "r").exists()


def test_relative_dataroot_evaluates_with_the_roi(rendered, av2_root, tmp_path, monkeypatch):
    """A dataroot relative to the working directory reaches the drivable-area ROI (the official evaluation runs
    in another folder): same counts as with the absolute path."""
    _, metrics, sub, _ = rendered
    monkeypatch.chdir(av2_root.parent)
    assert (
        main(
            [
                "evaluate",
                "--dataset",
                "av2",
                "--dataroot",
                av2_root.name,
                "--split",
                "val",
                "--submission",
                str(sub),
                "--out",
                str(tmp_path / "m.json"),
            ]
        )
        == 0
    )
    again = json.loads((tmp_path / "m.json").read_text())
    assert again["settings"]["drivable_area_roi"] is True
    assert {c: (m["tp"], m["fp"], m["fn"], m["ids"]) for c, m in again["per_class"].items()} == {
        c: (m["tp"], m["fp"], m["fn"], m["ids"]) for c, m in metrics["per_class"].items()
    }
