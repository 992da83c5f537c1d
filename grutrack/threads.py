"""The toolkit's CPU thread policy, in one place, applied by the commands that run the GRU-KF or the tracking
loop (``grutrack track``, ``grutrack train``) and by ``grutrack evaluate`` (BLAS only: reproducible sums), so
that no environment variable is needed.

The per-frame work is many small operations on batches of tens of tracks (GRU cells of width ~100, 10x10
Kalman algebra): extra threads only add synchronisation, and torch's default (one intra-op thread per core,
plus an inter-op pool) contends with BLAS and with anything else on the machine. Measured on 2 cores
(benchmarks/bench_commands.py): GRU-KF tracking and training several times slower with torch's default
threads than with one. ``OMP_NUM_THREADS`` / ``GRUTRACK_THREADS``, when set, still win.
"""

from __future__ import annotations

import os

_applied: dict = {}


def thread_count() -> int:
    """Threads for intra-op work: ``GRUTRACK_THREADS``, else ``OMP_NUM_THREADS``, else 1."""
    for var in ("GRUTRACK_THREADS", "OMP_NUM_THREADS"):
        value = os.environ.get(var, "").strip()
        if value.isdigit() and int(value) > 0:
            return int(value)
    return 1


def apply_thread_policy(torch_too: bool = True) -> int:
    """Limit BLAS (threadpoolctl, for the whole process) and, with ``torch_too``, torch's intra-op threads to
    :func:`thread_count` and its inter-op pool to one thread. Idempotent; returns the thread count."""
    n = thread_count()
    if "blas" not in _applied:
        from threadpoolctl import threadpool_limits

        _applied["blas"] = threadpool_limits(limits=n, user_api="blas")  # kept: the limit lasts for the process
    if torch_too and "torch" not in _applied:
        import torch

        torch.set_num_threads(n)
        try:
            torch.set_num_interop_threads(1)
        except RuntimeError:  # the inter-op pool already started (torch allows setting it once, before use)
            pass
        _applied["torch"] = n
    return n
