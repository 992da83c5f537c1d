"""Start-up cost of the command line: building the parser imports argument definitions only, and each
sub-command imports what it needs (checked on ``sys.modules`` in a fresh interpreter, so a heavy top-level
import added anywhere on those paths fails here)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

#: top-level packages that cost tens to thousands of milliseconds to import
HEAVY = (
    "numpy",
    "scipy",
    "torch",
    "nuscenes",
    "matplotlib",
    "sklearn",
    "pandas",
    "pyarrow",
    "shapely",
    "av2",
    "cv2",
    "trackeval",
    "motmetrics",
    "tqdm",
    "threadpoolctl",
    "snakemake",
    "yaml",
)


def _modules_after(code: str) -> set[str]:
    """Top-level package names in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    probe = code + "\nimport sys, json\nprint(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True, cwd=REPO_ROOT
    ).stdout
    return set(json.loads(out.splitlines()[-1]))


def test_parser_imports_nothing_heavy():
    loaded = _modules_after(
        "import grutrack.cli\nparser = grutrack.cli.build_parser()\n"
        "assert len(parser._subparsers._group_actions[0].choices) >= 9"
    )
    assert "grutrack" in loaded and "argparse" in loaded
    assert sorted(loaded.intersection(HEAVY)) == []


def test_help_of_every_command_imports_nothing_heavy():
    code = (
        "import contextlib, io, grutrack.cli\n"
        "names = list(grutrack.cli.build_parser()._subparsers._group_actions[0].choices)\n"
        "for name in names:\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        grutrack.cli.main([name, '--help'])\n"
    )
    assert sorted(_modules_after(code).intersection(HEAVY)) == []


def test_ekf_track_skips_devkit_and_torch(nusc_root, pointpillars_mini_val, tmp_path):
    """The EKF tracker's command reads the tables without the devkit's NuScenes class (which pulls matplotlib,
    OpenCV and scikit-learn) and never imports torch; it writes compact JSON."""
    sub = tmp_path / "tracks.json"
    code = (
        "import contextlib, io, grutrack.cli\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert grutrack.cli.main(['track', '--dataroot', {str(nusc_root)!r}, '--version', 'v1.0-mini', "
        f"'--split', 'mini_val', '--detections', {str(pointpillars_mini_val)!r}, "
        f"'--out', {str(sub)!r}, '--no-progress']) == 0\n"
    )
    loaded = _modules_after(code)
    assert {"numpy", "scipy"} <= loaded
    assert sorted(loaded.intersection({"torch", "nuscenes", "matplotlib", "sklearn", "cv2", "pandas"})) == []
    text = sub.read_text()
    assert len(json.loads(text)["results"]) == 81
    assert "\n" not in text.strip() and ", " not in text[:5000] and ": " not in text[:5000]  # compact JSON


@pytest.mark.parametrize("name", ["track", "evaluate", "train", "demo-data", "report", "submit"])
def test_command_help_lists_its_flags(name):
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    out = subprocess.run(
        [sys.executable, "-m", "grutrack", name, "--help"],
        capture_output=True,
        text=True,
        env=env,
        check=True,
        cwd=REPO_ROOT,
    ).stdout
    assert out.startswith(f"usage: grutrack {name}") and "--out" in out


def test_fast_evaluate_skips_the_devkit_package(nusc_root, tmp_path):
    """The fast evaluator's command (config, loading, metrics classes, the assignment of contested boxes) never
    imports the ``nuscenes`` package, whose import pulls matplotlib, OpenCV and scikit-learn, nor motmetrics,
    pandas or scipy; its figures stay those of the devkit's config. Every GT box comes back twice (the second
    0.6 m off, another id, a lower score), so frames have contested pairs and the assignment solver runs."""
    from grutrack.data.nuscenes import load_scenes, open_nuscenes

    scenes = load_scenes(open_nuscenes(nusc_root, "v1.0-mini"), "mini_val", with_gt=True)
    results = {f.token: [] for s in scenes for f in s.frames}
    for s in scenes:
        for f in s.frames:
            for b, lab, inst in zip(f.gt.boxes, f.gt.labels, f.gt.ids):
                for dx, suffix, score in ((0.0, "", 0.9), (0.6, "-dup", 0.5)):
                    results[f.token].append(
                        {
                            "sample_token": f.token,
                            "translation": [b[0] + dx, b[1], b[2]],
                            "size": b[3:6].tolist(),
                            "rotation": [float(np.cos(b[6] / 2)), 0.0, 0.0, float(np.sin(b[6] / 2))],
                            "velocity": b[7:9].tolist(),
                            "tracking_id": inst + suffix,
                            "tracking_score": score,
                            "tracking_name": _class_name(int(lab)),
                        }
                    )
    sub, metrics = tmp_path / "gt_tracks.json", tmp_path / "metrics.json"
    sub.write_text(
        json.dumps(
            {
                "meta": {
                    "use_camera": False,
                    "use_lidar": True,
                    "use_radar": False,
                    "use_map": False,
                    "use_external": False,
                },
                "results": results,
            }
        )
    )
    code = (
        "import contextlib, io, grutrack.cli, grutrack.evaluation.nuscenes_fast.motmetrics_assignment as lsap\n"
        "calls = []\n"
        "solve = lsap.motmetrics_lsa\n"
        "lsap.motmetrics_lsa = lambda dm: calls.append(dm.shape) or solve(dm)\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert grutrack.cli.main(['evaluate', '--dataroot', {str(nusc_root)!r}, '--version', 'v1.0-mini', "
        f"'--split', 'mini_val', '--submission', {str(sub)!r}, '--out', {str(metrics)!r}, "
        f"'--evaluator', 'fast']) == 0\n"
        "assert len(calls) > 0, 'no contested frame: the test would not cover the solver'\n"
    )
    loaded = _modules_after(code)
    assert (
        sorted(
            loaded.intersection(
                {
                    "torch",
                    "nuscenes",
                    "matplotlib",
                    "sklearn",
                    "cv2",
                    "motmetrics",
                    "pandas",
                    "scipy",
                    "numba",
                    "tqdm",
                    "yaml",
                }
            )
        )
        == []
    )
    doc = json.loads(metrics.read_text())
    # ground truth fed back (every annotation, zero-point ones too: those are extra predictions to the evaluator)
    # with a shifted duplicate of each: the duplicates are false positives below the GT boxes' score
    assert 0.8 < doc["overall"]["amota"] <= 1.0 and doc["overall"]["fp"] > 0
    assert doc["devkit_summary"]["cfg"]["num_thresholds"] == 40


def _class_name(label: int) -> str:
    from grutrack.classes import TRACKING_CLASSES

    return TRACKING_CLASSES[label]
