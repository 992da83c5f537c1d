#!/usr/bin/env bash
# The test command: creates .venv if missing, installs, runs pytest. Extra arguments go to pytest.
# One pytest worker per core, at most four (pytest-xdist; a worker that builds a workflow target runs Snakemake
# with two cores beside the others), each test file whole on one worker so that its module fixtures (a workflow run)
# are made once; `-n 0` after it runs everything in this process.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/env.sh"
cd "$ROOT"
exec python -m pytest -n auto --maxprocesses 4 --dist loadfile "$@"
