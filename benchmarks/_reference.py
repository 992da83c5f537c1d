"""Side-by-side measurement against a reference commit: the commit is checked out into a temporary
``git worktree`` and the same command runs with ``PYTHONPATH`` pointing at it, interleaved with the current
checkout's run, so drift of a shared machine falls on both. Each run is a child process measured with
``os.wait4`` (wall time, CPU time, peak resident memory of that child alone)."""

from __future__ import annotations

import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "GRUTRACK_THREADS")


@dataclass
class Run:
    """One child process: wall and CPU seconds, peak RSS in MiB, its stdout."""

    wall: float
    cpu: float
    rss_mib: float
    stdout: str


@dataclass
class Series:
    """Repeated runs of one measurement on one checkout."""

    runs: list[Run] = field(default_factory=list)

    def median(self, attr: str) -> float:
        return statistics.median(getattr(r, attr) for r in self.runs)


@contextlib.contextmanager
def reference_checkout(commit: str | None):
    """Yield the path of ``commit`` checked out in a temporary worktree (None: yield None)."""
    if not commit:
        yield None
        return
    tmp = Path(tempfile.mkdtemp(prefix="grutrack-ref-"))
    path = tmp / "ref"
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "--quiet", str(path), commit], check=True)
    try:
        yield path
    finally:
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(path)], check=False)
        with contextlib.suppress(OSError):
            tmp.rmdir()


def child_env(root: Path, keep_thread_vars: bool = False) -> dict:
    """The environment of a child run on checkout ``root``: ``root`` first on PYTHONPATH (other entries kept,
    either checkout removed), thread variables removed."""
    env = {k: v for k, v in os.environ.items() if keep_thread_vars or k not in THREAD_VARS}
    others = [
        p
        for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
        if p and Path(p).resolve() not in (REPO.resolve(), Path(root).resolve())
    ]
    env["PYTHONPATH"] = os.pathsep.join([str(root), *others])
    return env


def run_measured(
    argv: list[str], root: Path, cwd: Path | None = None, stdin: str | None = None, keep_thread_vars: bool = False
) -> Run:
    """Run ``argv`` with checkout ``root`` on PYTHONPATH (thread variables removed unless ``keep_thread_vars``);
    wall time, the child's own CPU time and peak RSS (``os.wait4``). Raises on a non-zero exit status."""
    import threading

    env = child_env(root, keep_thread_vars)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        argv,
        cwd=str(cwd or root),
        env=env,
        text=True,
        stdin=subprocess.PIPE if stdin is not None else subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    chunks: dict[str, str] = {}

    def _read(name, stream):
        chunks[name] = stream.read()

    readers = [
        threading.Thread(target=_read, args=("out", proc.stdout)),
        threading.Thread(target=_read, args=("err", proc.stderr)),
    ]
    for t in readers:
        t.start()
    if stdin is not None:
        proc.stdin.write(stdin)
        proc.stdin.close()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    for t in readers:
        t.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(
            f"{' '.join(argv[:4])} ... failed ({proc.returncode}) on {root}:\n{chunks.get('err', '')[-3000:]}"
        )
    return Run(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, chunks.get("out", ""))


def interleaved(measure, roots: dict[str, Path], repeat: int) -> dict[str, Series]:
    """Call ``measure(root) -> Run`` ``repeat`` times per checkout, alternating checkouts run by run."""
    series = {name: Series() for name in roots}
    for _ in range(repeat):
        for name, root in roots.items():
            series[name].runs.append(measure(root))
    return series


def concurrent(measure, roots: dict[str, Path], repeat: int) -> dict[str, Series]:
    """Like ``interleaved``, but each repeat runs every checkout's ``measure(root)`` at the same time (one thread,
    i.e. one child process, per checkout): for single-threaded commands too long to run one after the other; each
    child gets its own core on a 2-core machine and both see the same contention."""
    from concurrent.futures import ThreadPoolExecutor

    series = {name: Series() for name in roots}
    for _ in range(repeat):
        with ThreadPoolExecutor(max_workers=len(roots)) as pool:
            futures = {name: pool.submit(measure, root) for name, root in roots.items()}
            for name, fut in futures.items():
                series[name].runs.append(fut.result())
    return series


def python() -> str:
    """The interpreter running the benchmark (the project's virtualenv)."""
    return sys.executable
