"""The grid solve shared between two threads (kernels.coupled._solve_and_drift): whichever thread
takes whichever part of whichever stage, the grid, the drag's triples and the moved grains have
the bits of the serial solve followed by the serial drift."""

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation
from gouge_cli.kernels import coupled as KC
from gouge_cli.kernels import fluid_update as KF
from gouge_cli.kernels import step as KS
from gouge_cli.kernels.layout import S_EXPLICIT_UPDATES, THREADS, W_Z
from gouge_cli.model.params import numba_threads
from needs import skip_unless_two_threads

SCENE = {"packing": {"n_grains": 600, "width": 30}, "seed": 11,
         "loading": {"spring_constant": 2e-4, "velocity": 4e-4}, "numerics": {"dt_safety": 0.3}}


def _state(sim):
    s = sim.state
    return {"x": s.x.copy(), "z": s.z.copy(), "vx": s.vx.copy(), "vz": s.vz.copy(), "spin": s.spin.copy(),
            "pressure": sim.fluid.pressure.copy(), "fluid_state": sim.fluid.state.copy(),
            "s": sim.fluid.solid_fraction.copy()}


def _restore(sim, saved):
    s = sim.state
    for key in ("x", "z", "vx", "vz", "spin"):
        getattr(s, key)[:] = saved[key]
    sim.fluid.pressure[:] = saved["pressure"]
    sim.fluid.state[:] = saved["fluid_state"]
    sim.fluid.solid_fraction[:] = saved["s"]


def _update(sim, threads):
    """One fluid update with the next step's drift, as kernels.coupled.advance_fluid makes it:
    on one thread fluid_solve then every grain moved; on two the shared region. Returns the
    grid's arrays and the grains' positions and velocities after it."""
    s, fl, lists = sim.state, sim.fluid.record(), sim.state.lists()
    params = sim.params.copy()
    params[THREADS] = threads
    z_bot, z_top = sim.wall_planes()[0], float(s.wall[W_Z])
    dt_f = sim.fluid_interval * sim.dt
    serial = threads == 1
    KF.fluid_begin(s.x, s.z, s.vx, s.vz, s.radius, s.n, s.width, z_bot, z_top, dt_f, fl, None, serial, serial)
    KC._solve_and_drift(s.x, s.z, s.vx, s.vz, s.spin, s.force_x, s.force_z, s.torque, s.inv_mass, s.inv_inertia,
                        s.body, lists.x_build, lists.z_build, False, params, s.width, z_bot, z_top, dt_f, fl,
                        not serial, lists.cell_count)
    status = int(lists.cell_count[0])
    return status, {"pressure": fl.pressure.copy(), "s": fl.s.copy(), "ux": fl.ux.copy(), "uz": fl.uz.copy(),
                    "work": fl.work[:KF.G_TMP].copy(), "x": s.x.copy(), "z": s.z.copy(), "vx": s.vx.copy()}


@pytest.mark.parametrize("fluid, heun", [({"permeability": 1e-5, "solver": "implicit"}, False),
                                         ({"permeability": 1e-8}, True)])      # (auto: Heun, far below its bound)
def test_shared_grid_solve_has_the_serial_bits(fluid, heun):
    """30 updates from one state on two threads (the parts go to whichever thread takes them
    first, which changes from call to call) against the one-thread update: every array equal to
    the bit. With backward Euler (solved by thread 0 between the shared stages) and with Heun's
    step (its two halves shared)."""
    sim = Simulation(build_config(dict(SCENE, fluid=fluid)))
    compact(sim)
    sim.advance(3000)
    assert sim.fluid is not None and sim.fluid.nx >= 2
    saved = _state(sim)
    explicit = sim.fluid.state[S_EXPLICIT_UPDATES]
    status, serial = _update(sim, 1)
    assert status == 0 and np.abs(serial["pressure"]).max() > 0
    assert (sim.fluid.state[S_EXPLICIT_UPDATES] > explicit) == heun
    skip_unless_two_threads("the shared grid solve")
    with numba_threads(2):
        for trial in range(30):
            _restore(sim, saved)
            status, shared = _update(sim, 2)
            assert status == 0
            for key, value in serial.items():
                assert np.array_equal(shared[key], value), (trial, key)
