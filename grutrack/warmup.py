"""Compile the tracking kernels once, at set-up, instead of in a user's first command.

The tracking loop's kernels are numba functions cached on disk (``cache=True``: machine code under the package's
``__pycache__`` folders). The first process after an install compiles them (tens of seconds of CPU); every later
one loads them. ``scripts/env.sh`` runs ``python -m grutrack.warmup`` after installing, so that neither the demo
nor the user's first ``grutrack track`` pays it; after a plain ``pip install`` the first command says what it
is doing (:func:`cold_cache_notice`).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

#: the presets whose trackers together reach every compiled kernel (motion models, association, NMS variants)
PRESETS = (("ekf", "ekf"), ("ekf", "polymot"), ("ekf", "fastpoly"), ("greedy", None), ("ab3dmot", None))
#: modules with cached numba kernels; their cache files mark a warm cache
KERNEL_MODULES = ("motion/kalman.py", "motion/models.py", "tracking/association.py", "geometry.py")


def cache_is_warm() -> bool:
    """Whether the compiled kernels of every :data:`KERNEL_MODULES` module are cached for this Python (numba
    ``*.py311.nbi`` index files beside them, one set per Python version)."""
    root = Path(__file__).resolve().parent
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    for mod in KERNEL_MODULES:
        path = root / mod
        if not any((path.parent / "__pycache__").glob(f"{path.stem}.*.{tag}.nbi")):
            return False
    return True


def cold_cache_notice() -> None:
    """One line on stderr when the kernels are not compiled yet (a plain ``pip install``): the first command
    compiles them."""
    if not cache_is_warm():
        print(
            "grutrack: compiling the tracking kernels (first run after installing; cached for later runs; "
            "`python -m grutrack.warmup` does it ahead)",
            file=sys.stderr,
        )


def warm_up() -> float:
    """Build every preset's tracker and run its warm-up (two synthetic frames); returns the seconds taken."""
    from grutrack.tracking.factory import build_tracker

    t0 = time.perf_counter()
    for tracker, preset in PRESETS:
        build_tracker(tracker, preset).warm_up()
    return time.perf_counter() - t0


if __name__ == "__main__":
    print(f"grutrack: tracking kernels compiled and cached ({warm_up():.1f} s)", file=sys.stderr)
