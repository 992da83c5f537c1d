"""The toolkit's CPU thread policy, in one place, applied by the commands that run the GRU-KF or the tracking
loop (``grutrack track``, ``grutrack train``) and by ``grutrack evaluate`` / ``grutrack render`` (BLAS only:
reproducible sums), so that no environment variable is needed.

The per-frame work is many small operations on batches of tens of tracks (GRU cells of width ~100, 10x10
Kalman algebra): extra threads only add synchronisation, and torch's default (one intra-op thread per core,
plus an inter-op pool) contends with BLAS and with anything else on the machine. Measured on 2 cores
(docs/results/threads.md): GRU-KF training and tracking are slower with two intra-op threads than with one.

``OMP_NUM_THREADS`` is deliberately *not* read: Snakemake (and SLURM, and many cluster setups) export it as the
job's core count, which would make torch spin two threads on work where one is faster. Only
``GRUTRACK_THREADS`` changes the count, for a user who measured otherwise.
"""

from __future__ import annotations

import os

_applied: dict = {}

#: the one variable that sets the intra-op thread count (``OMP_NUM_THREADS`` is ignored, see the module doc)
THREADS_VAR = "GRUTRACK_THREADS"


def thread_count() -> int:
    """Threads for intra-op work: ``GRUTRACK_THREADS`` when it is a positive integer, else 1."""
    value = os.environ.get(THREADS_VAR, "").strip()
    if value.isdigit() and int(value) > 0:
        return int(value)
    return 1


def apply_thread_policy(torch_too: bool = True) -> int:
    """Limit BLAS (threadpoolctl, for the whole process) and, with ``torch_too``, torch's intra-op threads to
    :func:`thread_count` and its inter-op pool to one thread, whatever ``OMP_NUM_THREADS`` says. Idempotent;
    returns the thread count."""
    n = thread_count()
    if "blas" not in _applied:
        import numpy  # noqa: F401  (loads its BLAS: threadpoolctl limits only the libraries already loaded)
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
