"""A one-node SLURM cluster on this machine, for the test that runs the workflow through ``--executor slurm``.

Debian's ``slurm-wlm`` and ``munge`` (installed with apt-get when a command is missing and the tests run as
root), started in a private folder under /tmp: its own munge key and socket, ``slurm.conf`` (one node: this
machine, its CPUs and 80 % of its memory; one partition), state and spool folders, two free TCP ports, logs.
Nothing outside the folder is written (apart from the apt-get install); the folder is removed when the cluster
stops cleanly. The three daemons run in the foreground
as children of the calling process; :meth:`SlurmCluster.stop` cancels any job left, ends them and checks that
no daemon and no job step of the cluster is left running.

There is no accounting database (slurmdbd): ``sacct`` has nothing to answer from, so the executor plugin is told
to poll with ``squeue`` (``--slurm-status-command squeue``), which it accepts when ``MinJobAge`` (how long
slurmctld keeps a finished job in the queue) is at least three of its polling intervals; this cluster keeps
finished jobs 600 s. With no ``sacct`` answer the plugin also submits without an account (it says so).

``python tests/support/slurm_cluster.py`` starts one, prints ``sinfo`` and a test job's output, and stops it (its
folder kept).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

#: the commands the cluster needs: daemons (and munge's key tool), clients
SERVER_COMMANDS = ("munged", "mungekey", "slurmctld", "slurmd", "slurmstepd")
BINARIES = (*SERVER_COMMANDS, "sbatch", "srun", "squeue", "sinfo", "scancel", "scontrol")
#: Debian packages that provide them
PACKAGES = ("slurm-wlm", "munge")
#: seconds a finished job stays visible to squeue (the executor plugin's squeue polling needs >= 120)
MIN_JOB_AGE = 600


class ClusterUnavailable(RuntimeError):
    """SLURM cannot be installed or started here (the message says why)."""


def _which(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    for folder in ("/usr/sbin", "/usr/bin", "/sbin"):
        if os.access(Path(folder, name), os.X_OK):
            return str(Path(folder, name))
    return None


def missing_binaries() -> list[str]:
    return [b for b in BINARIES if _which(b) is None]


def ensure_installed() -> None:
    """Install ``slurm-wlm`` and ``munge`` with apt-get when a command is missing (root only)."""
    missing = missing_binaries()
    if not missing:
        return
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        raise ClusterUnavailable(
            f"SLURM commands missing ({', '.join(missing)}) and they cannot be installed here "
            f"(needs root and apt-get: apt-get install {' '.join(PACKAGES)})"
        )
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", *PACKAGES]):
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        if proc.returncode != 0:
            raise ClusterUnavailable(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[-800:]}")
    still = missing_binaries()
    if still:
        raise ClusterUnavailable(f"after apt-get install {' '.join(PACKAGES)}, still missing: {', '.join(still)}")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _mem_mb() -> int:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal:"):
            return int(line.split()[1]) // 1024
    raise ClusterUnavailable("cannot read MemTotal from /proc/meminfo")


def _pids_named(name: str) -> set[int]:
    """Pids of the running (not zombie) processes whose command name is ``name``."""
    pids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        comm, rest = text[text.index("(") + 1 : text.rindex(")")], text[text.rindex(")") + 1 :].split()
        if comm == name[:15] and rest[0] != "Z":
            pids.add(int(stat.parent.name))
    return pids


def slurm_conf(root: Path, node: str, cpus: int, mem_mb: int, partition: str, ports: tuple[int, int]) -> str:
    """slurm.conf of the one-node cluster: everything under ``root``, no cgroups (linuxproc process tracking,
    no task plugin), no accounting, cores and memory consumable."""
    return f"""# one-node test cluster (tests/support/slurm_cluster.py)
ClusterName=grutrack
SlurmctldHost={node}(127.0.0.1)
SlurmctldPort={ports[0]}
SlurmdPort={ports[1]}
AuthType=auth/munge
AuthInfo=socket={root}/munge.socket
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation={root}/state
SlurmdSpoolDir={root}/spool
SlurmctldPidFile={root}/slurmctld.pid
SlurmdPidFile={root}/slurmd.pid
SlurmctldLogFile={root}/slurmctld.log
SlurmdLogFile={root}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MinJobAge={MIN_JOB_AGE}
SlurmdTimeout=300
InactiveLimit=0
KillWait=10
NodeName={node} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={mem_mb} State=UNKNOWN
PartitionName={partition} Nodes={node} Default=YES MaxTime=INFINITE State=UP
"""


@dataclass
class SlurmCluster:
    """A running one-node cluster; ``env`` is the environment a client command (sbatch, squeue, snakemake) needs:
    this process's, with ``SLURM_CONF`` pointing at the cluster's slurm.conf and no inherited ``SLURM_*``."""

    root: Path
    partition: str
    node: str
    cpus: int
    mem_mb: int
    env: dict[str, str] = field(default_factory=dict)
    procs: dict[str, subprocess.Popen] = field(default_factory=dict)
    steps_before: set[int] = field(default_factory=set)
    #: remove ``root`` once stopped cleanly (it was made by :func:`start`)
    remove_root: bool = False

    @property
    def conf(self) -> Path:
        return self.root / "slurm.conf"

    def logs(self, tail: int = 30) -> str:
        """The end of each daemon's log (for failure messages)."""
        parts = []
        for name in ("munged", "slurmctld", "slurmd"):
            p = self.root / f"{name}.log"
            text = p.read_text(errors="replace").splitlines()[-tail:] if p.exists() else ["(no log)"]
            parts.append(f"--- {p}\n" + "\n".join(text))
        return "\n".join(parts)

    def run(self, *cmd: str, timeout: float = 30) -> subprocess.CompletedProcess:
        return subprocess.run(cmd, env=self.env, capture_output=True, text=True, timeout=timeout)

    def _start_daemon(self, name: str, cmd: list[str]) -> None:
        with open(self.root / f"{name}.out", "ab") as out:
            self.procs[name] = subprocess.Popen(
                cmd, env=self.env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT
            )

    def _wait_for(self, what: str, ready, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            dead = [n for n, p in self.procs.items() if p.poll() is not None]
            if dead:
                raise ClusterUnavailable(f"{', '.join(dead)} exited while waiting for {what}\n{self.logs()}")
            if ready():
                return
            time.sleep(0.5)
        raise ClusterUnavailable(f"{what}: not ready after {timeout:.0f} s\n{self.logs()}")

    def stop(self) -> None:
        """Cancel the jobs left in the queue, end slurmd, slurmctld and munged (SIGTERM, SIGKILL after 20 s) and
        check that none of them and no job step started since :func:`start` is left running."""
        ctld = self.procs.get("slurmctld")
        if ctld is not None and ctld.poll() is None:
            self.run("scancel", "--full", "--quiet", f"--partition={self.partition}")
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                queue = self.run("squeue", "--noheader", "--states=RUNNING,PENDING,COMPLETING")
                if queue.returncode != 0 or not queue.stdout.strip():
                    break
                time.sleep(0.5)
        for name in ("slurmd", "slurmctld", "munged"):
            proc = self.procs.get(name)
            if proc is None or proc.poll() is not None:
                continue
            proc.terminate()
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
        left = [n for n, p in self.procs.items() if p.poll() is None]
        steps = sorted(_pids_named("slurmstepd") - self.steps_before)
        if left or steps:
            raise RuntimeError(f"SLURM processes left running: daemons {left}, job steps (pids) {steps}")
        if self.remove_root:
            shutil.rmtree(self.root, ignore_errors=True)


def start(partition: str = "cpu", root: Path | None = None, timeout: float = 60) -> SlurmCluster:
    """Install SLURM if needed, start munged, slurmctld and slurmd in ``root`` (a new folder under /tmp when None:
    the munge socket's path must stay short) and wait until the node is idle. Raises :class:`ClusterUnavailable`
    when it cannot (whatever was started is stopped first)."""
    ensure_installed()
    remove_root = root is None
    root = Path(root if root is not None else tempfile.mkdtemp(prefix="grutrack-slurm-")).resolve()
    for sub in ("state", "spool"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    node = socket.gethostname().split(".")[0]
    cpus = os.cpu_count() or 1
    mem_mb = int(_mem_mb() * 0.8)
    cluster = SlurmCluster(root=root, partition=partition, node=node, cpus=cpus, mem_mb=mem_mb, remove_root=remove_root)
    cluster.conf.write_text(slurm_conf(root, node, cpus, mem_mb, partition, (_free_port(), _free_port())))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "SBATCH_", "SQUEUE_", "SRUN_"))}
    # Inside a job, the executor plugin's job step (snakemake-executor-plugin-slurm-jobstep 0.6) removes every
    # SLURM_* variable but a few job ids before it calls srun, SLURM_CONF included: a real cluster's srun finds
    # its config at /etc/slurm/slurm.conf (or in slurmd's configless cache, /run/slurm/conf), this one's lives
    # here. An srun first on the PATH (which sbatch --export=ALL hands to the job) sets it again.
    bindir = root / "bin"
    bindir.mkdir(exist_ok=True)
    (bindir / "srun").write_text(f'#!/bin/sh\nSLURM_CONF={cluster.conf} exec {_which("srun")} "$@"\n')
    (bindir / "srun").chmod(0o755)
    cluster.env = {**env, "SLURM_CONF": str(cluster.conf), "PATH": f"{bindir}{os.pathsep}{env.get('PATH', '')}"}
    cluster.steps_before = _pids_named("slurmstepd")

    key = root / "munge.key"
    subprocess.run([_which("mungekey"), "--create", "--keyfile", str(key)], check=True, capture_output=True)
    key.chmod(0o600)
    sock = root / "munge.socket"
    try:
        cluster._start_daemon(
            "munged",
            [
                _which("munged"),
                "--foreground",
                "--force",
                f"--key-file={key}",
                f"--socket={sock}",
                f"--pid-file={root}/munged.pid",
                f"--log-file={root}/munged.log",
                f"--seed-file={root}/munged.seed",
            ],
        )
        cluster._wait_for("munged's socket", sock.exists, 20)
        cluster._start_daemon("slurmctld", [_which("slurmctld"), "-D", "-i", "-f", str(cluster.conf)])
        cluster._wait_for("slurmctld", lambda: cluster.run("scontrol", "ping").returncode == 0, timeout)
        cluster._start_daemon("slurmd", [_which("slurmd"), "-D", "-f", str(cluster.conf), "-N", node])

        def idle() -> bool:
            proc = cluster.run("sinfo", "--noheader", f"--partition={partition}", "--format=%t")
            return proc.returncode == 0 and proc.stdout.strip() == "idle"

        cluster._wait_for(f"node {node} idle in partition {partition}", idle, timeout)
    except BaseException:
        cluster.remove_root = False  # keep the logs the error names
        cluster.stop()
        raise
    return cluster


if __name__ == "__main__":
    c = start()
    c.remove_root = False  # keep slurm.conf and the logs to look at
    try:
        print(c.run("sinfo").stdout)
        job = c.run("sbatch", "--parsable", "--wait", f"--output={c.root}/hello.out", "--wrap=hostname; nproc")
        print("sbatch:", job.returncode, job.stdout.strip(), job.stderr.strip())
        print((c.root / "hello.out").read_text())
    finally:
        c.stop()
    print(f"logs in {c.root}")
    print("stopped; munged/slurm* processes now:", sorted(_pids_named("munged") | _pids_named("slurmctld")))
