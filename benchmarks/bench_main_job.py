"""Wall time of the main job (`bash scripts/demo.sh`, i.e. `snakemake --cores 2 reports/demo_val.md`) as a new
user meets it: a fresh clone of a commit, first with the virtual environment created by the script itself, then
``--repeat`` times on the same clone with ``.venv`` present and every workflow output removed in between.

    .venv/bin/python benchmarks/bench_main_job.py --commit HEAD --repeat 3 --out /tmp/mainjob

Prints one line per run and the median of the runs with ``.venv`` present; also the first `grutrack track` after
set-up (the kernels are compiled by scripts/env.sh, not by the user's first command).
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: what the main job writes (all ignored by git): removed between the runs with .venv present
OUTPUTS = ("data", "detections", "checkpoints", "results", "submissions", "reports", "logs", ".snakemake")


def _run(cmd: list[str], cwd: Path, log: Path) -> float:
    """Run ``cmd`` in ``cwd`` with its output in ``log``; returns the wall seconds (raises on failure)."""
    t0 = time.perf_counter()
    with log.open("w") as fh:
        subprocess.run(cmd, cwd=cwd, stdout=fh, stderr=subprocess.STDOUT, check=True)
    return time.perf_counter() - t0


def _clean_outputs(clone: Path) -> None:
    """Remove the workflow's outputs (not .venv), restoring what git tracks under them."""
    for name in OUTPUTS:
        shutil.rmtree(clone / name, ignore_errors=True)
    subprocess.run(["git", "checkout", "--", "."], cwd=clone, check=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--commit", default="HEAD")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--out", default="/tmp/grutrack-mainjob")
    args = p.parse_args()
    out = Path(args.out)
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    clone = out / "main"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    subprocess.run(["git", "checkout", "-q", args.commit], cwd=clone, check=True)
    # ../shared beside the clone, as beside the repository (the test data; the main job itself reads none)
    if (REPO.parent / "shared").exists():
        (out / "shared").symlink_to(REPO.parent / "shared")
    fresh = _run(["bash", "scripts/demo.sh"], clone, out / "fresh.log")
    print(f"fresh clone, .venv created by the script: {fresh:.1f} s")
    det = REPO.parent / "shared/data/nuscenes/detections/pointpillars_mini_val.json"
    if det.is_file():
        first = _run(
            [
                ".venv/bin/grutrack",
                "track",
                "--dataroot",
                str(det.parents[1]),
                "--version",
                "v1.0-mini",
                "--split",
                "mini_val",
                "--detections",
                str(det),
                "--out",
                str(out / "first.json"),
                "--no-progress",
            ],
            clone,
            out / "first_track.log",
        )
        print(f"first grutrack track after set-up: {first:.1f} s")
    times = []
    for i in range(args.repeat):
        _clean_outputs(clone)
        times.append(_run(["bash", "scripts/demo.sh"], clone, out / f"warm{i}.log"))
        print(f"clean clone with .venv present, run {i + 1}: {times[-1]:.1f} s")
    print(f"median of {len(times)} with .venv present: {statistics.median(times):.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
