"""``device: auto`` chooses by the size of the network's per-frame batch (``resolve_device``'s documented rule): with a
GPU visible, tracking (one scene at a time) and training one scene per step stay on the CPU, training with
``scenes_per_step`` >= 8 (the network run once per frame over all of them, in lockstep) takes the GPU. No GPU is
needed: ``torch.cuda.is_available`` is made to answer True."""

from __future__ import annotations

import pytest
import torch


@pytest.fixture
def gpu_visible(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)


def test_auto_takes_the_gpu_only_for_many_scenes_per_frame(gpu_visible):
    from grutrack.tracking.grukf_backend import AUTO_CUDA_MIN_SCENES, resolve_device

    assert AUTO_CUDA_MIN_SCENES == 8
    assert resolve_device("auto") == torch.device("cpu")  # tracking: one scene at a time
    assert resolve_device("auto", scenes=1) == torch.device("cpu")
    assert resolve_device("auto", scenes=7) == torch.device("cpu")
    assert resolve_device("auto", scenes=8) == torch.device("cuda")
    assert resolve_device("auto", scenes=32) == torch.device("cuda")
    assert resolve_device("cpu", scenes=32) == torch.device("cpu")  # a named device is taken as named


def test_auto_is_the_cpu_without_a_gpu(monkeypatch):
    from grutrack.tracking.grukf_backend import resolve_device

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto", scenes=32) == torch.device("cpu")


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


@pytest.mark.parametrize("k, expected", [(1, "cpu"), (2, "cpu"), (8, "cuda"), (32, "cuda")])
def test_training_with_auto_takes_the_gpu_from_eight_scenes_per_step(gpu_visible, monkeypatch, tmp_path, k, expected):
    """The trainer asks the rule with its ``scenes_per_step`` (the device it gets is recorded, and the CPU handed
    to it instead, as this machine may have no GPU)."""
    import grutrack.training.trainer as trainer_mod
    from grutrack.training.config import load_train_config

    chosen = []

    def spy(device, what="--device", scenes=1):
        chosen.append(trainer_mod.resolve_device.__wrapped__(device, what, scenes))
        return torch.device("cpu")

    spy.__wrapped__ = trainer_mod.resolve_device
    monkeypatch.setattr(trainer_mod, "resolve_device", spy)
    cfg = load_train_config("grukf", {"device": "auto", "scenes_per_step": k, "epochs": 1, "checkpoint_every": 0})
    trainer_mod.Trainer(cfg, [], {}, tmp_path, progress=False)
    assert chosen == [torch.device(expected)]


def test_the_rule_is_documented_in_the_training_schema():
    from grutrack.config_loader import schema

    props = schema("training")["properties"]
    assert "scenes_per_step >= 8" in props["device"]["description"]
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
