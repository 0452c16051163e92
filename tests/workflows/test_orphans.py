"""No orphans: SIGKILL on the parent of `gouge study` (process pool) or `gouge campaign` (Dask
local cluster) in the middle of its work leaves no process of it alive after a bounded time, and
the next invocation finishes the work.

The command runs in a session of its own, so every process it started (pool workers, the
resource tracker, Dask nannies and workers) is found by its session id even after it has been
adopted by init. Zombies count as ended.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
import yaml

from gouge_cli.workflows.campaign_tasks import read_ledger
from gouge_cli.workflows.pairs import branch_status
from gouge_cli.workflows.watchdog import POLL
from slipping import slipping_run
from factories import fork_at

ROOT = Path(__file__).resolve().parents[2]
BOUND = 20.0        # seconds within which every process of the killed command must be gone
SCENE = {
    "name": "orphans", "seed": 1,
    "packing": {"n_grains": 200, "width": 12},
    "loading": {"spring_constant": 2e-4, "velocity": 1e-4},
    "numerics": {"dt_safety": 0.3, "threads": 1},
    "run": {"duration": 5000},
    "slips": {"start_factor": 5, "end_factor": 1.5, "merge_gap": 300},
    "output": {"series_interval": 10, "snapshot_interval": 10000, "checkpoint_interval": 1000},
}
ENV = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           PYTHONUNBUFFERED="1", NUMBA_NUM_THREADS="1")

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs Linux /proc to find processes")


def gouge(*args, timeout=600, **kw):
    return subprocess.run([sys.executable, "-m", "gouge_cli.cli", *map(str, args)], env=ENV, capture_output=True,
                          text=True, timeout=timeout, **kw)


def session(sid: int) -> list[int]:
    """Live (not zombie) processes of session ``sid``."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[3]) == sid and fields[0] != "Z":      # fields: state ppid pgrp session ...
            pids.append(int(stat.parent.name))
    return pids


def wait_until(what, limit: float, why: str, step: float = 0.05):
    deadline = time.time() + limit
    while time.time() < deadline:
        value = what()
        if value:
            return value
        time.sleep(step)
    pytest.fail(f"not within {limit:.0f} s: {why}")


def kill_and_count(proc: subprocess.Popen, workers: int) -> tuple[list[int], float]:
    """SIGKILL the command (the session leader) once ``workers`` more processes are in its session;
    returns those processes and the seconds until none of them is left."""
    others = wait_until(lambda: [p for p in session(proc.pid) if p != proc.pid][workers - 1:] and
                        [p for p in session(proc.pid) if p != proc.pid], 120, "the workers did not start")
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    t0 = time.perf_counter()
    deadline = t0 + BOUND
    while session(proc.pid) and time.perf_counter() < deadline:
        time.sleep(0.05)
    left = session(proc.pid)
    assert not left, f"processes outlived the killed command by {BOUND:.0f} s: {left}"
    return others, time.perf_counter() - t0


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """A loaded run with a slip kept with a checkpoint (the packing found through tests/slipping.py,
    so that it slips at every GOUGE_TEST_SEED_OFFSET)."""
    folder = tmp_path_factory.mktemp("orphans")
    _, run_dir, slips = slipping_run(SCENE, folder, slips=1, grow=2.0)   # folder/orphans.yaml: the seed it used
    return folder, run_dir, slips[0]


def test_sigkill_on_study_parent_leaves_no_worker(loaded):
    """Three branches on two pool workers: the parent is killed while the first two run (one is
    queued); the workers and the resource tracker end; `gouge study` again runs them all."""
    folder, run_dir, slip = loaded
    args = ["study", run_dir, "--perm", "1e-5", "--perm", "1e-3", "--slips", slip, "--jobs", 2, "--no-figures"]
    proc = subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", *map(str, args)], env=ENV, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_until(lambda: list((run_dir / "forks").glob("slip_*/*/run.h5")), 300, "no branch started")
        workers, seconds = kill_and_count(proc, 2)
    finally:
        if proc.poll() is None:
            proc.kill()
    print(f"study: {len(workers)} processes gone {seconds:.2f} s after SIGKILL on their parent")
    assert seconds < BOUND
    fork = fork_at(run_dir, slip).root
    assert [b for b in ("drained", "perm_1e-05", "perm_1e-03") if branch_status(fork / b) != "finished"], \
        "every branch finished before the kill: the test killed nothing"
    again = gouge(*args)
    assert again.returncode == 0, again.stdout + again.stderr
    for b in ("drained", "perm_1e-05", "perm_1e-03"):
        assert branch_status(fork / b) == "finished", b
    assert (fork / "pair.json").is_file()


def test_sigkill_on_campaign_parent_leaves_no_worker(loaded):
    """A 2-point run campaign on a local Dask cluster of two workers, killed while its runs go."""
    folder, _, _ = loaded
    spec = folder / "spec.yaml"
    spec.write_text(yaml.safe_dump({"name": "orph", "base": "orphans.yaml", "set": {"run.duration": 3000},
                                    "sweep": {"seeds": [1, 2]}}))
    cmd = [sys.executable, "-m", "gouge_cli.cli", "campaign", str(spec), "--workers", "2"]
    proc = subprocess.Popen(cmd, env=ENV, cwd=folder, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    root = folder / "campaigns" / "orph"
    try:
        wait_until(lambda: any((read_ledger(f) or {}).get("state") == "running"
                               for f in root.glob("*/ledger/run.json")), 300, "no run piece started")
        workers, seconds = kill_and_count(proc, 2)
    finally:
        if proc.poll() is None:
            proc.kill()
    print(f"campaign: {len(workers)} processes gone {seconds:.2f} s after SIGKILL on their parent")
    again = subprocess.run(cmd, env=ENV, cwd=folder, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "2 points, 2 pieces known: 2 done" in again.stdout
    for run_h5 in root.glob("*/run.h5"):
        with h5py.File(run_h5, "r") as h5:
            assert h5.attrs["status"] == "finished"


def test_follow_parent_ends_a_child_of_a_killed_parent(tmp_path):
    """The watchdog alone (no pool): a grandchild following its parent ends within POLL of the
    parent's SIGKILL; this checks the prctl signal and the polling fallback together."""
    code = ("import os, subprocess, sys, time\n"
            "child = subprocess.Popen([sys.executable, '-c', 'import os, time, sys; "
            "from gouge_cli.workflows.watchdog import follow_parent; follow_parent(int(sys.argv[1])); "
            "print(os.getpid(), flush=True); time.sleep(600)', str(os.getpid())], stdout=subprocess.PIPE, text=True)\n"
            "print(child.stdout.readline().strip(), flush=True)\n"
            "time.sleep(600)\n")
    parent = subprocess.Popen([sys.executable, "-c", code], env=ENV, stdout=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        child = int(parent.stdout.readline())
        assert child in session(parent.pid)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        t0 = time.perf_counter()
        wait_until(lambda: child not in session(parent.pid), BOUND, "the child outlived its parent")
        assert time.perf_counter() - t0 < 2 * POLL + 1.0
    finally:
        if parent.poll() is None:
            parent.kill()
