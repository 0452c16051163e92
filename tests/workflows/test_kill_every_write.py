"""A kill at every write of a run: `gouge run` under strace, SIGKILL injected at its N-th pwrite64
(every write HDF5 makes to run.h5 and to the checkpoints), then `gouge resume`. For each N the
run file opens (or is rebuilt), the resume succeeds (or says the run is complete), the final state
hash is the uninterrupted run's, and `gouge verify` finds nothing damaged.

The default suite kills at every write from the last checkpoint to the end of the close (the
closing flush and attributes, where a kill once left run.h5 unopenable) and at a spread of
earlier writes; `-m validation` at every write. Needs strace (skipped without it, or where
ptrace is not permitted)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import pytest
import yaml
from factories import scene

SCENE = scene("k", 4, run={"duration": 3000},
              output={"series_interval": 10, "snapshot_interval": 1500, "checkpoint_interval": 1000},
              slips={"start_factor": 4, "end_factor": 1.5})
ENV = dict(os.environ, PYTHONUNBUFFERED="1", NUMBA_NUM_THREADS="1")
GOUGE = [sys.executable, "-m", "gouge_cli.cli"]
STRACE = shutil.which("strace")


def _strace_works() -> bool:
    if STRACE is None:
        return False
    return subprocess.run([STRACE, "-qq", "-o", os.devnull, "true"], capture_output=True).returncode == 0


pytestmark = pytest.mark.skipif(not _strace_works(), reason="needs strace with ptrace permitted")


def _hash(run: Path) -> str:
    with h5py.File(run / "run.h5", "r") as h5:
        return str(h5.attrs["final_state_hash"])


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted run traced: (scene file, final state hash, number of pwrite64 calls, index
    of the first write after the last checkpoint was renamed into place)."""
    root = tmp_path_factory.mktemp("every_write")
    scene = root / "k.yaml"
    scene.write_text(yaml.safe_dump(SCENE))
    trace = root / "trace.txt"
    subprocess.run([STRACE, "-f", "-qq", "-o", str(trace), "-e", "trace=pwrite64,rename,renameat,renameat2",
                    *GOUGE, "run", str(scene), "--out", str(root / "ref"), "--quiet"], env=ENV, check=True,
                   capture_output=True)
    n, close_from = 0, 0
    for line in trace.read_text().splitlines():
        if "pwrite64(" in line:
            n += 1
        elif re.search(r"rename\w*\(.*checkpoints/latest\.h5", line):
            close_from = n + 1
    assert n > 50 and 0 < close_from <= n
    return scene, _hash(root / "ref"), n, close_from


def kill_at(reference, root: Path, n: int) -> str:
    """Kill `gouge run` at its n-th pwrite64, resume, check; returns what the kill left."""
    scene, ref_hash, _, _ = reference
    out = root / f"n{n:04d}"
    killed = subprocess.run([STRACE, "-f", "-qq", "-o", os.devnull, "-e", "trace=pwrite64", "-e",
                             f"inject=pwrite64:signal=SIGKILL:when={n}", *GOUGE, "run", str(scene), "--out", str(out),
                             "--quiet"], env=ENV, capture_output=True)
    status = "finished"
    if (out / "run.h5").is_file():
        try:
            with h5py.File(out / "run.h5", "r") as h5:
                status = str(h5.attrs["status"])
        except OSError:
            status = "unopenable"
    else:
        status = "no run file"
    if status != "finished":
        had_checkpoint = (out / "checkpoints" / "latest.h5").is_file()
        resumed = subprocess.run([*GOUGE, "resume", str(out), "--quiet"], env=ENV, capture_output=True, text=True)
        if resumed.returncode and not had_checkpoint and "gouge run ... --force" in resumed.stderr:
            status = "before its first checkpoint"     # nothing computed yet: started again as advised
            resumed = subprocess.run([*GOUGE, "run", str(scene), "--out", str(out), "--force", "--quiet"], env=ENV,
                                     capture_output=True, text=True)
        assert resumed.returncode == 0, (n, status, killed.returncode, resumed.stdout + resumed.stderr)
    assert _hash(out) == ref_hash, (n, status)
    verify = subprocess.run([*GOUGE, "verify", str(out)], env=ENV, capture_output=True, text=True)
    assert verify.returncode == 0, (n, status, verify.stdout + verify.stderr)
    assert not [p for p in out.rglob("*") if ".tmp" in p.name], n
    shutil.rmtree(out)
    return status


def test_kill_at_every_write_of_the_close_and_a_spread_before(reference, tmp_path):
    _, _, n, close_from = reference
    sample = sorted(set(range(close_from, n + 1)) | set(range(1, close_from, max(1, close_from // 4))))
    states = [kill_at(reference, tmp_path, k) for k in sample]
    assert "unopenable" not in states


@pytest.mark.validation
def test_kill_at_every_write(reference, tmp_path):
    _, _, n, close_from = reference
    states = [kill_at(reference, tmp_path, k) for k in range(1, n + 1)]
    counts = {s: states.count(s) for s in sorted(set(states))}
    print(f"\nkill at each of {n} writes (the close from write {close_from}): left {counts}; every resume bitwise")
