"""Where campaign pieces run: a Dask ``LocalCluster`` (default), an existing scheduler, or SLURM.

One piece ("advance this run or fork to completion") is one Dask task. Each worker process
runs ``tasks_per_worker`` tasks at a time (default 1: the numba kernels hold the GIL, so tasks
in one process would take turns) and each task runs its kernels on ``threads_per_task`` numba
threads, set through ``NUMBA_NUM_THREADS`` in the worker's environment before numba is
imported. The default local cluster has ``cores // threads_per_task`` worker processes, so every
core is busy and none is oversubscribed. Results do not depend on any of this: the force sums
have a fixed order for any thread count.
"""

from __future__ import annotations

from ..errors import ExecutorError
import contextlib
import logging
import os
import signal
import threading
from dataclasses import dataclass, field


def machine_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:       # not on Linux
        return os.cpu_count() or 1


@dataclass(frozen=True)
class ClusterOptions:
    """How to execute a campaign. ``workers=None``: cores // (threads_per_task x tasks_per_worker)
    on this machine; on SLURM, worker processes per job = cores // (same)."""

    threads_per_task: int = 1
    tasks_per_worker: int = 1
    workers: int | None = None
    scheduler: str | None = None
    slurm: bool = False
    slurm_cores: int = 16
    slurm_memory: str = "32GB"
    slurm_walltime: str = "24:00:00"
    slurm_queue: str | None = None
    slurm_account: str | None = None
    slurm_jobs: int = 1
    slurm_extra: list[str] = field(default_factory=list)
    retries: int = 3

    def check(self):
        if self.threads_per_task < 1 or self.tasks_per_worker < 1:
            raise ExecutorError("--threads and --tasks-per-worker must be at least 1")
        if self.workers is not None and self.workers < 1:
            raise ExecutorError("--workers must be at least 1")
        if self.scheduler and self.slurm:
            raise ExecutorError("give either --scheduler or --slurm, not both")
        if self.slurm and self.slurm_cores < self.threads_per_task * self.tasks_per_worker:
            raise ExecutorError(f"--slurm-cores {self.slurm_cores} is below --threads x --tasks-per-worker")
        return self


def worker_env(threads_per_task: int) -> dict[str, str]:
    """Environment of a worker process: numba threads per task, no nested BLAS/OpenMP threads."""
    return {"NUMBA_NUM_THREADS": str(threads_per_task), "OMP_NUM_THREADS": "1",
            "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def local_cluster(opts: ClusterOptions):
    """A ``LocalCluster`` of worker processes sized to this machine (no dashboard, quiet logs)."""
    from distributed import LocalCluster

    per_worker = opts.threads_per_task * opts.tasks_per_worker
    n = opts.workers or max(1, machine_cores() // per_worker)
    return LocalCluster(n_workers=n, threads_per_worker=opts.tasks_per_worker, processes=True,
                        env=worker_env(opts.threads_per_task), dashboard_address=None,
                        silence_logs=logging.ERROR)


def slurm_cluster(opts: ClusterOptions):
    """A dask-jobqueue ``SLURMCluster``: each job holds ``slurm_cores`` cores, split into worker
    processes of ``threads_per_task x tasks_per_worker`` cores; workers retire before the walltime
    (:func:`_lifetime`) so that their tasks move on (and resume from their checkpoints) elsewhere.
    :func:`open_client` keeps ``slurm_jobs`` jobs alive: a job that ends (walltime, ``scancel``,
    node failure) is replaced by a new one."""
    try:
        from dask_jobqueue import SLURMCluster
    except ImportError:
        raise ExecutorError("--slurm needs dask-jobqueue: pip install 'gouge[cluster]'") from None
    _keep_ctrl_c()
    per_worker = opts.threads_per_task * opts.tasks_per_worker
    processes = max(1, opts.slurm_cores // per_worker)
    env = worker_env(opts.threads_per_task)
    kwargs = dict(cores=processes * opts.tasks_per_worker, processes=processes, memory=opts.slurm_memory,
                  walltime=opts.slurm_walltime, queue=opts.slurm_queue, account=opts.slurm_account,
                  job_cpu=opts.slurm_cores, job_mem=opts.slurm_memory.upper().removesuffix("B"),
                  job_extra_directives=list(opts.slurm_extra),
                  job_script_prologue=[f"export {k}={v}" for k, v in env.items()],
                  worker_extra_args=_lifetime_args(opts.slurm_walltime))
    return SLURMCluster(**kwargs)


def _keep_ctrl_c():
    """dask-jobqueue's import sets SIGINT to ``sys.exit()`` (exit 0, nothing said): put Python's
    KeyboardInterrupt back, so that Ctrl-C stops a campaign with exit 130 and its jobs cancelled."""
    handler = signal.getsignal(signal.SIGINT)
    if getattr(handler, "__module__", "").startswith("dask_jobqueue") and \
            threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _lifetime_args(walltime: str) -> list[str]:
    """Dask worker options retiring a worker 5 minutes (+- 2) before the walltime; none for a
    walltime of 10 minutes or less, where SLURM's time limit itself ends the job (its pieces
    resume from their checkpoints in the next job)."""
    lifetime = _lifetime(walltime)
    return [] if lifetime is None else ["--lifetime", lifetime, "--lifetime-stagger", "2m"]


def _lifetime(walltime: str) -> str | None:
    """Walltime [[D-]HH:]MM:SS less 5 minutes, as seconds for ``--lifetime``; None for 10 minutes or less."""
    try:
        days, _, clock = walltime.rpartition("-")
        parts = [int(p) for p in clock.split(":")]
        if not 1 <= len(parts) <= 3 or min(parts) < 0:
            raise ValueError
    except ValueError:
        raise ExecutorError(f"--slurm-walltime {walltime!r}: give [[D-]HH:]MM:SS, e.g. 24:00:00") from None
    while len(parts) < 3:
        parts.insert(0, 0)
    seconds = (int(days or 0) * 24 + parts[0]) * 3600 + parts[1] * 60 + parts[2]
    return f"{seconds - 300}s" if seconds > 600 else None


def _worker_threads() -> tuple[int, int]:
    import numba

    return numba.config.NUMBA_NUM_THREADS, machine_cores()


def oversubscribed(client) -> list[str]:
    """Workers of an existing cluster whose task threads x numba threads exceed their cores (start
    them as ``NUMBA_NUM_THREADS=T dask worker ADDRESS --nthreads 1 --nworkers CORES/T``)."""
    tasks = client.nthreads()
    lines = []
    for address, (numba_threads, cores) in client.run(_worker_threads).items():
        if tasks.get(address, 1) * numba_threads > cores:
            lines.append(f"worker {address} runs {tasks.get(address, 1)} tasks x {numba_threads} numba threads on "
                         f"{cores} cores; start it as NUMBA_NUM_THREADS=T dask worker ADDRESS --nthreads 1 --nworkers CORES/T")
    return lines


@contextlib.contextmanager
def open_client(opts: ClusterOptions):
    """A ``distributed.Client`` for ``opts``; the cluster it started is closed on exit."""
    from distributed import Client

    opts.check()
    if opts.scheduler:
        try:
            client = Client(opts.scheduler, timeout="30s")
        except OSError as exc:
            raise ExecutorError(f"--scheduler {opts.scheduler}: cannot connect ({exc})") from None
        with client:
            for line in oversubscribed(client):
                print(f"warning: {line}", flush=True)
            yield client
        return
    cluster = slurm_cluster(opts) if opts.slurm else local_cluster(opts)
    try:
        if opts.slurm:      # adaptive between equal bounds: a job that ended is replaced
            cluster.adapt(minimum_jobs=opts.slurm_jobs, maximum_jobs=opts.slurm_jobs)
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()
