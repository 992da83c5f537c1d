"""Every `snakemake` command the README shows works as written: each is run from a working directory laid out
like the repository's (``workflow/`` and ``../shared/data`` where the README expects them), as a dry run that
must print a plan, and the small real ones (nuScenes mini on the real PointPillars file, AV2 on the two real
logs) for real. A README edit that adds a command is covered without touching this file; a command that stops
working (a renamed target, a config key, a missing configfile) fails here.

Commands that need what no test machine has are named in SKIP with the reason (a SLURM executor plugin).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: the README's placeholder for the user's full nuScenes dataroot, replaced by a folder with the version folders
NUSC_PLACEHOLDER = "/data/nuscenes"
#: commands that run for real (small, on the real fragments beside the checkout); the others are dry runs
REAL = ("workflow/config/mini.yaml", "workflow/config/av2_sim.yaml")
#: (substring, why) of commands not run here
SKIP = (
    ("workflow/profiles/slurm", "needs a SLURM cluster (tests/test_slurm.py runs the profile on a one-node cluster)"),
    ("cluster.yaml", "the SLURM test's own overlay, written by tests/test_slurm.py"),
)


def readme_commands() -> list[str]:
    """The `snakemake ...` commands of the bash blocks of the README and the guides under docs/ (continuation
    lines joined, comments cut)."""
    out = []
    for path in [README, *sorted((REPO / "docs").glob("*.md"))]:
        out += _commands(path.read_text().splitlines())
    return list(dict.fromkeys(out))


def _commands(lines: list[str]) -> list[str]:
    """The `snakemake ...` lines of the bash blocks of one markdown file."""
    out, in_block = [], False
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            in_block = line.strip() in ("```bash", "```sh") if not in_block else False
        elif in_block and line.lstrip().startswith("snakemake "):
            cmd = line.strip()
            while cmd.endswith("\\"):
                i += 1
                cmd = cmd[:-1] + " " + lines[i].strip()
            out.append(re.sub(r"\s+#.*$", "", cmd).strip())
        i += 1
    return out


COMMANDS = readme_commands()


def test_the_readme_names_the_main_targets():
    text = " ".join(COMMANDS)
    for target in (
        "reports/demo_val.md",
        "reports/nusc_val.md",
        "reports/av2_val.md",
        "reports/nusc_test.md",
        "submissions/nusc_test_centerpoint.zip",
        "reports/semi_supervised.md",
    ):
        assert target in text, f"the README shows no snakemake command for {target}"


@pytest.fixture(scope="module")
def layout(tmp_path_factory, test_data):
    """A working directory ``work/`` with ``workflow`` linked from the repository, ``../shared/data`` beside it
    (the real fragments) and an empty full-nuScenes dataroot for the placeholder (dry runs read no table)."""
    root = tmp_path_factory.mktemp("readme")
    work = root / "main"
    work.mkdir()
    (work / "workflow").symlink_to(REPO / "workflow")
    (root / "shared").mkdir()
    (root / "shared" / "data").symlink_to(test_data)
    nusc = root / "nuscenes"
    for version in ("v1.0-trainval", "v1.0-test"):
        (nusc / version).mkdir(parents=True)
    return {"work": work, "nusc": nusc}


def _argv(cmd: str, layout: dict) -> list[str]:
    args = shlex.split(cmd.replace(NUSC_PLACEHOLDER, str(layout["nusc"])))
    assert args[0] == "snakemake"
    return [sys.executable, "-m", "snakemake", *args[1:], "--snakefile", str(REPO / "Snakefile")]


def _run(argv: list[str], cwd: Path, timeout: int) -> subprocess.CompletedProcess:
    env = {**os.environ, "GRUTRACK_CODE_VERSION": "documented-targets"}
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)


@pytest.mark.parametrize("cmd", [c for c in COMMANDS if not any(s in c for s, _ in SKIP)])
def test_documented_command_plans(cmd, layout):
    """Dry run of the command as written (plus ``-n`` when it has none): a plan, no error."""
    argv = _argv(cmd, layout)
    if "--summary" not in argv and "-n" not in argv:
        argv.append("-n")
    proc = _run(argv, layout["work"], timeout=300)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"{cmd}\n{out[-3000:]}"
    assert "--summary" in argv or "Job stats" in out or "Nothing to be done" in out, out[-2000:]


@pytest.mark.slow
@pytest.mark.parametrize("cmd", [c for c in COMMANDS if any(r in c for r in REAL) and "-n" not in shlex.split(c)])
def test_documented_small_real_targets_run(cmd, layout):
    """The README's mini and AV2 commands for real: they finish and write their target."""
    proc = _run(_argv(cmd, layout), layout["work"], timeout=1500)
    assert proc.returncode == 0, f"{cmd}\n{(proc.stdout + proc.stderr)[-3000:]}"
    target = next(a for a in shlex.split(cmd)[1:] if re.match(r"^(reports|submissions|checkpoints)/", a))
    path = layout["work"] / target
    assert path.is_file(), target
    if path.suffix == ".json":
        doc = json.loads(path.read_text())
        assert 0.0 < doc["overall"]["amota"] < 1.0
    else:
        text = path.read_text()
        assert "SYNTHETIC" in text and "| Ours |" in text
