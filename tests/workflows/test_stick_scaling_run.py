"""A loading run with stick scaling: every slip at true inertia (rolled back to a pre-slip state),
a drained fork that retraces the run's slip bit for bit, and a run stopped in the middle of a
recomputed slip that resumes to exactly the uninterrupted run.

The scene (300 grains, lambda = 16) is raised seed by seed until a run has a rollback (whether a
given packing slips within 36,000 t0 is its business; the identities hold for any)."""

from __future__ import annotations

import json
from contextlib import contextmanager

import h5py
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from gouge_cli.io.checkpoint import read_checkpoint
from gouge_cli.cli.main import app
from gouge_cli.driver import phases
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.workflows.fork import ForkRequest, run_fork
from gouge_cli.driver.stick_scaling import StickScaling
from factories import branch_at, scene

SCENE = scene("scaled", 4, numerics={"stick_scaling": 16, "threads": 1}, run={"duration": 36000},
              output={"series_interval": 10, "snapshot_interval": 20000, "checkpoint_interval": 2000},
              slips={"start_factor": 4, "end_factor": 1.5})
runner = CliRunner()


def gouge(*args):
    return runner.invoke(app, [str(a) for a in args])


def series(path):
    with h5py.File(path, "r") as h5:
        return {k: v[...] for k, v in h5["series"].items()}


def counts(run_dir):
    with h5py.File(run_dir / "run.h5", "r") as h5:
        return json.loads(h5.attrs["stick_scaling_counts"])


@pytest.fixture(scope="module")
def scaled_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("scaled")
    for k in range(3):
        scene = dict(SCENE, seed=SCENE["seed"] + k)
        path = root / f"scene{k}.yaml"
        path.write_text(yaml.safe_dump(scene))
        out = root / f"run{k}"
        result = gouge("run", path, "--out", out, "--quiet")
        assert result.exit_code == 0, result.output
        if counts(out)["rollbacks"] >= 1 and any(e.checkpoint for e in slip_catalog(out)):
            return path, out, scene
    pytest.fail("no seed gave a rolled-back slip with a checkpoint")


def test_every_slip_is_computed_at_true_inertia(scaled_run):
    _, out, _ = scaled_run
    s = series(out / "run.h5")
    assert np.all(np.diff(s["time"]) > 0)                   # rolled-back rows were dropped, none twice
    lam = s["stick_scaling"]
    assert np.nanmax(lam) == 16.0 and np.nanmin(lam) == 1.0
    c = counts(out)
    assert c["steps_discarded"] > 0 and c["steps_true"] > 0 and c["steps_scaled"] > 0
    for e in slip_catalog(out):
        inside = (s["time"] >= e.onset_time - 10.0) & (s["time"] <= e.end_time + 10.0)
        assert np.all(lam[inside] == 1.0), e.number
        if e.checkpoint:     # from the pre-slip checkpoint on, the run is at true inertia
            assert e.checkpoint_time < e.onset_time
            after = (s["time"] > e.checkpoint_time) & (s["time"] <= e.end_time)
            assert np.all(lam[after] == 1.0), e.number
    hi = SCENE["slips"]["start_factor"] * SCENE["loading"]["velocity"]
    assert np.all(s["wall_vx"][lam > 1.0] < hi)            # no scaled row is past a trigger
    assert np.all(np.isfinite(s["inertial_number"][1:]))


def test_drained_fork_retraces_the_scaled_runs_slip(scaled_run):
    _, out, _ = scaled_run
    entry = next(e for e in slip_catalog(out) if e.checkpoint)
    ck = read_checkpoint(out / entry.checkpoint)
    assert ck.config.numerics.stick_scaling == 16.0
    summary = run_fork(ForkRequest(out, entry.number), quiet=True)
    drained = summary.branches["drained"]
    assert drained.first_slip is not None
    original = series(out / "run.h5")
    branch = branch_at(out, entry.number).run_file
    with h5py.File(branch, "r") as h5:
        assert yaml.safe_load(h5.attrs["config"])["numerics"]["stick_scaling"] == 1.0
    fork = series(branch)
    idx = np.searchsorted(original["time"], fork["time"][1:])
    assert np.array_equal(original["time"][idx], fork["time"][1:])
    for name in ("wall_x", "wall_vx", "tau_over_sigma", "porosity", "kinetic_energy"):
        assert np.array_equal(original[name][idx], fork[name][1:]), name
    with h5py.File(out / "run.h5", "r") as h5:          # restart reports times since loading began
        origin = float(h5["series/time"][0] - h5["series/load_time"][0])
    assert drained.first_slip.onset_time == pytest.approx(entry.onset_time - origin, abs=1e-9)


def test_stop_inside_a_recomputed_slip_then_resume_is_bitwise(scaled_run, tmp_path, monkeypatch):
    """Ctrl-C half-way through the first recomputed slip (simulated in-process: the interrupt flag
    is raised at the first series row past mid-slip at true inertia after a rollback; latest.h5 is
    written where it stops, as a kill -9 would find it there or earlier), then `gouge resume`."""
    path, out, scene = scaled_run
    entry = next(e for e in slip_catalog(out))
    t_mid = 0.5 * (entry.onset_time + entry.end_time)
    flag = {"set": False}
    after_row = StickScaling.after_row

    def spy(self, sim, row, *args):
        back = after_row(self, sim, row, *args)
        if self.lam == 1.0 and self.onset_scaled is not None and sim.state.time >= t_mid:
            flag["set"] = True
        return back

    @contextmanager
    def ctrl_c():
        yield lambda: flag["set"]

    monkeypatch.setattr(StickScaling, "after_row", spy)
    monkeypatch.setattr(phases, "deferred_interrupt", ctrl_c)
    cut = tmp_path / "cut"
    gouge("run", path, "--out", cut, "--quiet")
    monkeypatch.undo()
    with h5py.File(cut / "run.h5", "r") as h5:
        assert h5.attrs["status"] == "interrupted"
    ck = read_checkpoint(cut / "checkpoints" / "latest.h5")
    state = ck.states["stick_scaling"]
    assert state["lam"] == 1.0 and state["onset_scaled"] is not None      # inside a recomputation
    assert entry.onset_time < ck.time < entry.end_time
    result = gouge("resume", cut, "--quiet")
    assert result.exit_code == 0, result.output
    a = read_checkpoint(out / "checkpoints" / "latest.h5")
    b = read_checkpoint(cut / "checkpoints" / "latest.h5")
    for name in a.state:
        assert np.array_equal(a.state[name], b.state[name]), name
    assert a.states["stick_scaling"] == b.states["stick_scaling"]
    sa, sb = series(out / "run.h5"), series(cut / "run.h5")
    for name in ("time", "wall_vx", "tau_over_sigma", "stick_scaling", "inertial_number"):
        assert np.array_equal(sa[name], sb[name], equal_nan=True), name
    ca, cb = slip_catalog(out), slip_catalog(cut)
    assert [e.onset_time for e in ca] == [e.onset_time for e in cb]
    assert np.array_equal([e.checkpoint_time for e in ca], [e.checkpoint_time for e in cb],
                          equal_nan=True)                 # (NaN: a slip kept without a checkpoint)


@pytest.mark.validation
def test_kill_9_inside_a_recomputed_slip_then_resume_is_bitwise(scaled_run, tmp_path):
    """A real kill -9 of `gouge run` (a subprocess) as soon as latest.h5 (written every 100 t0)
    shows a true-inertia recomputation in progress, then `gouge resume`: bit for bit the
    uninterrupted run."""
    import os
    import signal
    import subprocess
    import sys
    import time

    path, out, scene = scaled_run
    dense = dict(scene, output=dict(scene["output"], checkpoint_interval=100))
    dense_path = tmp_path / "dense.yaml"
    dense_path.write_text(yaml.safe_dump(dense))
    straight = tmp_path / "straight"
    assert gouge("run", dense_path, "--out", straight, "--quiet").exit_code == 0
    cut = tmp_path / "cut"
    env = dict(os.environ, PYTHONUNBUFFERED="1", NUMBA_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "gouge_cli.cli", "run", str(dense_path), "--out", str(cut),
                             "--quiet"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    latest = cut / "checkpoints" / "latest.h5"
    caught = False
    try:
        deadline = time.time() + 300
        while time.time() < deadline and proc.poll() is None:
            if latest.exists():
                try:
                    state = read_checkpoint(latest).states.get("stick_scaling", {})
                except Exception:           # being replaced just now
                    state = {}
                if state.get("lam") == 1.0 and state.get("onset_scaled") is not None:
                    proc.send_signal(signal.SIGSTOP)
                    caught = True
                    break
            time.sleep(0.005)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert caught, "the run finished before a recomputation could be caught"
    result = gouge("resume", cut, "--quiet")
    assert result.exit_code == 0, result.output
    a = read_checkpoint(straight / "checkpoints" / "latest.h5")
    b = read_checkpoint(latest)
    for name in a.state:
        assert np.array_equal(a.state[name], b.state[name]), name
    assert a.states["stick_scaling"] == b.states["stick_scaling"]
    sa, sb = series(straight / "run.h5"), series(cut / "run.h5")
    for name in ("time", "wall_vx", "tau_over_sigma", "stick_scaling"):
        assert np.array_equal(sa[name], sb[name], equal_nan=True), name
    assert [e.onset_time for e in slip_catalog(straight)] == [e.onset_time for e in slip_catalog(cut)]
