"""The Snakemake workflow on real data, and its behaviour when killed mid-rule.

1. ``reports/nusc_val.md`` built on nuScenes v1.0-mini (split mini_val) with the real PointPillars detections as
   a ``local`` detector, the GRU-KF trainings on mini_train with simulated detections and one epoch. The full
   experiment (Table III and the whole Table IV ablation: 7 runs, 2 trainings) runs; about 5 minutes on 2 cores.
   The EKF run's metrics JSON equals, number for number, a by-hand CLI run (``grutrack track`` on the raw
   PointPillars file with the shipped ``ekf`` preset, then ``grutrack evaluate --evaluator devkit``), and the
   report's rounded numbers equal the rounded CLI / metrics-JSON numbers.
2. ``snakemake`` SIGKILLed (whole process group) while the train rule runs: what that rule has already written
   at its output paths is flagged incomplete (a dry run refuses it; with --rerun-incomplete it plans the rule
   again), nothing half-written sits at an output path, and a re-run completes with a loadable checkpoint.

The code-version param is pinned (GRUTRACK_CODE_VERSION) as in tests/test_workflow.py.
"""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_workflow import REPO, planned, snakemake  # noqa: E402  (tests/ is not a package)

EKF_KEYS = ("amota", "amotp", "ids")


def _run(cmd, cwd, timeout=300):
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def _table(text: str, heading: str, label: str) -> dict[str, list[str]]:
    """Rows (first cell -> other cells) of the first markdown table after ``heading`` then ``label``."""
    section = text.split(heading, 1)[1]
    block = section.split(label, 1)[1] if label else section
    rows, started = {}, False
    for line in block.splitlines():
        if line.startswith("|"):
            started = True
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if cells[0] in ("method", "run") or set(cells[0]) <= set(":- "):
                continue
            rows[cells[0]] = cells[1:]
        elif started:
            break
    return rows


# ------------------------------------------------------------------------------------------------------------
# 1. reports/nusc_val.md on nuScenes mini with the real PointPillars detections
# ------------------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def mini_run(tmp_path_factory, nusc_root, pointpillars_mini_val):
    work = tmp_path_factory.mktemp("wf_real")
    cfg = {
        "datasets": {"nuscenes": {"dataroot": str(nusc_root), "version": "v1.0-mini"}},
        "detectors": {
            "pointpillars": {
                "kind": "local",
                "format": "nuscenes_json",
                "member": None,
                "files": {"mini_val": str(pointpillars_mini_val)},
            }
        },
        # smallest training the config allows: one epoch (6 steps) on mini_train with 2 scenes held out for
        # validation (validated before the first step and after the 3rd and 6th), simulated detections
        "trainings": {
            "nusc_grukf": {
                "split": "mini_train",
                "detector": "centerpoint_sim",
                "overrides": {"epochs": 1, "validation_scenes": 2, "val_every": 3},
            },
            "nusc_grukf_bicycle": {
                "split": "mini_train",
                "detector": "centerpoint_sim",
                "overrides": {"epochs": 1, "ss_model": "BICYCLE", "validation_scenes": 2, "val_every": 3},
            },
        },
        # the nusc_val experiment (all 8 runs of Tables III and IV) on mini_val with the PointPillars detections
        "experiments": {"nusc_val": {"split": "mini_val", "detectors": ["pointpillars"]}},
        "tracking": {"device": "cpu"},
    }
    (work / "real.yaml").write_text(yaml.safe_dump(cfg))
    t0 = time.monotonic()
    proc = snakemake(work, "reports/nusc_val.md", configs=("real.yaml",), timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    print(f"workflow reports/nusc_val.md on mini_val: {time.monotonic() - t0:.0f} s")

    # the same EKF run by hand: raw PointPillars file, shipped ekf preset, devkit evaluator
    cli = work / "cli"
    cli.mkdir()
    common = ["--dataroot", str(nusc_root), "--version", "v1.0-mini", "--split", "mini_val"]
    _run(
        [
            sys.executable,
            "-m",
            "grutrack",
            "track",
            *common,
            "--detections",
            str(pointpillars_mini_val),
            "--tracker",
            "ekf",
            "--config",
            "ekf",
            "--out",
            str(cli / "tracks.json"),
            "--no-progress",
        ],
        cwd=cli,
    )
    _run(
        [
            sys.executable,
            "-m",
            "grutrack",
            "evaluate",
            *common,
            "--submission",
            str(cli / "tracks.json"),
            "--evaluator",
            "devkit",
            "--out",
            str(cli / "metrics.json"),
        ],
        cwd=cli,
    )
    return work


def _metrics(work: Path, run: str) -> dict:
    return json.loads((work / f"reports/metrics/nusc_val/pointpillars/{run}.json").read_text())


def test_mini_val_ekf_metrics_equal_the_cli_run(mini_run):
    wf = _metrics(mini_run, "ekf")
    cli = json.loads((mini_run / "cli/metrics.json").read_text())
    # the workflow scores with the fast evaluator, the command by hand with the devkit: the same numbers
    assert wf["split"] == cli["split"] == "mini_val" and (wf["evaluator"], cli["evaluator"]) == ("fast", "devkit")
    assert wf["overall"].keys() == cli["overall"].keys()
    for key, value in wf["overall"].items():
        ref = cli["overall"][key]
        assert (value is None and ref is None) or math.isclose(value, ref, rel_tol=1e-12, abs_tol=1e-12), key
    assert all(wf["overall"][k] == cli["overall"][k] for k in EKF_KEYS if k == "ids")  # counts exactly
    # per-class numbers: equal up to the last bits (the devkit's per-class MOTP has been seen to differ by one ulp
    # between two processes on the same submission)
    assert wf["per_class"].keys() == cli["per_class"].keys()
    for cls, row in wf["per_class"].items():
        for key, value in row.items():
            ref = cli["per_class"][cls][key]
            assert (value is None and ref is None) or math.isclose(value, ref, rel_tol=1e-12), (cls, key, value, ref)
    assert 0.0 < cli["overall"]["amota"] < 1.0  # a real, non-degenerate score


def test_mini_val_report_numbers_equal_the_cli_and_metrics(mini_run):
    text = (mini_run / "reports/nusc_val.md").read_text()
    assert "mini_val" in text and "pointpillars" in text
    # fast evaluator, the devkit cross-check of the grukf run stated; trainings on simulated detections flagged
    assert "Evaluated with grutrack's fast exact evaluator" in text
    cc = json.loads((mini_run / "reports/metrics/nusc_val/pointpillars/grukf.crosscheck.json").read_text())
    assert cc["equal"] and cc["scenes"] == ["scene-0103", "scene-0916"]
    assert (
        "Cross-check: run `grukf` scored by both nuscenes-devkit `TrackingEval` and the fast evaluator on both "
        "scenes of the split"
        in text
        and "**equal** to 1e-09" in text
    )
    assert (
        "SYNTHETIC TRAINING DATA" in text and "`nusc_grukf`: simulated detections (centerpoint profile, seed 1)" in text
    )
    cli = json.loads((mini_run / "cli/metrics.json").read_text())["overall"]

    every = _table(text, "## Every run", "")
    assert set(every) == {
        "ekf",
        "polymot",
        "fastpoly",
        "mctrack",
        "grukf",
        "ekf_bicycle",
        "ekf_ctra",
        "kf_ca",
        "grukf_bicycle",
    }
    # columns: AMOTA AMOTP MOTA recall IDS FRAG TP FP FN
    ekf = every["ekf"]
    assert [ekf[0], ekf[1], ekf[4]] == [f"{100 * cli['amota']:.1f}", f"{100 * cli['amotp']:.1f}", f"{cli['ids']:.0f}"]
    for run, row in every.items():
        o = _metrics(mini_run, run)["overall"]
        assert row[:5] == [
            f"{100 * o['amota']:.1f}",
            f"{100 * o['amotp']:.1f}",
            f"{100 * o['mota']:.1f}",
            f"{100 * o['recall']:.1f}",
            f"{o['ids']:.0f}",
        ], run

    t3 = _table(text, "## Table III", "**Reproduced**")
    rows3 = {"Ours": "grukf", "Poly-MOT": "polymot", "Fast-Poly (not in the paper)": "fastpoly"}
    rows3["MCTrack (not in the paper)"] = "mctrack"
    for row, run in rows3.items():
        o = _metrics(mini_run, run)["overall"]
        assert t3[row] == [f"{100 * o['amota']:.1f}", f"{100 * o['amotp']:.1f}", f"{o['ids']:.0f}"], row
    assert "Fast-Poly" not in _table(text, "## Table III", "**Difference**")  # no paper number to subtract

    t4 = _table(text, "## Table IV", "**Reproduced**")
    rows = {
        "Bicycle+EKF": "ekf_bicycle",
        "CTRA+EKF": "ekf_ctra",
        "CA+KF": "kf_ca",
        "CTRA+Ours": "grukf",
        "Bicycle+Ours": "grukf_bicycle",
        "MCTrack (not in the paper)": "mctrack",
    }
    assert set(t4) == set(rows)
    for row, run in rows.items():
        pc = _metrics(mini_run, run)["per_class"]
        assert t4[row] == [f"{100 * pc[c][k]:.1f}" for c in ("bicycle", "car") for k in ("amota", "amotp")], row


def test_mini_val_nothing_to_do_after_the_run(mini_run):
    proc = snakemake(mini_run, "reports/nusc_val.md", options=("-n",), configs=("real.yaml",))
    assert proc.returncode == 0 and planned(proc) == {}, proc.stdout[-2000:] + proc.stderr[-2000:]


# ------------------------------------------------------------------------------------------------------------
# 2. a killed rule leaves nothing Snakemake takes as complete; a re-run finishes it
# ------------------------------------------------------------------------------------------------------------

# tiny demo; a training long enough to be killed mid-way that writes train_log.csv (a declared output) early
KILL_CFG = """
datasets:
  demo: {scenes: 3, frames_per_scene: 12}
trainings:
  demo_grukf: {overrides: {sources: [], epochs: 25, checkpoint_every: 1, validation_scenes: 1}}
"""
TRAIN_OUTPUTS = (
    "checkpoints/demo_grukf/model.pt",
    "checkpoints/demo_grukf/train_log.csv",
    "checkpoints/demo_grukf/training.yaml",
)


def _snakemake_cmd(*args: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(REPO / "Snakefile"),
        "--cores",
        "1",
        "--configfile",
        "kill.yaml",
        *args,
        "--",
        TRAIN_OUTPUTS[0],
    ]


def _stepped(train_log: Path) -> bool:
    """Whether a train_log.csv being written holds a row of step 1 or later."""
    if not train_log.exists():
        return False
    rows = list(csv.DictReader(train_log.open()))
    return any(r.get("step", "").isdigit() and int(r["step"]) >= 1 for r in rows)


@pytest.mark.slow
def test_killed_rule_is_incomplete_and_a_rerun_finishes_it(tmp_path):
    (tmp_path / "kill.yaml").write_text(KILL_CFG)
    env = {**os.environ, "GRUTRACK_CODE_VERSION": "test-pinned"}
    log = tmp_path / "snakemake.out"
    with open(log, "w") as out:
        proc = subprocess.Popen(
            _snakemake_cmd(), cwd=tmp_path, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )  # own process group: snakemake + the rule
    train_log = tmp_path / TRAIN_OUTPUTS[1]
    try:
        deadline = time.monotonic() + 120
        while not _stepped(train_log):  # the train rule has made >= 1 step (step 0: the start-up validation)
            assert proc.poll() is None, f"snakemake ended before the kill:\n{log.read_text()[-3000:]}"
            assert time.monotonic() < deadline, f"train rule not started within 120 s:\n{log.read_text()[-3000:]}"
            time.sleep(0.2)
        assert (tmp_path / "logs/train/demo_grukf.log").exists()
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    time.sleep(0.5)
    out_text = log.read_text()
    assert "rule train:" in out_text, out_text[-3000:]
    assert "Finished jobid" not in out_text.split("rule train:", 1)[1]  # killed mid-rule
    assert not (tmp_path / TRAIN_OUTPUTS[0]).exists()  # the model is written last, atomically

    # what the killed rule left at its output paths is whole (atomic writes), and flagged incomplete
    left = [p for p in TRAIN_OUTPUTS if (tmp_path / p).exists()]
    assert "checkpoints/demo_grukf/train_log.csv" in left
    rows = list(csv.DictReader((tmp_path / TRAIN_OUTPUTS[1]).open()))
    assert rows and int(rows[-1]["step"]) >= 1
    if (tmp_path / TRAIN_OUTPUTS[2]).exists():
        assert yaml.safe_load((tmp_path / TRAIN_OUTPUTS[2]).read_text())["epochs"] == 25

    unlock = subprocess.run(
        _snakemake_cmd("--unlock"), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )  # SIGKILL left the working-dir lock
    assert unlock.returncode == 0, unlock.stderr[-2000:]
    # without the workflow's default profile (which sets rerun-incomplete), Snakemake refuses to take them as
    # complete and names them
    dry = subprocess.run(
        _snakemake_cmd("-n", "--workflow-profile", "none"),
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    text = dry.stdout + dry.stderr
    assert dry.returncode != 0 and "incomplete" in text.lower(), text[-3000:]
    for p in left:
        assert p in text, (p, text[-3000:])
    # with the default profile (rerun-incomplete: true) a plain dry run plans the killed rule again
    dry = subprocess.run(_snakemake_cmd("-n"), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert dry.returncode == 0, dry.stdout[-3000:] + dry.stderr[-3000:]
    assert planned(dry) == {"train": 1}, dry.stdout[-3000:]

    # the re-run completes the rule; its outputs are valid
    rerun = subprocess.run(_snakemake_cmd(), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stdout[-3000:] + rerun.stderr[-3000:]
    from grutrack.motion.checkpoint import read_checkpoint

    ck = read_checkpoint(tmp_path / TRAIN_OUTPUTS[0], map_location="cpu")
    assert ck["train_state"]["epoch"] == 25
    rows = list(csv.DictReader((tmp_path / TRAIN_OUTPUTS[1]).open()))
    assert [int(r["step"]) for r in rows] == list(range(0, len(rows))) and rows  # step 0: before training
    assert yaml.safe_load((tmp_path / TRAIN_OUTPUTS[2]).read_text())["epochs"] == 25
    after = subprocess.run(_snakemake_cmd("-n"), cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert after.returncode == 0 and planned(after) == {}, after.stdout[-2000:] + after.stderr[-2000:]
