"""The Snakemake workflow on a tiny demo (3 scenes x 12 frames, one training epoch), run for real once in a
temporary working directory: the report's tables match the metrics JSONs and its figures exist; a dry run
after one changed value plans only the stages that depend on it; a misspelt config key fails before any
rule runs, naming the key; a missing dataroot fails naming its config key; the leaderboard zip is validated.

The code-version param is pinned (GRUTRACK_CODE_VERSION) so that source edits made while the tests run cannot
re-plan stages; tests/test_pipeline.py checks the per-stage code versions themselves.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TINY = """
datasets:
  demo: {scenes: 3, frames_per_scene: 12}
trainings:
  demo_grukf: {overrides: {sources: [], epochs: 1, validation_scenes: 1}}
# a leaderboard-style experiment on the demo (no evaluation; a validated zip and the Table II report)
experiments:
  demo_lb:
    dataset: demo
    split: demo_val
    detectors: [centerpoint_sim]
    evaluator: none
    leaderboard_run: grukf
    runs: {grukf: {tracker: grukf, preset: ekf, training: demo_grukf}}
reports:
  demo_lb: {kind: nusc_test, experiment: demo_lb, tables: {II: {"Ours (CenterPoint)": grukf}}, trainings: {}}
"""


def snakemake(
    workdir: Path, *targets: str, options: tuple[str, ...] = (), configs: tuple[str, ...] = (), timeout: int = 600
):
    """Run snakemake on the repository's Snakefile in ``workdir``; returns the completed process."""
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), "--cores", "2", *options]
    if configs:
        cmd += ["--configfile", *configs]
    cmd += ["--", *targets]
    env = {**os.environ, "GRUTRACK_CODE_VERSION": "test-pinned"}
    return subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=timeout)


def planned(proc) -> dict[str, int]:
    """Rule -> job count from the 'Job stats' table of a dry run ({} when nothing is to be done)."""
    text = proc.stdout + proc.stderr
    if "Nothing to be done" in text:
        return {}
    block = text.split("Job stats:", 1)[1]
    out = {}
    for line in block.splitlines()[3:]:
        m = re.match(r"^(\w+)\s+(\d+)$", line.strip())
        if not m or m.group(1) == "total":
            break
        out[m.group(1)] = int(m.group(2))
    return out


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """A real run of reports/demo_val.md (and the leaderboard-style demo_lb report) on the tiny demo config."""
    work = tmp_path_factory.mktemp("wf")
    (work / "tiny.yaml").write_text(TINY)
    proc = snakemake(work, "reports/demo_val.md", "reports/demo_lb.md", configs=("tiny.yaml",))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return work


def test_demo_report_tables_match_metrics_json(demo_run):
    text = (demo_run / "reports/demo_val.md").read_text()
    assert "SYNTHETIC" in text and "No comparison between the two is implied" in text
    for run in ("ekf", "grukf", "grukf_demo", "constant_gain"):
        doc = json.loads((demo_run / f"reports/metrics/demo_val/centerpoint_sim/{run}.json").read_text())
        o = doc["overall"]
        row = re.search(rf"^\| {run} \| (.+) \|$", text, re.M).group(1).split(" | ")
        assert row[:5] == [
            f"{100 * o['amota']:.1f}",
            f"{100 * o['amotp']:.1f}",
            f"{100 * o['mota']:.1f}",
            f"{100 * o['recall']:.1f}",
            f"{o['ids']:.0f}",
        ]
    assert re.search(r"^\| Ours \(GRUTrack\) \| 73\.2 \| 51\.1 \| 267 \|$", text, re.M)  # paper numbers, labelled
    assert "| method | AMOTA | AMOTP (cm) | IDS |" in text
    assert "within the spread from one detection draw to another" in text  # the runs' differences put in scale
    # every rendered frame of the demo says SYNTHETIC under its title
    counts = json.loads((demo_run / "reports/renders/demo_val/centerpoint_sim/ekf/counts.json").read_text())
    assert counts["synthetic"] is True
    # a validation AMOTA of a training on SYNTHETIC data says so where it is printed
    assert re.search(r"last validation AMOTA 0\.\d{3} \(SYNTHETIC data\)\.", text)
    # the constant-gain ablation: a training of no step, shown beside the EKF and the trained GRU-KF
    assert (
        "## Training 'demo_constant_gain'\n\nNo training step: the network as initialised, whose gain is one "
        "constant" in text
    )
    assert re.search(r"^\| demo_constant_gain \| .* \| no step \(the initialised network\) \|", text, re.M)
    # the default recipe's learning curve on the scene held out of demo_train, with the EKF's line
    assert re.search(
        r"Validated on 1 scene held out of demo_train \(demo-scene-\d+\) with 4 detection sets "
        r"\(given, centerpoint, pointpillars, centerpoint_velfail; AMOTA their mean\), not trained on; "
        r"step 0 is the network before training\. model\.pt holds step [01] \(the latest step within "
        r"one standard error of the best validation AMOTA, AMOTA 0\.\d{3}\); tracker preset 'ekf' "
        r"\(its EKF\) on the same scenes: 0\.\d{3}\.",
        text,
    )
    # which network each GRU-KF run tracked with: the shipped pretrained one, and the one this job trained
    assert re.search(
        r"^\| grukf \| grukf_pretrained \| shipped pretrained network `grukf_default` "
        r"\(`bash scripts/pretrain_grukf\.sh`, commit [0-9a-f]{10}, written \d{4}-\d\d-\d\d\); not trained by "
        r"this workflow \| \d+ steps, 3 epochs \|$",
        text,
        re.M,
    )
    assert re.search(
        r"^\| grukf_demo \| demo_grukf \| trained by this workflow \(`checkpoints/demo_grukf`\) \|", text, re.M
    )
    assert "Validated on 2 scenes held out of mini_train" in text  # the pretrained network's learning curve
    assert not (demo_run / "checkpoints/grukf_pretrained").exists()  # no training job for a shipped network
    assert "figures/demo_val/learning_curve_demo_grukf.png" in text
    assert "config hash" in text and "grutrack 0.1.0" in text and "centerpoint_sim.json" in text
    links = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", text)
    assert links
    for link in links:
        assert (demo_run / "reports" / link).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a strip of key frames of each run's worst scene, from its render folder
    for run in ("ekf", "grukf"):
        assert f"figures/demo_val/worst_scene_{run}.png" in links
        counts = json.loads((demo_run / f"reports/renders/demo_val/centerpoint_sim/{run}/counts.json").read_text())
        assert len(counts["scenes"]) == 1 and f"**{run}**: {counts['scenes'][0]['name']}, frames" in text


def test_nothing_to_do_after_the_run(demo_run):
    assert planned(snakemake(demo_run, "reports/demo_val.md", options=("-n",), configs=("tiny.yaml",))) == {}


def test_demo_data_by_hand_with_the_same_settings_reruns_nothing(demo_run):
    # the README's demo-data command, with the settings of the tiny config, over the workflow's demo dataset
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "grutrack",
            "demo-data",
            "--out",
            "data/demo",
            "--scenes",
            "3",
            "--frames-per-scene",
            "12",
            "--seed",
            "0",
            "--version",
            "v1.0-demo",
        ],
        cwd=demo_run,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0 and "already up to date" in proc.stdout, proc.stdout + proc.stderr
    assert (
        planned(
            snakemake(demo_run, "reports/demo_val.md", "reports/demo_lb.md", options=("-n",), configs=("tiny.yaml",))
        )
        == {}
    )


def test_tracker_threshold_change_reruns_track_submit_evaluate_render_report(demo_run):
    (demo_run / "thr.yaml").write_text(
        "tracker_presets:\n  ekf: {overrides: {preprocessing: {score_threshold: {car: 0.25}}}}\n"
    )
    proc = snakemake(
        demo_run, "reports/demo_val.md", options=("-n", "--quiet", "rules"), configs=("tiny.yaml", "thr.yaml")
    )
    # only the run whose preset is `ekf` reruns; the GRU-KF run has its own preset entry (`grukf`)
    assert planned(proc) == {
        "resolve_tracker": 1,
        "track": 1,
        "submit": 1,
        "manifest": 1,
        "evaluate": 1,
        "render": 1,
        "report": 1,
    }, proc.stdout[-2000:]


def test_training_change_reruns_train_and_its_dependents_only(demo_run):
    (demo_run / "lr.yaml").write_text("trainings:\n  demo_grukf: {overrides: {epochs: 1, lr: 2.0e-5}}\n")
    proc = snakemake(
        demo_run, "reports/demo_val.md", options=("-n", "--quiet", "rules"), configs=("tiny.yaml", "lr.yaml")
    )
    # only the run tracked with the demo's training depends on it; the EKF run and the run tracked with the
    # shipped pretrained network (and its devkit cross-check) are untouched
    assert planned(proc) == {
        "train": 1,
        "track": 1,
        "submit": 1,
        "manifest": 1,
        "evaluate": 1,
        "render": 1,
        "report": 1,
    }


def test_av2_report_through_the_same_rules_with_simulated_detections(demo_run, av2_root):
    """reports/av2_val.md on the AV2 logs of ../shared/data with simulated detections chosen in the config:
    the same simulate, track, submit, evaluate and report rules as nuScenes; the GRU-KF trained on the
    nuScenes-format demo tracks AV2 (Table I's setting)."""
    (demo_run / "av2.yaml").write_text(
        f"datasets:\n  av2: {{dataroot: {av2_root}}}\n"
        "experiments:\n  av2_val:\n    detectors: [centerpoint_sim]\n"
        "    runs: {greedy: {tracker: greedy, preset: greedy, training: null},\n"
        "           ab3dmot: {tracker: ab3dmot, preset: ab3dmot, training: null},\n"
        "           grukf: {tracker: grukf, preset: grukf, training: demo_grukf}}\n"
    )
    proc = snakemake(demo_run, "reports/av2_val.md", configs=("tiny.yaml", "av2.yaml"))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert (demo_run / "detections/simulated/av2/val/centerpoint_sim.feather").is_file()
    text = (demo_run / "reports/av2_val.md").read_text()
    assert "SYNTHETIC DETECTIONS" in text and "centerpoint_sim" in text
    for run in ("greedy", "ab3dmot", "grukf", "ekf"):  # ekf: the config's extra Table I row
        doc = json.loads((demo_run / f"reports/metrics/av2_val/centerpoint_sim/{run}.json").read_text())
        assert doc["dataset"] == "av2" and doc["logs"] == 2 and 0.2 < doc["overall"]["hota"] < 1.0
        assert f"{100 * doc['overall']['hota']:.1f}" in text
        assert (demo_run / f"submissions/av2_val/centerpoint_sim/{run}.manifest.json").is_file()
    assert re.search(r"^\| EKF \(not in the paper\) \|", text, re.M)


def test_paper_numbers_change_reruns_only_the_report(demo_run):
    (demo_run / "paper.yaml").write_text((REPO / "workflow/config/paper.yaml").read_text())
    os.utime(demo_run / "paper.yaml")
    (demo_run / "paper_cfg.yaml").write_text(f"paper: {demo_run / 'paper.yaml'}\n")
    proc = snakemake(demo_run, "reports/demo_val.md", options=("-n",), configs=("tiny.yaml", "paper_cfg.yaml"))
    assert planned(proc) == {"report": 1}


def test_leaderboard_zip_rule_and_report(demo_run):
    zp = demo_run / "submissions/demo_lb_centerpoint_sim.zip"
    with zipfile.ZipFile(zp) as zf:
        assert zf.namelist() == ["grukf.json"]
    text = (demo_run / "reports/demo_lb.md").read_text()
    assert "submissions/demo_lb_centerpoint_sim.zip" in text and "Ours (LargeKernel3D)" in text
    assert re.search(r"^\| Ours \(CenterPoint\) \| 70\.0 \| 50\.4 \| 353 \|$", text, re.M)
    assert not (demo_run / "reports/metrics/demo_lb").exists()  # no ground truth, no evaluation


def test_leaderboard_zip_validates_before_zipping(demo_run, tmp_path):
    from grutrack.data.nuscenes import load_scenes, open_nuscenes
    from grutrack.errors import InputFormatError
    from grutrack.export.leaderboard import build_zip

    sub = demo_run / "submissions/demo_val/centerpoint_sim/grukf.json"
    tokens = [
        f.token for s in load_scenes(open_nuscenes(demo_run / "data/demo", "v1.0-demo"), "demo_val") for f in s.frames
    ]
    info = build_zip(sub, tokens, tmp_path / "lb.zip")
    with zipfile.ZipFile(tmp_path / "lb.zip") as zf:
        assert zf.namelist() == ["grukf.json"] and json.loads(zf.read("grukf.json"))["meta"]["use_lidar"]
    assert info["samples"] == len(tokens)
    broken = json.loads(sub.read_text())
    broken["results"].pop(tokens[0])
    (tmp_path / "broken.json").write_text(json.dumps(broken))
    with pytest.raises(InputFormatError, match="1 missing"):
        build_zip(tmp_path / "broken.json", tokens, tmp_path / "bad.zip")
    assert not (tmp_path / "bad.zip").exists()


@pytest.mark.parametrize(
    "overlay, key",
    [
        ("datasets:\n  demo: {scenez: 3}\n", "scenez"),
        ("trakers: {}\n", "trakers"),
        ("datasets:\n  demo: {scenes: three}\n", "config key datasets.demo.scenes (from --configfile "),
        # the same run as the line above, its message's other half
        pytest.param(
            "datasets:\n  demo: {scenes: three}\n",
            "bad.yaml): 'three' is not of type 'integer'",
            marks=pytest.mark.slow,
        ),
        ("tracker_presets:\n  ekf: {overrides: {lifecycle: {punish_nun: 2}}}\n", "lifecycle.punish_nun"),
    ],
)
def test_misspelt_config_key_fails_before_any_rule_runs(tmp_path, overlay, key):
    (tmp_path / "bad.yaml").write_text(overlay)
    proc = snakemake(tmp_path, "reports/demo_val.md", configs=("bad.yaml",))
    out = proc.stderr + proc.stdout
    assert proc.returncode == 2 and "Traceback" not in out and "WorkflowError" not in out, out[-2000:]
    assert len([line for line in out.splitlines() if key in line]) == 1, out[-2000:]
    assert not (tmp_path / "data").exists() and not (tmp_path / "logs").exists()  # nothing ran


def test_config_overrides_on_the_command_line_are_typed(tmp_path):
    from grutrack.pipeline.spec import typed_cli_config

    got = typed_cli_config(
        {
            "a": {
                "n": "12",
                "x": "1.2",
                "e": "1e-5",
                "b": "true",
                "z": "null",
                "s": "v1.0-mini",
                "p": "/data/12",
                "l": ["3", "CTRA"],
            },
            "top": 7,
        }
    )
    assert got == {
        "a": {"n": 12, "x": 1.2, "e": 1e-5, "b": True, "z": None, "s": "v1.0-mini", "p": "/data/12", "l": [3, "CTRA"]},
        "top": 7,
    }
    # numbers inside --config values reach the schema and the preset check as numbers
    train = "trainings={demo_grukf: {overrides: {epochs: 12, lr: 1e-4}}}"  # as the README shows it
    preset = "tracker_presets={ekf: {base: ekf, overrides: {association: {first_threshold: {car: 1.2}}}}}"
    proc = snakemake(tmp_path, "reports/demo_val.md", options=("-n", "--config", train, preset))
    assert proc.returncode == 0, proc.stderr[-2000:]
    proc = snakemake(tmp_path, "reports/demo_val.md", options=("-n", "--config", "datasets={demo: {scenes: 0}}"))
    assert proc.returncode != 0
    assert "config key datasets.demo.scenes (from --config): 0 is less than the minimum of" in proc.stdout + proc.stderr
    seeds = "detectors={centerpoint_sim: {seeds: {demo_val: -1}}}"  # a negative seed would alias another
    proc = snakemake(tmp_path, "reports/demo_val.md", options=("-n", "--config", seeds))
    assert proc.returncode == 2
    assert "detectors.centerpoint_sim.seeds.demo_val (from --config): -1 is less than the minimum of 0" in proc.stderr
    proc = snakemake(tmp_path, "reports/demo_val.md", options=("-n", "--config", "datasets={demo: {seed: -1}}"))
    assert proc.returncode == 2
    assert "datasets.demo.seed (from --config): -1 is less than the minimum of 0" in proc.stderr


def test_missing_dataroot_names_the_config_key(tmp_path):
    """A real dataset's dataroot unset (or not holding the version) stops the DAG with exit status 2 and one line
    naming the config key, no traceback, and nothing run."""
    proc = snakemake(tmp_path, "reports/nusc_val.md", options=("-n",))
    out = proc.stderr + proc.stdout
    assert proc.returncode == 2, out[-2000:]
    lines = [line for line in out.splitlines() if "config key" in line]
    assert len(lines) == 1 and lines[0].startswith("config key datasets.nuscenes.dataroot is not set"), lines
    assert "Traceback" not in out and "Exception" not in out
    proc = snakemake(
        tmp_path, "reports/av2_val.md", options=("-n", "--config", f"datasets={{nuscenes: {{dataroot: {tmp_path}}}}}")
    )
    assert proc.returncode == 2
    assert "datasets.av2.dataroot is not set" in proc.stderr + proc.stdout
    proc = snakemake(
        tmp_path, "reports/nusc_val.md", options=("--config", f"datasets={{nuscenes: {{dataroot: {tmp_path}}}}}")
    )
    out = proc.stderr + proc.stdout
    assert proc.returncode == 2 and "Traceback" not in out
    assert f"config key datasets.nuscenes.dataroot = {tmp_path}: " in out
    assert not (tmp_path / "results").exists() and not (tmp_path / "reports").exists()
