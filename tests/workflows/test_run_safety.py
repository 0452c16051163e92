"""Nothing a command does not own is deleted or truncated; concurrent, damaged, read-only and
full-disk cases end in one-line messages with exit 2 or 3 (issue 17)."""

from __future__ import annotations

import hashlib
import signal
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.cli.main import app
from gouge_cli.config import build_config
from gouge_cli.errors import MAX_MESSAGE
from gouge_cli.io.rundir import LOCK_NAME, holder
from gouge_cli.io.slipcatalog import slip_catalog
from test_kill_resume import ENV, slipping_scene
from factories import fork_at

runner = CliRunner()
QUICK = ["--set", "run.duration=200", "--set", "compaction.max_time=300", "--set", "compaction.min_time=100"]


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line(result, code: int, *words):
    assert result.exit_code == code, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    text = result.output.strip()
    assert "Traceback" not in text and len(text) <= MAX_MESSAGE + 100 and text.count("\n") == 0, text
    for w in words:
        assert w in text, (w, text)


def tree(root: Path) -> dict:
    """Relative path -> SHA-256 of every file (and '<dir>' for directories) under root."""
    out = {}
    for p in sorted(root.rglob("*")):
        out[str(p.relative_to(root))] = "<dir>" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture(scope="module")
def slipping(tmp_path_factory):
    """(scene file, finished run) of the kill scene, with a slip kept with a checkpoint."""
    scene_file, out, _, _ = slipping_scene(tmp_path_factory.mktemp("safety"))
    return scene_file, out


@pytest.fixture(scope="module")
def scene_file(slipping):
    return slipping[0]


@pytest.fixture(scope="module")
def finished(slipping):
    return slipping[1]


def copy_of(run: Path, target: Path) -> Path:
    shutil.copytree(run, target)
    return target


def test_out_at_a_foreign_directory_deletes_nothing(scene_file, tmp_path):
    d = tmp_path / "mine"
    for sub in ("figures", "checkpoints", "forks"):
        (d / sub).mkdir(parents=True)
        (d / sub / "precious.txt").write_text(sub)
    (d / "notes.txt").write_text("keep")
    before = tree(d)
    for force in ([], ["--force"]):
        one_line(gouge("run", scene_file, "--out", d, "--quiet", *force), 2, "not a gouge run directory")
        assert tree(d) == before


def test_existing_run_needs_force_and_force_replaces_only_its_own(finished, scene_file, tmp_path):
    d = copy_of(finished, tmp_path / "run")
    (d / "figures").mkdir()
    (d / "figures" / "old.png").write_text("x")
    (d / "my_notes.txt").write_text("keep")
    before = tree(d)
    one_line(gouge("run", scene_file, "--out", d, "--quiet"), 2, "already holds a run", "--force")
    assert tree(d) == before
    result = gouge("run", scene_file, "--out", d, "--quiet", "--force", *QUICK)
    assert result.exit_code == 0, result.output
    assert (d / "my_notes.txt").read_text() == "keep" and not (d / "figures").exists()
    # only the new run's checkpoints are left (a 200 t0 run may itself slip, from an unsettled start)
    kept = {e.checkpoint for e in slip_catalog(d) if e.checkpoint}
    assert {f"checkpoints/{p.name}" for p in (d / "checkpoints").glob("slip_*.h5")} == kept


@pytest.mark.parametrize("name", ["..", "."])
def test_dot_names_refused_and_cwd_untouched(scene_file, tmp_path, monkeypatch, name):
    work = tmp_path / "work"
    (work / "figures").mkdir(parents=True)
    (work / "figures" / "mine.png").write_text("x")
    monkeypatch.chdir(work / "figures")
    before = tree(work)
    for command in ("config", "run"):
        result = gouge(command, scene_file, "--set", f"name={name}", "--set", "packing.n_grains=300")
        assert result.exit_code == 2 and "name" in result.output, result.output
    assert tree(work) == before


def test_out_at_a_file_refused(scene_file, tmp_path):
    f = tmp_path / "file"
    f.write_text("data")
    one_line(gouge("run", scene_file, "--out", f, "--quiet"), 2, "is a file")
    assert f.read_text() == "data"


def test_stale_lock_of_a_dead_process_is_taken_over(finished, scene_file, tmp_path):
    d = copy_of(finished, tmp_path / "run")
    (d / LOCK_NAME).write_text("PID 999999999, gouge run\n")      # no process holds its flock
    assert holder(d) is None
    result = gouge("run", scene_file, "--out", d, "--quiet", "--force", *QUICK)
    assert result.exit_code == 0, result.output


def test_concurrent_commands_on_a_run_in_progress(scene_file, tmp_path):
    """Two runs into one new --out: one wins, the other is refused at once; while the winner
    runs, run --force, slips, resume and restart on it are refused and change nothing."""
    d = tmp_path / "busy"
    cmd = [sys.executable, "-m", "gouge_cli.cli", "run", str(scene_file), "--out", str(d), "--quiet"]
    procs = [subprocess.Popen(cmd, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE) for _ in range(2)]
    try:
        deadline = time.time() + 120
        while all(p.poll() is None for p in procs) and time.time() < deadline:
            time.sleep(0.01)
        loser = next(p for p in procs if p.poll() is not None)
        winner = next(p for p in procs if p is not loser)
        message = loser.stderr.read().decode()
        assert loser.returncode == 2 and "in progress" in message and "Traceback" not in message, message
        assert winner.poll() is None, "the winner should still be running"
        while not (d / "checkpoints" / "latest.h5").exists() and winner.poll() is None:
            time.sleep(0.005)
        one_line(gouge("run", scene_file, "--out", d, "--force", "--quiet"), 2, "in progress", "PID")
        one_line(gouge("slips", d), 2, "in progress")
        one_line(gouge("resume", d, "--quiet"), 2, "in progress")
        one_line(gouge("restart", d, "--slip", 1), 2, "in progress")
        assert winner.wait(timeout=300) == 0, winner.stderr.read().decode()
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()
    with h5py.File(d / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished"
    listed = gouge("slips", d, "--json")
    assert listed.exit_code == 0 and '"number": 1' in listed.output


def test_sigterm_stops_a_restart_cleanly(finished, tmp_path):
    """SIGTERM to `gouge restart` while a branch runs: exit 130, one line naming the command that
    finishes the fork, no temporary file; that command then finishes it."""
    d = copy_of(finished, tmp_path / "run")
    n = next(e.number for e in slip_catalog(d) if e.checkpoint)
    fork = fork_at(d, n).root
    args = ["restart", str(d), "--slip", str(n), "--perm", "1e-3", "--duration", "3000"]
    proc = subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", *args], env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
    deadline = time.time() + 300
    while proc.poll() is None and time.time() < deadline and not list(fork.glob("drained/.*tmp*")):
        time.sleep(0.01)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    output = proc.communicate(timeout=120)[0].decode()
    if proc.returncode == 0:
        pytest.skip("the fork finished before the signal (a slow start is this machine's, not the test's)")
    assert proc.returncode == 130, output
    assert "interrupted" in output and "gouge restart" in output and "Traceback" not in output
    assert not [p for p in fork.rglob("*") if ".tmp" in p.name]
    result = gouge(*args[:-2], "--duration", "3000", "--quiet")
    assert result.exit_code == 0, result.output
    with h5py.File(fork / "perm_1e-03" / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "finished"


def test_drained_only_fork_without_perm(finished, tmp_path):
    d = copy_of(finished, tmp_path / "run")
    n = next(e.number for e in slip_catalog(d) if e.checkpoint)
    result = gouge("restart", d, "--slip", n, "--quiet")
    assert result.exit_code == 0, result.output
    fork = fork_at(d, n).root
    assert list(fork.iterdir()) != [] and (fork / "drained/run.h5").is_file()
    assert not list(fork.glob("perm_*"))


def test_damaged_run_file_gives_one_line(finished, tmp_path):
    for kind in ("truncated", "flipped"):
        d = copy_of(finished, tmp_path / kind)
        h5 = d / "run.h5"
        data = bytearray(h5.read_bytes())
        if kind == "truncated":
            h5.write_bytes(bytes(data[: len(data) // 3]))
        else:
            data[0:8] = b"\x00GARBAGE"           # the superblock signature
            h5.write_bytes(bytes(data))
        one_line(gouge("slips", d), 2, "run.h5")
        one_line(gouge("restart", d, "--slip", 1), 2, "run.h5")
        with h5py.File(d / "checkpoints/latest.h5", "r"):
            pass
        one_line(gouge("resume", d, "--quiet"), 2, "run.h5")


def test_damaged_snapshot_chunk_gives_one_line_plot(finished, tmp_path):
    d = copy_of(finished, tmp_path / "run")
    with h5py.File(d / "run.h5", "r") as h5:
        ds = h5["snapshots"][sorted(h5["snapshots"])[-1]]["x"]
        info = ds.id.get_chunk_info(0)
    with open(d / "run.h5", "r+b") as f:
        f.seek(info.byte_offset)
        f.write(b"\xff" * info.size)
    result = gouge("plot", d)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and str(d) in result.output and len(result.output) < 600


def test_analyze_does_not_need_to_write_run_h5(finished, tmp_path):
    d = copy_of(finished, tmp_path / "run")
    with h5py.File(d / "run.h5", "r"):           # run.h5 open elsewhere, read-only: cannot be written
        result = gouge("analyze", d)
    assert result.exit_code == 0, result.output
    assert (d / "analysis" / "catalog.csv").is_file() and "/analysis not written into" in result.output


@pytest.fixture
def read_only_copy(finished, tmp_path):
    """A copy of the run on a read-only file system (root: a tmpfs remounted read-only),
    or with write permission removed (other users)."""
    if os.geteuid() != 0:
        d = copy_of(finished, tmp_path / "ro")
        for p in [d, *d.rglob("*")]:
            p.chmod(p.stat().st_mode & 0o555)
        yield d
        for p in [d, *d.rglob("*")]:
            p.chmod(p.stat().st_mode | 0o200)
        return
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=20m", "tmpfs", str(mnt)]).returncode != 0:
        pytest.skip("cannot mount a tmpfs")
    try:
        d = copy_of(finished, mnt / "ro")
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
        yield d
    finally:
        subprocess.run(["umount", str(mnt)])


def test_read_only_run_directory_gives_one_line(read_only_copy):
    d = read_only_copy
    before = tree(d)
    one_line(gouge("restart", d, "--slip", 1), 2, str(d))
    one_line(gouge("resume", d, "--quiet"), 0, str(d), "finished already: nothing to resume")     # nothing to write
    result = gouge("analyze", d)
    assert result.exit_code == 2 and "Traceback" not in result.output and str(d) in result.output, result.output
    one_line(gouge("plot", d), 2, str(d))
    assert tree(d) == before


def test_tiny_wall_mass_refused_before_writing(scene_file, tmp_path):
    out = tmp_path / "never"
    one_line(gouge("run", scene_file, "--out", out, "--set", "loading.wall_mass=1e-12"), 2, "loading.wall_mass")
    assert not out.exists()


def test_guard_names_the_damping(scene_file):
    """A runaway overlap at a step close to the dashpot's own limit blames material.damping."""
    from gouge_cli.driver.guards import OverlapGuard, Scan
    from gouge_cli.driver.simulation import Simulation
    from gouge_cli.errors import PhysicsError

    data = dict(yaml.safe_load(scene_file.read_text()), material={"damping": 10.0}, numerics={"dt_safety": 0.15})
    sim = Simulation(build_config(data))
    scan = Scan.of(sim)
    scan.overlap = 0.9
    with pytest.raises(PhysicsError, match="lower material.damping"):
        OverlapGuard()(sim, scan)


@pytest.mark.skipif(os.geteuid() != 0, reason="needs a small tmpfs (root)")
def test_full_disk_stops_cleanly_and_resumes(scene_file, tmp_path):
    mnt = tmp_path / "small"
    mnt.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=5m", "tmpfs", str(mnt)]).returncode != 0:
        pytest.skip("cannot mount a tmpfs")
    try:
        d = mnt / "run"
        proc = subprocess.run([sys.executable, "-m", "gouge_cli.cli", "run", str(scene_file), "--out", str(d),
                               "--quiet"], env=ENV, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 3, proc.stderr
        assert "no space left on device" in proc.stderr and str(d) in proc.stderr and "Traceback" not in proc.stderr
        ck = read_checkpoint(d / "checkpoints" / "latest.h5")          # the last good checkpoint is valid
        with h5py.File(d / "run.h5", "r") as h5:
            assert "No space left" in h5.attrs["status"] and h5["series/time"][-1] <= ck.time + 1e-9 + 1e3
        subprocess.run(["mount", "-o", "remount,size=60m", str(mnt)], check=True)
        result = gouge("resume", d, "--quiet")
        assert result.exit_code == 0, result.output
    finally:
        subprocess.run(["umount", str(mnt)])
