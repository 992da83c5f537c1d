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


# ----- submissions given to evaluate (the same one-line errors as leaderboard-zip) -----------------------------
def _box(token, name="car", **over):
    return {"sample_token": token, "translation": [600.0, 1600.0, 1.0], "size": [1.9, 4.5, 1.6],
            "rotation": [1.0, 0.0, 0.0, 0.0], "velocity": [0.0, 0.0], "tracking_id": "1", "tracking_name": name,
            "tracking_score": 0.5, **over}


@pytest.fixture(scope="module")
def mini_val_tokens(nusc_mini):
    from grutrack.data.nuscenes import load_scenes

    return [f.token for s in load_scenes(nusc_mini, "mini_val") for f in s.frames]


def _mini_train_submission(nusc_mini):
    from grutrack.data.nuscenes import load_scenes

    return {"meta": {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False,
                     "use_external": False},
            "results": {f.token: [] for s in load_scenes(nusc_mini, "mini_train") for f in s.frames}}


def _submission(tokens, mutate=None):
    sub = {"meta": {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False,
                    "use_external": False}, "results": {t: [_box(t)] for t in tokens}}
    if mutate:
        mutate(sub, tokens)
    return sub


BAD_SUBMISSIONS = {
    "missing_samples": (lambda s, t: [s["results"].pop(x) for x in t[:5]], "5 missing, 0 not in the split"),
    "unknown_name": (lambda s, t: s["results"][t[0]].append(_box(t[0], "van")), "tracking_name 'van' is not one of"),
    "over_500": (lambda s, t: s["results"][t[1]].extend([_box(t[1])] * 500), "has 501 boxes (max 500)"),
    "string_number": (lambda s, t: s["results"][t[2]].append(_box(t[2], tracking_score="0.5")),
                      "tracking_score must be a number in [0, 1], got '0.5'"),
    "string_translation": (lambda s, t: s["results"][t[2]].append(_box(t[2], translation=["1", "2", "3"])),
                           "'translation' must be 3 finite numbers, got ['1', '2', '3']"),
    "other_token": (lambda s, t: s["results"][t[3]].append(_box(t[4])), f"box 1: sample_token is"),
}


@pytest.mark.parametrize("evaluator", ["fast", "devkit"])
@pytest.mark.parametrize("case", sorted(BAD_SUBMISSIONS))
def test_evaluate_rejects_bad_submissions_in_one_line(nusc_root, mini_val_tokens, tmp_path, capsys, case,
                                                      evaluator):
    mutate, message = BAD_SUBMISSIONS[case]
    sub = tmp_path / "sub.json"
    sub.write_text(json.dumps(_submission(mini_val_tokens, mutate)))
    args = ["evaluate", "--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val", "--submission",
            sub, "--out", tmp_path / "m.json", "--evaluator", evaluator]
    fails(capsys, args, f"{sub}: ", message)
    assert not (tmp_path / "m.json").exists()
    zip_args = ["leaderboard-zip", "--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val",
                "--submission", sub, "--out", tmp_path / "z.zip"]
    fails(capsys, zip_args, f"{sub}: ", message)


def test_evaluate_rejects_wrong_split_truncated_json_and_detections(nusc_mini, nusc_root, pointpillars_mini_val,
                                                                    mini_val_tokens, tmp_path, capsys):
    common = ["--dataroot", nusc_root, "--version", "v1.0-mini", "--split", "mini_val", "--out",
              tmp_path / "m.json", "--evaluator", "fast"]
    other = tmp_path / "train.json"
    other.write_text(json.dumps(_mini_train_submission(nusc_mini)))
    fails(capsys, ["evaluate", *common, "--submission", other], "must hold exactly the 81 samples of the split",
          "81 missing, 323 not in the split")
    cut = tmp_path / "cut.json"
    cut.write_text(json.dumps(_submission(mini_val_tokens))[:5000])
    fails(capsys, ["evaluate", *common, "--submission", cut], f"{cut}: cannot read a tracking submission JSON")
    fails(capsys, ["evaluate", *common, "--submission", pointpillars_mini_val], "box 0: keys must be",
          "tracking_id")
    ok = tmp_path / "ok.json"
    ok.write_text(json.dumps(_submission(mini_val_tokens)))
    assert main(["evaluate", *map(str, common), "--submission", str(ok)]) == 0
    assert json.loads((tmp_path / "m.json").read_text())["overall"]["amota"] >= 0
