"""The workflow on a SLURM cluster: a one-node cluster started on this machine (tests/support/slurm_cluster.py:
Debian's slurm-wlm and munge, installed with apt-get when missing) runs a small demo target through
``snakemake --executor slurm`` with the shipped profile (``--workflow-profile workflow/profiles/slurm``), every
job as a SLURM job: the demo data, simulated detections, tracking (EKF and Poly-MOT presets), submission,
manifest, evaluation, render and report jobs. The report and the metrics equal those of the same target built
locally (``--cores 2``, the default profile). The cluster is stopped afterwards and nothing of it is left running.

Outside CI (``CI`` unset) the slow test skips, naming the reason, when SLURM cannot be installed or started here
(not root, no apt-get); with ``CI=true`` it fails instead. docs/cluster.md shows the commands and the timings.

The code-version param is pinned (GRUTRACK_CODE_VERSION) as in tests/test_workflow.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from support import slurm_cluster

REPO = Path(__file__).resolve().parents[1]
PROFILE = REPO / "workflow" / "profiles" / "slurm"
TARGET = "reports/demo_cluster.md"
#: the demo dataset at its smallest, and an experiment with two untrained runs (no training job) with its report
CONFIG = {
    "datasets": {"demo": {"scenes": 3, "frames_per_scene": 12}},
    "experiments": {
        "demo_cluster": {
            "dataset": "demo",
            "split": "demo_val",
            "detectors": ["centerpoint_sim"],
            "evaluator": "fast",
            "cross_check": None,
            "leaderboard_run": None,
            "runs": {
                "ekf": {"tracker": "ekf", "preset": "ekf", "training": None},
                "polymot": {"tracker": "ekf", "preset": "polymot", "training": None},
            },
        }
    },
    "reports": {"demo_cluster": {"kind": "demo", "experiment": "demo_cluster", "tables": {}, "trainings": {}}},
}
RUNS = ("ekf", "polymot")
#: per-run timings in a metrics JSON (wall time of the evaluation): everything else must be equal
TIMING_KEYS = {"seconds", "eval_time"}
# the executor plugin polls with squeue (no accounting database for sacct), first after 5 s
SLURM_OPTIONS = ("--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "5")


def _unavailable(msg: str):
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(msg)
    pytest.skip(msg)


def _snakemake(work: Path, *options: str, env: dict | None = None, timeout: int = 600) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(REPO / "Snakefile"), *options]
    cmd += ["--configfile", "cluster.yaml", "--", TARGET]
    env = {**(env or os.environ), "GRUTRACK_CODE_VERSION": "test-pinned"}
    return subprocess.run(cmd, cwd=work, env=env, capture_output=True, text=True, timeout=timeout)


def _workdir(tmp_path_factory, name: str) -> Path:
    work = tmp_path_factory.mktemp(name)
    (work / "cluster.yaml").write_text(yaml.safe_dump(CONFIG))
    return work


def _require_plugin() -> None:
    try:
        import snakemake_executor_plugin_slurm  # noqa: F401
    except ImportError:
        _unavailable("snakemake-executor-plugin-slurm is not installed (the `cluster` extra of pyproject.toml)")


@pytest.fixture(scope="module")
def builds(tmp_path_factory):
    """The target built locally, then on a one-node SLURM cluster (started and stopped here)."""
    _require_plugin()
    local = _workdir(tmp_path_factory, "local")
    t0 = time.monotonic()
    proc = _snakemake(local, "--cores", "2")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    local_s = time.monotonic() - t0

    try:
        cluster = slurm_cluster.start(partition="cpu")  # the partition the profile names
    except slurm_cluster.ClusterUnavailable as exc:
        _unavailable(f"no SLURM cluster on this machine: {exc}")
    slurm = _workdir(tmp_path_factory, "slurm")
    try:
        t0 = time.monotonic()
        proc = _snakemake(slurm, "--workflow-profile", str(PROFILE), *SLURM_OPTIONS, env=cluster.env, timeout=1500)
        slurm_s = time.monotonic() - t0
        # finished jobs stay in the queue for MinJobAge: what SLURM ran, and how it ended
        queue = cluster.run("squeue", "--noheader", "--states=all", "--format=%i|%T|%k|%P")
    except BaseException:
        cluster.remove_root = False
        cluster.stop()
        raise
    log = proc.stdout + proc.stderr
    if proc.returncode != 0:
        cluster.remove_root = False  # keep slurm.conf and the daemons' logs
    daemon_logs = cluster.logs()
    cluster.stop()  # raises when a daemon or a job step is left running
    assert proc.returncode == 0, log[-4000:] + "\n" + daemon_logs
    print(f"{TARGET}: local (--cores 2) {local_s:.0f} s, SLURM (one node, {cluster.cpus} CPUs) {slurm_s:.0f} s")
    jobs = [line.split("|") for line in queue.stdout.splitlines() if line.strip()]
    return {"local": local, "slurm": slurm, "log": log, "jobs": jobs, "cluster": cluster}


def _metrics(work: Path, run: str) -> dict:
    return json.loads((work / f"reports/metrics/demo_cluster/centerpoint_sim/{run}.json").read_text())


def _strip_timings(obj):
    if isinstance(obj, dict):
        return {k: _strip_timings(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [_strip_timings(v) for v in obj]
    return obj


@pytest.mark.slow
def test_slurm_report_equals_the_local_one(builds):
    """The report's text (every number in it) and each run's metrics JSON, timings aside, are the local run's."""
    local = (builds["local"] / TARGET).read_text()
    slurm = (builds["slurm"] / TARGET).read_text()
    assert "ekf" in slurm and "polymot" in slurm
    assert slurm == local
    for run in RUNS:
        a, b = _metrics(builds["local"], run), _metrics(builds["slurm"], run)
        assert b["overall"]["amota"] == a["overall"]["amota"]
        assert _strip_timings(b) == _strip_timings(a), run


@pytest.mark.slow
def test_every_job_ran_as_a_slurm_job(builds):
    """Tracking, evaluation and report (and every other job of the target) were SLURM jobs of the profile's
    partition, all completed; the rules wrote their logs and benchmarks in the working directory."""
    jobs = builds["jobs"]
    assert jobs, builds["log"][-3000:]
    rules = sorted(comment.split("_wildcards_")[0].removeprefix("rule_") for _, _, comment, _ in jobs)
    expected = ["demo_data", "simulate_detections", "report"]
    expected += [r for r in ("resolve_tracker", "track", "submit", "manifest", "evaluate", "render") for _ in RUNS]
    assert rules == sorted(expected)
    assert {state for _, state, _, _ in jobs} == {"COMPLETED"}, jobs
    assert {part for _, _, _, part in jobs} == {"cpu"}
    slurm = builds["slurm"]
    for run in RUNS:
        assert (slurm / f"logs/track/demo_cluster/centerpoint_sim/{run}.json.log").exists()
        assert (slurm / f"logs/benchmarks/evaluate/demo_cluster/centerpoint_sim/{run}.tsv").exists()
    assert (slurm / "logs/report/demo_cluster.log").exists()


@pytest.mark.slow
def test_the_cluster_is_stopped(builds):
    """The three daemons the test started have exited (stop() also checked that no job step is left)."""
    cluster = builds["cluster"]
    assert set(cluster.procs) == {"munged", "slurmctld", "slurmd"}
    assert all(p.poll() is not None for p in cluster.procs.values())


def test_slurm_profile_plans_the_target(tmp_path):
    """The shipped SLURM profile (a workflow profile, in place of profiles/default) plans the target with its
    resources, and repeats the default profile's settings except the local core count and latency wait."""
    _require_plugin()
    default = yaml.safe_load((REPO / "workflow/profiles/default/config.yaml").read_text())
    slurm = yaml.safe_load((PROFILE / "config.yaml").read_text())
    assert slurm["executor"] == "slurm" and "cores" not in slurm
    for key, value in default.items():
        if key not in ("cores", "latency-wait"):
            assert slurm.get(key) == value, key
    (tmp_path / "cluster.yaml").write_text(yaml.safe_dump(CONFIG))
    proc = _snakemake(tmp_path, "-n", "--workflow-profile", str(PROFILE))
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0, text[-3000:]
    assert f"workflow specific profile {PROFILE}" in text
    assert "mem_mb=6000" in text and "slurm_partition=cpu" in text and "runtime=120" in text
