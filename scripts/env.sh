#!/usr/bin/env bash
# Create .venv at the repository root if it is missing (or stale) and install grutrack into it
# with the pinned constraints in constraints.txt. Sourced by scripts/test.sh and scripts/demo.sh.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PY="${GRUTRACK_PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
stamp_src="$(cat "$ROOT/pyproject.toml" "$ROOT/constraints.txt" | sha256sum | cut -d' ' -f1)"
if [ ! -x "$VENV/bin/python" ]; then
    echo "[grutrack] creating $VENV with $PY" >&2
    "$PY" -m venv "$VENV"
fi
if [ "$(cat "$VENV/.grutrack-stamp" 2>/dev/null)" != "$stamp_src" ]; then
    echo "[grutrack] installing grutrack and its pinned dependencies into $VENV" >&2
    "$VENV/bin/python" -m pip install --quiet --upgrade "pip>=23" >&2
    "$VENV/bin/python" -m pip install --quiet -c "$ROOT/constraints.txt" -e "$ROOT[test]" >&2
    echo "$stamp_src" > "$VENV/.grutrack-stamp"
fi
# compile the tracking kernels now (cached on disk), not in the first command
if ! "$VENV/bin/python" -c "import sys, grutrack.warmup as w; sys.exit(0 if w.cache_is_warm() else 1)"; then
    "$VENV/bin/python" -m grutrack.warmup
fi
export PATH="$VENV/bin:$PATH"
