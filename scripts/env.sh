#!/usr/bin/env bash
# Create .venv at the repository root if it is missing (or stale) and install grutrack into it
# with the pinned constraints in constraints.txt. Sourced by scripts/test.sh and scripts/demo.sh.
# GRUTRACK_PYTHON picks the interpreter that creates it (default python3.11; 3.12 works too, docs/results/python312.md)
# and GRUTRACK_VENV another folder for it (default .venv).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${GRUTRACK_VENV:-$ROOT/.venv}"
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
    # trackeval (the av2 evaluator's) has no release that allows both Python 3.12 and numpy<2: 1.0.0 says
    # Python<3.12, 1.0.1 (the same code) numpy>=2.3.2. On 3.12 the pinned 1.0.0 goes in past its Python bound;
    # its requirements are already there (pyproject.toml).
    if "$VENV/bin/python" -c "import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)"; then
        "$VENV/bin/python" -m pip install --quiet --no-deps --ignore-requires-python \
            -c "$ROOT/constraints.txt" trackeval >&2
    fi
    echo "$stamp_src" > "$VENV/.grutrack-stamp"
fi
# compile the tracking kernels now (cached on disk), not in the first command
if ! "$VENV/bin/python" -c "import sys, grutrack.warmup as w; sys.exit(0 if w.cache_is_warm() else 1)"; then
    "$VENV/bin/python" -m grutrack.warmup
fi
export PATH="$VENV/bin:$PATH"
