"""Start-up cost of the command line: building the parser imports argument definitions only, and each
sub-command imports what it needs (checked on ``sys.modules`` in a fresh interpreter, so a heavy top-level
import added anywhere on those paths fails here)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]

#: top-level packages that cost tens to thousands of milliseconds to import
HEAVY = ("numpy", "scipy", "torch", "nuscenes", "matplotlib", "sklearn", "pandas", "pyarrow", "shapely", "av2",
         "cv2", "trackeval", "motmetrics", "tqdm", "threadpoolctl", "snakemake")


def _modules_after(code: str) -> set[str]:
    """Top-level package names in ``sys.modules`` after running ``code`` in a fresh interpreter."""
    probe = code + "\nimport sys, json\nprint(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=True,
                         cwd=REPO_ROOT).stdout
    return set(json.loads(out.splitlines()[-1]))


def test_parser_imports_nothing_heavy():
    loaded = _modules_after("import grutrack.cli\nparser = grutrack.cli.build_parser()\n"
                            "assert len(parser._subparsers._group_actions[0].choices) >= 9")
    assert "grutrack" in loaded and "argparse" in loaded
    assert sorted(loaded.intersection(HEAVY)) == []


def test_help_of_every_command_imports_nothing_heavy():
    code = ("import contextlib, io, grutrack.cli\n"
            "names = list(grutrack.cli.build_parser()._subparsers._group_actions[0].choices)\n"
            "for name in names:\n"
            "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "        grutrack.cli.main([name, '--help'])\n")
    assert sorted(_modules_after(code).intersection(HEAVY)) == []


def test_ekf_track_skips_devkit_and_torch(nusc_root, pointpillars_mini_val, tmp_path):
    """The EKF tracker's command reads the tables without the devkit's NuScenes class (which pulls matplotlib,
    OpenCV and scikit-learn) and never imports torch; it writes compact JSON."""
    sub = tmp_path / "tracks.json"
    code = ("import contextlib, io, grutrack.cli\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert grutrack.cli.main(['track', '--dataroot', {str(nusc_root)!r}, '--version', 'v1.0-mini', "
            f"'--split', 'mini_val', '--detections', {str(pointpillars_mini_val)!r}, "
            f"'--out', {str(sub)!r}, '--no-progress']) == 0\n")
    loaded = _modules_after(code)
    assert {"numpy", "scipy"} <= loaded
    assert sorted(loaded.intersection({"torch", "nuscenes", "matplotlib", "sklearn", "cv2", "pandas"})) == []
    text = sub.read_text()
    assert len(json.loads(text)["results"]) == 81
    assert "\n" not in text.strip() and ", " not in text[:5000] and ": " not in text[:5000]  # compact JSON


@pytest.mark.parametrize("name", ["track", "evaluate", "train", "demo-data", "report", "submit"])
def test_command_help_lists_its_flags(name):
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    out = subprocess.run([sys.executable, "-m", "grutrack", name, "--help"], capture_output=True, text=True,
                         env=env, check=True, cwd=REPO_ROOT).stdout
    assert out.startswith(f"usage: grutrack {name}") and "--out" in out
