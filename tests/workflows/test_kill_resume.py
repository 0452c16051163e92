"""kill -9 at random moments (compaction and checkpoint writes included), then `gouge resume`:
the final state, every series row, the slip catalog (checkpoint paths included) and the slip
checkpoints are bit for bit those of an uninterrupted run, and no temporary file is left.

The default suite kills 3 times (one in compaction, one during a checkpoint write, one at
random); `-m validation` kills 20 times. The scene (300 grains, first slip detected from
4 V_s) slips once, with its checkpoint taken from the pre-slip ring, within ~18,000 t0 (~4 s).
"""

from __future__ import annotations

import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.errors import CheckpointError
from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.io.integrity import seal
from gouge_cli.cli.main import app
from gouge_cli.io.slipcatalog import slip_catalog
from factories import scene

SCENE = scene("kill", 4, run={"duration": 14000},
              output={"series_interval": 10, "snapshot_interval": 5000, "checkpoint_interval": 1000},
              slips={"start_factor": 4, "end_factor": 1.5})
ENV = dict(os.environ, PYTHONUNBUFFERED="1", NUMBA_NUM_THREADS="1")


def _start(scene_file: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", "run", str(scene_file), "--out", str(out),
                             "--quiet"], env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def _wait_for(path: Path, proc: subprocess.Popen, limit: float = 120.0):
    deadline = time.time() + limit
    while not path.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.002)


def _phase(latest: Path) -> str | None:
    try:
        return read_checkpoint(latest).header.phase
    except (OSError, ValueError, KeyError, CheckpointError):       # (not there yet)
        return None


def slipping_scene(root: Path, tries: int = 4) -> tuple[Path, Path, float, float]:
    """SCENE, its seed raised by 0, 1, ... until an uninterrupted run slips with a ring checkpoint
    (whether 14,000 t0 of one packing slip is that packing's business: some first slip just after,
    so each try runs 1.5 times longer than the one before; the identities tested here hold for any).
    Returns (scene file, run dir, seconds from run.h5 to the end, seconds from run.h5 to the last
    compaction checkpoint seen: at most the compaction's length, which is the packing's)."""
    for k in range(tries):
        scene_file = root / f"kill{k}.yaml"
        run = {"duration": SCENE["run"]["duration"] * 1.5 ** k}
        scene_file.write_text(yaml.safe_dump(dict(SCENE, seed=SCENE["seed"] + k, run=run)))
        out = root / f"reference{k}"
        proc = _start(scene_file, out)
        _wait_for(out / "run.h5", proc)
        t0, compaction, phase = time.time(), 0.0, None
        while proc.poll() is None and phase != "loading":
            phase = _phase(out / "checkpoints" / "latest.h5")
            if phase == "compaction":
                compaction = time.time() - t0
            time.sleep(0.005)
        assert proc.wait(timeout=300) == 0, proc.stderr.read().decode()
        if any(e.checkpoint for e in slip_catalog(out)):
            return scene_file, out, time.time() - t0, compaction
    pytest.fail(f"none of {tries} packings of the kill scene slipped with a ring checkpoint")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Uninterrupted run: (scene file, run dir, seconds from run.h5 to the end, to loading)."""
    return slipping_scene(tmp_path_factory.mktemp("kill"))


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def assert_identical(ref: Path, run: Path):
    a, b = read_checkpoint(ref / "checkpoints/latest.h5"), read_checkpoint(run / "checkpoints/latest.h5")
    for name in a.state:
        assert np.array_equal(a.state[name], b.state[name]), f"final state {name}"
    with h5py.File(ref / "run.h5", "r") as ha, h5py.File(run / "run.h5", "r") as hb:
        assert sorted(ha["series"]) == sorted(hb["series"])
        for name in ha["series"]:
            assert np.array_equal(ha["series"][name][...], hb["series"][name][...], equal_nan=True), name
        assert sorted(ha["snapshots"]) == sorted(hb["snapshots"])
        assert hb.attrs["status"] == "finished"
    ca, cb = slip_catalog(ref), slip_catalog(run)
    assert len(ca) == len(cb)
    for ea, eb in zip(ca, cb):
        da, db = ea.to_dict(), eb.to_dict()
        for key in da:
            assert _same(da[key], db[key]), (ea.number, key, da[key], db[key])
        if ea.checkpoint:
            sa, sb = read_checkpoint(ref / ea.checkpoint).state, read_checkpoint(run / eb.checkpoint).state
            assert all(np.array_equal(sa[k], sb[k]) for k in sa)
    assert not [p.name for p in (run / "checkpoints").iterdir() if ".tmp" in p.name]


def kill_and_resume(reference, out: Path, kind: str, rng: random.Random) -> dict:
    """One trial: start the run, kill -9 it (kind: 'compaction', 'write' or 'random'), resume,
    compare with the reference. Returns what was hit."""
    scene_file, ref, span, compaction = reference
    proc = _start(scene_file, out)
    _wait_for(out / "run.h5", proc)
    # (compaction: within the first half of the reference's, whatever the packing's compaction length)
    delay = {"compaction": rng.uniform(0.0, 0.5) * compaction / span, "write": rng.uniform(0.0, 0.8),
             "random": rng.uniform(0.0, 0.85), "ctrl-c": rng.uniform(0.0, 0.85), "sigterm": rng.uniform(0.2, 0.85),
             "sighup": rng.uniform(0.2, 0.85)}[kind] * span
    time.sleep(delay)
    tmp_seen = False
    if kind == "write":
        deadline = time.time() + span
        ck_dir = out / "checkpoints"
        while proc.poll() is None and time.time() < deadline:
            try:
                if any(".tmp" in name for name in os.listdir(ck_dir)):
                    tmp_seen = True
                    break
            except FileNotFoundError:
                pass
    sig = {"ctrl-c": signal.SIGINT, "sigterm": signal.SIGTERM, "sighup": signal.SIGHUP}.get(kind, signal.SIGKILL)
    proc.send_signal(sig)
    proc.wait()
    with h5py.File(out / "run.h5", "r") as h5:
        if h5.attrs["status"] == "finished":     # ended (or was killed while exiting, after its file was
            assert proc.returncode in (0, -signal.SIGKILL, -sig, 130)   # closed) first: not a trial
            assert_identical(ref, out)
            return None
        assert proc.returncode in (-signal.SIGKILL, 130), proc.stderr.read().decode()
        if sig != signal.SIGKILL:               # a clean stop: said, recorded, nothing half-written
            assert proc.returncode == 130 and h5.attrs["status"] == "interrupted"
            assert "gouge resume" in proc.stderr.read().decode()
            assert not [p for p in out.rglob("*") if ".tmp" in p.name]
    latest = out / "checkpoints" / "latest.h5"
    phase = read_checkpoint(latest).header.phase if latest.exists() else "none"
    leftovers = [p.name for p in (out / "checkpoints").glob(".*tmp*")] if (out / "checkpoints").exists() else []
    result = CliRunner().invoke(app, ["resume", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert_identical(ref, out)
    return {"kind": kind, "delay": delay, "phase": phase, "tmp_seen": tmp_seen, "tmp_left": bool(leftovers)}


def trials(reference, root: Path, kinds: list[str], seed: int) -> list[dict]:
    """One killed-and-resumed trial per kind (a run that finished before the kill is drawn again)."""
    rng, hits = random.Random(seed), []
    for i, kind in enumerate(kinds):
        for attempt in range(5):
            hit = kill_and_resume(reference, root / f"k{i:02d}_{attempt}", kind, rng)
            if hit is not None:
                hits.append(hit)
                break
    return hits


def test_kill_9_then_resume_is_bitwise(reference, tmp_path):
    hits = trials(reference, tmp_path, ["compaction", "write", "random"], 17)
    assert len(hits) == 3
    assert hits[0]["phase"] in ("compaction", "none")      # killed before loading began


def test_sigterm_and_sighup_stop_cleanly_and_resume_bitwise(reference, tmp_path):
    """SIGTERM (SLURM at the wall-time limit, `timeout`, systemd) and SIGHUP stop a run as Ctrl-C
    does: exit 130, status 'interrupted', a message naming `gouge resume`, no temporary file; the
    resumed run ends in the uninterrupted run's bits."""
    hits = trials(reference, tmp_path, ["sigterm", "sighup"], 23)
    assert len(hits) == 2


@pytest.mark.validation
def test_ctrl_c_then_resume_is_bitwise(reference, tmp_path):
    """Ctrl-C (SIGINT) at random moments, compaction included: exit 130, then resume."""
    hits = trials(reference, tmp_path, ["ctrl-c"] * 4, 99)
    assert len(hits) == 4


@pytest.mark.validation
def test_kill_9_twenty_times(reference, tmp_path):
    hits = trials(reference, tmp_path, ["compaction"] * 5 + ["write"] * 5 + ["random"] * 10, 1717)
    print("\nkill-resume trials:", len(hits), "identical;",
          sum(h["phase"] in ("compaction", "none") for h in hits), "during compaction,",
          sum(h["tmp_seen"] for h in hits), "during a checkpoint write,",
          sum(h["tmp_left"] for h in hits), "left a temporary file (removed by resume)")
    assert len(hits) == 20


@pytest.mark.parametrize("where", ["before the onset", "during the slip"])
def test_resume_keeps_the_pre_slip_ring(reference, tmp_path, where):
    """A run stopped where the slip's checkpoint exists only in memory (the ring of pre-slip
    states, or the state set aside at the trigger) and resumed: the slip keeps that checkpoint."""
    scene_file, ref, _, _ = reference
    entry = next(e for e in slip_catalog(ref) if e.checkpoint)
    stop = entry.onset_time - 5.0 if where == "before the onset" else 0.5 * (entry.onset_time + entry.end_time)
    with h5py.File(ref / "run.h5", "r") as h5:
        load_start, end_time = float(h5.attrs["load_start_time"]), float(h5.attrs["end_time"])
    assert entry.checkpoint_time < stop
    out = tmp_path / "stopped"
    runner = CliRunner()
    result = runner.invoke(app, ["run", str(scene_file), "--out", str(out), "--quiet",
                                 "--set", f"run.duration={stop - load_start}"])
    assert result.exit_code == 0, result.output
    assert not (out / entry.checkpoint).exists()            # the slip was not recorded yet
    saved = read_checkpoint(out / "checkpoints" / "latest.h5")
    assert any(k.startswith("ring_") for k in saved.attached)
    with h5py.File(out / "run.h5", "r+") as h5:                 # as if it had been killed there
        h5.attrs["status"] = "running"
        h5.attrs["end_time"] = end_time
        seal(h5)                                                # the root's checksum, as the writer keeps it
    result = runner.invoke(app, ["resume", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert_identical(ref, out)
