"""A single-node SLURM cluster on loopback for the opt-in SLURM test (tests/test_pipeline.py).

Debian's packages (slurmctld, slurmd, munge, slurm-client), installed when missing; the munge key,
munged's socket (`AuthInfo=socket=`), state, spool and logs live in one folder of the test's own.
slurm.conf goes where every SLURM command looks for it, /etc/slurm/slurm.conf: SLURM_CONF would not
do, since the executor's job step drops SLURM_* variables before its inner `srun`. The test writes
it only where none exists (or one it left), and removes it at the end. The node is this machine
with its real CPUs and memory (`slurmd -C`).

Accounting without a database: `AccountingStorageType=accounting_storage/none` leaves plain `sacct`
with "Slurm accounting storage is disabled"; slurmdbd would need a MariaDB server. Job completion
records (`JobCompType=jobcomp/filetxt`) are the simplest thing `sacct` can read: `sacct --completion`
lists every finished job from that file. Snakemake's executor then follows its jobs with `squeue`
(`--slurm-status-command squeue`), reliable because `MinJobAge` keeps finished jobs for an hour.
"""

import io
import os
import shutil
import signal
import socket
import subprocess
import time
from pathlib import Path

import pandas as pd

PACKAGES = ["slurmctld", "slurmd", "munge", "slurm-client"]
CONF = Path("/etc/slurm/slurm.conf")
MARK = "# a test cluster of condmon's tests/slurm_cluster.py, removed when the test ends\n"
SACCT_FIELDS = "JobID,JobName,Partition,State,Start,End,Elapsed,NCPUS,NodeList,ExitCode"


def installed() -> bool:
    return all(shutil.which(name) for name in ("slurmctld", "slurmd", "munged", "sbatch", "sacct"))


def can_install_packages() -> bool:
    """The daemons are there, or this is root on a machine with apt-get to install them."""
    return installed() or (os.geteuid() == 0 and shutil.which("apt-get") is not None)


def machine_has_its_own_slurm() -> bool:
    return CONF.exists() and not CONF.read_text().startswith(MARK)


def install_packages():
    if installed():
        return
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    for command in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", *PACKAGES]):
        result = subprocess.run(command, env=env, capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed:\n{result.stderr[-3000:]}")


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class SlurmCluster:
    """`with SlurmCluster(folder) as cluster:` starts munged, slurmctld and slurmd, waits for the
    node to be idle, and stops the three daemons (by their pid files) on leaving."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.conf = CONF
        self.env = dict(os.environ)
        self.env.pop("SLURM_CONF", None)
        self.pid_files = []

    def __enter__(self):
        install_packages()
        try:
            self._start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc):
        self.stop()

    def _start(self):
        run, key, log = self.root / "run", self.root / "key", self.root / "log"
        for folder, mode in (
            (run, 0o755),
            (key, 0o700),
            (log, 0o755),
            (self.root / "state", 0o755),
            (self.root / "spool", 0o755),
        ):
            folder.mkdir(parents=True, exist_ok=True)
            folder.chmod(
                mode
            )  # munged refuses a socket folder others cannot enter, a key others can read
        self.root.chmod(0o755)
        self._run(["mungekey", "--create", f"--keyfile={key / 'munge.key'}"])
        self.socket = run / "munge.socket"
        self._daemon(
            run / "munged.pid",
            [
                "munged",
                f"--key-file={key / 'munge.key'}",
                f"--socket={self.socket}",
                f"--pid-file={run / 'munged.pid'}",
                f"--log-file={log / 'munged.log'}",
                f"--seed-file={key / 'munged.seed'}",
            ],
        )
        if self.conf.exists() and not self.conf.read_text().startswith(MARK):
            raise RuntimeError(
                f"{self.conf} belongs to this machine's own SLURM; the test will not replace it"
            )
        self.conf.parent.mkdir(parents=True, exist_ok=True)
        self.conf.write_text(MARK + self.slurm_conf())
        self._daemon(run / "slurmctld.pid", ["slurmctld"])
        self._daemon(run / "slurmd.pid", ["slurmd"])
        self._wait_for_idle_node()

    def slurm_conf(self) -> str:
        host = socket.gethostname().split(".")[
            0
        ]  # slurmctld only runs on the host SlurmctldHost names
        node = self._run(["slurmd", "-C"]).splitlines()[
            0
        ]  # "NodeName=<host> CPUs=... RealMemory=..."
        assert node.startswith(f"NodeName={host} "), node
        root = self.root
        return f"""\
ClusterName=condmontest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={free_port()}
SlurmdPort={free_port()}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={self.socket}
CredType=cred/munge
StateSaveLocation={root / "state"}
SlurmdSpoolDir={root / "spool"}
SlurmctldPidFile={root / "run" / "slurmctld.pid"}
SlurmdPidFile={root / "run" / "slurmd.pid"}
SlurmctldLogFile={root / "log" / "slurmctld.log"}
SlurmdLogFile={root / "log" / "slurmd.log"}
# no cgroups in a container: processes tracked through /proc, no task binding
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/linux
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
# finished jobs stay visible to squeue for an hour (the executor's status queries)
MinJobAge=3600
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc={root / "log" / "jobcomp.txt"}
{node} NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=main Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""

    def node(self) -> dict:
        """The node's CPUs and memory (MB) as slurm.conf declares them."""
        line = next(
            line for line in self.conf.read_text().splitlines() if line.startswith("NodeName=")
        )
        fields = dict(item.split("=", 1) for item in line.split())
        return {"cpus": int(fields["CPUs"]), "mem_mb": int(fields["RealMemory"])}

    def sacct(self) -> pd.DataFrame:
        """Every finished job, from the job completion records."""
        text = self._run(["sacct", "--completion", "--parsable2", f"--format={SACCT_FIELDS}"])
        return pd.read_csv(io.StringIO(text), sep="|", dtype=str)

    def sacct_text(self) -> str:
        return self._run(["sacct", "--completion", f"--format={SACCT_FIELDS}"])

    def stop(self):
        for pid_file in reversed(self.pid_files):
            if pid_file.exists():
                pid = int(pid_file.read_text().split()[0])
                try:
                    os.kill(pid, signal.SIGTERM)
                except ProcessLookupError:
                    continue
                deadline = time.monotonic() + 30
                while _alive(pid) and time.monotonic() < deadline:
                    time.sleep(0.2)
        self.pid_files = []
        if self.conf.exists() and self.conf.read_text().startswith(MARK):
            self.conf.unlink()

    def _daemon(self, pid_file: Path, command: list):
        self._run(command)  # each daemon forks into the background and writes its pid file
        deadline = time.monotonic() + 30
        while not (pid_file.exists() and pid_file.read_text().strip()):
            if time.monotonic() > deadline:
                raise RuntimeError(
                    f"{command[0]} wrote no pid file {pid_file}; see {self.root / 'log'}"
                )
            time.sleep(0.2)
        self.pid_files.append(pid_file)

    def _wait_for_idle_node(self, timeout=60):
        deadline = time.monotonic() + timeout
        state = ""
        while time.monotonic() < deadline:
            result = subprocess.run(
                ["sinfo", "--noheader", "--format=%t"], env=self.env, capture_output=True, text=True
            )
            state = result.stdout.strip() or result.stderr.strip()
            if state == "idle":
                return
            time.sleep(0.5)
        raise RuntimeError(
            f"the SLURM node never became idle (sinfo: {state!r}); see {self.root / 'log'}"
        )

    def _run(self, command: list) -> str:
        result = subprocess.run(command, env=self.env, capture_output=True, text=True)
        if result.returncode != 0:
            raise RuntimeError(
                f"{' '.join(command)} failed ({result.returncode}): {result.stderr.strip()}; "
                f"logs in {self.root / 'log'}"
            )
        return result.stdout


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True
