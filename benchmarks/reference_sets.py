"""Every preset and the shipped GRU-KF on the four reference sets of ../shared/data/nuscenes/reference, beside
Poly-MOT's, Fast-Poly's and MCTrack's own runs (their ``*.metrics_summary.json``, the stock devkit):
AMOTA / AMOTP (m) / IDS, as a markdown table.

    .venv/bin/python benchmarks/reference_sets.py --out /tmp/refsets

Tracks with `grutrack track` and scores with `grutrack evaluate --evaluator fast` (equal to the devkit); the
GRU-KF row is `--tracker grukf` with the shipped pretrained network.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("GRUTRACK_TEST_DATA", REPO.parent / "shared/data")) / "nuscenes"
#: (label, split, detection file, reference stem)
SETS = (
    ("mini_val, real PointPillars", "mini_val", "detections/pointpillars_mini_val.json", "pointpillars_mini_val"),
    (
        "mini_val, SYNTHETIC CenterPoint-like s7",
        "mini_val",
        "reference/mini_val_centerpoint_sim_s7.json",
        "mini_val_centerpoint_sim_s7",
    ),
    (
        "mini_val, SYNTHETIC PointPillars-like s7",
        "mini_val",
        "reference/mini_val_pointpillars_sim_s7.json",
        "mini_val_pointpillars_sim_s7",
    ),
    (
        "mini_train, SYNTHETIC CenterPoint-like s7",
        "mini_train",
        "reference/mini_train_centerpoint_sim_s7.json",
        "mini_train_centerpoint_sim_s7",
    ),
)
#: (column, grutrack track arguments)
RUNS = (
    ("`mctrack`", ["--tracker", "ekf", "--config", "mctrack"]),
    ("`polymot`", ["--tracker", "ekf", "--config", "polymot"]),
    ("`fastpoly`", ["--tracker", "ekf", "--config", "fastpoly"]),
    ("`ekf` (default)", ["--tracker", "ekf"]),
    ("`grukf` (pretrained)", ["--tracker", "grukf", "--device", "cpu"]),
)
OWN = (("MCTrack's code", "mctrack"), ("Poly-MOT's code", "polymot"), ("Fast-Poly's code", "fastpoly"))


def _cell(amota: float, amotp: float, ids: float) -> str:
    return f"{amota:.4f} / {amotp:.3f} / {ids:.0f}"


def _ours(out: Path, split: str, det: Path, args: list[str], name: str) -> str:
    common = ["--dataroot", str(DATA), "--version", "v1.0-mini", "--split", split]
    sub, met = out / f"{name}.json", out / f"{name}.metrics.json"
    grutrack = [sys.executable, "-m", "grutrack"]
    subprocess.run(
        [*grutrack, "track", *common, "--detections", str(det), *args, "--out", str(sub), "--no-progress"],
        check=True,
        capture_output=True,
    )
    subprocess.run(
        [*grutrack, "evaluate", *common, "--submission", str(sub), "--evaluator", "fast", "--out", str(met)],
        check=True,
        capture_output=True,
    )
    o = json.loads(met.read_text())["overall"]
    return _cell(o["amota"], o["amotp"], o["ids"])


def _own(stem: str, tracker: str) -> str:
    s = json.loads((DATA / "reference" / f"{tracker}_{stem}.metrics_summary.json").read_text())
    return _cell(s["amota"], s["amotp"], s["ids"])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="/tmp/grutrack-refsets")
    out = Path(p.parse_args().out)
    out.mkdir(parents=True, exist_ok=True)
    head = ["detections", *(c for c, _ in RUNS), *(c for c, _ in OWN)]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for label, split, det, stem in SETS:
        cells = [_ours(out, split, DATA / det, args, f"{stem}_{i}") for i, (_, args) in enumerate(RUNS)]
        cells += [_own(stem, t) for _, t in OWN]
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
