"""Parity of the fast tracking evaluator with the official nuScenes devkit (``TrackingEval``, tracking_nips_2019).

Every number of the devkit's ``metrics_summary.json`` (overall and per class; ``eval_time`` aside) and of its
per-threshold metric data (``metrics_details.json``) must equal ours to 1e-9, NaN equal to NaN.

``assert_parity(nusc, submission, split)`` is the reusable check: one line per new case. The devkit reference
of the cases here is computed once per session (``devkit_reference`` fixture).
"""

from __future__ import annotations

import copy
import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support.compare import entry_differences, flatten
from support.fast_synth import corrupt_submission, gt_submission
from support.tracking import track

from grutrack.evaluation.nuscenes_fast import evaluate_tracks, exact_center_distances, fast_tracking_eval, load_tracks

TOL = 1e-9


# ----------------------------------------------------------------------------------------------------------------
# The devkit reference and the comparison
# ----------------------------------------------------------------------------------------------------------------


def devkit_evaluate(nusc, submission, split: str, config=None, workdir: str | None = None):
    """The official evaluation: ``TrackingEval.__init__``'s loading steps on the already loaded ``nusc`` (no
    second NuScenes load), then the devkit's own ``TrackingEval.evaluate``; no rendering, nothing printed.

    :return: ``(metrics_summary dict as TrackingEval.main writes it, TrackingMetricDataList, tracks_gt,
        tracks_pred)``.
    """
    return _devkit_run(nusc, submission, split, config, workdir, evaluate=True)


def devkit_load_tracks(nusc, submission, split: str, config=None, workdir: str | None = None):
    """``TrackingEval.__init__``'s loading steps alone (those of :func:`devkit_evaluate`, without its
    ``evaluate``).

    :return: ``(tracks_gt, tracks_pred, meta)``: the devkit's tracks and the submission's meta as it read them.
    """
    return _devkit_run(nusc, submission, split, config, workdir, evaluate=False)


def _devkit_run(nusc, submission, split: str, config, workdir: str | None, evaluate: bool):
    import contextlib
    import io
    import tempfile

    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.common.loaders import (
        add_center_dist,
        filter_eval_boxes,
        get_samples_of_custom_split,
        load_gt,
        load_gt_of_sample_tokens,
        load_prediction,
        load_prediction_of_sample_tokens,
    )
    from nuscenes.eval.tracking.data_classes import TrackingBox
    from nuscenes.eval.tracking.evaluate import TrackingEval
    from nuscenes.eval.tracking.loaders import create_tracks
    from nuscenes.utils.splits import is_predefined_split

    cfg = config if config is not None else config_factory("tracking_nips_2019")
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        if isinstance(submission, (str, os.PathLike)):
            path = os.fspath(submission)
        else:
            path = os.path.join(tmp, "submission.json")
            with open(path, "w") as f:
                json.dump(submission, f)
        ev = object.__new__(TrackingEval)
        ev.cfg, ev.result_path, ev.eval_set, ev.output_dir = cfg, path, split, tmp
        ev.verbose, ev.render_classes = False, None
        with contextlib.redirect_stderr(io.StringIO()):
            if is_predefined_split(split_name=split):
                pred_boxes, ev.meta = load_prediction(path, cfg.max_boxes_per_sample, TrackingBox)
                gt_boxes = load_gt(nusc, split, TrackingBox)
            else:
                tokens = get_samples_of_custom_split(split_name=split, nusc=nusc)
                pred_boxes, ev.meta = load_prediction_of_sample_tokens(
                    path, cfg.max_boxes_per_sample, TrackingBox, sample_tokens=tokens
                )
                gt_boxes = load_gt_of_sample_tokens(nusc, tokens, TrackingBox)
        if set(pred_boxes.sample_tokens) != set(gt_boxes.sample_tokens):  # TrackingEval.__init__'s assert
            raise AssertionError("Samples in split don't match samples in predicted tracks.")
        pred_boxes = filter_eval_boxes(nusc, add_center_dist(nusc, pred_boxes), cfg.class_range)
        gt_boxes = filter_eval_boxes(nusc, add_center_dist(nusc, gt_boxes), cfg.class_range)
        ev.sample_tokens = gt_boxes.sample_tokens
        ev.tracks_gt = create_tracks(gt_boxes, nusc, split, gt=True)
        ev.tracks_pred = create_tracks(pred_boxes, nusc, split, gt=False)
        if not evaluate:
            return ev.tracks_gt, ev.tracks_pred, ev.meta.copy()
        metrics, md_list = ev.evaluate()
    summary = metrics.serialize()
    summary["meta"] = ev.meta.copy()
    return summary, md_list, ev.tracks_gt, ev.tracks_pred


def compare_summaries(ref: dict[str, Any], ours: dict[str, Any]) -> tuple[float, list]:
    """(max abs difference, [mismatches]) over every entry but eval_time; keys must be identical."""
    try:
        diffs = entry_differences(ref, ours)
    except ValueError as exc:
        raise AssertionError(str(exc)) from exc
    fr, fo = flatten(ref), flatten(ours)
    worst, bad = 0.0, []
    for key, d in diffs.items():
        if d > TOL:
            bad.append((key, fr[key], fo[key]))
        elif d > worst:
            worst = d
    return worst, bad


def compare_metric_data(ref_list, our_list) -> tuple[float, list]:
    """The per-threshold metric data (metrics_details.json), every value."""
    ref, ours = ref_list.serialize(), our_list.serialize()
    assert set(ref) == set(ours)
    worst, bad = 0.0, []
    for cls in ref:
        assert set(ref[cls]) == set(ours[cls])
        for metric in ref[cls]:
            a = np.asarray(ref[cls][metric], dtype=float)
            b = np.asarray(ours[cls][metric], dtype=float)
            assert a.shape == b.shape
            if [type(v) for v in ref[cls][metric]] != [type(v) for v in ours[cls][metric]]:
                bad.append((cls, metric, "value types (int/float in metrics_details.json)"))
            if not np.array_equal(np.isnan(a), np.isnan(b)):
                bad.append((cls, metric, "NaN pattern", a.tolist(), b.tolist()))
                continue
            m = ~np.isnan(a)
            d = float(np.abs(a[m] - b[m]).max()) if m.any() else 0.0
            if d > TOL:
                bad.append((cls, metric, d, a.tolist(), b.tolist()))
            worst = max(worst, d)
    return worst, bad


def assert_parity(nusc, submission, split: str, config=None, reference=None) -> dict[str, Any]:
    """Check ``fast_tracking_eval`` against the devkit on one input; return a small report.

    ``submission``: a tracking-submission dict or its JSON path; ``split``: predefined or custom split name;
    ``reference``: a precomputed ``devkit_evaluate`` result (else the devkit runs here).
    """
    t0 = time.perf_counter()
    ref_summary, ref_md, tracks_gt, tracks_pred = reference or devkit_evaluate(nusc, submission, split, config)
    t1 = time.perf_counter()
    ours = fast_tracking_eval(nusc, submission, split, config=config)
    t2 = time.perf_counter()

    worst, bad = compare_summaries(ref_summary, ours)
    assert not bad, "summary mismatches (key, devkit, ours): %s" % bad[:20]
    assert isinstance(ours["eval_time"], float) and ours["eval_time"] >= 0

    # Per-threshold data on the same loaded tracks (our accumulation only).
    our_metrics, our_md = evaluate_tracks(tracks_gt, tracks_pred, config)
    worst_md, bad_md = compare_metric_data(ref_md, our_md)
    assert not bad_md, "metric-data mismatches: %s" % bad_md[:5]
    worst2, bad2 = compare_summaries(ref_summary, dict(our_metrics.serialize(), meta=ref_summary["meta"]))
    assert not bad2, bad2[:20]
    return {
        "max_abs_diff": max(worst, worst_md, worst2),
        "devkit_s": t1 - t0,
        "fast_s": t2 - t1,
        "amota": ours["amota"],
    }


# ----------------------------------------------------------------------------------------------------------------
# Cases on the real nuScenes v1.0-mini fragment
# ----------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def devkit_reference():
    """Memoised devkit results, one run per (case name) for the whole module."""
    cache: dict[str, Any] = {}

    def get(name: str, nusc, submission, split: str, config=None):
        if name not in cache:
            t0 = time.perf_counter()
            cache[name] = devkit_evaluate(nusc, submission, split, config)
            DEVKIT_SECONDS[name] = time.perf_counter() - t0
        return cache[name]

    return get


DEVKIT_SECONDS: dict[str, float] = {}


@pytest.fixture(scope="module")
def mini_val_gt(nusc_mini):
    return gt_submission(nusc_mini, "mini_val")


def _case(nusc, name: str, split: str, submission, devkit_reference) -> dict[str, Any]:
    report = assert_parity(nusc, submission, split, reference=devkit_reference(name, nusc, submission, split))
    print(
        "\n%-28s AMOTA %.6f  max|diff| %.3g  devkit (whole) %.2fs  fast (whole) %.2fs"
        % (name, report["amota"], report["max_abs_diff"], DEVKIT_SECONDS.get(name, math.nan), report["fast_s"])
    )
    return report


def test_oracle_mini_val(nusc_mini, devkit_reference):
    """Ground truth fed back (zero-point annotations left out): AMOTA 1, TP 3669 (data README)."""
    sub = gt_submission(nusc_mini, "mini_val", skip_empty=True)
    _case(nusc_mini, "oracle_mini_val", "mini_val", sub, devkit_reference)
    summary = devkit_reference("oracle_mini_val", nusc_mini, sub, "mini_val")[0]
    assert summary["amota"] == 1.0 and summary["tp"] == 3669.0


def test_oracle_with_empty_boxes_mini_val(nusc_mini, mini_val_gt, devkit_reference):
    """All annotations fed back: the zero-point ones are false positives (the GT drops them)."""
    _case(nusc_mini, "oracle_all_mini_val", "mini_val", mini_val_gt, devkit_reference)


@pytest.mark.slow  # the oracle of test_oracle_mini_val on the larger split (the devkit's run: seconds)
def test_oracle_mini_train(nusc_mini, devkit_reference):
    sub = gt_submission(nusc_mini, "mini_train", skip_empty=True)
    _case(nusc_mini, "oracle_mini_train", "mini_train", sub, devkit_reference)
    summary = devkit_reference("oracle_mini_train", nusc_mini, sub, "mini_train")[0]
    assert summary["amota"] == 1.0 and summary["tp"] == 7127.0


@pytest.mark.slow
def test_corrupted_tracks_mini_val(nusc_mini, mini_val_gt, devkit_reference):
    """Noise, id switches, fragments, dropped boxes and tracks, false-positive tracks, class changes, shadow
    tracks, empty samples, per-box scores."""
    sub = corrupt_submission(nusc_mini, "mini_val", seed=0, base=mini_val_gt)
    report = _case(nusc_mini, "corrupted_mini_val", "mini_val", sub, devkit_reference)
    summary = devkit_reference("corrupted_mini_val", nusc_mini, sub, "mini_val")[0]
    assert 0.2 < report["amota"] < 0.9 and summary["ids"] > 0 and summary["frag"] > 0
    assert math.isnan(summary["label_metrics"]["amota"]["trailer"])  # predictions but no GT


#: the contested case: shadow tracks, exact duplicates (distance ties broken by the solver), an id used twice
CONTESTED = dict(seed=2, duplicate=0.3, exact_duplicate=0.15, repeated_id=0.01, noise=0.4)


@pytest.mark.slow
def test_contested_tracks_mini_val(nusc_mini, mini_val_gt, devkit_reference):
    """Many competing candidates: shadow tracks, exact duplicates (distance ties broken by the solver), an id
    used twice in a frame."""
    sub = corrupt_submission(nusc_mini, "mini_val", base=mini_val_gt, **CONTESTED)
    _case(nusc_mini, "contested_mini_val", "mini_val", sub, devkit_reference)


def test_equal_scores_and_missing_classes_mini_val(nusc_mini, mini_val_gt, devkit_reference):
    """Every score equal (one distinct threshold), GT classes without predictions, a class without GT."""
    sub = corrupt_submission(nusc_mini, "mini_val", seed=1, base=mini_val_gt, equal_scores=0.5)
    for token, boxes in sub["results"].items():
        sub["results"][token] = [b for b in boxes if b["tracking_name"] not in ("bus", "bicycle")]
    _case(nusc_mini, "equal_scores_mini_val", "mini_val", sub, devkit_reference)
    summary = devkit_reference("equal_scores_mini_val", nusc_mini, sub, "mini_val")[0]
    assert summary["label_metrics"]["amota"]["bus"] == 0.0 and summary["label_metrics"]["amotp"]["bus"] == 2.0


def test_submission_path_equals_dict(nusc_mini, mini_val_gt, tmp_path):
    sub = corrupt_submission(nusc_mini, "mini_val", seed=3, base=mini_val_gt, equal_scores=1.0)
    path = tmp_path / "sub.json"
    path.write_text(json.dumps(sub))
    a = fast_tracking_eval(nusc_mini, sub, "mini_val")
    b = fast_tracking_eval(nusc_mini, str(path), "mini_val")
    worst, bad = compare_summaries(a, b)
    assert not bad and worst == 0.0
    assert a["meta"] == sub["meta"]


def test_custom_split(nusc_root, tmp_path):
    """A custom split from <dataroot>/<version>/splits.json (tables linked into a temporary dataroot)."""
    from nuscenes import NuScenes

    version = "v1.0-mini"
    root = tmp_path / "nuscenes"
    (root / version).mkdir(parents=True)
    for table in (Path(nusc_root) / version).glob("*.json"):
        os.symlink(table, root / version / table.name)
    os.symlink(Path(nusc_root) / "maps", root / "maps")
    (root / version / "splits.json").write_text(json.dumps({"custom_one": ["scene-0916"]}))
    nusc = NuScenes(version=version, dataroot=str(root), verbose=False)
    sub = corrupt_submission(nusc, "custom_one", seed=4, fp_tracks_per_scene=10, equal_scores=0.6)
    # The prediction loader of a custom split ignores samples outside it.
    sub["results"]["not-a-sample-of-the-split"] = []
    report = assert_parity(nusc, sub, "custom_one")
    print("\ncustom split AMOTA %.6f max|diff| %.3g" % (report["amota"], report["max_abs_diff"]))


# ----------------------------------------------------------------------------------------------------------------
# Small synthetic tracks (no dataset): motmetrics' corner cases, the devkit's own accumulation as reference
# ----------------------------------------------------------------------------------------------------------------


def _box(name: str, tid: str, xy, score: float = -1.0):
    from nuscenes.eval.tracking.data_classes import TrackingBox

    return TrackingBox(
        sample_token="s",
        translation=(float(xy[0]), float(xy[1]), 0.0),
        size=(1.0, 1.0, 1.0),
        rotation=(1.0, 0.0, 0.0, 0.0),
        tracking_id=tid,
        tracking_name=name,
        tracking_score=float(score),
    )


def _random_tracks(seed: int, n_scenes: int = 3, n_frames: int = 12, classes=("car", "pedestrian")):
    """Crowded scenes on a coarse grid (exact distance ties), id switches, duplicates, repeated ids, gaps."""
    from collections import defaultdict

    rng = np.random.default_rng(seed)
    tracks_gt: dict[str, dict[int, list]] = {}
    tracks_pred = defaultdict(lambda: defaultdict(list))
    for s in range(n_scenes):
        scene = "scene%d" % s
        gt: dict[int, list] = {}
        pred: dict[int, list] = {}
        n_obj = int(rng.integers(2, 9))
        origin = 0.0 if s % 2 == 0 else 1234.0  # exact arithmetic (true ties) / rounding residues
        pos = rng.integers(-4, 5, (n_obj, 2)).astype(float) * 0.5 + origin
        cls = [str(rng.choice(classes)) for _ in range(n_obj)]
        alive = [
            (int(rng.integers(0, n_frames // 2)), int(rng.integers(n_frames // 2, n_frames + 1))) for _ in range(n_obj)
        ]
        hyp = ["h%d" % i for i in range(n_obj)]
        track_score = {h: float(rng.choice([0.3, 0.5, 0.5, 0.7, 0.9])) for h in hyp}
        for f in range(n_frames):
            ts = 1000 * f
            gt[ts], pred[ts] = [], []
            pos += rng.integers(-1, 2, pos.shape) * 0.5
            for i in range(n_obj):
                if not alive[i][0] <= f < alive[i][1]:
                    continue
                gt[ts].append(_box(cls[i], "o%d-%d" % (s, i), pos[i]))
                if rng.random() < 0.15:
                    continue  # miss
                if rng.random() < 0.08:
                    hyp[i] = "h%d-%d" % (i, f)  # new id (switch / fragment)
                    track_score[hyp[i]] = float(rng.choice([0.3, 0.5, 0.7]))
                off = rng.integers(-2, 3, 2) * 0.5 if rng.random() < 0.5 else rng.normal(0, 0.4, 2)
                name = cls[i] if rng.random() > 0.05 else str(rng.choice(classes))
                pred[ts].append(_box(name, hyp[i], pos[i] + off, track_score[hyp[i]]))
                if rng.random() < 0.15:  # a second hypothesis near the object
                    pred[ts].append(
                        _box(cls[i], hyp[int(rng.integers(n_obj))], pos[i] + rng.integers(-2, 3, 2) * 0.5, 0.5)
                    )
            for _ in range(int(rng.poisson(1.0))):  # false positives
                pred[ts].append(
                    _box(
                        str(rng.choice(classes)),
                        "fp%d-%d" % (f, int(rng.integers(3))),
                        origin + rng.integers(-6, 7, 2) * 0.5,
                        float(rng.choice([0.2, 0.5])),
                    )
                )
        tracks_gt[scene] = gt
        tracks_pred[scene] = defaultdict(list, pred)
    return tracks_gt, tracks_pred


def _devkit_metric_data(tracks_gt, tracks_pred, cfg):
    from nuscenes.eval.tracking.algo import TrackingEvaluation
    from nuscenes.eval.tracking.data_classes import TrackingMetricData, TrackingMetricDataList

    md_list = TrackingMetricDataList()
    for name in cfg.class_names:
        ev = TrackingEvaluation(
            tracks_gt,
            tracks_pred,
            name,
            cfg.dist_fcn_callable,
            cfg.dist_th_tp,
            cfg.min_recall,
            num_thresholds=TrackingMetricData.nelem,
            metric_worst=cfg.metric_worst,
            verbose=False,
        )
        md_list.set(name, ev.accumulate())
    return md_list


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_random_crowded_tracks(seed):
    """Grid positions (exact ties), previous-pairing rules, switches, repeated ids, class changes, gaps."""
    from nuscenes.eval.common.config import config_factory

    cfg = config_factory("tracking_nips_2019")
    tracks_gt, tracks_pred = _random_tracks(seed)
    ref = _devkit_metric_data(tracks_gt, tracks_pred, cfg)
    _, ours = evaluate_tracks(tracks_gt, tracks_pred, cfg)
    worst, bad = compare_metric_data(ref, ours)
    assert not bad, bad[:3]


def test_duplicate_gt_ids_fall_back_to_devkit():
    """Two GT boxes with one id in a frame are outside the fast path's model: that class uses the devkit."""
    from nuscenes.eval.common.config import config_factory

    cfg = config_factory("tracking_nips_2019")
    tracks_gt, tracks_pred = _random_tracks(7, n_scenes=1, classes=("car",))
    first = next(iter(tracks_gt.values()))
    ts = next(t for t, boxes in first.items() if boxes)
    first[ts].append(copy.deepcopy(first[ts][0]))
    ref = _devkit_metric_data(tracks_gt, tracks_pred, cfg)
    _, ours = evaluate_tracks(tracks_gt, tracks_pred, cfg)
    assert not compare_metric_data(ref, ours)[1]


def test_exact_center_distances_bitwise():
    """Same bits as the devkit's sklearn euclidean_distances call, on realistic global coordinates."""
    from sklearn.metrics.pairwise import euclidean_distances

    rng = np.random.default_rng(0)
    for _ in range(300):
        n, m = int(rng.integers(1, 30)), int(rng.integers(1, 50))
        c = rng.uniform(300, 2500, 2)
        x = c + rng.normal(0, 20, (n, 2))
        y = c + rng.normal(0, 20, (m, 2))
        y[: min(n, m) // 2] = x[: min(n, m) // 2]  # identical points: rounding residues
        assert np.array_equal(exact_center_distances(x, y), euclidean_distances(x, y))


def _same_tracks(ref, ours) -> int:
    """Same scenes, frames, boxes in the same order, same id/class/translation/score; returns the box count."""
    n = 0
    assert list(ref) == list(ours)
    for scene in ref:
        assert list(ref[scene]) == list(ours[scene])
        for ts in ref[scene]:
            a = [
                (b.tracking_id, b.tracking_name, tuple(map(float, b.translation)), float(b.tracking_score))
                for b in ref[scene][ts]
            ]
            b = [
                (b.tracking_id, b.tracking_name, tuple(map(float, b.translation)), float(b.tracking_score))
                for b in ours[scene][ts]
            ]
            assert a == b, (scene, ts)
            n += len(a)
    return n


@pytest.mark.parametrize("loader", ["fast", "devkit"])
def test_load_tracks_matches_devkit(nusc_mini, mini_val_gt, loader):
    """Both loaders give the devkit's tracks: same frames, same boxes in the same order (interpolated boxes
    included), same track-averaged scores. The reference is the devkit's loading alone (``TrackingEval.__init__``'s
    steps, as in :func:`devkit_evaluate`): its whole evaluation of these two cases takes half a minute."""
    for sub in (
        corrupt_submission(nusc_mini, "mini_val", seed=0, base=mini_val_gt),
        corrupt_submission(nusc_mini, "mini_val", base=mini_val_gt, **CONTESTED),
    ):
        ref_gt, ref_pred, _ = devkit_load_tracks(nusc_mini, sub, "mini_val")
        tracks_gt, tracks_pred, meta = load_tracks(nusc_mini, sub, "mini_val", loader=loader)
        assert meta == sub["meta"]
        assert _same_tracks(ref_gt, tracks_gt) == 3669
        assert _same_tracks(ref_pred, tracks_pred) > 4000


def _devkit_error(nusc, submission, split):
    try:
        devkit_evaluate(nusc, submission, split)
    except Exception as exc:  # noqa: BLE001 - whatever the devkit raises
        return exc
    return None


@pytest.mark.parametrize(
    "defect",
    [
        "nan_translation",
        "unknown_class",
        "string_translation",
        "missing_sample",
        "no_boxes",
        "too_many_boxes",
        "missing_key",
    ],
)
def test_invalid_submissions_fail_like_the_devkit(nusc_mini, mini_val_gt, defect):
    """Input the devkit rejects: the fast loader hands over to the devkit's loaders, which raise their error."""
    sub = copy.deepcopy(mini_val_gt)
    tokens = list(sub["results"])
    box = next(b for t in tokens for b in sub["results"][t])
    if defect == "nan_translation":
        box["translation"][0] = float("nan")
    elif defect == "unknown_class":
        box["tracking_name"] = "barrier"
    elif defect == "string_translation":
        box["translation"] = [str(v) for v in box["translation"]]
    elif defect == "missing_sample":
        del sub["results"][tokens[0]]
    elif defect == "no_boxes":
        sub["results"] = {t: [] for t in tokens}
    elif defect == "too_many_boxes":
        sub["results"][tokens[0]] = [box] * 501
    elif defect == "missing_key":
        del box["velocity"]
    expected = _devkit_error(nusc_mini, sub, "mini_val")
    assert expected is not None
    with pytest.raises(type(expected)) as raised:
        fast_tracking_eval(nusc_mini, sub, "mini_val")
    assert str(raised.value) == str(expected)


# ----- the real tracker's output: EKF on the real PointPillars detections, and the synthetic demo ------------
@pytest.mark.slow  # the ekf on the real file end to end is quick in test_track_nuscenes, the parity in the cases above
def test_ekf_on_pointpillars_mini_val(nusc_mini, pointpillars_mini_val):
    sub, _ = track(nusc_mini, "ekf", "mini_val", pointpillars_mini_val)
    assert_parity(nusc_mini, sub, "mini_val")


def test_ekf_on_simulated_demo_val(tmp_path, capsys):
    from grutrack.cli import main
    from grutrack.data.nuscenes import open_nuscenes

    data, dets = tmp_path / "demo", tmp_path / "dets.json"
    assert main(["demo-data", "--out", str(data), "--scenes", "5", "--frames-per-scene", "20", "--seed", "4"]) == 0
    assert (
        main(
            [
                "simulate-detections",
                "--dataroot",
                str(data),
                "--version",
                "v1.0-demo",
                "--split",
                "demo_val",
                "--profile",
                "centerpoint",
                "--seed",
                "9",
                "--out",
                str(dets),
            ]
        )
        == 0
    )
    nusc = open_nuscenes(data, "v1.0-demo")
    sub, _ = track(nusc, "ekf", "demo_val", dets)
    assert_parity(nusc, sub, "demo_val")
    # what `grutrack evaluate` prints of the demo says it is SYNTHETIC
    common = ["--dataroot", str(data), "--version", "v1.0-demo", "--split", "demo_val"]
    (tmp_path / "sub.json").write_text(json.dumps(sub))
    capsys.readouterr()
    argv = ["evaluate", *common, "--submission", str(tmp_path / "sub.json"), "--out", str(tmp_path / "m.json")]
    assert main([*argv, "--evaluator", "fast"]) == 0
    assert capsys.readouterr().out.startswith("SYNTHETIC data: the scenes and ground truth of ")


# ----------------------------------------------------------------------------------------------------------------
# Per-box decisions (what grutrack render draws)
# ----------------------------------------------------------------------------------------------------------------


def _decision_sums(decisions, class_name: str) -> dict[str, float]:
    from grutrack.evaluation.nuscenes_fast import MATCH, MISS_OR_FP, SWITCH

    c = decisions.class_names.index(class_name)
    g = decisions.g_status[decisions.g_cls == c]
    p = decisions.p_status[decisions.p_cls == c]
    return {
        "tp": float(np.sum(g == MATCH)),
        "fp": float(np.sum(p == MISS_OR_FP)),
        "fn": float(np.sum(g == MISS_OR_FP)),
        "ids": float(np.sum(g == SWITCH)),
    }


def _assert_decisions_match(decisions, label_metrics: dict[str, dict[str, float]]) -> None:
    for name in decisions.class_names:
        sums = _decision_sums(decisions, name)
        for key in ("tp", "fp", "fn", "ids"):
            ref = label_metrics[key][name]
            if ref is None or (isinstance(ref, float) and math.isnan(ref)):
                # No value in the summary: a class without an achieved threshold has no FP / IDS decisions.
                assert sums[key] == 0, (name, key, sums)
            else:
                assert sums[key] == ref, (name, key, sums[key], ref)


@pytest.mark.slow  # the devkit's whole evaluation of corrupted_mini_val (shared with the slow cases above)
def test_match_decisions_sum_to_the_devkit_counts(nusc_mini, mini_val_gt, devkit_reference):
    """Per-box decisions at each class's best-MOTA threshold add up to the devkit's TP / FP / FN / IDS."""
    from grutrack.evaluation.nuscenes_fast import match_decisions

    sub = corrupt_submission(nusc_mini, "mini_val", seed=0, base=mini_val_gt)
    summary = devkit_reference("corrupted_mini_val", nusc_mini, sub, "mini_val")[0]
    tracks_gt, tracks_pred, _ = load_tracks(nusc_mini, sub, "mini_val")
    decisions, _ = match_decisions(tracks_gt, tracks_pred)
    assert sum(_decision_sums(decisions, "car").values()) > 0 and summary["ids"] > 0
    _assert_decisions_match(decisions, summary["label_metrics"])
    assert len(decisions.frame_keys) == 81


@pytest.mark.parametrize("seed", [0, 3])
def test_match_decisions_random_crowded_tracks(seed):
    """Contested frames, switches and repeated ids: the decisions' sums equal the summary's counts."""
    from grutrack.evaluation.nuscenes_fast import match_decisions

    tracks_gt, tracks_pred = _random_tracks(seed)
    decisions, metrics = match_decisions(tracks_gt, tracks_pred)
    _assert_decisions_match(decisions, metrics.serialize()["label_metrics"])
    assert metrics.serialize()["ids"] > 0


def test_match_decisions_accumulates_each_class_once(monkeypatch):
    """One accumulation per class gives both the decisions and the metrics, which are evaluate_tracks'."""
    from grutrack.evaluation.nuscenes_fast import ClassAccumulator, match_decisions

    tracks_gt, tracks_pred = _random_tracks(3)
    built = []
    init = ClassAccumulator.__init__

    def counting(self, flat, c, dist_th):
        built.append(c)
        init(self, flat, c, dist_th)

    monkeypatch.setattr(ClassAccumulator, "__init__", counting)
    _, metrics = match_decisions(tracks_gt, tracks_pred)
    assert built == list(range(len(metrics.class_names)))
    monkeypatch.undo()
    ref, _ = evaluate_tracks(tracks_gt, tracks_pred)
    ours, ref = metrics.serialize(), ref.serialize()
    ours.pop("eval_time"), ref.pop("eval_time")
    assert json.dumps(ours) == json.dumps(ref)


# ----- the accumulation as a drop-in inside the devkit's own TrackingEval -----------------------------------------
def _plugin_evaluate(reference, tmp_path):
    """FastTrackingEval.evaluate on the tracks the devkit loaded for ``reference`` (its __init__'s output)."""
    from nuscenes.eval.common.config import config_factory

    from grutrack.evaluation.devkit_plugin import FastTrackingEval

    ev = object.__new__(FastTrackingEval)
    ev.cfg, ev.output_dir, ev.verbose, ev.render_classes = (
        config_factory("tracking_nips_2019"),
        str(tmp_path),
        False,
        None,
    )
    ev.tracks_gt, ev.tracks_pred = reference[2], reference[3]
    return ev.evaluate()


@pytest.mark.slow  # the devkit's whole evaluation of both cases (shared with the slow cases above)
@pytest.mark.parametrize("case", ["corrupted_mini_val", "contested_mini_val"])
def test_devkit_tracking_eval_with_the_fast_accumulation(nusc_mini, mini_val_gt, devkit_reference, case, tmp_path):
    """The devkit's own TrackingEval (its aggregation code) driving FastTrackingEvaluation gives the devkit's
    metrics and per-threshold data; the devkit's modules are left as they were."""
    import nuscenes.eval.tracking.algo as algo
    import nuscenes.eval.tracking.evaluate as evaluate

    if case == "corrupted_mini_val":  # the submissions of the cases above (their devkit runs are reused)
        sub = corrupt_submission(nusc_mini, "mini_val", seed=0, base=mini_val_gt)
    else:
        sub = corrupt_submission(
            nusc_mini,
            "mini_val",
            seed=2,
            base=mini_val_gt,
            duplicate=0.3,
            exact_duplicate=0.15,
            repeated_id=0.01,
            noise=0.4,
        )
    ref = devkit_reference(case, nusc_mini, sub, "mini_val")
    metrics, md_list = _plugin_evaluate(ref, tmp_path)
    worst, bad = compare_summaries(ref[0], dict(metrics.serialize(), meta=ref[0]["meta"]))
    assert not bad, bad[:5]
    assert not compare_metric_data(ref[1], md_list)[1]
    assert type(md_list["car"]).__module__ == "nuscenes.eval.tracking.data_classes"
    assert evaluate.TrackingEvaluation is algo.TrackingEvaluation


@pytest.mark.parametrize("seed", [0, 3])
def test_fast_tracking_evaluation_is_a_drop_in_per_class(seed):
    """Same constructor and accumulate() as the devkit's TrackingEvaluation, same metric data, including a
    class that falls back to the devkit (a repeated GT id) and one without ground truth."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.tracking.data_classes import TrackingMetricData

    from grutrack.evaluation.devkit_plugin import FastTrackingEvaluation

    cfg = config_factory("tracking_nips_2019")
    tracks_gt, tracks_pred = _random_tracks(seed)
    first = next(iter(tracks_gt.values()))
    ts = next(t for t, boxes in first.items() if boxes)
    first[ts].append(copy.deepcopy(first[ts][0]))  # one class goes to the devkit's own class
    ref = _devkit_metric_data(tracks_gt, tracks_pred, cfg)
    for name in ("car", "pedestrian", "bus"):
        md = FastTrackingEvaluation(
            tracks_gt,
            tracks_pred,
            name,
            cfg.dist_fcn_callable,
            cfg.dist_th_tp,
            cfg.min_recall,
            num_thresholds=TrackingMetricData.nelem,
            metric_worst=cfg.metric_worst,
            verbose=False,
        ).accumulate()
        assert isinstance(md, TrackingMetricData)
        assert md == ref[name] or not compare_metric_data(_one(ref[name], name), _one(md, name))[1], name


def _one(md, name):
    from nuscenes.eval.tracking.data_classes import TrackingMetricDataList

    out = TrackingMetricDataList()
    out.set(name, md)
    return out


def test_fast_tracking_eval_main_on_a_submission_file(nusc_root, pointpillars_mini_val, tmp_path):
    """The whole devkit path (NuScenes load, loaders, filters, files written) with the fast accumulation, on a
    tracker's submission file: the summary equals the toolkit's fast evaluator's."""
    from nuscenes.eval.common.config import config_factory

    from grutrack.data.nuscenes import open_nuscenes
    from grutrack.evaluation.devkit_plugin import FastTrackingEval
    from grutrack.evaluation.nuscenes_fast import fast_tracking_eval as fast

    sub, _ = track(open_nuscenes(nusc_root, "v1.0-mini"), "ekf", "mini_val", pointpillars_mini_val)
    path = tmp_path / "sub.json"
    path.write_text(json.dumps(sub))
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        summary = FastTrackingEval(
            config_factory("tracking_nips_2019"),
            str(path),
            "mini_val",
            str(tmp_path / "out"),
            "v1.0-mini",
            str(nusc_root),
            verbose=False,
        ).main(render_curves=False)
    assert (tmp_path / "out" / "metrics_summary.json").is_file()
    ours = fast(open_nuscenes(nusc_root, "v1.0-mini"), str(path), "mini_val")
    worst, bad = compare_summaries(summary, ours)
    assert not bad, bad[:5]
    assert 0.1 < summary["amota"] < 0.3
