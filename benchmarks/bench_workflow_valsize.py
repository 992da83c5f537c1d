"""``snakemake --cores 2 reports/nusc_val.md`` at nuScenes-val size on a SYNTHETIC stand-in, end to end: the
real target's DAG (two GRU-KF trainings at the paper's scale, eight tracking runs, submissions and manifests, the
fast evaluator, the devkit cross-check, renders, the report) with the overlay ``workflow/config/valsize.yaml``
(a 750-scene demo dataset: 600 demo_train, 150 demo_val scenes of 40 frames) and, on top of it, val detections
at real CenterPoint's density (about 75 per frame, made from the ground truth by benchmarks/bench_tracking.py's
noise model, a ``local`` detector of a second overlay written into OUT: the demo's scenes hold fewer objects than
nuScenes', so the shipped overlay's simulated detections are sparser).

Runs in a scratch folder (``snakemake --directory OUT``), then prints each job's wall time and peak memory (the
rules' ``benchmark:`` files), the sums per stage, the total wall time and the cross-check's verdict; with
``--markdown F`` the same as a markdown table. A script, not a test: it runs for most of an hour on two cores.

    .venv/bin/python benchmarks/bench_workflow_valsize.py --out /tmp/valsize [--cores 2] [--markdown F]
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

REPO = Path(__file__).resolve().parents[1]
OVERLAY = REPO / "workflow/config/valsize.yaml"
DENSE = "detections/dense/valsize_demo_val.json"  # the dense detector's file, relative to OUT
DENSE_OVERLAY = f"""detectors:
  dense: {{kind: local, format: nuscenes_json, member: null, files: {{demo_val: {DENSE}}}}}
experiments:
  nusc_val: {{detectors: [dense]}}
"""

DENSE_DRIVER = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[3])
from bench_commands import write_dense_detections
from grutrack.data.nuscenes import load_scenes, open_nuscenes
scenes = load_scenes(open_nuscenes(sys.argv[1], "v1.0-demo"), "demo_val", with_gt=True)
out = Path(sys.argv[2]); out.parent.mkdir(parents=True, exist_ok=True)
n = write_dense_detections(scenes, out)
print(f"{n} detections on {sum(len(s) for s in scenes)} frames")
"""


def snakemake(out: Path, cores: int, target: str) -> float:
    """Run one snakemake target in ``out`` with the two overlays; returns its wall seconds."""
    (out / "dense.yaml").write_text(DENSE_OVERLAY)
    t0 = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            target,
            "--snakefile",
            str(REPO / "Snakefile"),
            "--directory",
            str(out),
            "--cores",
            str(cores),
            "--configfile",
            str(OVERLAY),
            str(out / "dense.yaml"),
        ],
        check=True,
    )
    return time.perf_counter() - t0


def job_rows(out: Path) -> list[tuple[str, str, float, float]]:
    """(stage, job, wall s, peak MiB) of every rule benchmark file under ``out/logs/benchmarks``."""
    rows = []
    root = out / "logs" / "benchmarks"
    for tsv in sorted(root.rglob("*.tsv")):
        with tsv.open() as f:
            rec = next(csv.DictReader(f, delimiter="\t"))
        rel = tsv.relative_to(root)
        rss = rec.get("max_rss", "NA")
        rows.append(
            (
                rel.parts[0],
                str(rel.with_suffix("")),
                float(rec["s"]),
                float(rss) if rss not in ("NA", "-") else float("nan"),
            )
        )
    return rows


def table(rows: list[list[str]], head: list[str]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="scratch folder (the workflow's working directory)")
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--markdown", default=None, help="also write the tables as markdown here")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    t_data = snakemake(out, args.cores, "data/valsize")
    t0 = time.perf_counter()
    dense = subprocess.run(
        [sys.executable, "-", str(out / "data/valsize"), str(out / DENSE), str(Path(__file__).resolve().parent)],
        input=DENSE_DRIVER,
        text=True,
        cwd=REPO,
        capture_output=True,
        check=True,
    ).stdout.strip()
    t_dense = time.perf_counter() - t0
    t_report = snakemake(out, args.cores, "reports/nusc_val.md")
    total = time.perf_counter() - t_start

    jobs = job_rows(out)
    stages: dict[str, list] = {}
    for stage, _, s, mib in jobs:
        stages.setdefault(stage, []).append((s, mib))
    stage_rows = [
        [st, str(len(v)), f"{sum(s for s, _ in v):.0f}", f"{max(m for _, m in v):.0f}"] for st, v in stages.items()
    ]
    stage_rows.append(["dense val detections (this script)", "1", f"{t_dense:.0f}", "-"])
    job_table = table([[j, f"{s:.1f}", f"{m:.0f}"] for _, j, s, m in jobs], ["job", "wall s", "peak MiB"])
    stage_table = table(stage_rows, ["stage", "jobs", "job wall s (sum)", "peak MiB (largest job)"])
    cc_files = list((out / "reports/metrics").rglob("*.crosscheck.json"))
    cc = json.loads(cc_files[0].read_text()) if cc_files else {}
    summary = (
        f"total wall {total:.0f} s ({total / 60:.1f} min) on --cores {args.cores}: data {t_data:.0f} s, "
        f"dense detections {t_dense:.0f} s ({dense}), reports/nusc_val.md {t_report:.0f} s"
    )
    cross = (
        f"cross-check ({cc_files[0].name if cc_files else '-'}): {len(cc.get('scenes', []))} of "
        f"{cc.get('split_scenes')} scenes, {cc.get('entries')} entries, max |difference| "
        f"{cc.get('max_abs_difference')}, equal {cc.get('equal')}, devkit {cc.get('seconds', {}).get('devkit')} s"
        f", fast {cc.get('seconds', {}).get('fast')} s"
    )
    text = "\n\n".join([summary, cross, stage_table, job_table])
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
