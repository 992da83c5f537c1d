"""The style check of the test command: `ruff check` (pycodestyle, pyflakes, import order, the modern dialect)
and `ruff format --check` over the package, the tests, the benchmarks and the scripts (settings in
pyproject.toml). `ruff check --fix` and `ruff format` make a failing tree pass."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PATHS = ("grutrack", "tests", "benchmarks", "scripts")


@pytest.mark.parametrize("command", [("check",), ("format", "--check")], ids=["lint", "format"])
def test_ruff(command):
    proc = subprocess.run([sys.executable, "-m", "ruff", *command, *PATHS], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-4000:]
