"""`gouge campaign --slurm` against a real single-node SLURM cluster started by this module.

The fixture starts munged, slurmctld and slurmd (Debian's munge and slurm-wlm) as root in a
temporary folder: one node (this host, its CPUs), one partition, free ports, its own munge key
and socket. Where that cannot be done (not root, binaries or dask-jobqueue missing, a daemon that
does not come up) every test here is skipped with the reason (``pytest -rs`` shows it);
``.ci/slurm-setup.sh`` installs the packages.

Tests: a small study campaign end to end through SLURM jobs; a job cancelled with ``scancel`` in
the middle of a run and a job that reaches its walltime, each followed by the next invocation,
which resumes the run from its checkpoint: nothing lost (every piece done, the run bit for bit a
serial ``gouge run``) and nothing repeated (no series row twice, finished pieces not run again).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.workflows.campaign_tasks import read_ledger

ROOT = Path(__file__).resolve().parents[2]
DAEMONS = ("munged", "slurmctld", "slurmd")
CLIENTS = ("sbatch", "squeue", "scancel", "sinfo", "scontrol")

SCENE = {
    "name": "tiny", "seed": 1,
    "packing": {"n_grains": 200, "width": 12},
    "loading": {"spring_constant": 2e-4, "velocity": 1e-4},
    "numerics": {"dt_safety": 0.3},
    "run": {"duration": 20000},
    "slips": {"start_factor": 5, "end_factor": 1.5, "merge_gap": 300},
    "output": {"series_interval": 10, "snapshot_interval": 10000, "checkpoint_interval": 2000},
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cannot_start() -> str | None:
    """Why a SLURM cluster cannot be started here, or None."""
    if os.name != "posix" or os.geteuid() != 0:
        return "starting munged, slurmctld and slurmd needs root"
    missing = [b for b in DAEMONS + CLIENTS if shutil.which(b) is None]
    if missing:
        return (f"SLURM or munge is not installed ({', '.join(missing)} missing): apt-get install slurm-wlm munge "
                "(or .ci/slurm-setup.sh)")
    try:
        import dask_jobqueue  # noqa: F401
    except ImportError:
        return "dask-jobqueue is not installed (pip install 'gouge[cluster]')"
    return None


class SlurmCluster:
    """munged + slurmctld + slurmd in the foreground, owned by this process, in ``root``."""

    def __init__(self, root: Path):
        self.root = root
        self.host = socket.gethostname().split(".")[0]
        self.cpus = len(os.sched_getaffinity(0))
        self.procs: list[subprocess.Popen] = []
        self.conf = root / "slurm.conf"
        self.env = dict(os.environ, SLURM_CONF=str(self.conf))

    def write(self):
        r = self.root
        for d in ("munge", "state", "spool", "log"):
            (r / d).mkdir(mode=0o700, exist_ok=True)
        os.chmod(r, 0o755)        # munged wants the folders of its socket reachable, its key private
        key = r / "munge" / "munge.key"
        key.write_bytes(os.urandom(1024))
        key.chmod(0o400)
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2**20 // 2
        self.conf.write_text(f"""\
ClusterName=gougetest
SlurmctldHost={self.host}(127.0.0.1)
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket={r}/munge/munge.socket
CredType=cred/munge
StateSaveLocation={r}/state
SlurmdSpoolDir={r}/spool
SlurmctldPidFile={r}/slurmctld.pid
SlurmdPidFile={r}/slurmd.pid
SlurmctldLogFile={r}/log/slurmctld.log
SlurmdLogFile={r}/log/slurmd.log
ProctrackType=proctrack/pgid
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
KillWait=5
MinJobAge=600
SchedulerType=sched/builtin
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
NodeName={self.host} NodeAddr=127.0.0.1 CPUs={self.cpus} RealMemory={memory} State=UNKNOWN
PartitionName=debug Nodes={self.host} Default=YES MaxTime=INFINITE State=UP
""")

    def _start(self, *cmd):
        log = open(self.root / "log" / f"{Path(cmd[0]).name}.out", "w")
        self.procs.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=self.env,
                                           start_new_session=True))

    def start(self, limit: float = 30.0) -> float:
        """Start the three daemons; seconds until the node is idle. RuntimeError if it is not within ``limit``."""
        self.write()
        r = self.root
        t0 = time.perf_counter()
        self._start("munged", "-F", "--force", f"--key-file={r}/munge/munge.key", f"--socket={r}/munge/munge.socket",
                    f"--pid-file={r}/munge/munged.pid", f"--seed-file={r}/munge/munged.seed",
                    f"--log-file={r}/log/munged.log")
        while not (r / "munge" / "munge.socket").exists():
            self._check_alive(t0, limit)
            time.sleep(0.05)
        self._start("slurmctld", "-D", "-i", "-f", str(self.conf))
        self._start("slurmd", "-D", "-f", str(self.conf))
        while self.run("sinfo", "-h", "-o", "%T", check=False).strip() not in ("idle", "mixed", "allocated"):
            self._check_alive(t0, limit)
            time.sleep(0.1)
        return time.perf_counter() - t0

    def _check_alive(self, t0: float, limit: float):
        dead = [p.args[0] for p in self.procs if p.poll() is not None]
        if dead or time.perf_counter() - t0 > limit:
            logs = "; ".join(f"{f.name}: {f.read_text()[-300:]}" for f in sorted((self.root / "log").glob("*")))
            raise RuntimeError(f"{', '.join(dead) or 'the node'} did not come up within {limit:.0f} s ({logs})")

    def run(self, *cmd, check=True) -> str:
        out = subprocess.run(cmd, capture_output=True, text=True, env=self.env, timeout=60)
        if check and out.returncode:
            raise RuntimeError(f"{' '.join(cmd)}: {out.stderr}")
        return out.stdout

    def jobs(self) -> list[tuple[str, str]]:
        """(job id, state) of every job in the queue."""
        return [tuple(line.split()) for line in self.run("squeue", "-h", "-o", "%i %T").splitlines() if line.strip()]

    def job_state(self, job: str) -> str:
        text = self.run("scontrol", "show", "job", job, check=False)
        return next((w.split("=", 1)[1] for w in text.split() if w.startswith("JobState=")), "")

    def cancel_all(self, limit: float = 60.0):
        self.run("scancel", "--user", "root", check=False)
        deadline = time.time() + limit
        while self.jobs() and time.time() < deadline:
            time.sleep(0.2)

    def stop(self):
        try:
            self.cancel_all()
        finally:
            for p in reversed(self.procs):
                if p.poll() is None:
                    p.terminate()
            for p in reversed(self.procs):
                try:
                    p.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


@pytest.fixture(scope="module")
def slurm(tmp_path_factory):
    """A running single-node SLURM cluster; SLURM_CONF points at it for this module."""
    reason = _cannot_start()
    if reason:
        pytest.skip(reason)
    cluster = SlurmCluster(tmp_path_factory.mktemp("slurm"))
    try:
        cluster.seconds_to_start = cluster.start()
    except (RuntimeError, OSError) as exc:
        cluster.stop()
        pytest.skip(f"a single-node SLURM cluster could not be started: {exc}")
    print(f"\nSLURM cluster up in {cluster.seconds_to_start:.2f} s ({cluster.cpus} CPUs)")
    mp = pytest.MonkeyPatch()
    mp.setenv("SLURM_CONF", str(cluster.conf))
    yield cluster
    mp.undo()
    cluster.stop()


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("campaigns")
    (path / "tiny.yaml").write_text(yaml.safe_dump(SCENE))
    return path


def write_spec(folder: Path, **spec) -> Path:
    path = folder / f"{spec['name']}.yaml"
    path.write_text(yaml.safe_dump({"base": "tiny.yaml", "out": "campaigns", **spec}, sort_keys=False))
    return path


def env(slurm: SlurmCluster | None = None) -> dict:
    base = slurm.env if slurm is not None else os.environ
    return dict(base, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
                PYTHONUNBUFFERED="1", NUMBA_NUM_THREADS="1")


def campaign_cmd(spec: Path, walltime: str = "00:30:00", cores: int = 1, memory: str = "2GB") -> list[str]:
    return [sys.executable, "-m", "gouge_cli.cli", "campaign", str(spec), "--slurm", "--slurm-cores", str(cores),
            "--slurm-memory", memory, "--slurm-walltime", walltime, "--retries", "0"]


def run_campaign(spec: Path, slurm: SlurmCluster, timeout: float = 600, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(campaign_cmd(spec, **kw), cwd=spec.parent, env=env(slurm), capture_output=True,
                          text=True, timeout=timeout)


def series(path: Path) -> dict:
    with h5py.File(path, "r") as h5:
        return {k: v[...] for k, v in h5["series"].items()}


def alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def wait_until(what, limit: float, step: float = 0.2, why: str = ""):
    deadline = time.time() + limit
    while time.time() < deadline:
        value = what()
        if value:
            return value
        time.sleep(step)
    pytest.fail(f"not within {limit:.0f} s: {why}")


def test_example_campaign_end_to_end_on_slurm(slurm, folder):
    """A 2-point study (runs, then drained + undrained forks of every kept slip) through SLURM
    jobs; a second invocation runs nothing."""
    spec = write_spec(folder, name="slurm_demo", set={"run.duration": 5000},
                      sweep={"grid": {"loading.normal_stress": [3.0e-4, 3.5e-4]}},
                      action="study", study={"permeabilities": [1.0e-3], "duration": 800})
    t0 = time.perf_counter()
    done = run_campaign(spec, slurm, cores=slurm.cpus, memory="4GB")
    seconds = time.perf_counter() - t0
    assert done.returncode == 0, done.stdout + done.stderr
    root = folder / "campaigns" / "slurm_demo"
    points = sorted(p for p in root.iterdir() if (p / "point.yaml").is_file())
    assert len(points) == 2
    ledgers = [read_ledger(f) for p in points for f in (p / "ledger").glob("*.json")]
    assert ledgers and all(r["state"] == "done" for r in ledgers)
    assert all(r.get("slurm_job") for r in ledgers), "a piece ran outside a SLURM job"
    forks = list(root.glob("*/forks/slip_*/pair.json"))
    assert len(ledgers) == 2 + len(forks)
    assert (root / "table.csv").read_text().count("\n") == 1 + 2 + len(forks)
    assert "0 failed, 0 left" in done.stdout
    again = run_campaign(spec, slurm)
    assert again.returncode == 0 and "0 pieces run" in again.stdout, again.stdout + again.stderr
    print(f"end to end: {seconds:.1f} s, {len(ledgers)} pieces")


@pytest.fixture(scope="module")
def reference(folder):
    """The disrupted campaigns' point run serially (`gouge run`, the point's own command)."""
    out = folder / "serial"
    done = subprocess.run([sys.executable, "-m", "gouge_cli.cli", "run", str(folder / "tiny.yaml"), "--set",
                           f"run.duration={DISRUPTED_DURATION}", "--out", str(out), "--quiet"],
                          env=env(), capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return series(out / "run.h5"), [e.onset_time for e in slip_catalog(out)]


DISRUPTED_DURATION = 8000


def disrupted_campaign(slurm, folder, name: str, disrupt, walltime: str) -> dict:
    """Start a 1-point run campaign; once its run has written a checkpoint in a SLURM job, call
    ``disrupt(job, pid)``; then stop the campaign (SIGINT: exit 130) and invoke it again, which
    must resume the run and finish it. Returns what was seen."""
    spec = write_spec(folder, name=name, set={"run.duration": DISRUPTED_DURATION},
                      sweep={"points": [{"loading.normal_stress": 3.0e-4}]}, action="run")
    root = folder / "campaigns" / name
    first = subprocess.Popen(campaign_cmd(spec, walltime=walltime), cwd=folder, env=env(slurm),
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        def running():
            for ledger in root.glob("*/ledger/run.json"):
                record = read_ledger(ledger) or {}
                if record.get("state") == "running" and (ledger.parent.parent / "checkpoints" / "latest.h5").is_file():
                    return ledger.parent.parent, record
            assert first.poll() is None, first.stdout.read()
            return None

        run_dir, record = wait_until(running, 300, why="the run piece wrote no checkpoint in its job")
        job, pid = record["slurm_job"], int(record["pid"])
        seen = {"job": job, "pid": pid, "disrupt": disrupt(job, pid)}
        wait_until(lambda: not alive(pid), 60, why=f"the worker {pid} of job {job} outlived it")
        first.send_signal(signal.SIGINT)
        out, _ = first.communicate(timeout=120)
        seen["first"] = (first.returncode, out)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert first.returncode == 130, out
    wait_until(lambda: not slurm.jobs(), 60, why="the stopped campaign left SLURM jobs behind")
    status = subprocess.run([sys.executable, "-m", "gouge_cli.cli", "campaign", str(spec), "--status"],
                            cwd=folder, env=env(slurm), capture_output=True, text=True, timeout=120)
    assert "interrupted" in status.stdout and "resumes" in status.stdout, status.stdout + status.stderr
    second = run_campaign(spec, slurm, walltime="00:30:00")
    assert second.returncode == 0, second.stdout + second.stderr
    assert "run: done" in second.stdout and "resumed" in second.stdout and "1 pieces run" in second.stdout
    final = read_ledger(run_dir / "ledger" / "run.json")
    assert final["state"] == "done" and final["result"]["resumed"] and final["attempts"] >= 2
    assert final["slurm_job"] != job
    seen["run_dir"] = run_dir
    return seen


def assert_nothing_lost_or_repeated(run_dir: Path, reference):
    ref_series, ref_onsets = reference
    got = series(run_dir / "run.h5")
    assert np.all(np.diff(got["time"]) > 0), "a series row was written twice"
    assert got.keys() == ref_series.keys()
    for name in got:
        assert np.array_equal(got[name], ref_series[name], equal_nan=True), name
    assert [e.onset_time for e in slip_catalog(run_dir)] == ref_onsets
    with h5py.File(run_dir / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished"


def test_scancel_mid_run_then_next_invocation_resumes(slurm, folder, reference):
    seen = disrupted_campaign(slurm, folder, "cancelled", lambda job, pid: slurm.run("scancel", job), "00:30:00")
    assert slurm.job_state(seen["job"]) == "CANCELLED"
    assert_nothing_lost_or_repeated(seen["run_dir"], reference)


def test_walltime_mid_run_then_next_invocation_resumes(slurm, folder, reference):
    """The job's worker is frozen (SIGSTOP) after its first checkpoint, as a long computation
    would be, so that the job reaches its walltime (1 minute, SLURM's smallest) at any machine
    speed; SLURM ends it (TIMEOUT) and the next invocation resumes the run."""
    t0 = time.perf_counter()

    def freeze(job, pid):
        os.kill(pid, signal.SIGSTOP)
        return wait_until(lambda: slurm.job_state(job) == "TIMEOUT", 180, step=1,
                          why=f"job {job} did not reach its walltime")

    seen = disrupted_campaign(slurm, folder, "walltime", freeze, "00:01:00")
    assert slurm.job_state(seen["job"]) == "TIMEOUT"
    assert_nothing_lost_or_repeated(seen["run_dir"], reference)
    print(f"walltime test: {time.perf_counter() - t0:.1f} s")
