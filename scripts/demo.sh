#!/usr/bin/env bash
# The main job on the embedded default (the SYNTHETIC demo dataset; no download): the README's main command,
#   snakemake --cores 2 reports/demo_val.md
# i.e. demo data -> simulated CenterPoint-like detections -> train the GRU-KF -> track demo_val with the EKF and
# the GRU-KF -> official nuScenes submission files -> official TrackingEval -> reports/demo_val.md.
# Creates .venv if it is missing. Re-running runs only what is out of date. Extra arguments go to snakemake
# (e.g. `bash scripts/demo.sh -n` for a dry run, or another target such as reports/semi_supervised.md).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/env.sh"
cd "$ROOT"
# no target given: the default target (rule all) is reports/demo_val.md
[ $# -gt 0 ] || set -- reports/demo_val.md
exec snakemake --cores "${GRUTRACK_CORES:-2}" "$@"
