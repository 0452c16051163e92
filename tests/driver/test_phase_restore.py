"""Phase.restore (driver.phase), the one code that puts a saved state back, from each kind of
checkpoint, bit for bit (atol = 0) against the uninterrupted run:

* latest.h5 written while compacting (a Ctrl-C on a check) and while loading (a stop before the
  first slip, its pre-slip state still in the ring), resumed; and the same two written in the flat
  extra of older files (io.checkpoint.split_extra maps them, compaction's legacy start included);
* a ring state put back as stick scaling's rollback does (that state alone in the ring): the
  callbacks as the recorder's former rewind_to left them, and the run from there the same;
* a slip checkpoint: a fork's start (arrays only), whose drained branch retraces the run.

The scene slips once within about 20,000 t0 with its checkpoint taken from the ring (the kill
test's scene, tests/workflows/test_kill_resume.py)."""

from __future__ import annotations

import json
import math
import shutil
from contextlib import contextmanager
from dataclasses import replace

import h5py
import numpy as np
import pytest

from gouge_cli.config import load_config
from gouge_cli.driver import phases
from gouge_cli.driver.compaction import Settling
from gouge_cli.driver.guards import Guards
from gouge_cli.driver.phase import Phase
from gouge_cli.driver.phases import SeriesWriter, load_phase
from gouge_cli.driver.simulation import Simulation
from gouge_cli.driver.slips import SlipRecorder, ring_attachments
from gouge_cli.driver.stick_scaling import TrueInertia
from gouge_cli.io.checkpoint import DIGEST_PREFIX, LEGACY_START, SETTLING, SLIP_RECORDER, read_checkpoint
from gouge_cli.io.integrity import content_digest
from gouge_cli.io.layout import RunLayout
from gouge_cli.io.runwriter import RunFile
from gouge_cli.io.slipcatalog import slip_catalog
from gouge_cli.workflows.fork import ForkRequest, run_fork
from gouge_cli.workflows.run import resume_run, run_scene
from slipping import slipping_run

SCENE = {
    "name": "restore",
    "seed": 4,
    "packing": {"n_grains": 300, "width": 15},
    "loading": {"spring_constant": 2e-4, "velocity": 4e-5},
    "numerics": {"dt_safety": 0.3, "threads": 1},
    "run": {"duration": 14000},
    "output": {"series_interval": 10, "snapshot_interval": 5000, "checkpoint_interval": 1000},
    "slips": {"start_factor": 4, "end_factor": 1.5},
}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """(config file, uninterrupted run dir, its first slip with a checkpoint)."""
    config, out, numbers = slipping_run(SCENE, tmp_path_factory.mktemp("restore"), slips=1, grow=1.5)
    return config, out, next(e for e in slip_catalog(out) if e.number == numbers[0])


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def assert_identical(ref, run):
    """Final latest.h5 (arrays, callback states, ring), every series column, the snapshots and the
    catalog (checkpoint times included) of `run` are those of `ref`, bit for bit."""
    a, b = read_checkpoint(RunLayout(ref).latest), read_checkpoint(RunLayout(run).latest)
    for name in a.state:
        assert np.array_equal(a.state[name], b.state[name]), name
    assert _same(a.states, b.states) and a.header == b.header
    assert [c.time for c in a.attached.values()] == [c.time for c in b.attached.values()]
    with h5py.File(RunLayout(ref).run_file, "r") as ha, h5py.File(RunLayout(run).run_file, "r") as hb:
        assert hb.attrs["status"] == "finished"
        assert sorted(ha["series"]) == sorted(hb["series"]) and sorted(ha["snapshots"]) == sorted(hb["snapshots"])
        for name in ha["series"]:
            assert np.array_equal(ha["series"][name][...], hb["series"][name][...], equal_nan=True), name
    ca, cb = slip_catalog(ref), slip_catalog(run)
    assert len(ca) == len(cb) and all(_same(x.to_dict(), y.to_dict()) for x, y in zip(ca, cb))


def _to_legacy(path):
    """Rewrite checkpoint `path` (and its attached states) with the flat extra of older files:
    header fields and callback states side by side, no recorded-slips field, compaction's start
    under LEGACY_START; its checksum stamped again."""
    def flat(extra: dict) -> dict:
        states = extra.pop("states")
        extra.pop("slips", None)
        if SETTLING in states:
            extra[LEGACY_START] = states.pop(SETTLING)["start"]
        return {**extra, **states}

    with h5py.File(path, "r+") as h5:
        h5.attrs["extra"] = json.dumps(flat(json.loads(h5.attrs["extra"])))
        for child in (h5["attached"].values() if "attached" in h5 else []):
            child.attrs["extra"] = json.dumps(flat(json.loads(child.attrs["extra"])))
        h5.attrs["checksum"] = DIGEST_PREFIX + content_digest(h5)


def _cut_in_compaction(config_file, out, monkeypatch):
    """The run stopped by a Ctrl-C on compaction's second check (latest.h5 saved there)."""
    act, calls = Settling.act, []

    def interrupted(self, sim):
        calls.append(sim.state.step)
        if len(calls) == 2:
            raise KeyboardInterrupt
        act(self, sim)

    monkeypatch.setattr(Settling, "act", interrupted)
    assert run_scene(load_config(config_file), out, quiet=True).status == "interrupted"
    monkeypatch.undo()
    assert read_checkpoint(RunLayout(out).latest).header.phase == "compaction"


def _cut_in_loading(config_file, out, t_cut, monkeypatch):
    """The run stopped (as by Ctrl-C) at the first series row at or after t_cut [t0]."""
    flag = {"set": False}
    act = SeriesWriter.act

    def spy(self, sim):
        act(self, sim)
        flag["set"] = flag["set"] or sim.state.time >= t_cut

    @contextmanager
    def ctrl_c():
        yield lambda: flag["set"]

    monkeypatch.setattr(SeriesWriter, "act", spy)
    monkeypatch.setattr(phases, "deferred_interrupt", ctrl_c)
    assert run_scene(load_config(config_file), out, quiet=True).status == "interrupted"
    monkeypatch.undo()


@pytest.mark.parametrize("legacy", [False, True], ids=["current", "legacy extra"])
def test_resume_from_latest_while_compacting(reference, tmp_path, monkeypatch, legacy):
    config_file, ref, _ = reference
    cut = tmp_path / "cut"
    _cut_in_compaction(config_file, cut, monkeypatch)
    if legacy:
        _to_legacy(RunLayout(cut).latest)
        assert read_checkpoint(RunLayout(cut).latest).states[SETTLING]["start"][1] == 0
    assert resume_run(cut, quiet=True).status == "finished"
    assert_identical(ref, cut)


@pytest.fixture(scope="module")
def cut_before_slip(reference, tmp_path_factory):
    """The run stopped between the first slip's pre-slip state and its onset: latest.h5 there
    holds that state in its attached ring. (run dir, that ring state's key)."""
    config_file, _, entry = reference
    out = tmp_path_factory.mktemp("cut") / "loading"
    with pytest.MonkeyPatch.context() as monkeypatch:
        _cut_in_loading(config_file, out, 0.5 * (entry.checkpoint_time + entry.onset_time), monkeypatch)
    ck = read_checkpoint(RunLayout(out).latest)
    assert ck.header.phase == "loading" and ck.time < entry.onset_time
    key = next(k for k, c in ck.attached.items() if c.time == entry.checkpoint_time)
    return out, key


@pytest.mark.parametrize("legacy", [False, True], ids=["current", "legacy extra"])
def test_resume_from_latest_while_loading(reference, cut_before_slip, tmp_path, legacy):
    _, ref, _ = reference
    cut = tmp_path / "cut"
    shutil.copytree(cut_before_slip[0], cut)
    if legacy:
        _to_legacy(RunLayout(cut).latest)
        ck = read_checkpoint(RunLayout(cut).latest)
        assert ck.header.slips == ck.states[SLIP_RECORDER]["count"] and ck.header.series_tail is not None
    assert resume_run(cut, quiet=True).status == "finished"
    assert_identical(ref, cut)


def test_ring_state_restores_as_the_rollback_did(reference, cut_before_slip, tmp_path):
    """Phase.restore of a ring state with that state alone attached (stick scaling's rollback):
    the arrays, the guards' state kept with it, the recorder as SlipRecorder.rewind_to left it
    (its ring_state, no pending state or Deborah samples, the ring holding that state alone), the
    run file cut back to it; and the run from there the uninterrupted run."""
    _, ref, entry = reference
    cut = tmp_path / "cut"
    shutil.copytree(cut_before_slip[0], cut)
    latest = read_checkpoint(RunLayout(cut).latest)
    ring = latest.attached[cut_before_slip[1]]
    assert ring.header.slips == ring.states[SLIP_RECORDER]["count"] == 0
    sim = Simulation(latest.config, arrays=latest.state)         # where the stop left it, past the ring state
    guards = Guards()
    recorder = SlipRecorder(latest.config, sim, None, None, kept_with=[guards])
    phase = Phase("loading", [TrueInertia(), guards, recorder])
    phase.restore(sim, latest)
    assert len(recorder.ring) == len([k for k in latest.attached if k.startswith("ring_")]) >= 1
    writer = RunFile(RunLayout(cut).run_file, latest.config, sim.dt, mode="a", threads=1)
    try:
        phase.restore(sim, ring, writer, attached=ring_attachments([ring]))
        times = writer.h5["series/time"][...]
    finally:
        writer.close("interrupted")
    for name, values in sim.state.arrays().items():
        assert np.array_equal(values, ring.state[name]), name
    assert _same(guards.state_dict(), ring.states["guards"])
    assert _same(recorder.state_dict(), {**ring.states[SLIP_RECORDER], "deborah": [], "pending_in_ring": None})
    assert list(recorder.ring) == [ring] and recorder.pending is None
    assert times[-1] <= ring.time < times[-1] + 10.0 + 1e-9        # (series_interval 10 t0)
    # the run from the ring state, as the rollback goes on (load_phase's Phase.restore with those arguments)
    cut_dir = tmp_path / "from_ring"
    shutil.copytree(cut, cut_dir)
    sim = Simulation(ring.config, arrays=ring.state)
    writer = RunFile(RunLayout(cut_dir).run_file, ring.config, sim.dt, mode="a", threads=1)
    writer.set_attr("status", "running")
    end_time = float(writer.h5.attrs["end_time"])
    status, _ = load_phase(sim, writer, cut_dir, end_time, quiet=True,
                           resume_from=replace(ring, attached=ring_attachments([ring])))
    writer.close(status)
    assert_identical(ref, cut_dir)


def test_slip_checkpoint_starts_a_fork_that_retraces_the_run(reference, tmp_path):
    """A fork's start (Phase.restore, states=False): the drained branch from the slip checkpoint
    computes the run's rows again, bit for bit, with a catalog of its own."""
    _, ref, entry = reference
    run = tmp_path / "run"
    shutil.copytree(ref, run)
    ck = read_checkpoint(run / entry.checkpoint)
    assert ck.header.slip == entry.number and ck.header.onset_time == entry.onset_time
    assert set(ck.states) == {SLIP_RECORDER, "guards"}
    summary = run_fork(ForkRequest(run, entry.number), quiet=True)
    assert summary.branches["drained"].first_slip is not None
    branch = RunLayout(run).fork(entry.number).branch(None).run_file
    with h5py.File(RunLayout(run).run_file, "r") as ho, h5py.File(branch, "r") as hf:
        t = hf["series/time"][...]
        idx = np.searchsorted(ho["series/time"][...], t)
        assert t[0] == ck.time and np.array_equal(ho["series/time"][...][idx[1:]], t[1:])
        for name in ("wall_x", "wall_vx", "tau_over_sigma", "porosity", "kinetic_energy"):
            assert np.array_equal(ho["series"][name][...][idx[1:]], hf["series"][name][1:]), name
    assert slip_catalog(branch.parent)[0].number == 1
