"""The thread policy: one intra-op thread whatever OMP_NUM_THREADS says (Snakemake and SLURM export it as the
job's cores, and two spinning torch threads per job made side-by-side trainings eight times slower,
docs/results/threads.md); GRUTRACK_THREADS is the one override; the workflow's training rule asks for one core."""

import re
import subprocess
import sys
from pathlib import Path

from grutrack.threads import thread_count

REPO = Path(__file__).resolve().parents[1]


def test_omp_num_threads_is_ignored(monkeypatch):
    monkeypatch.delenv("GRUTRACK_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert thread_count() == 1
    monkeypatch.setenv("GRUTRACK_THREADS", "3")
    assert thread_count() == 3
    monkeypatch.setenv("GRUTRACK_THREADS", "zero")
    assert thread_count() == 1


def test_torch_runs_one_thread_under_snakemakes_environment():
    """In a fresh process started as Snakemake starts a `threads: 2` job, the policy leaves torch one intra-op
    thread and BLAS one thread."""
    code = (
        "from grutrack.threads import apply_thread_policy; apply_thread_policy(); import torch; "
        "from threadpoolctl import threadpool_info; "
        "print(torch.get_num_threads(), max([p['num_threads'] for p in threadpool_info() "
        "if p['user_api'] == 'blas'] or [1]))"
    )
    env = {"PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "1"]


def test_training_and_tracking_rules_ask_for_one_core():
    """Snakemake runs as many jobs side by side as --cores allows: a training or tracking job holds one."""
    train = (REPO / "workflow/rules/train.smk").read_text()
    assert re.search(r"^\s*threads:\s*1\b", train, re.M)
    track = (REPO / "workflow/rules/track.smk").read_text()
    assert not re.search(r"^\s*threads:", track, re.M)  # Snakemake's default: one


def test_the_suites_own_processes_run_under_the_policy():
    """Every pytest process (each worker of `bash scripts/test.sh`) runs under the policy (tests/conftest.py), so a
    test that trains or tracks in-process does not start torch's per-core pool beside the other worker."""
    import torch

    assert torch.get_num_threads() == thread_count()
