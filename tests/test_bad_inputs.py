"""Bad input on the command line: exit status 2 and one line naming the file, field or flag and what was
expected (one test per kind of input: flags, config keys, files and their fields). Programming errors keep their
tracebacks."""

from __future__ import annotations

import json
import re

import pytest
import torch

from grutrack.cli import main
from grutrack.config_loader import config_path


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
    return [
        "track",
        "--dataroot",
        nusc_root,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--detections",
        pointpillars_mini_val,
        "--out",
        tmp_path / "o.json",
        "--no-progress",
    ]


def _checkpoint(path, mutate=None):
    from grutrack.motion.checkpoint import save_checkpoint
    from grutrack.motion.grukf import GRUKalmanNet, GRUKFConfig

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
    fails(
        capsys,
        [*mini_track, "--tracker", "grukf", "--checkpoint", ck, "--device", "cuda"],
        "--device: 'cuda' asked for a GPU, but this torch build",
        "has no CUDA support",
        "use auto or cpu",
    )
    fails(
        capsys,
        [*mini_track, "--tracker", "grukf", "--checkpoint", ck, "--device", "gpu"],
        "--device: unknown torch device 'gpu' (expected auto, cpu, cuda or cuda:N)",
    )
    assert not (tmp_path / "o.json").exists()


def test_checkpoint_with_another_tracker_is_refused(mini_track, tmp_path, capsys):
    fails(
        capsys,
        [*mini_track, "--tracker", "ekf", "--checkpoint", tmp_path / "m.pt"],
        "--checkpoint is for --tracker grukf; --tracker ekf has no learned model",
    )


def test_checkpoint_with_a_mis_shaped_tensor(mini_track, tmp_path, capsys):
    from grutrack.errors import InputFormatError
    from grutrack.motion.checkpoint import load_network

    def shrink(ck):
        k = next(iter(ck["model"]))
        ck["model"][k] = ck["model"][k][..., :1].clone()

    bad = _checkpoint(tmp_path / "bad.pt", shrink)
    fails(
        capsys,
        [*mini_track, "--tracker", "grukf", "--checkpoint", bad, "--device", "cpu"],
        "bad.pt: tensor 'model.",
        "has shape",
        "expected",
    )
    gone = _checkpoint(tmp_path / "gone.pt", lambda ck: ck["model"].pop(next(iter(ck["model"]))))
    with pytest.raises(InputFormatError, match="gone.pt: field 'model' does not fit the architecture"):
        load_network(gone)
    arch = _checkpoint(tmp_path / "arch.pt", lambda ck: ck["arch"].update(wings=2))
    with pytest.raises(InputFormatError, match="arch.pt: field 'arch' is not a GRU-KF architecture"):
        load_network(arch)
    assert load_network(_checkpoint(tmp_path / "ok.pt")) is not None


# ----- submissions given to evaluate (the same one-line errors as leaderboard-zip) -----------------------------
def _box(token, name="car", **over):
    return {
        "sample_token": token,
        "translation": [600.0, 1600.0, 1.0],
        "size": [1.9, 4.5, 1.6],
        "rotation": [1.0, 0.0, 0.0, 0.0],
        "velocity": [0.0, 0.0],
        "tracking_id": "1",
        "tracking_name": name,
        "tracking_score": 0.5,
        **over,
    }


@pytest.fixture(scope="module")
def mini_val_tokens(nusc_mini):
    from grutrack.data.nuscenes import load_scenes

    return [f.token for s in load_scenes(nusc_mini, "mini_val") for f in s.frames]


def _mini_train_submission(nusc_mini):
    from grutrack.data.nuscenes import load_scenes

    return {
        "meta": {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False},
        "results": {f.token: [] for s in load_scenes(nusc_mini, "mini_train") for f in s.frames},
    }


def _submission(tokens, mutate=None):
    sub = {
        "meta": {"use_camera": False, "use_lidar": True, "use_radar": False, "use_map": False, "use_external": False},
        "results": {t: [_box(t)] for t in tokens},
    }
    if mutate:
        mutate(sub, tokens)
    return sub


BAD_SUBMISSIONS = {
    "missing_samples": (lambda s, t: [s["results"].pop(x) for x in t[:5]], "5 missing, 0 not in the split"),
    "unknown_name": (
        lambda s, t: s["results"][t[0]].append(_box(t[0], "van")),
        "[1].tracking_name' must be one of bicycle, bus, car, motorcycle, pedestrian, trailer, truck, got 'van'",
    ),
    "over_500": (
        lambda s, t: s["results"][t[1]].extend([_box(t[1])] * 500),
        "' must be a list of at most 500 boxes (the official format's limit), got a list of 501 items",
    ),
    "string_number": (
        lambda s, t: s["results"][t[2]].append(_box(t[2], tracking_score="0.5")),
        "[1].tracking_score' must be a number in [0, 1], got '0.5' (a number written as a string)",
    ),
    "string_translation": (
        lambda s, t: s["results"][t[2]].append(_box(t[2], translation=["1", "2", "3"])),
        "[1].translation' must be a list of 3 finite numbers [x, y, z] (box centre, metres, global frame), "
        "got ['1', '2', '3'] (a number written as a string)",
    ),
    "other_token": (lambda s, t: s["results"][t[3]].append(_box(t[4])), "[1].sample_token' is '"),
}


@pytest.mark.parametrize("evaluator", ["fast", "devkit"])
@pytest.mark.parametrize("case", sorted(BAD_SUBMISSIONS))
def test_evaluate_rejects_bad_submissions_in_one_line(nusc_root, mini_val_tokens, tmp_path, capsys, case, evaluator):
    mutate, message = BAD_SUBMISSIONS[case]
    sub = tmp_path / "sub.json"
    sub.write_text(json.dumps(_submission(mini_val_tokens, mutate)))
    args = [
        "evaluate",
        "--dataroot",
        nusc_root,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--submission",
        sub,
        "--out",
        tmp_path / "m.json",
        "--evaluator",
        evaluator,
    ]
    fails(capsys, args, f"{sub}: ", message)
    assert not (tmp_path / "m.json").exists()
    zip_args = [
        "leaderboard-zip",
        "--dataroot",
        nusc_root,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--submission",
        sub,
        "--out",
        tmp_path / "z.zip",
    ]
    fails(capsys, zip_args, f"{sub}: ", message)


def test_evaluate_rejects_wrong_split_truncated_json_and_detections(
    nusc_mini, nusc_root, pointpillars_mini_val, mini_val_tokens, tmp_path, capsys
):
    common = [
        "--dataroot",
        nusc_root,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--out",
        tmp_path / "m.json",
        "--evaluator",
        "fast",
    ]
    other = tmp_path / "train.json"
    other.write_text(json.dumps(_mini_train_submission(nusc_mini)))
    fails(
        capsys,
        ["evaluate", *common, "--submission", other],
        "must hold exactly the 81 samples of the split",
        "81 missing, 323 not in the split",
    )
    cut = tmp_path / "cut.json"
    cut.write_text(json.dumps(_submission(mini_val_tokens))[:5000])
    fails(capsys, ["evaluate", *common, "--submission", cut], f"{cut}: not valid JSON")
    fails(
        capsys,
        ["evaluate", *common, "--submission", pointpillars_mini_val],
        "[0].tracking_id' is missing; expected a string (the track's identity)",
    )
    ok = tmp_path / "ok.json"
    ok.write_text(json.dumps(_submission(mini_val_tokens)))
    assert main(["evaluate", *map(str, common), "--submission", str(ok)]) == 0
    assert json.loads((tmp_path / "m.json").read_text())["overall"]["amota"] >= 0


# ----- detection files, output paths, rates ------------------------------------------------------------------
@pytest.fixture(scope="module")
def pp_results(pointpillars_mini_val):
    return json.loads(pointpillars_mini_val.read_text())


def _with(pp_results, tmp_path, mutate, name="d.json"):
    data = json.loads(json.dumps(pp_results))
    first = sorted(data["results"])[0]
    mutate(data["results"], first)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path, first


def test_detection_json_bad_values(nusc_root, pp_results, tmp_path, capsys):
    common = [
        "track",
        "--dataroot",
        nusc_root,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_val",
        "--out",
        tmp_path / "o.json",
        "--no-progress",
        "--detections",
    ]

    def many(res, t):
        res[t] = [dict(res[t][0])] * 100_000

    path, t = _with(pp_results, tmp_path, many)
    fails(
        capsys,
        [*common, path],
        f"{path}: field 'results['{t}']' must be a list of at most 500 boxes",
        "got a list of 100000 items",
    )

    def string_number(res, t):
        res[t][1]["translation"] = [str(x) for x in res[t][1]["translation"]]

    path, t = _with(pp_results, tmp_path, string_number)
    fails(
        capsys,
        [*common, path],
        f"field 'results['{t}'][1].translation' must be a list of 3 finite numbers",
        "(a number written as a string)",
    )

    def other_sample(res, t):
        res[t][2]["sample_token"] = "another"

    path, t = _with(pp_results, tmp_path, other_sample)
    fails(
        capsys,
        [*common, path],
        f"field 'results['{t}'][2].sample_token' is 'another', expected the sample it is listed under",
    )
    feather = tmp_path / "d.feather"
    import pandas as pd

    pd.DataFrame({"a": [1.0, 2.0]}).to_feather(feather)
    fails(capsys, [*common, feather], f"{feather}: detection file must be JSON text, but this file is binary")
    assert not (tmp_path / "o.json").exists()


def test_output_paths(mini_track, tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    out = mini_track.index("--out") + 1
    argv = list(mini_track)
    argv[out] = tmp_path / "file" / "o.json"
    fails(capsys, argv, f"{tmp_path / 'file' / 'o.json'}: cannot create its folder: {tmp_path / 'file'} is a file")
    argv[out] = tmp_path
    fails(capsys, argv, f"{tmp_path}: output is a folder; expected a file path")


@pytest.mark.parametrize("rate", ["0", "-2", "nan"])
def test_av2_rate(av2_root, tmp_path, capsys, rate):
    fails(
        capsys,
        [
            "track",
            "--dataset",
            "av2",
            "--dataroot",
            av2_root,
            "--split",
            "val",
            "--detections",
            tmp_path / "d.feather",
            "--out",
            tmp_path / "o.pkl",
            "--rate",
            rate,
        ],
        "--rate: the frame rate must be a positive number of frames per second",
    )


def test_lt3d_sweep_with_too_many_detections():
    import numpy as np

    from grutrack.data.lt3d_detections import MAX_DETECTIONS_PER_SWEEP, _check_sweep_counts
    from grutrack.errors import InputFormatError

    n = MAX_DETECTIONS_PER_SWEEP
    logs = np.array(["a"] * n + ["b"] * (n + 1), dtype=object)
    ts = np.array([5] * n + [7] * (n + 1), dtype=np.int64)
    _check_sweep_counts("d.feather", logs[:n], ts[:n])
    with pytest.raises(InputFormatError, match=f"log b, timestamp_ns 7 has {n + 1} detections; at most {n}"):
        _check_sweep_counts("d.feather", logs, ts)


# ----- training configuration and flags ----------------------------------------------------------------------
def test_yaml_exponent_without_a_point_is_a_number(tmp_path):
    import yaml

    from grutrack.config_loader import config_path
    from grutrack.errors import ConfigError
    from grutrack.training.config import load_train_config

    text = config_path("training", "grukf").read_text()
    cfg_text = "\n".join("lr: 1e-5" if ln.startswith("lr:") else ln for ln in text.splitlines())
    assert yaml.safe_load(cfg_text)["lr"] == "1e-5"  # what PyYAML makes of it
    (tmp_path / "t.yaml").write_text(cfg_text)
    assert load_train_config(tmp_path / "t.yaml").lr == 1e-5
    (tmp_path / "u.yaml").write_text(cfg_text.replace("lr: 1e-5", "lr: fast"))
    with pytest.raises(ConfigError, match=r"u.yaml: 'lr' must be a positive number, got 'fast'"):
        load_train_config(tmp_path / "u.yaml")
    (tmp_path / "v.yaml").write_text("- a list\n")
    with pytest.raises(ConfigError, match="v.yaml: expected a mapping of training settings, got list"):
        load_train_config(tmp_path / "v.yaml")


def test_bad_training_flags_are_blamed_on_the_flag(tmp_path, capsys):
    base = [
        "train",
        "--dataroot",
        tmp_path,
        "--version",
        "v1.0-mini",
        "--split",
        "mini_train",
        "--detections",
        tmp_path / "d.json",
        "--out",
        tmp_path / "ck",
    ]
    fails(
        capsys,
        [*base, "--epochs", "-1"],
        "grutrack train: error: --epochs must be an integer >= 0 (0: no step, the initialised network), got -1",
    )
    fails(capsys, [*base, "--val-every", "-1"], "--val-every must be an integer >= 0, got -1")
    # a bad value of a config key: the file and the key, what was expected
    for value, got in (("-1.0", "got -1.0"), ("far", "got 'far'")):
        cfg = tmp_path / f"gate{got[-3:-1]}.yaml"
        cfg.write_text(
            config_path("training", "grukf").read_text().replace("gt_term_gate: 0.0", f"gt_term_gate: {value}")
        )
        fails(
            capsys, [*base, "--config", cfg], f"{cfg}: 'gt_term_gate' must be a distance in metres (0 for no gate)", got
        )
    for key, value, expected in (
        ("centre_huber_delta: 0.0", "-0.5", "a distance in metres (0 for the squared loss)"),
        ("lr_min: 0.0", "low", "a learning rate >= 0"),
        ("grad_clip_norm: 10.0", "-1", "a gradient norm >= 0 (0: no clipping)"),
        ("yaw_loss: axis", "degrees", "'heading' or 'axis'"),
        ("coast_yaw_rate: zero", "hold", "'keep' or 'zero'"),
        ("coast_acceleration: zero", "hold", "'keep' or 'zero'"),
    ):
        name = key.split(":")[0]
        cfg = tmp_path / f"{name}.yaml"
        shipped = config_path("training", "grukf").read_text()
        line = re.search(rf"^( *){re.escape(key)}$", shipped, re.M)  # the shipped value, replaced by the bad one
        assert line, key
        cfg.write_text(shipped.replace(line.group(0), f"{line.group(1)}{name}: {value}"))
        where = f"network.{name}" if line.group(1) else name  # the network's options are one section
        fails(capsys, [*base, "--config", cfg], f"{cfg}: '{where}' must be {expected}")


def test_a_closed_stdout_is_not_a_traceback(nusc_root, tmp_path):
    """`grutrack simulate-detections ... | head -0`: the reader is gone before the summary line is printed; the
    file is written, the command ends with 141 (SIGPIPE's status) and no traceback."""
    import os
    import subprocess
    import sys

    r, w = os.pipe()
    os.close(r)  # nobody will read stdout
    out = tmp_path / "d.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "grutrack",
            "simulate-detections",
            "--dataroot",
            str(nusc_root),
            "--version",
            "v1.0-mini",
            "--split",
            "mini_val",
            "--out",
            str(out),
        ],
        stdout=w,
        stderr=subprocess.PIPE,
        text=True,
        timeout=300,
    )
    os.close(w)
    assert proc.returncode == 141 and "Traceback" not in proc.stderr and proc.stderr.strip() == "", proc.stderr
    assert out.stat().st_size > 10_000


def test_a_flag_that_is_a_prefix_of_another_is_not_taken_for_it(tmp_path, capsys):
    """argparse takes an unambiguous prefix for the whole flag by default: `--detection` (a typo) would run as
    `--detections`. grutrack's parsers refuse it: exit status 2 naming the flag the command still lacks."""
    argv = ["track", "--dataroot", str(tmp_path), "--split", "mini_val", "--out", str(tmp_path / "t.json")]
    with pytest.raises(SystemExit) as exc:
        main([*argv, "--detection", str(tmp_path / "d.json")])
    assert exc.value.code == 2
    assert "the following arguments are required: --detections" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["evaluate", "--datar", str(tmp_path), "--split", "mini_val", "--submission", "s.json"])
    assert exc.value.code == 2
    assert "--datar" in capsys.readouterr().err


def test_the_shipped_network_on_a_missing_gpu_is_one_line(mini_track, capsys, monkeypatch):
    """Without --checkpoint the shipped network is named, but only once the run is set up: a refused device
    stays one line."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setattr(torch.version, "cuda", None)
    fails(capsys, [*mini_track, "--tracker", "grukf", "--device", "cuda"], "--device: 'cuda' asked for a GPU")


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["simulate-detections", "--dataroot", "d", "--split", "s", "--out", "o.json", "--seed", "abc"], "--seed"),
        (["simulate-detections", "--dataroot", "d", "--split", "s", "--out", "o.json", "--seed", "-1"], "got '-1'"),
        (["demo-data", "--out", "d", "--seed", "4294967296"], "expected an integer in [0, 4294967295]"),
        (["track", "--dataroot", "d"], "the following arguments are required: --split, --detections, --out"),
        (["track", "--dataroot", "d", "--split", "s", "--detections", "x", "--out", "o", "--bogus"], "--bogus"),
        (["tarck"], "invalid choice: 'tarck'"),
        ([], "the following arguments are required: COMMAND"),
    ],
)
def test_argument_errors_are_one_line_with_exit_2(capsys, argv, fragment):
    """argparse's refusals (a bad value, a missing or unknown flag or command): one line naming it, exit 2, no
    usage block."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1 and fragment in err[0] and "--help)" in err[0], err
