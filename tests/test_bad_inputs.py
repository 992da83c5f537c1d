"""Bad input on the command line: exit status 2 and one line naming the file, field or flag and what was
expected (tests/README.md tabulates every case). Programming errors keep their tracebacks."""

from __future__ import annotations

import json

import pytest
import torch

from grutrack.cli import main


def fails(capsys, argv: list[str], *fragments: str) -> str:
    """Run ``grutrack argv``; assert exit 2 and one stderr line holding every fragment; return the line."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    err = [ln for ln in err if not ln.startswith("grutrack track: warning")]
    assert len(err) == 1 and "Traceback" not in err[0], err
    for f in fragments:
        assert f in err[0], (f, err[0])
    return err[0]


@pytest.fixture()
def mini_track(nusc_root, pointpillars_mini_val, tmp_path):
    """``grutrack track`` arguments on mini_val with the real PointPillars detections."""
    return ["track", "--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val", "--detections",
            pointpillars_mini_val, "--out", tmp_path / "o.json", "--no-progress"]


def _checkpoint(path, mutate=None):
    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig
    from grutrack.training.checkpoint import save_checkpoint

    net = GRUKalmanNet(GRUKFConfig())
    save_checkpoint(path, net)
    if mutate:
        ck = torch.load(path, weights_only=False)
        mutate(ck)
        torch.save(ck, path)
    return path


# ----- devices and checkpoints -------------------------------------------------------------------------------
def test_cuda_device_without_cuda_is_one_line(mini_track, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    ck = _checkpoint(tmp_path / "m.pt")
    fails(capsys, [*mini_track, "--tracker", "grukf", "--checkpoint", ck, "--device", "cuda"],
          "--device: 'cuda' asked for a GPU, but this torch build", "has no CUDA support", "use auto or cpu")
    fails(capsys, [*mini_track, "--tracker", "grukf", "--checkpoint", ck, "--device", "gpu"],
          "--device: unknown torch device 'gpu' (expected auto, cpu, cuda or cuda:N)")
    assert not (tmp_path / "o.json").exists()


def test_checkpoint_with_another_tracker_is_refused(mini_track, tmp_path, capsys):
    fails(capsys, [*mini_track, "--tracker", "ekf", "--checkpoint", tmp_path / "m.pt"],
          "--checkpoint is for --tracker grukf; --tracker ekf has no learned model")


def test_checkpoint_with_a_mis_shaped_tensor(mini_track, tmp_path, capsys):
    from grutrack.errors import InputFormatError
    from grutrack.training.checkpoint import load_network

    def shrink(ck):
        k = next(iter(ck["model"]))
        ck["model"][k] = ck["model"][k][..., :1].clone()

    bad = _checkpoint(tmp_path / "bad.pt", shrink)
    fails(capsys, [*mini_track, "--tracker", "grukf", "--checkpoint", bad, "--device", "cpu"],
          "bad.pt: tensor 'model.", "has shape", "expected")
    gone = _checkpoint(tmp_path / "gone.pt", lambda ck: ck["model"].pop(next(iter(ck["model"]))))
    with pytest.raises(InputFormatError, match="gone.pt: field 'model' does not fit the architecture"):
        load_network(gone)
    arch = _checkpoint(tmp_path / "arch.pt", lambda ck: ck["arch"].update(wings=2))
    with pytest.raises(InputFormatError, match="arch.pt: field 'arch' is not a GRU-KF architecture"):
        load_network(arch)
    assert load_network(_checkpoint(tmp_path / "ok.pt")) is not None
