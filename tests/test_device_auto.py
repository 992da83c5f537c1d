"""``device: auto`` is the CPU (``resolve_device``'s documented rule, from the H100 measurements in
docs/results/lockstep.md#gpu): with a GPU visible, tracking and training with any ``scenes_per_step`` stay on the
CPU, and a named ``cuda`` is taken as named. No GPU is needed: ``torch.cuda.is_available`` is made to answer True."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture
def gpu_visible(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)


def test_auto_is_the_cpu_although_a_gpu_is_visible(gpu_visible, monkeypatch):
    from grutrack.tracking.grukf_backend import resolve_device

    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert resolve_device("auto") == torch.device("cpu")
    assert resolve_device("cuda") == torch.device("cuda")  # a named device is taken as named
    assert resolve_device("cuda:0") == torch.device("cuda:0")


def test_auto_is_the_cpu_without_a_gpu(monkeypatch):
    from grutrack.tracking.grukf_backend import resolve_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu")


def test_grukf_tracking_with_auto_stays_on_the_cpu(gpu_visible):
    """``grutrack track --tracker grukf --device auto`` (the command's default) builds its network groups on the
    CPU although a GPU is visible."""
    from grutrack.tracking.factory import build_tracker
    from grutrack.tracking.grukf_backend import GRUKFBackend
    from grutrack.training.pretrained import pretrained_dir

    tracker = build_tracker("grukf", checkpoint=pretrained_dir("grukf_default") / "model.pt", device="auto")
    backends = [g.backend for g in tracker.groups if isinstance(g.backend, GRUKFBackend)]
    assert backends and all(b.device == torch.device("cpu") for b in backends)
    assert all(p.device.type == "cpu" for p in backends[0].net.parameters())


@pytest.mark.parametrize("k", [1, 8, 32])
def test_training_with_auto_stays_on_the_cpu_for_any_scenes_per_step(gpu_visible, tmp_path, k):
    """The trainer's network and its device are the CPU with ``device: auto``, however many scenes a step holds."""
    from grutrack.training.config import load_train_config
    from grutrack.training.trainer import Trainer

    cfg = load_train_config("grukf", {"device": "auto", "scenes_per_step": k, "epochs": 1, "checkpoint_every": 0})
    t = Trainer(cfg, [], {}, tmp_path, progress=False)
    assert t.device == torch.device("cpu")
    assert all(p.device.type == "cpu" for p in t.net.parameters())


def test_the_rule_is_documented_in_the_training_schema():
    from grutrack.config_loader import schema

    props = schema("training")["properties"]
    assert "auto is the CPU" in props["device"]["description"]
    assert "docs/results/lockstep.md#gpu" in props["device"]["description"]
    assert "training_classes" in props["scenes_per_step"]["description"]


@pytest.mark.skipif(torch.cuda.is_available(), reason="a GPU is visible here")
def test_the_lockstep_benchmark_refuses_cuda_without_a_gpu_in_one_line():
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "benchmarks/bench_grukf.py", "--lockstep", "--device", "cpu,cuda"]
    r = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "--device: 'cuda' asked for a GPU" in r.stderr
    assert r.stdout == ""
