"""Compile once: the kernels' argument types do not depend on where a state came from.

numba compiles a kernel again for every new set of argument types (dtype, layout, read-only
flag, int vs float scalars), minutes for the parallel step kernels. A fresh run (dry and wet)
and the bench's direct kernel calls fix the reference set of specialisations; restarts and
forks from HDF5 checkpoints, a compaction resumed, the bench's cached npz state, its
footprint profile and a state built from float32 / strided / read-only arrays must add none.
"""

from __future__ import annotations

import importlib
import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

import gouge_cli.kernels
from gouge_cli.studies import bench, bench_profile
from gouge_cli.io.checkpoint import CheckpointHeader, read_checkpoint, snapshot_of, write_checkpoint
from gouge_cli.config import build_config
from gouge_cli.kernels import layout as L
from gouge_cli.kernels import forces as F
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation
from gouge_cli.model.state import State

SCENE = {"packing": {"n_grains": 200, "width": 12}, "numerics": {"dt_safety": 0.3},
         "compaction": {"min_time": 200, "max_time": 400}}
WET = {**SCENE, "fluid": {"permeability": 1e-5}}


def specialisations() -> dict[str, set[str]]:
    """Signatures compiled or loaded so far in this process, per dispatcher of gouge_cli.kernels."""
    out = {}
    for info in pkgutil.iter_modules(gouge_cli.kernels.__path__):
        module = importlib.import_module(f"gouge_cli.kernels.{info.name}")
        for name, obj in vars(module).items():
            if isinstance(obj, numba.core.registry.CPUDispatcher) and obj.__module__ == module.__name__:
                out[f"{info.name}.{name}"] = {str(sig) for sig in obj.signatures}
    return out


def contact_forces_args(sim: Simulation) -> tuple:
    """kernels.forces.contact_forces arguments exactly as compute_forces passes them (one thread)."""
    s = sim.state
    params = sim.params.copy()
    params[L.THREADS] = 1
    return (s.grains(), s.lists(), s.pairs(), *sim.drag, params)


def step_and_observe(sim: Simulation, steps: int = 30) -> Simulation:
    sim.advance(steps)
    sim.observe()
    return sim


def via_hdf5(sim: Simulation, path, phase="loading"):
    write_checkpoint(path, snapshot_of(sim, CheckpointHeader(phase)))
    return read_checkpoint(path)


@pytest.fixture(scope="module")
def reference():
    """Fresh dry and wet runs and the bench's direct kernel calls; the specialisations they use."""
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    dry = Simulation(build_config(SCENE))
    compact(dry)
    step_and_observe(dry)
    wet = Simulation(build_config(WET))
    compact(wet)
    wet.start_fluid()
    step_and_observe(wet)
    start = dry.state.arrays()
    bench_profile.profile_step(dry, start, 1, repeats=1)
    F.contact_forces(*contact_forces_args(dry))
    yield dry, wet, start, specialisations()
    numba.set_num_threads(before)


def assert_no_new(reference_sigs: dict, path: str):
    now = specialisations()
    new = {name: sorted(now[name] - reference_sigs.get(name, set())) for name in now
           if now[name] - reference_sigs.get(name, set())}
    assert not new, f"{path} compiled a second specialisation: {new}"


def test_restarts_and_forks_reuse_the_compiled_kernels(reference, tmp_path):
    dry, wet, _, sigs = reference
    ck = via_hdf5(dry, tmp_path / "dry.h5")
    step_and_observe(Simulation(ck.config, arrays=ck.state, fluid_arrays=ck.fluid))
    assert_no_new(sigs, "a restart from a dry HDF5 checkpoint")
    step_and_observe(Simulation(build_config(WET), arrays=ck.state))
    assert_no_new(sigs, "a drained -> undrained fork of a dry checkpoint")
    ck = via_hdf5(wet, tmp_path / "wet.h5")
    step_and_observe(Simulation(ck.config, arrays=ck.state, fluid_arrays=ck.fluid))
    assert_no_new(sigs, "a restart from a wet HDF5 checkpoint")
    compacting = Simulation(build_config(SCENE))
    ck = via_hdf5(compacting, tmp_path / "compaction.h5", "compaction")
    resumed = Simulation(ck.config, arrays=ck.state)
    compact(resumed)
    step_and_observe(resumed)
    assert_no_new(sigs, "a compaction resumed from its checkpoint")


def test_the_bench_cache_and_profiles_reuse_the_compiled_kernels(reference, tmp_path):
    dry, _, start, sigs = reference
    for _ in range(2):          # the second one reads the npz the first one wrote
        sim, arrays = bench.prepare(150, 0.5, 0.2, tmp_path)
        bench.time_gouge(sim, arrays, 1, 20, 1)
    assert list(tmp_path.glob("prep_150_*.npz"))
    assert_no_new(sigs, "the bench's cached npz state")
    bench_profile.footprint_profile(dry, start, [50, 100], repeats=1)
    assert_no_new(sigs, "the bench's footprint profile (contact pass on a sub-system)")


def test_a_state_from_any_float_arrays_gets_the_kernels_types(reference):
    """float32, strided and read-only arrays and an integer width are cast at the boundary (State),
    not compiled for."""
    dry, _, _, sigs = reference
    s = dry.state
    assert s.width == int(s.width)          # SCENE is 12 d wide: an int width is the same scene
    order = np.argsort(s.id)
    x = np.repeat(s.x[order], 2).astype(np.float32)[::2]          # strided float32
    z = s.z[order].copy()
    z.flags.writeable = False
    state = State(x=x, z=z, radius=s.radius[order].astype(np.float32), body=s.body[order].astype(np.int64),
                  density=1, width=int(s.width))
    assert all(a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
               for a in (state.x, state.z, state.radius, state.vx))
    assert state.body.dtype == np.int8 and type(state.width) is float
    step_and_observe(Simulation(dry.config, state=state))
    assert_no_new(sigs, "a state built from float32 / strided / read-only arrays")


# Kernels a fresh dry + wet run compiles more than once, on purpose: permute moves arrays of three
# dtypes (int8 body, int64 ids, float64 values); the deposit runs without an owed kick once, at the
# fluid's start (fluid_init: no forces yet), and with one in every coupled step.
SEVERAL = {"reorder.permute", "deposit.deposit", "deposit._deposit_grouped", "deposit._groups_parallel",
           "deposit._velocity_range", "deposit._velocity_loop"}


@pytest.mark.validation
def test_a_fresh_cache_compiles_each_kernel_once_per_argument_kind():
    """benchmarks/compile_time.py in a fresh process and an empty numba cache (the only way to see
    the kernels a caller compiles inside itself: a cached caller loads them whole): no kernel is
    compiled again for a literal constant (kernels/__init__), only the SEVERAL kinds above."""
    repo = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, str(repo / "benchmarks" / "compile_time.py"), "--json"],
                         capture_output=True, text=True, timeout=1800, cwd=repo)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout.splitlines()[-1])
    extra = {name: args for name, args in result["repeated"].items() if name not in SEVERAL}
    assert not extra, f"compiled more than once: {extra}"
    assert result["wet_seconds"] > 0 and "coupled.advance_fluid" in result["kernels"]
