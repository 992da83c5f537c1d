"""``grutrack render`` on the real mini_val fragment: the real PointPillars detections tracked by the EKF with
Poly-MOT's preset (``--config polymot``, pinned box for box to Poly-MOT's own output by the parity tests, so the
false positive and id switch named below do not move when the default preset is tuned), both scenes rendered. The
counts drawn must be the official evaluation's, and the marks must be where the boxes are."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from grutrack.cli import main

FP_RGB = np.array([0xE6, 0x19, 0x4B])
IDS_RGB = np.array([0xC0, 0x00, 0xC0])


@pytest.fixture(scope="module")
def rendered(nusc_root, pointpillars_mini_val, tmp_path_factory):
    """(render folder, metrics JSON, submission) of the EKF on PointPillars mini_val, both scenes rendered."""
    tmp = tmp_path_factory.mktemp("render")
    common = ["--dataset", "nuscenes", "--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    sub, metrics, out = tmp / "ekf.json", tmp / "metrics.json", tmp / "render"
    assert (
        main(
            [
                "track",
                *common,
                "--detections",
                str(pointpillars_mini_val),
                "--tracker",
                "ekf",
                "--config",
                "polymot",
                "--out",
                str(sub),
                "--no-progress",
            ]
        )
        == 0
    )
    assert main(["evaluate", *common, "--submission", str(sub), "--out", str(metrics), "--evaluator", "devkit"]) == 0
    assert (
        main(
            [
                "render",
                *common,
                "--submission",
                str(sub),
                "--detections",
                str(pointpillars_mini_val),
                "--scene",
                "scene-0103",
                "scene-0916",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out, json.loads(metrics.read_text()), json.loads(sub.read_text())


def _frame(doc: dict, scene: str, index: int) -> dict:
    s = next(s for s in doc["scenes"] if s["name"] == scene)
    return s["frames"][index]


def _pixels(out: Path, rec: dict) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(out / rec["png"]).convert("RGB")).astype(int)


def _near(img: np.ndarray, rgb: np.ndarray, tol: int = 40) -> np.ndarray:
    return np.abs(img - rgb).sum(axis=-1) <= tol


def _ego(nusc_root, sample_token: str):
    """Ego pose (xy, yaw) of a sample from the dataset itself (not from counts.json)."""
    from grutrack.boxes import yaw_from_quaternion
    from grutrack.data.nuscenes import open_nuscenes

    nusc = open_nuscenes(nusc_root, "v1.0-mini")
    sd = nusc.get("sample_data", nusc.get("sample", sample_token)["data"]["LIDAR_TOP"])
    pose = nusc.get("ego_pose", sd["ego_pose_token"])
    return nusc, np.asarray(pose["translation"][:2]), float(yaw_from_quaternion(np.asarray(pose["rotation"]))[0])


def test_per_class_counts_equal_the_official_metrics(rendered):
    """Both scenes rendered: per_class in counts.json is the devkit's TP / FP / FN / IDS for every class."""
    out, metrics, _ = rendered
    doc = json.loads((out / "counts.json").read_text())
    assert set(doc["per_class"]) == set(metrics["per_class"])
    for cls, counts in doc["per_class"].items():
        for key in ("tp", "fp", "fn", "ids"):
            ref = metrics["per_class"][cls][key]
            assert counts[key] == (None if ref is None else int(ref)), (cls, key, counts[key], ref)
    # The real run has all four kinds of decisions.
    assert doc["per_class"]["car"] == {"tp": 1033, "fp": 34, "fn": 1147, "ids": 8}
    # Per-frame counts add up to per_class.
    frames = [f for s in doc["scenes"] for f in s["frames"]]
    assert len(frames) == 81
    assert sum(f["per_class"]["car"]["ids"] for f in frames) == 8
    assert sum(len(f["false_positives"]) for f in frames) == int(metrics["overall"]["fp"])


def test_frames_and_animations_written(rendered):
    from PIL import Image

    out, _, _ = rendered
    doc = json.loads((out / "counts.json").read_text())
    assert doc["synthetic"] is False  # real mini scenes: no SYNTHETIC in the titles
    for s, n in zip(doc["scenes"], (40, 41)):
        assert [f["index"] for f in s["frames"]] == list(range(n))
        assert all((out / f["png"]).is_file() for f in s["frames"])
        with Image.open(out / s["animation"]) as gif:
            assert gif.format == "GIF" and gif.n_frames == n
        with Image.open(out / s["frames"][0]["png"]) as png:
            assert png.size == (1060, 760)


def test_false_positive_drawn_in_fp_colour_where_its_box_is(rendered, nusc_root):
    """scene-0103, frame 3: the EKF's track 0 is a false positive (evaluator's decision); its box, taken from the
    submission and placed with the dataset's ego pose, is filled with the false-positive colour."""
    from grutrack.boxes import yaw_from_quaternion
    from grutrack.render.draw import LAYOUT, to_plot

    out, _, sub = rendered
    doc = json.loads((out / "counts.json").read_text())
    rec = _frame(doc, "scene-0103", 2)
    assert [fp["track_id"] for fp in rec["false_positives"]] == ["0"]
    img = _pixels(out, rec)
    _, ego_xy, ego_yaw = _ego(nusc_root, rec["sample_token"])
    box = next(b for b in sub["results"][rec["sample_token"]] if b["tracking_id"] == "0")
    yaw = yaw_from_quaternion(np.asarray(box["rotation"]))[0]
    back = np.asarray(box["translation"][:2]) - box["size"][1] / 4 * np.array([np.cos(yaw), np.sin(yaw)])
    for point in (np.asarray(box["translation"][:2]), back):  # centre, and halfway to the rear edge
        col, row = np.round(LAYOUT.pixel(to_plot(point, ego_xy, ego_yaw))[0]).astype(int)
        assert _near(img[row - 1 : row + 2, col - 1 : col + 2], FP_RGB).sum() >= 5, (point, img[row, col])
    # A matched track of the same frame is not drawn in that colour.
    tp_ids = {b["tracking_id"] for b in sub["results"][rec["sample_token"]]} - {"0"}
    for b in sub["results"][rec["sample_token"]]:
        if b["tracking_id"] in tp_ids:
            col, row = np.round(LAYOUT.pixel(to_plot(np.asarray(b["translation"][:2]), ego_xy, ego_yaw))[0]).astype(int)
            if 0 <= row < img.shape[0] and 0 <= col < LAYOUT.panel:
                assert not _near(img[row, col], FP_RGB)


def test_id_switch_marked_on_its_ground_truth(rendered, nusc_root):
    """scene-0103, frame 7: the car that track 9 followed is taken over by track 10 (IDS); a magenta ring is
    drawn around that annotation's centre, and a frame without an id switch has no magenta in its view."""
    from grutrack.render.draw import LAYOUT, to_plot

    out, _, _ = rendered
    doc = json.loads((out / "counts.json").read_text())
    rec = _frame(doc, "scene-0103", 6)
    assert [(s["previous_track_id"], s["track_id"]) for s in rec["id_switches"]] == [("9", "10")]
    nusc, ego_xy, ego_yaw = _ego(nusc_root, rec["sample_token"])
    ann = next(
        nusc.get("sample_annotation", a)
        for a in nusc.get("sample", rec["sample_token"])["anns"]
        if nusc.get("sample_annotation", a)["instance_token"] == rec["id_switches"][0]["instance"]
    )
    col, row = LAYOUT.pixel(to_plot(np.asarray(ann["translation"][:2]), ego_xy, ego_yaw))[0]
    img = _pixels(out, rec)
    rr, cc = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
    dist = np.hypot(rr - row, cc - col)
    magenta = _near(img, IDS_RGB, 60)
    assert magenta[(dist > 9) & (dist < 19)].sum() >= 60
    quiet = _frame(doc, "scene-0103", 0)
    assert not quiet["id_switches"]
    view = _pixels(out, quiet)[
        LAYOUT.margin : LAYOUT.margin + LAYOUT.panel, LAYOUT.margin : LAYOUT.margin + LAYOUT.panel
    ]
    assert _near(view, IDS_RGB, 60).sum() == 0


def test_worst_scenes_rank_by_errors(nusc_root, rendered):
    """--worst ranks scenes by IDS + FP + FN of the evaluator's decisions."""
    from grutrack.render.nuscenes import load_evaluation, select_scenes

    out, _, _ = rendered
    doc = json.loads((out / "counts.json").read_text())
    errors = {s["name"]: sum(f["totals"][k] for f in s["frames"] for k in ("ids", "fp", "fn")) for s in doc["scenes"]}
    assert errors == {s["name"]: s["errors"] for s in doc["scenes"]}
    _, scenes, _, decisions = load_evaluation(nusc_root, "v1.0-mini", "mini_val", out.parent / "ekf.json")
    worst = select_scenes(scenes, decisions, None, 1)
    assert [s.name for s in worst] == [max(errors, key=errors.get)] == ["scene-0916"]


@pytest.mark.parametrize(
    "case", ["unknown_scene", "other_split", "missing_file", "worst_zero", "av2", "detections_other_split"]
)
def test_bad_inputs_exit_2_with_one_line(case, rendered, nusc_root, tmp_path, capsys):
    out, _, sub = rendered
    args = [
        "render",
        "--dataroot",
        str(nusc_root),
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--submission",
        str(out.parent / "ekf.json"),
        "--out",
        str(tmp_path / "r"),
    ]
    expect = {
        "unknown_scene": "--scene scene-9999",
        "other_split": "from other splits",
        "missing_file": "does not exist",
        "worst_zero": "--worst",
        "av2": "has no split folder 'mini_val'",
        "detections_other_split": "sample tokens of the split are missing",
    }[case]
    if case == "unknown_scene":
        args += ["--scene", "scene-9999"]
    else:
        args += ["--worst", "0" if case == "worst_zero" else "1"]
    if case == "other_split":
        bad = dict(sub, results=dict(sub["results"], **{"0" * 32: []}))
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        args[args.index("--submission") + 1] = str(tmp_path / "bad.json")
    if case == "missing_file":
        args[args.index("--submission") + 1] = str(tmp_path / "none.json")
    if case == "av2":
        args += ["--dataset", "av2"]
    if case == "detections_other_split":
        (tmp_path / "dets.json").write_text(json.dumps({"meta": {}, "results": {"0" * 32: []}}))
        args += ["--detections", str(tmp_path / "dets.json")]
    capsys.readouterr()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("grutrack render: error:") and expect in err[0], err
    assert not (tmp_path / "r" / "counts.json").exists()


def test_report_embeds_key_frames_of_the_worst_scene(rendered, tmp_path):
    """A report given the run's render folder shows a strip of the worst scene's id-switch frames."""
    from PIL import Image

    from grutrack.render.draw import LAYOUT

    out, metrics, _ = rendered
    metrics_path = tmp_path / "ekf_metrics.json"
    metrics_path.write_text(json.dumps(metrics))
    paper = Path(__file__).resolve().parents[1] / "workflow/config/paper.yaml"
    md = tmp_path / "rep" / "r.md"
    assert (
        main(
            [
                "report",
                "nusc_val",
                "--out",
                str(md),
                "--paper",
                str(paper),
                "--experiment",
                "mini_val:nuscenes:mini_val:pointpillars",
                "--run",
                f"ekf={metrics_path}",
                "--render",
                f"ekf={out / 'counts.json'}",
            ]
        )
        == 0
    )
    text = md.read_text()
    # scene-0916 has the most IDS + FP + FN; its id-switch frames (19, 24, 29) are among the key frames shown
    assert "**ekf**: scene-0916, frames 8, 19, 24, 29" in text
    assert "id switches shown: 72\u219281, 57\u219289, 63\u219257, 63\u219257, 57\u219289" in text
    link = re.search(r"!\[ekf: key frames of scene-0916\]\(([^)]+)\)", text).group(1)
    with Image.open(md.parent / link) as im:
        side = int(LAYOUT.panel * 0.45)
        assert im.size == (4 * side + 3 * 6, side + 24)
        strip = np.asarray(im.convert("RGB")).astype(int)
    assert _near(strip, IDS_RGB, 60).sum() > 100  # the id-switch rings are in the strip


def test_report_rejects_a_folder_that_is_not_a_render(tmp_path, capsys):
    bad = tmp_path / "counts.json"
    bad.write_text(json.dumps({"scenes": []}))
    m = tmp_path / "m.json"
    m.write_text(json.dumps({"dataset": "nuscenes", "overall": {}, "per_class": {}}))
    paper = Path(__file__).resolve().parents[1] / "workflow/config/paper.yaml"
    assert (
        main(
            [
                "report",
                "demo",
                "--out",
                str(tmp_path / "r.md"),
                "--paper",
                str(paper),
                "--run",
                f"ekf={m}",
                "--render",
                f"ekf={bad}",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "counts.json" in err[0]


def test_rerun_layers_carry_the_submission_heights(rendered, nusc_root):
    """The 3D layers (grutrack render --rerun) of a nuScenes frame: each submitted track box at its own centre
    height and size, relative to the scene's first ego position."""
    from grutrack.render.nuscenes import load_evaluation
    from grutrack.render.rerun_log import frame_layers, scene_origin
    from grutrack.render.views import build_views

    out, _, sub = rendered
    _, scenes, results, decisions = load_evaluation(nusc_root, "v1.0-mini", "mini_val", out.parent / "ekf.json")
    views = build_views(scenes[0], results, decisions)
    origin = scene_origin(views)
    v = views[6]
    lay = frame_layers(v, origin)["world/tracks"]
    boxes = sub["results"][v.sample_token]
    n = len(boxes)
    assert n > 0 and len(lay["centers"]) == len(v.tr_ids) >= n
    np.testing.assert_allclose(lay["centers"][:n] + origin, [b["translation"] for b in boxes], atol=1e-3)
    np.testing.assert_allclose(
        lay["half_sizes"][:n] * 2, [[b["size"][1], b["size"][0], b["size"][2]] for b in boxes], atol=1e-5
    )
