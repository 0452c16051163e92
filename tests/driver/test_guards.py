"""Run-time guards (gouge_cli.driver.guards): each fires on a planted failure with a message that
names the cause and the parameter to change, and stays quiet on a healthy scene."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gouge_cli.config import build_config
from gouge_cli.driver.guards import (FluidSubstepGuard, Guards, KineticEnergyGuard, NonFiniteGuard, OverlapGuard, Scan,
                              guard_callbacks)
from gouge_cli.driver.phases import guarded_run
from gouge_cli.driver.schedules import Every
from gouge_cli.kernels import layout as L
from gouge_cli.driver.compaction import compact
from gouge_cli.driver.simulation import Simulation
from gouge_cli.errors import PhysicsError
from gouge_cli.model.timestep import stability_bound

SCENE = {"packing": {"n_grains": 200, "width": 12}, "seed": 4,
         "loading": {"spring_constant": 2e-4, "velocity": 4e-5},
         "numerics": {"dt_safety": 0.3}, "compaction": {"min_time": 300, "max_time": 3000}}


@pytest.fixture(scope="module")
def loaded():
    """A compacted 200-grain layer loaded for 200 t0 (dry): config and state arrays."""
    sim = Simulation(build_config(SCENE))
    compact(sim)
    sim.run(200.0)
    return sim.config, sim.state.arrays()


def fresh(loaded, overrides=None):
    config, arrays = loaded
    if overrides:
        config = build_config(config.to_dict(), overrides)
    return Simulation(config, arrays=arrays)


def test_healthy_scene_passes_every_guard(loaded):
    sim = fresh(loaded)
    guards = Guards()
    for _ in range(20):
        sim.advance(40)
        guards(sim)
    scan = Scan.of(sim)
    assert scan.nonfinite == 0 and 0.0 < scan.overlap < 0.5 and scan.kinetic > 0.0 and scan.contact_energy > 0.0


def test_guards_do_not_change_the_state(loaded):
    plain, guarded = fresh(loaded), fresh(loaded)
    plain.run(100.0)
    guarded.run(100.0, guard_callbacks(guarded, interval=5.0))
    for name, arr in plain.state.arrays().items():
        assert arr.tobytes() == guarded.state.arrays()[name].tobytes(), name


def test_guards_and_series_share_one_measurement_per_row(loaded):
    """guarded_run's "guards" and "series" callbacks, due on the same steps, run the measurement
    kernel once per row; the rows are those of a plain run observed at the same steps."""
    sim = fresh(loaded)
    calls = []
    observe = sim.observe
    sim.observe = lambda: calls.append(sim.state.step) or observe()
    rows = guarded_run(sim, 50.0, interval=5.0, compact=False)
    per = sim.steps_for(5.0)
    assert len(rows) >= 1 + sim.steps_for(50.0) // per > 5
    assert len(calls) == len(rows) and len(set(calls)) == len(calls)
    plain = fresh(loaded)
    expected = [plain.observe()]
    plain.run(50.0, [Every(per, lambda s: expected.append(s.observe()), "series")])
    assert rows == expected


def test_nan_in_a_velocity(loaded):
    sim = fresh(loaded)
    NonFiniteGuard()(sim)
    free = int(np.flatnonzero(sim.state.body == 0)[7])
    sim.state.vz[free] = np.nan
    with pytest.raises(PhysicsError, match=r"non-finite state \(1 grains\)") as info:
        NonFiniteGuard()(sim)
    assert "numerics.dt_safety (now 0.3)" in str(info.value) and info.value.time == sim.state.time
    with pytest.raises(PhysicsError, match="non-finite"):
        Guards()(sim)


def test_infinite_wall_velocity(loaded):
    sim = fresh(loaded)
    sim.state.wall[L.W_VX] = np.inf
    with pytest.raises(PhysicsError, match="non-finite state \\(the top wall\\)"):
        NonFiniteGuard()(sim)


def test_forced_overlap(free_grains, single_thread):
    sim = free_grains([10.0, 11.1], [5.0, 5.0], [0.5, 0.5])      # within the skin: listed as a pair
    guard = OverlapGuard()
    guard(sim)
    sim.state.x[1] = 10.0 + 1.0 - 0.2                              # overlap 0.4 R: allowed
    guard(sim)
    sim.state.x[1] = 10.0 + 1.0 - 0.3                              # overlap 0.6 R
    with pytest.raises(PhysicsError, match=r"runaway overlap: grains 0 and 1 overlap by 0\.6 of the smaller "
                                           r"radius \(limit 0\.5\)") as info:
        guard(sim)
    assert "loading.normal_stress" in str(info.value)
    OverlapGuard(limit=0.7)(sim)


def test_kinetic_energy_blow_up(loaded):
    sim = fresh(loaded)
    guard = KineticEnergyGuard()
    for _ in range(5):
        sim.advance(40)
        guard(sim)
    s = sim.state
    free = s.body == 0
    s.vx[free] = 0.1               # energy from nowhere: every free grain at 0.1 v0 (~550 m/s in granite)
    planted = Scan.of(sim).kinetic
    assert planted > 10 * guard.margin * guard.budget(sim, float(s.wall[L.W_Z]))    # (for any packing)
    with pytest.raises(PhysicsError, match="kinetic-energy blow-up") as info:
        guard(sim)
    assert "numerics.dt_safety" in str(info.value)


def test_spring_release_is_not_a_blow_up(loaded):
    """A stretched spring releases its energy into a fast slip: kinetic energy rises by orders
    of magnitude, but stays inside what the spring supplied, so the guard keeps quiet."""
    sim = fresh(loaded)
    k0 = Scan.of(sim).kinetic
    sim.state.clock[L.C_DRIVE_TIME] += 1.5 / sim.config.loading.velocity   # spring stretched by 1.5 d more
    guard = KineticEnergyGuard()
    top = 0.0
    for _ in range(100):
        guard(sim)
        sim.advance(20)
        top = max(top, Scan.of(sim).kinetic)
    guard(sim)
    assert top > 1e3 * k0 and sim.state.wall[L.W_X] > 0.5


def test_unstable_step_is_stopped_before_nan_spreads(loaded):
    """A step 4x the stability bound (forced past the config check): the guards, every 10
    steps, stop the run with a message naming the time-step setting."""
    sim = fresh(loaded)
    sim.params[L.DT] = 4.0 * stability_bound(sim.config).bound
    with pytest.raises(PhysicsError, match="numerics.dt_safety") as info:
        sim.run(2000 * sim.params[L.DT], [guard_callbacks(sim, interval=10 * sim.dt)[0]])
    assert any(word in str(info.value) for word in ("non-finite", "kinetic-energy blow-up", "runaway overlap"))


@pytest.fixture(scope="module")
def explicit_wet(loaded):
    """The loaded layer with a very permeable pore fluid and the explicit solver."""
    config, arrays = loaded
    data = config.to_dict()
    data["fluid"] = {"permeability": 1e-1, "solver": "explicit"}
    return build_config(data), arrays


def test_explicit_fluid_substeps_above_limit(explicit_wet):
    sim = Simulation(*explicit_wet)
    sim.advance(4 * sim.fluid_interval)
    substeps = int(sim.fluid.state[L.S_SUBSTEPS])
    assert substeps > 100
    FluidSubstepGuard()(sim)
    with pytest.raises(PhysicsError, match="explicit pressure step above its bound") as info:
        FluidSubstepGuard(limit=10)(sim)
    message = str(info.value)
    assert f"needs {substeps} sub-steps per update (limit 10)" in message
    assert "fluid.solver=implicit" in message and "fluid.cell_size" in message
    bound = sim.fluid.state[L.S_DT_MAX]
    assert f"FTCS bound {bound:.3g} t0" in message and math.isfinite(bound)


def test_explicit_fluid_kernel_limit_stops_the_run(explicit_wet):
    sim = Simulation(*explicit_wet)
    sim.fluid.params[L.P_MAX_SUBSTEPS] = 5
    with pytest.raises(PhysicsError, match=r"explicit pressure step needs \d+ sub-steps .* above the limit 5"):
        sim.advance(2 * sim.fluid_interval)


def test_implicit_fluid_is_not_flagged(explicit_wet):
    config, arrays = explicit_wet
    data = config.to_dict()
    data["fluid"]["solver"] = "implicit"
    sim = Simulation(build_config(data), arrays=arrays)
    sim.advance(2 * sim.fluid_interval)
    FluidSubstepGuard(limit=0)(sim)


def test_nan_pressure(explicit_wet):
    sim = Simulation(*explicit_wet)
    sim.fluid.pressure[0, 0] = np.nan
    with pytest.raises(PhysicsError, match=r"non-finite state \(the pore pressure\)") as info:
        NonFiniteGuard()(sim)
    assert "fluid.step" in str(info.value)
