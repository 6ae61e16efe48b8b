"""A one-node SLURM cluster on this machine, for the session: munged, MariaDB, slurmdbd,
slurmctld and slurmd on 127.0.0.1, their configs, state, logs and database in a temporary
directory, a cluster and an account registered with sacctmgr. Everything it started is stopped
when the session ends, also when a test (or the start itself) fails.

It needs root (slurmd runs jobs as their user; MariaDB and munged are started as root here) and
Debian's packages slurm-wlm, slurmdbd, mariadb-server and munge: the README's setup installs
them, and the fixture installs what is missing with apt-get. Where it cannot (not root, no
apt-get), the test fails under CI=true and is skipped with that reason elsewhere (docs/cluster.md, "The test").
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "workflow"))
from workflow_helpers import end_process  # noqa: E402

PACKAGES = ["slurm-wlm", "slurmdbd", "mariadb-server", "munge"]
COMMANDS = ["munged", "mariadb-install-db", "mariadbd", "slurmdbd", "slurmctld", "slurmd", "sacctmgr", "sbatch"]
CLUSTER = "invrender"
ACCOUNT = "invrender"
# The executor's job step (snakemake-executor-plugin-slurm-jobstep 0.6) drops every SLURM_*
# variable, SLURM_CONF included, before its `srun`: inside a job only the default path finds the
# config. It is linked there for the session when the machine has none of its own.
DEFAULT_CONF = Path("/etc/slurm/slurm.conf")


@dataclass
class Cluster:
    root: Path
    env: dict  # os.environ with SLURM_CONF: for sbatch, sacct, snakemake
    node: str

    def run(self, *cmd, check=True, timeout=60) -> str:
        result = subprocess.run(
            [str(c) for c in cmd],
            env=self.env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            timeout=timeout,
        )
        if check and result.returncode != 0:
            raise AssertionError(f"{' '.join(map(str, cmd))} failed ({result.returncode}):\n{result.stdout}")
        return result.stdout

    def log_tails(self) -> str:
        """The last lines of every daemon's log: what a failing start or run shows."""
        tails = []
        for log in sorted((self.root / "log").glob("*")):
            lines = log.read_text(errors="replace").splitlines()[-15:]
            tails.append(f"--- {log.name}\n" + "\n".join(lines))
        return "\n".join(tails)


def _cannot_run(reason: str):
    message = f"the SLURM cluster test cannot run here: {reason}"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message, pytrace=False)
    pytest.skip(message)


def _install_packages():
    missing = [c for c in COMMANDS if shutil.which(c) is None]
    if not missing:
        return
    if os.geteuid() != 0:
        _cannot_run(f"{', '.join(missing)} missing and not root (apt-get install {' '.join(PACKAGES)})")
    if shutil.which("apt-get") is None:
        _cannot_run(f"{', '.join(missing)} missing and no apt-get (Debian's {' '.join(PACKAGES)})")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    install = ["apt-get", "install", "-y", "-q", *PACKAGES]
    result = subprocess.run(install, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if result.returncode != 0:  # a fresh machine's package lists may be missing
        subprocess.run(["apt-get", "update", "-q"], env=env, check=True, stdout=subprocess.DEVNULL)
        result = subprocess.run(install, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert result.returncode == 0, f"apt-get install {' '.join(PACKAGES)} failed:\n{result.stdout[-3000:]}"


def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket() for _ in range(n)]
    for s in sockets:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


def _wait(what: str, ready, timeout: float, process: subprocess.Popen | None = None, log: Path | None = None):
    """Poll ready() until it is true; fail naming `what` (and its log) on timeout or exit."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if ready():
            return
        if process is not None and process.poll() is not None:
            break
        time.sleep(0.2)
    tail = log.read_text(errors="replace")[-3000:] if log and log.exists() else ""
    state = f"exited with {process.returncode}" if process is not None and process.poll() is not None else "timed out"
    raise AssertionError(f"{what} did not start ({state}):\n{tail}")


def _succeeds(cmd, env) -> bool:
    return subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0


def _start(stack: contextlib.ExitStack, cmd: list, log: Path, env=None) -> subprocess.Popen:
    """A daemon in the foreground, as our child; stopped (SIGTERM, then SIGKILL) when the stack
    unwinds."""
    out = open(log.with_suffix(".out"), "w")
    process = subprocess.Popen(
        [str(c) for c in cmd], stdout=out, stderr=subprocess.STDOUT, env=env, start_new_session=True
    )

    def stop():
        end_process(process, signal.SIGTERM, timeout=30)
        out.close()

    stack.callback(stop)
    return process


MIN_CPUS = 4


def _node() -> tuple[str, str]:
    """(node name, its hardware as `slurmd -C` sees it: CPUs=.. Boards=.. ... RealMemory=..),
    with at least MIN_CPUS CPUs: the crops' group job asks for one per crop (three), which a
    2-core CI machine then runs side by side on its 2 cores (SlurmdParameters=config_overrides
    lets slurmd accept a node larger than it finds)."""
    line = subprocess.run(["slurmd", "-C"], stdout=subprocess.PIPE, text=True, check=True).stdout.splitlines()[0]
    fields = dict(item.split("=", 1) for item in line.split())
    name = fields.pop("NodeName")
    if int(fields["CPUs"]) < MIN_CPUS:
        fields.update(CPUs=MIN_CPUS, Boards=1, SocketsPerBoard=1, CoresPerSocket=MIN_CPUS, ThreadsPerCore=1)
    # Some memory stays with the system: slurmd drains a node whose RealMemory exceeds what it finds.
    fields["RealMemory"] = str(int(int(fields["RealMemory"]) * 0.9))
    return name, " ".join(f"{k}={v}" for k, v in fields.items())


SLURMDBD_CONF = """\
AuthType=auth/munge
AuthInfo=socket={root}/munge/munge.socket
DbdHost=localhost
DbdAddr=127.0.0.1
DbdPort={dbd_port}
SlurmUser=root
LogFile={root}/log/slurmdbd.log
PidFile={root}/state/slurmdbd.pid
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort={db_port}
StorageUser=slurm
StoragePass=slurm
StorageLoc=slurm_acct_db
"""

# proctrack/linuxproc and task/none: no cgroups (a container, gVisor among them, may not let us
# have them), so no cgroup.conf is read. cons_tres with CR_Core_Memory: jobs are placed by their
# CPUs and memory, so a request the node cannot hold stays pending (the test sees it).
# AccountingStoreFlags=job_comment: sacct shows the comment, where the executor names the rule.
SLURM_CONF = """\
ClusterName={cluster}
SlurmctldHost={node}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={root}/munge/munge.socket
StateSaveLocation={root}/state
SlurmdSpoolDir={root}/spool
SlurmctldPidFile={root}/state/slurmctld.pid
SlurmdPidFile={root}/state/slurmd.pid
SlurmctldLogFile={root}/log/slurmctld.log
SlurmdLogFile={root}/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
JobAcctGatherType=jobacct_gather/linux
JobAcctGatherFrequency=5
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=127.0.0.1
AccountingStoragePort={dbd_port}
AccountingStoragePass={root}/munge/munge.socket
AccountingStoreFlags=job_comment
MinJobAge=600
SlurmdParameters=config_overrides
NodeName={node} NodeAddr=127.0.0.1 {hardware} State=UNKNOWN
PartitionName=main Nodes=ALL Default=YES MaxTime=INFINITE State=UP
"""


def _start_cluster(stack: contextlib.ExitStack, root: Path) -> Cluster:
    for sub in ("munge", "mysql", "log", "state", "spool"):
        (root / sub).mkdir()
    root.chmod(0o755)  # munged wants its socket's directories searchable
    env = {**os.environ, "SLURM_CONF": str(root / "slurm.conf")}

    # munged: a key of our own, on a socket of our own
    key = root / "munge" / "munge.key"
    key.write_bytes(os.urandom(1024))
    key.chmod(0o400)
    munge_socket = root / "munge" / "munge.socket"
    munged = _start(
        stack,
        [
            "munged",
            "--foreground",
            "--force",
            f"--socket={munge_socket}",
            f"--key-file={key}",
            f"--log-file={root}/log/munged.log",
            f"--pid-file={root}/munge/munged.pid",
            f"--seed-file={root}/munge/seed",
        ],
        root / "log" / "munged.log",
    )
    _wait("munged", munge_socket.exists, 20, munged, root / "log" / "munged.log")

    # MariaDB, on a port of its own, with a user for slurmdbd
    db_port, dbd_port, ctld_port, slurmd_port = _free_ports(4)
    data = root / "mysql" / "data"
    subprocess.run(
        [
            "mariadb-install-db",
            "--no-defaults",
            f"--datadir={data}",
            "--user=root",
            "--auth-root-authentication-method=socket",
            "--skip-test-db",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
        check=True,
    )
    db_socket = root / "mysql" / "mysql.sock"
    mariadb = _start(
        stack,
        [
            "mariadbd",
            "--no-defaults",
            f"--datadir={data}",
            f"--socket={db_socket}",
            f"--port={db_port}",
            "--bind-address=127.0.0.1",
            "--user=root",
            f"--pid-file={root}/mysql/mariadbd.pid",
            f"--log-error={root}/log/mariadb.log",
            "--innodb-buffer-pool-size=64M",
            "--skip-name-resolve",
        ],
        root / "log" / "mariadb.log",
    )
    _wait(
        "MariaDB",
        lambda: _succeeds(["mariadb-admin", f"--socket={db_socket}", "ping"], env),
        60,
        mariadb,
        root / "log" / "mariadb.log",
    )
    sql = "CREATE USER 'slurm'@'127.0.0.1' IDENTIFIED BY 'slurm';GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1';"
    subprocess.run(["mariadb", f"--socket={db_socket}", "-e", sql], check=True)

    node, hardware = _node()
    values = dict(
        root=root,
        db_port=db_port,
        dbd_port=dbd_port,
        ctld_port=ctld_port,
        slurmd_port=slurmd_port,
        node=node,
        hardware=hardware,
        cluster=CLUSTER,
    )
    (root / "slurm.conf").write_text(SLURM_CONF.format(**values))
    dbd_conf = root / "slurmdbd.conf"  # slurmdbd reads it beside $SLURM_CONF, only if private
    dbd_conf.write_text(SLURMDBD_CONF.format(**values))
    dbd_conf.chmod(0o600)

    _link_default_conf(stack, root / "slurm.conf")
    slurmdbd = _start(stack, ["slurmdbd", "-D"], root / "log" / "slurmdbd.log", env)
    _wait(
        "slurmdbd",
        lambda: _succeeds(["sacctmgr", "-n", "list", "cluster"], env),
        60,
        slurmdbd,
        root / "log" / "slurmdbd.log",
    )
    cluster = Cluster(root=root, env=env, node=node)
    cluster.run("sacctmgr", "-i", "add", "cluster", CLUSTER)
    cluster.run("sacctmgr", "-i", "add", "account", ACCOUNT, "Description=invrender tests", "Organization=invrender")
    cluster.run("sacctmgr", "-i", "add", "user", "root", f"Account={ACCOUNT}", f"DefaultAccount={ACCOUNT}")

    slurmctld = _start(stack, ["slurmctld", "-D", "-i"], root / "log" / "slurmctld.log", env)
    _wait("slurmctld", lambda: _succeeds(["scontrol", "ping"], env), 60, slurmctld, root / "log" / "slurmctld.log")
    slurmd = _start(stack, ["slurmd", "-D"], root / "log" / "slurmd.log", env)
    stack.callback(_cancel_all_jobs, cluster)  # unwound first: job steps would outlive slurmd
    idle = lambda: "idle" in cluster.run("sinfo", "-h", "-N", "-o", "%T", check=False)  # noqa: E731
    _wait("slurmd (node idle)", idle, 60, slurmd, root / "log" / "slurmd.log")
    return cluster


def _link_default_conf(stack: contextlib.ExitStack, conf: Path):
    DEFAULT_CONF.parent.mkdir(parents=True, exist_ok=True)
    DEFAULT_CONF.symlink_to(conf)
    stack.callback(lambda: DEFAULT_CONF.unlink() if DEFAULT_CONF.is_symlink() else None)


def _cancel_all_jobs(cluster: Cluster):
    """scancel whatever the tests left queued or running, and wait until the node is empty."""
    cluster.run("scancel", "--user=root", check=False)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and cluster.run("squeue", "-h", check=False).strip():
        time.sleep(0.5)


@pytest.fixture(scope="session")
def slurm_cluster(tmp_path_factory):
    if os.geteuid() != 0:
        _cannot_run("it starts slurmd, slurmctld, slurmdbd, munged and MariaDB, which needs root")
    _install_packages()
    if DEFAULT_CONF.exists() or DEFAULT_CONF.is_symlink():
        _cannot_run(f"{DEFAULT_CONF} exists: this machine has a SLURM config of its own, which the test leaves alone")
    with contextlib.ExitStack() as stack:
        yield _start_cluster(stack, tmp_path_factory.mktemp("slurm"))
